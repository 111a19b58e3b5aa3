//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f02000098d757d28b7a704083882438a471afc0ee9b6f01e2d8eabf0d07aebc1af6683f35dca602e83000401f7e8910ca401c3f35dca602e83000407b6408e6a0e09a40fdc1e93f53b7b63f1f7e8910ca401c3ffdc1e93f53b7b63f394a5b7d694cd33e0000000000b8614000000000002fa5406a7e9f63a4f0c73f6f5a68439a1b1c427501672f48155caf00672bab1ec52bc02cedac06208af13f000000e04d0b6d40c2d7f6fbf1df2a401098e11e94852240be9d12a4b087134074d5e851f670813e6957dc61e49984be4d8d12a99f518dbe6957dc61e49984be39ab0fbf44df923e669e14643477983e4d8d12a99f518dbe669e14643477983e0fba1b2e52fba03edc1eeb83aad68c3f0000000000b8614000000000002fa540000000e051b89e3fe0c8abd1c78814c0b57b94340a1d0000a69b443cae47613d0a45f954c8eaa73f12d443d9f45342407dee0462400c7540ff217407cf01613f0000000000000000000000000000000000000000ec424f6e";

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
