//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f02000062d229fb507a7040ccfaf62ee085afc08f7dcb4c94ddeabfb03e9e52ece8663f5f61980da80eff3f29c18427bff51a3f5f61980da80eff3f2d7e73485d719a40889e6fe6954bb63f29c18427bff51a3f889e6fe6954bb63f9a0aea7e0fe4d23e0000000000b8614000000000002fa5404d07fa747e49c83f5f5a68432d211c421b04672f380968af40aa2c5ffead2bc098224e67f98bf13f000000e04b0b6d40b7dd7152eadf2a40b453abffbd8522405baeda2138881340e9319ad3d403723eac0064014ced77be290b9cd3b34280beac0064014ced77be5c433f04edf8853ea155e7d7cc0c8c3e290b9cd3b34280bea155e7d7cc0c8c3edf455dc77830933eaa536dfbde638e3f0000000000b8614000000000002fa540000000e051b89e3fa00a05d7e98114c0137b9434051d0000a69b443cae47613d00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000a16260f3";

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
