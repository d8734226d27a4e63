//! Sizes a compressed chunk claims, checked before the `exr` crate decodes it.
//!
//! A decoder that allocates what a damaged chunk claims does not fail with an
//! error: the allocation aborts the process (`memory allocation of
//! 35184372088832 bytes failed`), which no `catch_unwind` can stop. So every
//! size field a decoder trusts when it allocates is checked here against what
//! the block can hold, before the chunk reaches the crate. From reading the
//! decompressors of `exr` 1.74:
//!
//! * **DWAA / DWAB** trust the chunk's fixed header of eleven little-endian
//!   `u64` counters: the UNKNOWN section's inflated size is allocated at once
//!   (zlib size hint), as are the AC and DC coefficient counts (`Vec` capacity,
//!   and `count * 2` bytes for zlib) and the RLE section's inflated size; the
//!   RLE output grows up to the claimed raw size. The compressed sizes are
//!   checked by the crate against the chunk before anything is allocated.
//! * **ZIP, ZIPS, PXR24, RLE, PIZ, B44, B44A** allocate from the block's own
//!   pixel size (its rectangle times the bytes per pixel), never from a field
//!   of the chunk: PIZ's Huffman tables and bitmap are of fixed size, and its
//!   decoder output is sized by the block. The block size comes from the
//!   header and is checked against the memory limit when the file is opened
//!   ([`super::ExrInput::block_bytes`]).
//! * **NONE**: the chunk's data must be present in the file.
//!
//! The bounds are what a valid chunk of that block can need, with room to
//! spare; a chunk beyond them is damaged.

use exr::meta::attribute::ChannelList;
use exr::prelude::Compression;

/// Bytes of the DWA chunk leader: eleven `u64` counters.
const DWA_LEADER: usize = 11 * 8;

/// The leader's counters, in on-disk order (OpenEXR's `DataSizesSingle`).
const DWA_FIELDS: [&str; 11] = [
    "version",
    "unknown uncompressed size",
    "unknown compressed size",
    "AC compressed size",
    "DC compressed size",
    "RLE compressed size",
    "RLE uncompressed size",
    "RLE raw size",
    "AC count",
    "DC count",
    "AC compression",
];

/// Check the sizes that the compressed data of one block of `w` x `h` pixels
/// claims. `Err` names the field, its value and the bound.
pub fn check(
    compression: Compression,
    channels: &ChannelList,
    w: usize,
    h: usize,
    data: &[u8],
) -> Result<(), String> {
    match compression {
        Compression::DWAA(_) | Compression::DWAB(_) => check_dwa(channels, w, h, data),
        _ => Ok(()),
    }
}

fn check_dwa(channels: &ChannelList, w: usize, h: usize, data: &[u8]) -> Result<(), String> {
    let raw = w.saturating_mul(h).saturating_mul(channels.bytes_per_pixel);
    // An empty chunk, or one stored raw because compressing did not help, has
    // no leader; one shorter than the leader is refused by the crate.
    if data.is_empty() || data.len() == raw || data.len() < DWA_LEADER {
        return Ok(());
    }
    let counter = |k: usize| {
        let b: [u8; 8] = data[k * 8..k * 8 + 8].try_into().unwrap_or([0xff; 8]);
        u64::from_le_bytes(b)
    };
    // 8x8 DCT blocks of every channel (an upper bound: only lossy channels
    // have them), each with one DC and at most 63 AC coefficients.
    let dct_blocks = (channels.list.len() as u64)
        .saturating_mul(w.div_ceil(8) as u64)
        .saturating_mul(h.div_ceil(8) as u64);
    let raw = raw as u64;
    let body = (data.len() - DWA_LEADER) as u64;
    let bounds: [(usize, u64); 7] = [
        (1, raw),
        (6, raw.saturating_mul(2).saturating_add(64)),
        (7, raw),
        (8, dct_blocks.saturating_mul(63)),
        (9, dct_blocks),
        // The compressed sections lie in the chunk (the crate checks this
        // too, but without overflow it needs each to fit on its own).
        (2, body),
        (3, body),
    ];
    for (k, limit) in bounds {
        let v = counter(k);
        if v > limit {
            return Err(format!(
                "DWA chunk claims {} = {v}, more than a {w}x{h} block can hold ({limit})",
                DWA_FIELDS[k]
            ));
        }
    }
    let sections: u64 = (2..=5).map(counter).fold(0u64, u64::saturating_add);
    if sections > body {
        return Err(format!(
            "DWA chunk claims {sections} bytes of compressed sections in {body} bytes of data"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::meta::attribute::{ChannelDescription, SampleType};
    use exr::prelude::{SmallVec, Text};

    fn rgb() -> ChannelList {
        let list: SmallVec<[ChannelDescription; 5]> = ["B", "G", "R"]
            .iter()
            .map(|n| ChannelDescription::new(Text::from(*n), SampleType::F16, false))
            .collect();
        ChannelList::new(list)
    }

    fn leader(counters: [u64; 11], body: usize) -> Vec<u8> {
        let mut v: Vec<u8> = counters.iter().flat_map(|c| c.to_le_bytes()).collect();
        v.resize(v.len() + body, 0);
        v
    }

    #[test]
    fn a_plausible_leader_passes_and_each_enlarged_field_is_named() {
        // 64x32 RGB half: 12288 raw bytes, 3 * 8 * 4 = 96 DCT blocks.
        let ok = [2, 100, 40, 300, 50, 20, 200, 100, 2000, 96, 0];
        let data = leader(ok, 410);
        assert_eq!(
            check(Compression::DWAA(None), &rgb(), 64, 32, &data),
            Ok(())
        );
        for k in [1usize, 2, 3, 6, 7, 8, 9] {
            let mut c = ok;
            c[k] = 1 << 45;
            let err = check(Compression::DWAB(None), &rgb(), 64, 32, &leader(c, 410)).unwrap_err();
            assert!(err.contains(DWA_FIELDS[k]), "{k}: {err}");
        }
        let mut c = ok;
        c[5] = 400; // fits alone, not with the others
        assert!(check(Compression::DWAA(None), &rgb(), 64, 32, &leader(c, 410)).is_err());
    }

    #[test]
    fn raw_empty_and_other_codecs_are_left_to_the_decoder() {
        let raw = vec![7u8; 64 * 32 * 6];
        assert_eq!(check(Compression::DWAA(None), &rgb(), 64, 32, &raw), Ok(()));
        assert_eq!(check(Compression::DWAA(None), &rgb(), 64, 32, &[]), Ok(()));
        let junk = vec![0xffu8; 200];
        assert_eq!(check(Compression::ZIP16, &rgb(), 64, 32, &junk), Ok(()));
        assert!(check(Compression::DWAA(None), &rgb(), 64, 32, &junk).is_err());
    }
}
