//! ZIP / ZIPS block coding: encoding for the writer, with a faster deflate
//! level, and decoding for the reader into a buffer it hands in.
//!
//! The format is OpenEXR's: little-endian samples, even and odd bytes split
//! into two halves, a byte-wise delta predictor (`d = b[i] - b[i-1] + 128`),
//! then zlib. A block that does not shrink is stored raw (readers recognise it
//! by its size). `exr` compresses at a fixed level 4, many times slower than
//! it decodes; at level 1 the same deflate implementation is several times
//! faster with files of nearly the same size, and any reader decodes them
//! the same.

/// Deflate level used for output ZIP blocks (miniz_oxide, 1 = fastest).
pub const ZIP_LEVEL: u8 = 1;

/// Whether blocks of `compression` are coded here rather than by `exr`: ZIP
/// and ZIPS, on a little-endian machine (the samples' bytes as they lie in
/// memory are the file's).
pub fn codes(compression: exr::compression::Compression) -> bool {
    use exr::compression::Compression;
    cfg!(target_endian = "little") && matches!(compression, Compression::ZIP1 | Compression::ZIP16)
}

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
    pack(&mut buf, level).unwrap_or_else(|| le.to_vec())
}

/// Apply the delta predictor to a block's split bytes and deflate them:
/// the stream, or `None` (the split bytes as they came) when it is no
/// smaller.
fn pack(buf: &mut [u8], level: u8) -> Option<Vec<u8>> {
    let n = buf.len();
    for i in (1..n).rev() {
        buf[i] = buf[i].wrapping_sub(buf[i - 1]).wrapping_add(128);
    }
    let packed = miniz_oxide::deflate::compress_to_vec_zlib(buf, level);
    if packed.len() < n {
        return Some(packed);
    }
    undo_predictor(buf, None);
    None
}

/// One block's bytes split as ZIP deflates them, filled sample by sample:
/// byte `j` of the block at `j / 2` for even `j`, at `half + j / 2` for odd
/// `j`. The writer's samples go there straight, with no buffer of the
/// block's bytes in between (on wide inputs, megabytes a compression task).
pub struct SplitBlock {
    buf: Vec<u8>,
    /// Pairs of bytes filled.
    pairs: usize,
}

impl SplitBlock {
    /// A block of `pairs` pairs of bytes (samples are 2 or 4 bytes), in
    /// `buf` (a buffer of an earlier block, or empty): on wide outputs a
    /// block is megabytes, and a fresh one a block costs as much in page
    /// faults as its deflate. Every byte is written before it is read.
    pub fn new_in(mut buf: Vec<u8>, pairs: usize) -> Self {
        buf.truncate(2 * pairs);
        buf.resize(2 * pairs, 0);
        SplitBlock { buf, pairs: 0 }
    }

    /// Append `src`'s samples, `N` little-endian bytes each (`N` even);
    /// samples past the block's end are left out.
    #[inline]
    pub fn push<T: Copy, const N: usize>(&mut self, src: &[T], le: impl Fn(T) -> [u8; N]) {
        let half = self.buf.len() / 2;
        let per = N / 2;
        let count = src.len().min((half - self.pairs) / per.max(1));
        let (first, second) = self.buf.split_at_mut(half);
        let at = self.pairs..self.pairs + count * per;
        for ((v, a), b) in src[..count]
            .iter()
            .zip(first[at.clone()].chunks_exact_mut(per))
            .zip(second[at].chunks_exact_mut(per))
        {
            let bytes = le(*v);
            for (k, pair) in bytes.chunks_exact(2).enumerate() {
                a[k] = pair[0];
                b[k] = pair[1];
            }
        }
        self.pairs += count * per;
    }

    /// The block's ZIP stream ([`compress`] of its bytes), and its buffer
    /// for the next block.
    pub fn compress(mut self, level: u8) -> (Vec<u8>, Vec<u8>) {
        let stream = pack(&mut self.buf, level).unwrap_or_else(|| {
            let half = self.buf.len() / 2;
            let (first, second) = self.buf.split_at(half);
            first
                .iter()
                .zip(second)
                .flat_map(|(&a, &b)| [a, b])
                .collect()
        });
        (stream, self.buf)
    }
}

/// Decode the zlib stream of one ZIP / ZIPS block that holds `expected`
/// bytes into `out`: inflate (at most `expected` bytes) and undo the delta
/// predictor, leaving the bytes split: byte `j` of the block is `out[j / 2]`
/// for even `j` and `out[half + j / 2]` for odd `j`, `half =
/// expected.div_ceil(2)` ([`split_byte`]). `false` when the stream is damaged
/// or decodes to another size.
///
/// The reader takes the samples from the split bytes where it cannot decode
/// a block in place ([`decode_into`]: half floats, some of the channels,
/// tiles).
///
/// `exr` (1.74) interleaves each decoded block back through a per-thread
/// scratch buffer as large as the largest block that thread has seen, kept
/// for the life of the thread. On wide inputs a block is megabytes, so every
/// worker (and the reader, filter and writer threads) held one, and peak
/// memory grew with the threads. Here the
/// reader takes the samples straight from the split bytes: no second buffer,
/// and one pass less over the block.
pub fn unpredict(packed: &[u8], expected: usize) -> Option<Vec<u8>> {
    let mut out = vec![0; expected];
    let (done, rc) = zlib_rs::decompress_slice(&mut out, packed, zlib_rs::InflateConfig::default());
    if rc != zlib_rs::ReturnCode::Ok || done.len() != expected {
        return None;
    }
    undo_predictor(&mut out, None);
    Some(out)
}

