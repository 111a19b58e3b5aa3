//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f020000726fd0106f7a704055800c87e47cafc08c6c488b6cdbeabf0db486fd099d6a3f91dae8b7c06801405ddfc242e0521e3f91dae8b7c06801400c5e0b0f83ea9c40e73b25a85b69b83f5ddfc242e0521e3fe73b25a85b69b83f1b32be2732b7d43e0000000000b8614000000000002fa540fc860341e6cbc83f6f5a68439a1b1c427501672f48155caf00d450cf4fd42bc0920150fa2ba0f13f000000e04d0b6d404089e7aaf1df2a40a05fb1eb9a8522404e5f002ed3871340c203d3febe39803e5bbb052f617d83bec3c5d462da788bbe5bbb052f617d83be65e3be6eaed2913e02883f426800973ec3c5d462da788bbe02883f426800973ea4668d1786c79f3edf7d98960fe98e3f0000000000b8614000000000002fa540000000e051b89e3fe004325c238814c0b57b94340a1d0000a69b443cae47613d0cee6f137b40a83fb203f41fe84b42409ad415be690e75404aa0d9509ea2503f0000000000000000000000000000000000000000274ce2bf";

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
