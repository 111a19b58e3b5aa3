//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a5443040040010100000007020000d8e2acae677a70409879e629a37bafc0eed985c969dbeabf5c3aa47033dc4c3f7bc2bb840bd8e33f67af5ee3d437013f69c2bb840bd8e33f93b6acb1c91a81409d98060506d89c3f5eaf5ee3d437013fa298060506d89c3fb24637fa3470b83e0000000000b8614000000000002fa540afa831bf4125c83f5f5a68432d211c421b04672f380968af5e7f6e6398771140856499275c83f03f000000e04b0b6d4041fb7d3ef0df2a4017f80918538522403fcb15dca98513405d3f658b88a82b3e3d17c4624c9333be23aaf8dfa2443abe3d17c4624c9333bebcdacb065457443ef355c020033c493e23aaf8dfa2443abef355c020033c493e948d17cff99c503eafa831bf4125c83f0000000000b8614000000000002fa5400000000000000000000000000000000000000000e2e13a9b";

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
