//! `probe-bench calibrate`: calibrate the simulated unit on phantoms A–E.

use super::{progress, MethodArgs};
use crate::calfile::{self, ProfileFile};
use crate::scene::parse_noise;
use anyhow::{bail, Result};
use clap::Args;
use hal_sim::NoiseScene;
use pzt_probe::board::sim::{self as simboard, CALIBRATION_PHANTOMS};
use pzt_probe::reading::{Procedure, Settings};
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::Method;
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    pub m: MethodArgs,
    /// Readings per phantom (the paper took 20).
    #[arg(long, default_value_t = 20)]
    pub repeats: usize,
    /// First noise seed.
    #[arg(long, default_value_t = 1000)]
    pub seed: u64,
    /// Output unit profile (JSON): calibration, Q model, air reference.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the profile as the firmware store's record, a Rust source for the simulated
    /// unit's factory flash (`src/board/sim_factory.rs`, checked by `tests/factory_profile.rs`).
    #[arg(long)]
    pub firmware_record: Option<PathBuf>,
}

/// The simulated unit's profile — air reference, then A–E × `repeats` with `method` and
/// `settings` under `noise` — with a progress bar (the procedure is
/// `board::sim::unit_profile_with`).
pub fn unit_profile(
    method: Method,
    settings: &Settings,
    noise: NoiseScene,
    repeats: usize,
    seed: u64,
) -> Result<UnitProfile> {
    let repeats = repeats.clamp(1, simboard::MAX_REPEATS);
    let pb = progress(
        (CALIBRATION_PHANTOMS.len() * repeats) as u64,
        "calibrating on A–E",
    );
    let r = simboard::unit_profile_with(method, *settings, noise, repeats, seed, || pb.inc(1));
    pb.finish_and_clear();
    r.map_err(|e| anyhow::anyhow!("calibration failed: {e}"))
}

/// Run the subcommand.
pub fn run(a: CalibrateArgs) -> Result<()> {
    let method = a.m.method()?;
    let settings = a.m.settings(method);
    let noise = parse_noise(&a.m.noise)?;
    Procedure::new(
        method,
        &settings,
        &simboard::scale_of(&hal_sim::FrontEnd::default()),
        0,
        &UnitProfile::fallback(),
    )
    .map_err(|e| anyhow::anyhow!("bad settings: {e}"))?;
    if a.repeats == 0 || a.repeats > simboard::MAX_REPEATS {
        bail!("--repeats must be 1 to {}", simboard::MAX_REPEATS);
    }
    let profile = unit_profile(method, &settings, noise, a.repeats, a.seed)?;
    let taken = format!(
        "simulated unit: air reference (sweep 170-290 Hz, noise seed {}), then A-E x {} with {} (noise {}, seeds from {})",
        simboard::AIR_SEED,
        a.repeats,
        method.name(),
        a.m.noise,
        a.seed
    );
    ProfileFile::from_profile(&profile, Some(method.name()), taken).save(&a.out)?;
    println!(
        "calibrated on A–E × {} with {}: {}",
        a.repeats,
        method.name(),
        calfile::describe_profile(&profile)
    );
    println!("written to {}", a.out.display());
    if let Some(path) = &a.firmware_record {
        std::fs::write(path, firmware_record(&profile, &taken_cmd(&a, method)))?;
        println!("firmware record written to {}", path.display());
    }
    Ok(())
}

/// The command line that makes the record, for the generated file's header.
fn taken_cmd(a: &CalibrateArgs, method: Method) -> String {
    format!(
        "cargo run --release -p probe-bench -- calibrate --method {} --noise {} --repeats {} --seed {} --out unit.json --firmware-record src/board/sim_factory.rs",
        method.name(),
        a.m.noise,
        a.repeats,
        a.seed
    )
}

/// The Rust source of the simulated unit's factory record: `profile` encoded as the store
/// writes it (sequence number 1).
pub fn firmware_record(profile: &UnitProfile, cmd: &str) -> String {
    let hex: String = pzt_probe::unit::store::encode(profile, 1)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    format!(
        "//! The simulated unit's factory flash: its unit profile as the store's record (sequence 1),\n\
         //! made by the unit's own procedure (air reference, then A–E) and programmed by the QEMU\n\
         //! board at power-on. Generated — do not edit; regenerate with\n\
         //! `{cmd}`.\n\
         //! `tests/factory_profile.rs` checks it is current.\n\
         \n\
         use crate::unit::profile::UnitProfile;\n\
         use crate::unit::store::{{decode, RECORD_LEN}};\n\
         \n\
         /// The record bytes, in hex.\n\
         const HEX: &[u8; 2 * RECORD_LEN] =\n    b\"{hex}\";\n\
         \n\
         /// The record bytes.\n\
         pub const RECORD: [u8; RECORD_LEN] = bytes(HEX);\n\
         \n\
         const fn bytes(hex: &[u8; 2 * RECORD_LEN]) -> [u8; RECORD_LEN] {{\n    \
         const fn nibble(c: u8) -> u8 {{\n        \
         match c {{\n            \
         b'0'..=b'9' => c - b'0',\n            \
         b'a'..=b'f' => c - b'a' + 10,\n            \
         _ => panic!(\"not lower-case hex\"),\n        \
         }}\n    \
         }}\n    \
         let mut out = [0; RECORD_LEN];\n    \
         let mut i = 0;\n    \
         while i < RECORD_LEN {{\n        \
         out[i] = nibble(hex[2 * i]) << 4 | nibble(hex[2 * i + 1]);\n        \
         i += 1;\n    \
         }}\n    \
         out\n\
         }}\n\
         \n\
         /// The profile the record holds (`None` only if the record were corrupt).\n\
         pub fn profile() -> Option<UnitProfile> {{\n    decode(&RECORD).map(|(_, p)| p)\n}}\n"
    )
}

#[cfg(test)]
mod tests {
    /// The committed factory record is exactly what `firmware_record` writes for the profile it
    /// holds (and the command in its header): the generated file is never edited by hand.
    /// (`tests/factory_profile.rs` checks the profile is today's procedure's.)
    #[test]
    fn the_factory_record_file_is_the_generators_output() {
        let text = include_str!("../../../src/board/sim_factory.rs");
        let cmd = text
            .lines()
            .find_map(|l| l.strip_prefix("//! `cargo run"))
            .and_then(|l| l.strip_suffix("`."))
            .map(|l| format!("cargo run{l}"))
            .expect("the regeneration command in the header");
        let profile = pzt_probe::board::sim_factory::profile().expect("a valid record");
        assert_eq!(super::firmware_record(&profile, &cmd), text);
    }
}
