//! The reader's unit tests.

use super::layers::layer_colour;
use super::*;

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// `exr`'s own reading of a chunk, with the checks `read_chunk` makes:
/// what the borrowed reader must agree with.
fn exr_read_chunk(
    bytes: &[u8],
    meta: &MetaData,
    part: usize,
    offset: usize,
    expected: TileCoordinates,
) -> Option<(Chunk, usize)> {
    let mut slice = bytes.get(offset..)?;
    let chunk = Chunk::read(&mut slice, meta).ok()?;
    let end = bytes.len() - slice.len();
    let found = meta.headers[chunk.layer_index]
        .get_block_data_indices(&chunk.compressed_block)
        .ok()?;
    (chunk.layer_index == part && found == expected).then_some((chunk, end))
}

/// What a flat chunk holds (`Chunk` has no `PartialEq`).
fn key(c: &Chunk) -> (usize, Option<i32>, Option<TileCoordinates>, &[u8]) {
    match &c.compressed_block {
        CompressedBlock::ScanLine(b) => (
            c.layer_index,
            Some(b.y_coordinate),
            None,
            &b.compressed_pixels_le,
        ),
        CompressedBlock::Tile(t) => (
            c.layer_index,
            None,
            Some(t.coordinates),
            &t.compressed_pixels_le,
        ),
        _ => unreachable!("deep parts are skipped"),
    }
}

#[test]
fn borrowed_chunks_are_the_chunks_exr_reads() {
    // Every block of every flat part of the repository's files, damaged
    // ones included, and every block's leader cut short or with a
    // corrupted size: the same chunk and end, or an error for both.
    let mut files = Vec::new();
    let mut dirs = vec![std::path::PathBuf::from("tests/data/exr")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "exr") || d.ends_with("Damaged") {
                files.push(p);
            }
        }
    }
    files.sort();
    let (mut blocks, mut agreed_errors) = (0, 0);
    for path in &files {
        let bytes = std::fs::read(path).unwrap();
        let Ok((meta, tables, _)) = parse_meta(path, &bytes) else {
            continue;
        };
        for (part, header) in meta.headers.iter().enumerate() {
            if header.deep {
                continue;
            }
            for (index, tile) in header.blocks_increasing_y_order().enumerate() {
                let Some(&offset) = tables[part].get(index) else {
                    continue;
                };
                let offset = offset as usize;
                let mut variants = vec![bytes.clone()];
                // Cut inside the leader and inside the data.
                for cut in [offset + 2, offset + 6, offset + 9, offset + 40] {
                    if cut < bytes.len() {
                        variants.push(bytes[..cut].to_vec());
                    }
                }
                // A size field of -1 and of i32::MAX where a scan-line
                // block (4 bytes on) or a tile (16 bytes on) keeps it.
                let skip = if meta.requirements.is_multilayer() {
                    4
                } else {
                    0
                };
                for field in [4, 16] {
                    for v in [-1i32, i32::MAX] {
                        let at = offset + skip + field;
                        if at + 4 <= bytes.len() {
                            let mut b = bytes.clone();
                            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
                            variants.push(b);
                        }
                    }
                }
                for b in &variants {
                    let ours = read_chunk(path, b, &meta, part, offset, tile.location).ok();
                    let theirs = exr_read_chunk(b, &meta, part, offset, tile.location);
                    match (ours, theirs) {
                        (Some((c, end)), Some((d, e))) => {
                            assert!(
                                key(&c.to_chunk()) == key(&d) && end == e,
                                "{path:?} block {index}"
                            );
                            blocks += 1;
                        }
                        (None, None) => agreed_errors += 1,
                        (o, t) => panic!(
                            "{path:?} part {part} block {index}: ours {}, exr's {}",
                            o.is_some(),
                            t.is_some()
                        ),
                    }
                }
            }
        }
    }
    assert!(
        blocks > 1000 && agreed_errors > 1000,
        "{blocks} {agreed_errors}"
    );
}

#[test]
fn a_vector_layer_is_not_a_luminance() {
    let n = names(&[
        "Y", "N.X", "N.Y", "N.Z", "vel.X", "vel.Y", "grey.Y", "grey.A",
    ]);
    assert_eq!(layer_colour(&n, ""), Some(vec!["Y"]));
    assert_eq!(layer_colour(&n, "N."), None);
    assert_eq!(layer_colour(&n, "vel."), None);
    assert_eq!(layer_colour(&n, "grey."), Some(vec!["Y", "A"]));
    // Unlayered X, Y, Z (a Radiance XYZE picture's) keep their Y.
    assert_eq!(layer_colour(&names(&["X", "Y", "Z"]), ""), Some(vec!["Y"]));
}

