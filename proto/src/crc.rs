//! CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG): polynomial 0x04C11DB7 reflected
//! (0xEDB88320), initial value and final XOR 0xFFFFFFFF, input and output reflected; check
//! value 0xCBF43926 over the ASCII bytes `123456789`. Four bits at a time through a 16-entry
//! table (64 bytes of flash).

/// The table of the reflected polynomial for one nibble.
const TABLE: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// CRC-32/ISO-HDLC of `data` (zlib's `crc32(0, data)`).
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c ^= b as u32;
        c = (c >> 4) ^ TABLE[(c & 0xF) as usize];
        c = (c >> 4) ^ TABLE[(c & 0xF) as usize];
    }
    !c
}

#[cfg(test)]
mod tests {
    use super::crc32;

    #[test]
    fn check_value_of_the_catalogue() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        // zlib.crc32(b"The quick brown fox jumps over the lazy dog")
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
    }
}
