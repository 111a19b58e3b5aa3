//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f02000078d4768e597a704060921423b87bafc08adfe99762dbeabf0389a857aed9693fb7818df5dbe90040e94ea449926f1d3f89818df5dbe900402232e27eaa2d9c40f97ab2e4e8c1b73fbc4ea449926f1d3f007bb2e4e8c1b73f61b6dccaa222d43e0000000000b8614000000000002fa5403e3e05a8c713c83f6f5a68439a1b1c427501672f48155caf401145a60bd72bc0001aca92bc8cf13f000000e04d0b6d40aa64c2a2dbdf2a4033e5a108ac8522400f019f0709881340a952cf2c1905823e3e8c08ea1f6885be77d79fad38558ebe3e8c08ea1f6885becdfa5e8d097b933e0e4dda30683a993e77d79fad38558ebe0e4dda30683a993e33283e1b9c7da13e9043d06ea4f18b3f0000000000b8614000000000002fa540000000e051b89e3f00789458b59214c0b57b94340a1d0000a69b443cae47613dddde2b41d9d4a73f72a6bfe7133f42402d139191af127540ff2683b7d009533f0000000000000000000000000000000000000000fd924987";

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
