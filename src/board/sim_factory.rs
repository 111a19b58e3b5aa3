//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f020000630be1f5667a70401c986157c27eafc0f4b735a201dceabffc00a53e061a663f90424302b748fe3f05e7b1c045461a3f90424302b748fe3f9743dd09d90f9a40b9d25fd848f7b53f13e7b1c045461a3fb9d25fd848f7b53fafb0c10fc39ad23e0000000000b8614000000000002fa5406af7919fca2dc83f5f5a68432d211c421b04672f380968af808afe143f932bc0a36f6eec3d5df13f000000e04b0b6d40249ddb57eddf2a4006bb9c2ab6852240975908aa11881340f3d8f88cb397713e073a8377ee3877beb924d17fa89a7fbe073a8377ee3877beb56b5e0a2b66853e387e82df0f458b3eb924d17fa89a7fbe387e82df0f458b3e414b6edb379e923e6af7919fca2dc83f0000000000b8614000000000002fa540000000e051b89e3fe03eaea0778614c0137b9434051d0000a69b443cae47613d00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000fe0155f2";

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