/// Inflate window bits of OpenEXR's zlib streams.
const WINDOW_BITS: u8 = 15;

/// Bytes of the second half inflated at a time by [`decode_into`] (the
/// inflater copies up to 32 KiB of each call's output into its window).
const PIECE: usize = 256 << 10;

/// Decode the zlib stream of one ZIP / ZIPS block of `out.len()` bytes
/// straight into `out`, in the block's own byte order: no buffer of its own,
/// and no pass over split bytes. `false` when the stream is damaged or
/// decodes to another size.
///
/// The stream holds the block's even bytes, then its odd ones. The even half
/// is inflated into the upper half of `out`; the odd half then arrives
/// `PIECE` bytes at a time and each byte pair is written in place, at `2j`
/// and `2j + 1`, below the even bytes still to be read (`2j + 1 < half + j +
/// 1` for every `j < half`). A buffer per block, megabytes on wide inputs,
/// was mapped, faulted in page by page and unmapped every time (glibc maps
/// large buffers) and held once per block decoding: time in the kernel, and
/// memory that grew with the threads.
pub fn decode_into(packed: &[u8], out: &mut [u8]) -> bool {
    let n = out.len();
    if n % 2 == 1 {
        // Never a block of 2- or 4-byte samples: through the split bytes.
        let Some(t) = unpredict(packed, n) else {
            return false;
        };
        for (j, o) in out.iter_mut().enumerate() {
            *o = split_byte(&t, j);
        }
        return true;
    }
    let half = n / 2;
    let mut z = zlib_rs::Inflate::new(true, WINDOW_BITS);
    let inflate = |z: &mut zlib_rs::Inflate, dst: &mut [u8]| -> Option<(usize, bool)> {
        let (i0, o0) = (z.total_in() as usize, z.total_out());
        let rest = packed.get(i0..)?;
        let status = z
            .decompress(rest, dst, zlib_rs::InflateFlush::NoFlush)
            .ok()?;
        Some((
            (z.total_out() - o0) as usize,
            status == zlib_rs::Status::StreamEnd,
        ))
    };
    // The even bytes, whole (the inflater stops when its output is full).
    let mut got = 0;
    let mut ended = false;
    while got < half && !ended {
        let Some((m, end)) = inflate(&mut z, &mut out[half + got..]) else {
            return false;
        };
        if m == 0 && !end {
            return false;
        }
        (got, ended) = (got + m, end);
    }
    if got < half || ended && n > 0 {
        return false;
    }
    let mut prev = undo_predictor(&mut out[half..], None);
    // The odd bytes, a piece at a time, each pair placed.
    let mut piece = vec![0u8; PIECE.min(half)];
    let mut j = 0;
    while j < half {
        let want = piece.len().min(half - j);
        let Some((m, end)) = inflate(&mut z, &mut piece[..want]) else {
            return false;
        };
        if m == 0 {
            return false;
        }
        prev = undo_predictor(&mut piece[..m], prev);
        interleave(out, half, j, &piece[..m]);
        j += m;
        if end {
            ended = true;
            break;
        }
    }
    if j < half {
        return false;
    }
    if !ended {
        // The stream must end here (its checksum is checked at the end).
        let mut extra = [0u8; 1];
        match inflate(&mut z, &mut extra) {
            Some((0, true)) => {}
            _ => return false,
        }
    }
    true
}

/// Place the odd bytes `odd` of pairs `j..` of a block: pair `i` is
/// `out[half + i]` (its even byte, still in the upper half) then `odd[i - j]`,
/// written at `2i`. Each run of pairs whose places lie below the even bytes
/// it reads is a loop over two disjoint slices; the runs halve towards the
/// end of the block, where places and even bytes meet.
fn interleave(out: &mut [u8], half: usize, j: usize, odd: &[u8]) {
    let (mut a, end) = (j, j + odd.len());
    while a < end {
        // Pairs a..c go to 2a..2c, below the even bytes half + a.. they read.
        let c = end.min((half + a) / 2).max(a + 1);
        let (low, high) = out.split_at_mut(half + a);
        let evens = &high[..c - a];
        if 2 * c <= half + a {
            for ((pair, &e), &o) in low[2 * a..2 * c]
                .chunks_exact_mut(2)
                .zip(evens)
                .zip(&odd[a - j..c - j])
            {
                pair[0] = e;
                pair[1] = o;
            }
        } else {
            // The last pair, whose place holds its own even byte.
            let e = out[half + a];
            out[2 * a] = e;
            out[2 * a + 1] = odd[a - j];
        }
        a = c;
    }
}

