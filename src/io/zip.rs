//! ZIP / ZIPS block coding: encoding for the writer, with a faster deflate
//! level, and decoding for the reader without a per-thread buffer.
//!
//! The format is OpenEXR's: little-endian samples, even and odd bytes split
//! into two halves, a byte-wise delta predictor (`d = b[i] - b[i-1] + 128`),
//! then zlib. A block that does not shrink is stored raw (readers recognise it
//! by its size). `exr` compresses at a fixed level 4, about 9x slower than it
//! decodes; at level 1 the same deflate implementation is several times
//! faster with files within a few percent in size (measured in the closing
//! notes of the pipeline issue), and any reader decodes them the same.

/// Deflate level used for output ZIP blocks (miniz_oxide, 1 = fastest).
pub const ZIP_LEVEL: u8 = 1;

/// Encode the little-endian bytes of one block.
pub fn compress(le: &[u8], level: u8) -> Vec<u8> {
    let n = le.len();
    let half = n.div_ceil(2);
    let mut buf = vec![0u8; n];
    {
        let (first, second) = buf.split_at_mut(half);
        for ((a, b), pair) in first
            .iter_mut()
            .zip(second.iter_mut())
            .zip(le.chunks_exact(2))
        {
            *a = pair[0];
            *b = pair[1];
        }
        if n % 2 == 1 {
            first[half - 1] = le[n - 1];
        }
    }
    for i in (1..n).rev() {
        buf[i] = buf[i].wrapping_sub(buf[i - 1]).wrapping_add(128);
    }
    let packed = miniz_oxide::deflate::compress_to_vec_zlib(&buf, level);
    if packed.len() < n {
        packed
    } else {
        le.to_vec()
    }
}

/// Room the inflater asks for past the end of its output: zune-inflate
/// 0.2's `FASTLOOP_MAX_BYTES_WRITTEN` (about 600 bytes) and
/// `FASTCOPY_BYTES`, with a margin.
const INFLATE_SLACK: usize = 4096;

/// Decode the zlib stream of one ZIP / ZIPS block that holds `expected`
/// bytes: inflate (at most `expected` bytes) and undo the delta predictor,
/// leaving the bytes split: byte `j` of the block is `out[j / 2]` for even
/// `j` and `out[half + j / 2]` for odd `j`, `half = expected.div_ceil(2)`
/// ([`split_byte`]). `None` when the stream is damaged or decodes to another
/// size.
///
/// `exr` (1.74) interleaves each decoded block back through a per-thread
/// scratch buffer as large as the largest block that thread has seen, kept
/// for the life of the thread. At 32769 float RGB samples a block is 6.3 MB,
/// so every worker (and the reader, filter and writer threads) held one:
/// peak memory grew from 130 MiB at 2 threads to 345 MiB at 16. Here the
/// reader takes the samples straight from the split bytes: no second buffer,
/// and one pass less over the block.
pub fn unpredict(packed: &[u8], expected: usize) -> Option<Vec<u8>> {
    // The decoder's fast loop wants `INFLATE_SLACK` bytes of room past
    // what it writes: a buffer of exactly `expected` bytes is grown at its
    // last few hundred bytes, and growing doubles its capacity (held until
    // the block is dropped: twice the block, per decoding worker).
    let options = zune_inflate::DeflateOptions::default()
        .set_limit(expected)
        .set_size_hint(expected + INFLATE_SLACK);
    let mut t = zune_inflate::DeflateDecoder::new_with_options(packed, options)
        .decode_zlib()
        .ok()?;
    if t.len() != expected {
        return None;
    }
    // The predictor stored `b[i] - b[i-1] + 128`: a running sum of
    // `d ^ 0x80` (that is, `d - 128` mod 256) undoes it, eight bytes at a
    // time (the sum within eight does not wait for the eight before).
    if let Some((first, rest)) = t.split_first_mut() {
        let mut prev = *first;
        let mut eights = rest.chunks_exact_mut(8);
        for c in &mut eights {
            let b = run8(prev, c);
            c.copy_from_slice(&b);
            prev = b[7];
        }
        for v in eights.into_remainder() {
            prev = prev.wrapping_add(*v ^ 0x80);
            *v = prev;
        }
    }
    Some(t)
}

