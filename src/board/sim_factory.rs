//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f020000025fd89d5a7a704069f9e82d647bafc0229a820850dbeabfe008ec9ac8d0693fbdb0fcb17ae600409f22dd1879691d3fbdb0fcb17ae60040940831eace2b9c40f11a9d5d44c0b73f9f22dd1879691d3ff11a9d5d44c0b73fd90562c82a21d43e0000000000b8614000000000002fa540322115f65c14c83f6f5a68439a1b1c427501672f48155caf00dd7d4f84d62bc070f32d26738cf13f000000e04d0b6d401927cfe1dbdf2a402747352eac8522400ee0136d098813409b33961af409823edcfb3040807185becc26d27cc6618ebedcfb3040807185be5c7d1ea92286933ea3ff8b9aa948993ecc26d27cc6618ebea3ff8b9aa948993ed5b6ae185e87a13e3fa6633e0d018c3f0000000000b8614000000000002fa540000000e051b89e3f2022351d849214c0b57b94340a1d0000a69b443cae47613d83bd67cdd4d3a73fd41831aa6f3f424021b3f563961275404ee527360ff4523f0000000000000000000000000000000000000000fe67f2f4";

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
