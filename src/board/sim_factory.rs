//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f020000ce710c39457a704008f46982c182afc0dc4fd0d3e4dceabf494b16c248386a3f3b96239ee44e01406c15efc1bd0f1e3f3b96239ee44e0140f1fdd1fa73069d4084ec5995346db83f6c15efc1bd0f1e3f84ec5995346db83f7e2af0c12aaad43e0000000000b8614000000000002fa54030e4b454494ec83f6f5a68439a1b1c427501672f48155caf40b58e347f292cc03dd6655628f8f13f000000e04d0b6d4066106fffd3df2a4000ef66f2bb852240e572acf039881340529cfedf5b29813e704bb908739784bef8cd866504408dbe704bb908739784be9fe65d4df9b7923edac839a45865983ef8cd866504408dbedac839a45865983e06d1abff5e05a13edf9a505750388b3f0000000000b8614000000000002fa540000000e051b89e3f20a4e60e8fa014c0b57b94340a1d0000a69b443cae47613d4ba035260f9ba73f5a7d3451401442402b8aae1ba4027540d166acbaf7ec6b3f0000000000000000000000000000000000000000dc456ae8";

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
