//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::unit::profile::UnitProfile;
use crate::unit::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544307008001010000001f0200001b50e0945a7a7040027e1d85527bafc0aa3751f14cdbeabfa505169fefd8693f9da8d48fb8e9004033e7941a966f1d3f9da8d48fb8e900404cc50525922d9c40df34f3eb17c2b73f33e7941a966f1d3fdf34f3eb17c2b73f68f297440223d43e0000000000b8614000000000002fa540811c928db913c83f6f5a68439a1b1c427501672f48155caf0011365f67d62bc05a89c6d8308cf13f000000e04d0b6d40507af905dcdf2a40d785ceb6ab85224086d3fd0508881340ff3223d71202823eb2138cc4156685be43af201522528ebeb2138cc4156685be73575d63327a933e7e14419a7339993e43af201522528ebe7e14419a7339993ee4779003117da13ed786bd6358f48b3f0000000000b8614000000000002fa540000000e051b89e3f00aca096909214c0b57b94340a1d0000a69b443cae47613dff70c30c1ed4a73f44e10de6833f4240f2c789d38e1275409bb6ea8f200d533f000000000000000000000000000000000000000078f0426b";

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
