//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f02000063e471766b7a704026c184b53f82afc010822984c5dceabf55faf1267502683f243b539bf3d1ff3fb615278aa0a91b3f243b539bf3d1ff3fea9ebfe3c10e9b40b307614c3ac9b63fb615278aa0a91b3fb307614c3ac9b63f78a924d4e949d33e0000000000b8614000000000002fa5403fe1641f9596c83f5f5a68432d211c421b04672f380968af80a8cbefe5992bc0c99564352746f13f000000e04b0b6d40bc7ecb57eddf2a40bb7541c69b8522405a50c86ca6871340668ed140c2917b3e190be8ab65b781be2cc8e8a3039b88be190be8ab65b781bed5665c76289b903eb1878c603961953e2cc8e8a3039b88beb1878c603961953e3f03b6b750799d3e3fe1641f9596c83f0000000000b8614000000000002fa540000000e051b89e3f20f8938cee9114c0137b9434051d0000a69b443cae47613d0000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000068ddd20a";

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
