//! `probe-bench calibrate`: calibrate the simulated unit on phantoms A–E.

use super::{progress, MethodArgs};
use crate::calfile::{self, CalFile};
use crate::scene::parse_noise;
use anyhow::{bail, Result};
use clap::Args;
use hal_sim::NoiseScene;
use pzt_probe::board::sim::{self as simboard, CALIBRATION_PHANTOMS};
use pzt_probe::calibration::PowerLaw;
use pzt_probe::measure::{Procedure, Settings};
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
    /// Output calibration file (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

/// Calibrate the simulated unit on A–E with `method` and `settings` under `noise`, with a
/// progress bar (the calibration itself is `board::sim::calibrate_unit_with`).
pub fn calibrate_unit(
    method: Method,
    settings: &Settings,
    noise: NoiseScene,
    repeats: usize,
    seed: u64,
) -> Result<PowerLaw> {
    let repeats = repeats.clamp(1, simboard::MAX_REPEATS);
    let pb = progress(
        (CALIBRATION_PHANTOMS.len() * repeats) as u64,
        "calibrating on A–E",
    );
    let r = simboard::calibrate_unit_with(method, *settings, noise, repeats, seed, || pb.inc(1));
    pb.finish_and_clear();
    r.map(|(law, _)| law)
        .map_err(|e| anyhow::anyhow!("calibration failed: {e:?}"))
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
    )
    .map_err(|e| anyhow::anyhow!("bad settings: {e}"))?;
    if a.repeats == 0 || a.repeats > simboard::MAX_REPEATS {
        bail!("--repeats must be 1 to {}", simboard::MAX_REPEATS);
    }
    let law = calibrate_unit(method, &settings, noise, a.repeats, a.seed)?;
    CalFile::from_law(&law, Some(method.name())).save(&a.out)?;
    println!(
        "calibrated on A–E × {} with {}: {}",
        a.repeats,
        method.name(),
        calfile::describe(&law)
    );
    println!("written to {}", a.out.display());
    Ok(())
}
