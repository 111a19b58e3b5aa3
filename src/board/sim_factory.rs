//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),
//! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU
//! board at power-on. Generated — do not edit; regenerate with
//! `cargo run --release -p probe-bench -- calibrate --method auto --noise bench --repeats 20 --seed 1000 --out unit.json --firmware-record src/board/sim_factory.rs`.
//! `tests/factory_profile.rs` checks it is current.

use crate::profile::UnitProfile;
use crate::store::{decode, RECORD_LEN};

/// The record bytes, in hex.
const HEX: &[u8; 2 * RECORD_LEN] =
    b"505a544305008001010000000f0200006bb7c3b8517a7040d9d856e59b85afc06843057880ddeabfccd707238af0663f53e4abf07816ff3f06dfbf36bffc1a3f53e4abf07816ff3fd49153b1c9779a40832bcaaefe50b63f06dfbf36bffc1a3f832bcaaefe50b63f5e17a34fa6e8d23e0000000000b8614000000000002fa540843b5c5bfb49c83f5f5a68432d211c421b04672f380968afc091de3dc2a52bc0f0b073ba597cf13f000000e04b0b6d40d4caf70ceadf2a405233e211bd85224031d3c3833a881340e11bba2ea8f3713e02aa60ed24d577be332a1ee6a43280be02aa60ed24d577be7f5985c1b6de853e94ec64bb2fec8b3e332a1ee6a43280be94ec64bb2fec8b3ea255359ea61a933ee6438fac4a878e3f0000000000b8614000000000002fa540000000e051b89e3fc0fc88a9d78114c0137b9434051d0000a69b443cae47613d00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000207cee48";

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
