//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f020000a87ebd05677a7040d0ad14b6bb7eafc02265d13a00dceabff7ba33330a1a663f585bfa23b348fe3f87763a1c48461a3f585bfa23b348fe3fd6d43d0bcd0f9a40d1374e8743f7b53f87763a1c48461a3fd1374e8743f7b53f41bf1a9fc29ad23e0000000000b8614000000000002fa540749781a4c12dc83f5f5a68432d211c421b04672f380968af808afe143f932bc0a36f6eec3d5df13f000000e04b0b6d404298dc57eddf2a40c6ce9a2ab68522404c9902aa118813403d030b2fb497713e3ceb1ed1ee3877be3ed01ba5a99a7fbe3ceb1ed1ee3877be071e12bd2a66853e45b1170d10458b3e3ed01ba5a99a7fbe45b1170d10458b3e918eeb63389e923ead19255cbcf78b3f0000000000b8614000000000002fa540000000e051b89e3fe03eaea0778614c0137b9434051d0000a69b443cae47613d00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000f52ebd08";

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