/// An RGB float file of `w` x `h` in `dir`, in `compression`, its
/// samples counting up: its path and its rows.
fn counting_rgb(
    dir: &std::path::Path,
    (w, h): (usize, usize),
    compression: exr::prelude::Compression,
) -> (std::path::PathBuf, Vec<f32>) {
    use crate::pipeline::{Precision, Sink};
    let path = dir.join("rgb.exr");
    let channels = names(&["R", "G", "B"]);
    let mut out = crate::io::writer::ExrOutput::create_new(
        &path,
        w,
        h,
        &channels,
        compression,
        Precision::F32,
        &[],
    )
    .unwrap();
    let rows: Vec<f32> = (0..w * h * 3).map(|i| i as f32).collect();
    out.write_rows(0, h, &rows).unwrap();
    out.finish().unwrap();
    out.commit().unwrap();
    (path, rows)
}

#[test]
fn a_batch_without_a_decoder_holds_the_blocks_asked_for() {
    // One-line blocks: 64 of them, a few hundred bytes each, so the
    // default batch (READ_AHEAD_BYTES of blocks) is the whole image.
    let (w, h) = (4, 64);
    let dir = tempfile::tempdir().unwrap();
    let (path, rows) = counting_rgb(dir.path(), (w, h), exr::prelude::Compression::ZIP1);
    let input = ExrInput::open(&path, None).unwrap();
    let buffered = |blocks: usize| {
        let mut src = input.source().with_batch_blocks(blocks);
        let strip = crate::pipeline::Source::next_strip(&mut src, 1)
            .unwrap()
            .unwrap();
        assert_eq!(strip.data, rows[..w * 3]);
        match src {
            InputSource::Exr(e) => e.buf.len() / (w * 3),
            _ => unreachable!("an EXR"),
        }
    };
    assert_eq!(buffered(0), h);
    assert_eq!(buffered(2), 2);
}

#[test]
fn a_strip_given_back_holds_the_next_one() {
    use crate::pipeline::Source;
    let (w, h) = (8, 32);
    let dir = tempfile::tempdir().unwrap();
    let (path, rows) = counting_rgb(dir.path(), (w, h), exr::prelude::Compression::ZIP16);
    let input = ExrInput::open(&path, None).unwrap();
    let mut src = input.source();
    // A buffer far larger than a strip: a strip made in it keeps its
    // capacity, a fresh one has only its rows'.
    const GIVEN: usize = 4096;
    let row = w * 3;
    let mut y = 0;
    while let Some(strip) = src.next_strip(4).unwrap() {
        assert_eq!(strip.data, rows[y * row..(y + strip.rows) * row]);
        if y > 0 {
            assert!(strip.data.capacity() >= GIVEN, "a fresh buffer at row {y}");
        }
        y += strip.rows;
        src.give_back(Vec::with_capacity(GIVEN));
    }
    assert_eq!(y, h);
}

#[test]
fn the_largest_chunk_is_the_widest_gap_to_the_next_or_the_end() {
    assert_eq!(
        blocks::largest_chunk([100, 10, 40].into_iter(), 130),
        Some(60)
    );
    assert_eq!(blocks::largest_chunk([10].into_iter(), 12), Some(2));
    assert_eq!(blocks::largest_chunk(std::iter::empty(), 12), None);
}

/// What the reader's window holds of the mapped file a block: at least
/// each chunk's bytes, at most a decoded block.
#[test]
fn a_block_stored_bounds_its_chunks_and_no_more_than_it_decodes_to() {
    use exr::prelude::Compression;
    let (w, h) = (64, 48);
    for compression in [Compression::Uncompressed, Compression::ZIP16] {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = counting_rgb(dir.path(), (w, h), compression);
        let input = ExrInput::open(&path, None).unwrap();
        let (stored, decoded) = (input.stored_block_bytes(), input.block_bytes());
        assert!(stored <= decoded, "{compression:?}");
        let bytes = std::fs::read(&path).unwrap();
        for r in &input.rows {
            for &(offset, at) in &r.chunks {
                let (_, end) = exr_read_chunk(&bytes, &input.meta, 0, offset, at).unwrap();
                let chunk = (end - offset) as u64;
                assert!(chunk <= stored || stored == decoded, "{compression:?}");
            }
        }
        if compression == Compression::ZIP16 {
            assert!(stored < decoded, "counting values compress");
        }
    }
}
