//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f0200004bf8f83e5a7a7040d4c1c2d9947bafc0010f982c5adbeabfbcc76f5462d3693f62a395c0a4e70040fdc41b6f826b1d3f62a395c0a4e7004092f29e99022d9c409cf35f2346c1b73ffdc41b6f826b1d3f9cf35f2346c1b73f67ce89d50322d43e0000000000b8614000000000002fa54021cda3dfc814c83f6f5a68439a1b1c427501672f48155caf40b97e23c8d62bc001261669b18cf13f000000e04d0b6d4031f9e9a1dbdf2a40072deba9ac852240ec4b2a720a881340976a4591ed02823e47cf5f7fbe6985beca51986f8a568ebe47cf5f7fbe6985bed7930768037f933e6e7bfbaa693f993eca51986f8a568ebe6e7bfbaa693f993e42000830ec80a13e5f09c74ecd128c3f0000000000b8614000000000002fa540000000e051b89e3f401ed714919214c0b57b94340a1d0000a69b443cae47613df5111b53bbd4a73f6666aa0c553f4240e107db1d9c1275403d45b00f3cef523f0000000000000000000000000000000000000000f5469c8c";

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
