//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f02000046436606737a7040fcb0c855597aafc044dadaedeadaeabf3175880f62a66a3fbb08a7b72c750140c91d083a9e691e3fbb08a7b72c7501407a35546fa6039d40ba1e5fda3780b83fc91d083a9e691e3fba1e5fda3780b83fd18183e4e8cbd43e0000000000b8614000000000002fa540e9b86efc8fdcc83f6f5a68439a1b1c427501672f48155caf001a3411bed42bc0122ddbc8a5a3f13f000000e04d0b6d40fd21c45df0df2a40501cd2939a8522408c936307ce87134070fe9ba7f71e803eb533c93e505383befcd0a38c9a408bbeb533c93e505383be397c37f675a7913ef4bb0b37efc8963efcd0a38c9a408bbef4bb0b37efc8963eaca072600c7c9f3e12b3ba1a62c68e3f0000000000b8614000000000002fa540000000e051b89e3f8054bd13bc8614c0b57b94340a1d0000a69b443cae47613d3eb40bb27443a83fcc3efa54914c42406fb527f75f0e7540fb246d58342f4b3f0000000000000000000000000000000000000000f94be3b7";

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
