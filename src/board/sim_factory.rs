//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f0200006081ebac937a704013fe8ca17272afc076efa0fff4d8eabff7a4814e3f3f693fd652e14da45f0040f8d5f9d730921c3fc252e14da45f0040d51c59eace299b408b02903861f5b63fe4d5f9d730921c3f9002903861f5b63f6b327a774581d33e0000000000b8614000000000002fa5405a5cbe63390cc83f6f5a68439a1b1c427501672f48155caf006b782dd3d22bc0bc464c18bf88f13f000000e04d0b6d4095ef4898f9df2a408efe0302a88522403f932185cf871340c6b4b8844214803eaca8aaad16fd82be7335cfc6e2058bbeaca8aaad16fd82be744043a8ca62913eff128206f089963e7335cfc6e2058bbeff128206f089963e42e2271f9f499f3e9f28188e52848b3f0000000000b8614000000000002fa540000000e051b89e3fa0d351b1119b14c0b57b94340a1d0000a69b443cae47613d77edf422e8c4a73f20af6a2dda494240b6d7851ef2f974409c98e32477dd643f0000000000000000000000000000000000000000790ec34e";

/// The record bytes.
pub const RECORD: [u8; RECORD_LEN] = bytes(HEX);

const fn bytes(hex: &[u8; 2 * RECORD_LEN]) -> [u8; RECORD_LEN] {
    const fn nibble(c: u8) -> u8 {
        match c {
            b'0'..=b'9' => c - b'0',
            b'a'..=b'f' => c - b'a' + 10,
            _ => panic!("not lower-case hex"),
        }
    }
    let mut out = [0; RECORD_LEN];
    let mut i = 0;
    while i < RECORD_LEN {
        out[i] = nibble(hex[2 * i]) << 4 | nibble(hex[2 * i + 1]);
        i += 1;
    }
    out
}

/// The profile the record holds (`None` only if the record were corrupt).
pub fn profile() -> Option<UnitProfile> {
    decode(&RECORD).map(|(_, p)| p)
}