/// Undo the delta predictor over `t` in place, after the byte `prev` (`None`:
/// `t` starts the block); returns its last byte.
fn undo_predictor(t: &mut [u8], prev: Option<u8>) -> Option<u8> {
    let (mut prev, rest) = match prev {
        Some(p) => (p, t),
        None => match t.split_first_mut() {
            Some((first, rest)) => (*first, rest),
            None => return None,
        },
    };
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
    Some(prev)
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

    /// `n` bytes: every `every`-th a xorshift draw from `seed`, the rest runs
    /// of `run` equal bytes (something deflate shrinks, and not all of it).
    fn test_bytes(n: usize, seed: &mut u64, every: usize, run: usize) -> Vec<u8> {
        (0..n)
            .map(|i| {
                *seed ^= *seed << 13;
                *seed ^= *seed >> 7;
                *seed ^= *seed << 17;
                if i % every == 0 {
                    (*seed >> 56) as u8
                } else {
                    (i / run) as u8
                }
            })
            .collect()
    }

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
            let data = test_bytes(n, &mut seed, 3, 7);
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
    fn a_block_filled_sample_by_sample_compresses_as_its_bytes() {
        // Four-byte and two-byte samples, something deflate shrinks and
        // noise it does not (stored raw: the bytes back in order), and
        // samples past the block's end left out.
        let mut seed = 0x853c_49e6_748f_ea9bu64;
        // Each block in the buffer of the one before (a smaller one after a
        // larger: its old bytes are all written over).
        let mut spare = Vec::new();
        for (words, halves, every) in [(0, 0, 2), (1, 0, 2), (0, 1, 2), (301, 77, 3), (64, 9, 1)] {
            let data = test_bytes(4 * words + 2 * halves, &mut seed, every, 5);
            let (w, h) = data.split_at(4 * words);
            let w: Vec<u32> = w
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let h: Vec<u16> = h
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            let mut block = SplitBlock::new_in(std::mem::take(&mut spare), 2 * words + halves);
            block.push(&w, u32::to_le_bytes);
            block.push(&h, u16::to_le_bytes);
            block.push(&h, u16::to_le_bytes);
            let (packed, buf) = block.compress(ZIP_LEVEL);
            spare = buf;
            assert_eq!(packed, compress(&data, ZIP_LEVEL), "{words} + {halves}");
            if every == 1 {
                assert_eq!(packed, data, "noise is stored as it is");
            }
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

    /// The block's bytes decoded in place.
    fn decode_in_place(packed: &[u8], n: usize) -> Option<Vec<u8>> {
        // Stale bytes in the buffer: every one must be written.
        let mut out = vec![0xa5u8; n];
        decode_into(packed, &mut out).then_some(out)
    }

    #[test]
    fn decoding_in_place_equals_decoding_through_split_bytes() {
        // Lengths around the pieces of the second half, odd and even, and
        // blocks compressed at several levels (stored, fixed and dynamic
        // Huffman blocks).
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let lengths = (0..40).chain([
            2 * PIECE - 1,
            2 * PIECE,
            2 * PIECE + 2,
            5 * PIECE + 6,
            100_000,
        ]);
        for n in lengths {
            let data = test_bytes(n, &mut seed, 5, 11);
            for level in [0, 1, 6] {
                let packed = compress(&data, level);
                if packed.len() == n {
                    continue;
                }
                assert_eq!(
                    decode_in_place(&packed, n).as_deref(),
                    Some(&data[..]),
                    "n = {n}, level {level}"
                );
                assert_eq!(
                    decompress(&packed, n),
                    decode_in_place(&packed, n),
                    "n = {n}"
                );
            }
        }
    }

    #[test]
    fn decoding_in_place_refuses_damage_and_wrong_sizes() {
        let data: Vec<u8> = (0..3 * PIECE)
            .map(|i| (i % 251) as u8 ^ (i / 97) as u8)
            .collect();
        let n = data.len();
        let packed = compress(&data, ZIP_LEVEL);
        assert!(packed.len() < n);
        for m in [n - 2, n - 1, n + 1, n + 2, n / 2, 0] {
            assert_eq!(decode_in_place(&packed, m), None, "m = {m}");
        }
        for cut in [
            0,
            1,
            2,
            packed.len() / 3,
            packed.len() / 2,
            packed.len() - 1,
        ] {
            assert_eq!(decode_in_place(&packed[..cut], n), None, "cut = {cut}");
        }
        // A flipped byte in the checksum is refused; one in the data decodes
        // as the one-shot decoder decodes it (or is refused by both).
        let mut bad = packed.clone();
        *bad.last_mut().unwrap() ^= 0x40;
        assert_eq!(decode_in_place(&bad, n), None);
        for at in (2..packed.len()).step_by(packed.len() / 61) {
            let mut bad = packed.clone();
            bad[at] ^= 0x40;
            assert_eq!(decode_in_place(&bad, n), decompress(&bad, n), "at = {at}");
        }
        assert_eq!(decode_in_place(&[], n), None);
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
