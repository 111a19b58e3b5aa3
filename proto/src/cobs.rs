//! Consistent Overhead Byte Stuffing (Cheshire and Baker, IEEE/ACM Trans. Networking 7(2),
//! 1999): a frame's content without any 0x00, so 0x00 can end frames. Each block is a code byte
//! `c` (1–255) followed by `c − 1` non-zero bytes; a block with `c < 255` stands for its bytes
//! and a 0x00, except the last block, whose 0x00 is not part of the content. Overhead: one byte
//! per 254 of content, at least one.

/// Most bytes the encoding of `len` content bytes takes (without the delimiter).
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
}

/// The encoder between two content bytes: where the open block's code byte goes, where the
/// next byte goes, and the open block's code so far.
struct Blocks {
    code_at: usize,
    out: usize,
    code: u8,
}

impl Blocks {
    const fn new() -> Self {
        Self {
            code_at: 0,
            out: 1,
            code: 1,
        }
    }

    /// Content byte `b` into `dst`: `None` when `dst` is too short.
    fn push(&mut self, dst: &mut [u8], b: u8) -> Option<()> {
        if b == 0 {
            return self.close(dst);
        }
        *dst.get_mut(self.out)? = b;
        self.out += 1;
        self.code += 1;
        if self.code == 0xFF {
            return self.close(dst);
        }
        Some(())
    }

    /// Write the open block's code and open the next.
    fn close(&mut self, dst: &mut [u8]) -> Option<()> {
        *dst.get_mut(self.code_at)? = self.code;
        self.code_at = self.out;
        self.out += 1;
        self.code = 1;
        Some(())
    }

    /// Write the last block's code: the encoded length.
    fn finish(self, dst: &mut [u8]) -> Option<usize> {
        *dst.get_mut(self.code_at)? = self.code;
        Some(self.out)
    }
}

/// COBS-encode the `len` content bytes at `buf[start..]` to the start of `buf`, in place: the
/// encoded length, or `None` when `buf` is too short, the content does not fit, or `start` is
/// too small for the encoding to stay behind the bytes still to be read
/// (`start ≥ len / 254 + 1` suffices).
pub fn encode_within(buf: &mut [u8], start: usize, len: usize) -> Option<usize> {
    let end = start.checked_add(len)?;
    if end > buf.len() {
        return None;
    }
    let mut enc = Blocks::new();
    for at in start..end {
        let b = *buf.get(at)?;
        // The write may reach the byte just read, never one still to be read.
        if enc.out > at {
            return None;
        }
        enc.push(buf, b)?;
    }
    if enc.code_at > end {
        return None;
    }
    enc.finish(buf)
}

/// COBS-encode `src` into `dst`: the encoded length, or `None` when `dst` is too short.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut enc = Blocks::new();
    for &b in src {
        enc.push(dst, b)?;
    }
    enc.finish(dst)
}

/// Decode the COBS bytes of `buf` (one frame, no delimiter) in place: the content's length,
/// or `None` when they are no COBS encoding (a 0x00, or a block running past the end).
pub fn decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let n = buf.len();
    let (mut i, mut out) = (0usize, 0usize);
    while i < n {
        let code = *buf.get(i)? as usize;
        if code == 0 {
            return None;
        }
        i += 1;
        let end = i + code - 1;
        if end > n {
            return None;
        }
        if buf.get(i..end)?.contains(&0) {
            return None;
        }
        // `out ≤ i − 1`: the copy moves bytes toward the start.
        buf.copy_within(i..end, out);
        out += code - 1;
        i = end;
        if code != 0xFF && i < n {
            *buf.get_mut(out)? = 0;
            out += 1;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(content: &[u8]) {
        let mut enc = [0u8; 1200];
        let n = encode(content, &mut enc).unwrap();
        assert!(n <= max_encoded_len(content.len()));
        assert!(!enc[..n].contains(&0));
        // In place, from the end of a buffer.
        let start = content.len() / 254 + 1;
        let mut buf = [0u8; 1200];
        buf[start..start + content.len()].copy_from_slice(content);
        let m = encode_within(&mut buf, start, content.len()).unwrap();
        assert_eq!(&buf[..m], &enc[..n]);
        let d = decode_in_place(&mut enc[..n]).unwrap();
        assert_eq!(&enc[..d], content);
    }

    #[test]
    fn the_papers_examples_and_block_edges() {
        let mut out = [0u8; 8];
        let n = encode(&[0x11, 0x22, 0x00, 0x33], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = encode(&[0x00], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x01, 0x01]);
        for len in [0, 1, 253, 254, 255, 508, 509, 1000] {
            let v: [u8; 1000] = core::array::from_fn(|i| (i % 255) as u8 + 1);
            round_trip(&v[..len]);
            let z = [0u8; 1000];
            round_trip(&z[..len]);
        }
    }

    #[test]
    fn bad_encodings_are_refused() {
        assert_eq!(
            decode_in_place(&mut [0x05, 0x11]),
            None,
            "block past the end"
        );
        assert_eq!(
            decode_in_place(&mut [0x03, 0x00, 0x11]),
            None,
            "zero inside"
        );
        assert_eq!(decode_in_place(&mut [0x00]), None);
    }
}