/// The running sum of `d ^ 0x80` over eight bytes, after `prev`: the bytes
/// added lane by lane in a `u64` (no carry between lanes), the prefix in
/// three shifted adds.
#[inline]
fn run8(prev: u8, d: &[u8]) -> [u8; 8] {
    const LOW: u64 = 0x7f7f_7f7f_7f7f_7f7f;
    const HIGH: u64 = 0x8080_8080_8080_8080;
    #[inline]
    fn add(a: u64, b: u64) -> u64 {
        ((a & LOW) + (b & LOW)) ^ ((a ^ b) & HIGH)
    }
    let mut bytes = [0u8; 8];
    bytes.copy_from_slice(d);
    let mut x = u64::from_le_bytes(bytes) ^ HIGH;
    x = add(x, x << 8);
    x = add(x, x << 16);
    x = add(x, x << 32);
    add(x, u64::from(prev) * 0x0101_0101_0101_0101).to_le_bytes()
}

/// Byte `j` of a block whose bytes are split as [`unpredict`] leaves them.
#[inline]
pub fn split_byte(split: &[u8], j: usize) -> u8 {
    let half = split.len().div_ceil(2);
    if j % 2 == 0 {
        split[j / 2]
    } else {
        split[half + j / 2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The format as OpenEXR writes it, byte by byte: the reference.
    fn decode_reference(le: &[u8]) -> Vec<u8> {
        let mut t = le.to_vec();
        for i in 1..t.len() {
            t[i] = (t[i - 1] as i32 + t[i] as i32 - 128) as u8;
        }
        let half = t.len().div_ceil(2);
        let mut out = Vec::with_capacity(t.len());
        for k in 0..t.len() {
            out.push(if k % 2 == 0 {
                t[k / 2]
            } else {
                t[half + k / 2]
            });
        }
        out
    }

    /// The block's bytes in order.
    fn decompress(packed: &[u8], n: usize) -> Option<Vec<u8>> {
        unpredict(packed, n).map(|t| (0..n).map(|j| split_byte(&t, j)).collect())
    }

    #[test]
    fn decompress_inverts_compress_at_every_length() {
        // Lengths around the eight-byte runs, odd and even, and a real block.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        for n in (0..80).chain([1000, 4097, 6 * 1024 + 3]) {
            let data: Vec<u8> = (0..n)
                .map(|i| {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    if i % 3 == 0 {
                        (seed >> 56) as u8
                    } else {
                        (i / 7) as u8
                    }
                })
                .collect();
            let packed = compress(&data, ZIP_LEVEL);
            if packed.len() == n {
                continue; // stored raw: the reader takes it as it is
            }
            assert_eq!(
                decompress(&packed, n).as_deref(),
                Some(&data[..]),
                "n = {n}"
            );
        }
    }

    #[test]
    fn decompress_matches_the_byte_by_byte_reference() {
        for n in [1usize, 2, 3, 17, 18, 33, 250] {
            let predicted: Vec<u8> = (0..n).map(|i| (i * 37 + 11) as u8).collect();
            let packed = miniz_oxide::deflate::compress_to_vec_zlib(&predicted, 6);
            assert_eq!(
                decompress(&packed, n),
                Some(decode_reference(&predicted)),
                "n = {n}"
            );
        }
    }

    #[test]
    fn decompress_refuses_damage_and_wrong_sizes() {
        let data = vec![7u8; 300];
        let packed = compress(&data, ZIP_LEVEL);
        assert_eq!(decompress(&packed, 299), None);
        assert_eq!(decompress(&packed, 301), None);
        let mut bad = packed.clone();
        bad.truncate(packed.len() / 2);
        assert_eq!(decompress(&bad, 300), None);
        assert_eq!(decompress(&[], 300), None);
    }
}
