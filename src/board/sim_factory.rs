//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f020000f857bcc0517a70404fa33c279a85afc09ee69d1a80ddeabfcfe0fcce75f0663f79ca32100916ff3f83fcf6d067fc1a3f79ca32100916ff3f26e4b2cf25779a40912670747b50b63f83fcf6d067fc1a3f912670747b50b63ff003ad1a3de8d23e0000000000b8614000000000002fa540ed7f62909a49c83f5f5a68432d211c421b04672f380968afc04f496bcaa52bc08f72fee65a7cf13f000000e04b0b6d409f4dd307eadf2a409b012719bd85224015bdbd933a88134025254ae4bcf5713e9c21ecf3acd777be0a006a56783480be9c21ecf3acd777be290b60b4dce0853e3d43029e1bef8b3e0a006a56783480be3d43029e1bef8b3ed09cf466c81c933e0a0669f18b898e3f0000000000b8614000000000002fa540000000e051b89e3f407c1a16d68114c0137b9434051d0000a69b443cae47613d00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000f7712527";

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
