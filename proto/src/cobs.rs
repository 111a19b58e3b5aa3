//! Consistent Overhead Byte Stuffing (Cheshire and Baker, IEEE/ACM Trans. Networking 7(2),
//! 1999): a frame's content without any 0x00, so 0x00 can end frames. Each block is a code byte
//! `c` (1–255) followed by `c − 1` non-zero bytes; a block with `c < 255` stands for its bytes
//! and a 0x00, except the last block, whose 0x00 is not part of the content. Overhead: one byte
//! per 254 of content, at least one.

/// Most bytes the encoding of `len` content bytes takes (without the delimiter).
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
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
    let mut code_at = 0usize;
    let mut out = 1usize;
    let mut code = 1u8;
    for k in 0..len {
        let at = start + k;
        let b = *buf.get(at)?;
        // The write may reach the byte just read, never one still to be read.
        if out > at {
            return None;
        }
        if b == 0 {
            *buf.get_mut(code_at)? = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            *buf.get_mut(out)? = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                *buf.get_mut(code_at)? = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    if code_at > end || code_at >= buf.len() {
        return None;
    }
    *buf.get_mut(code_at)? = code;
    Some(out)
}

/// COBS-encode `src` into `dst`: the encoded length, or `None` when `dst` is too short.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut code_at = 0usize;
    let mut out = 1usize;
    let mut code = 1u8;
    for &b in src {
        if b == 0 {
            *dst.get_mut(code_at)? = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            *dst.get_mut(out)? = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                *dst.get_mut(code_at)? = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    *dst.get_mut(code_at)? = code;
    Some(out)
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
