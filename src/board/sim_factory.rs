//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f020000cedade56807a7040f15b7460c674afc072ca4b8799d9eabf6b1d8dbefab9683f33b58b894a0f0040aaeec8fa82011c3f33b58b894a0f004019ecf0b779ab9a403f6e17bcd486b63faaeec8fa82011c3f3f6e17bcd486b63f062a15ea3e20d33e0000000000b8614000000000002fa540874cbb15b3c0c73f6f5a68439a1b1c427501672f48155caf0095c655e7c02bc03a48c08d2984f13f000000e04d0b6d40207e0248eddf2a4005e39fbd9985224043e0a67db4871340aaa9ddffafb8803e39567fbbb8c283beeca7357dfe1e8cbe39567fbbb8c283bee5d2cb766115923e72d2ab71ba74973eeca7357dfe1e8cbe72d2ab71ba74973e914a6dd7764aa03ea65d1380fb318b3f0000000000b8614000000000002fa540000000e051b89e3f00824443448a14c0b57b94340a1d0000a69b443cae47613df10a15ad8df2a73f20f871a61b574240286803c528087540a3f62e8541495e3f00000000000000000000000000000000000000000f6dff6a";

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
