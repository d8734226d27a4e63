//! Chunks whose size fields lie: the sizes a decoder would allocate are
//! checked first (`src/io/chunk_sizes.rs`), so a damaged file gives one line
//! and status 1, never an abort, in every command that reads pixels.

use std::path::Path;
use std::process::{Command, Output};

use crate::corpus::data_dir;
use crate::exr_io::tmpdir;
use exr::io::{PeekRead, Tracking};
use exr::meta::header::Header;
use exr::meta::{magic_number, BlockDescription, MetaData, Requirements};

/// Address space a damaged file may make epfilt use (`ulimit -v`, KiB): far
/// above what these small files need (threads, stacks and the binary take
/// a few hundred MiB of address space), far below what a lying size field
/// claims, so an unchecked allocation fails and aborts the process.
const ADDRESS_SPACE_KIB: u64 = 4 << 20;

/// (start, length) of each chunk's compressed data in a single-part file.
fn chunk_data(bytes: &[u8]) -> (Header, Vec<(usize, usize)>) {
    let mut read = PeekRead::new(Tracking::new(bytes));
    assert!(magic_number::is_exr(&mut read).unwrap());
    let req = Requirements::read(&mut read).unwrap();
    let headers = Header::read_all(&mut read, &req, false).unwrap();
    let tables = MetaData::read_offset_tables(&mut read, &headers).unwrap();
    let header = headers[0].clone();
    let skip = match header.blocks {
        BlockDescription::ScanLines => 4,
        BlockDescription::Tiles(_) => 16,
    };
    let chunks = tables[0]
        .iter()
        .map(|&o| {
            let at = o as usize + skip;
            let len = i32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
            (at + 4, len)
        })
        .collect();
    (header, chunks)
}

/// Run the binary under the address-space limit.
fn run_limited(args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {ADDRESS_SPACE_KIB}; exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_epfilt"))
        .args(args)
        .output()
        .expect("sh")
}

/// Fails unless `o` is a success or one clear line with status 1.
fn clean_outcome(o: &Output, what: &str, file: &Path) {
    clean_outcome_of(o, what, file, &[1]);
}

/// [`clean_outcome`] for a command whose failures have statuses of their
/// own (`compare`'s, as idiff's: 3 sizes differ, 4 a file unreadable).
fn clean_outcome_of(o: &Output, what: &str, file: &Path, failures: &[i32]) {
    let err = String::from_utf8_lossy(&o.stderr);
    match o.status.code() {
        Some(0) => {}
        Some(c) if failures.contains(&c) => {
            assert_eq!(err.trim_end().lines().count(), 1, "{what}: {err}");
            let name = file.file_name().unwrap().to_string_lossy();
            assert!(
                err.contains(&*name),
                "{what}: error does not name the file: {err}"
            );
        }
        other => panic!("{what}: status {other:?} (killed by a signal?): {err}"),
    }
}

#[test]
fn dwa_chunks_with_enlarged_or_flipped_size_fields_never_abort() {
    let dir = tmpdir();
    let out = dir.path().join("o.exr");
    let png = dir.path().join("o.png");
    for name in [
        "small/dwaa_half_rgba.exr",
        "small/dwab_half_rgb_float_z.exr",
        "small/dwaa_tiled_half_rgb.exr",
    ] {
        let original = data_dir().join(name);
        let bytes = std::fs::read(&original).unwrap();
        let (header, chunks) = chunk_data(&bytes);
        assert!(matches!(
            header.compression,
            exr::prelude::Compression::DWAA(_) | exr::prelude::Compression::DWAB(_)
        ));
        // The largest chunk: compressed, with every section in use.
        let &(start, len) = chunks.iter().max_by_key(|c| c.1).unwrap();
        assert!(len > 88, "{name}: chunk too small to hold a DWA leader");
        // The fields a decoder allocates from (see chunk_sizes.rs), and the
        // compressed sizes.
        for field in 1..=9usize {
            let at = start + field * 8;
            let value = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
            for lie in [
                value ^ (1 << 40),
                value.saturating_mul(4).saturating_add(1 << 20),
                1 << 45,
                i64::MAX as u64 - 7,
            ] {
                let mut damaged = bytes.clone();
                damaged[at..at + 8].copy_from_slice(&lie.to_le_bytes());
                let file = dir
                    .path()
                    .join(format!("{}-{field}-{lie}.exr", name.replace('/', "_")));
                std::fs::write(&file, &damaged).unwrap();
                let f = file.to_str().unwrap();
                let what = format!("{name} field {field} = {lie}");
                let o = run_limited(&["filter", f, out.to_str().unwrap(), "-s", "1", "-q"]);
                clean_outcome(&o, &format!("filter, {what}"), &file);
                if o.status.code() == Some(1) {
                    assert!(!out.exists(), "{what}: output left behind");
                }
                let o = run_limited(&["preview", f, png.to_str().unwrap()]);
                clean_outcome(&o, &format!("preview, {what}"), &file);
                let o = run_limited(&["compare", f, original.to_str().unwrap()]);
                clean_outcome_of(&o, &format!("compare, {what}"), &file, &[3, 4]);
                std::fs::remove_file(&file).unwrap();
                let _ = std::fs::remove_file(&out);
            }
        }
    }
}

#[test]
fn the_size_check_names_the_field_it_refuses() {
    let dir = tmpdir();
    let original = data_dir().join("small/dwaa_half_rgba.exr");
    let bytes = std::fs::read(&original).unwrap();
    let (_, chunks) = chunk_data(&bytes);
    let &(start, _) = chunks.iter().max_by_key(|c| c.1).unwrap();
    for (field, words) in [
        (1, "unknown uncompressed size"),
        (8, "AC count"),
        (9, "DC count"),
    ] {
        let mut damaged = bytes.clone();
        damaged[start + field * 8..start + field * 8 + 8]
            .copy_from_slice(&(1u64 << 45).to_le_bytes());
        let file = dir.path().join("d.exr");
        std::fs::write(&file, &damaged).unwrap();
        let out = dir.path().join("o.exr");
        let job = epfilt::FilterJob::new(
            &file,
            &out,
            epfilt::FilterParams::new(epfilt::Method::Box, 1),
        );
        let err = epfilt::filter_file(&job, &|_, _| {})
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(words) && err.contains("d.exr") && err.contains("block at byte"),
            "{err}"
        );
    }
}
