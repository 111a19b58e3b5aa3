//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f020000c8e73fa1617a7040b4a38f69777fafc06c7b017b3ddceabf8d6c6bd1eb39673faa0d80058a62ff3f1a04af577c451b3faa0d80058a62ff3fdf5d6d4768a49a40611c812de07bb63f1a04af577c451b3f611c812de07bb63fa104d4b97d11d33e0000000000b8614000000000002fa540eef8988bb959c83fbe596843c9451c425b06672f9af150af00bb3b5069092cc07a698db627c6f13f000000c0370b6d40698867acffdf2a403ee31f59c48522408c67f8b022881340e38beb873cf3713e7087f9396ff577be2f7f1ae6854680be7087f9396ff577bea614a99a7605863e87318254971e8c3e2f7f1ae6854680be87318254971e8c3eba69c0be4b3b933e8228ca7db18c8c3f0000000000b8614000000000002fa540000000e051b89e3f406145cc2c9714c0627c9434111d0000a69b443cae47613d0000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000022e22d93";

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
