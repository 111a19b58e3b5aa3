//! `probe-bench calibrate`: calibrate the simulated unit on phantoms A–E.

use super::{progress, MethodArgs};
use crate::calfile::{self, CalFile};
use crate::scene::parse_noise;
use anyhow::{bail, Result};
use clap::Args;
use hal_sim::{NoiseScene, Scene};
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

/// Calibrate the simulated unit on A–E with `method` and `settings` under `noise`.
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
    // Calibrate phantom by phantom so the bar moves; the fit itself is the library's.
    let mut data = Vec::new();
    let cal = PowerLaw::paper_experiment();
    for (pi, p) in CALIBRATION_PHANTOMS.iter().enumerate() {
        let scene = Scene::on_phantom(p).with_noise(noise);
        for r in 0..repeats {
            let s = seed + (pi * simboard::MAX_REPEATS + r) as u64;
            let reading = simboard::read(&scene, s, method, settings, &cal, |_| {})
                .map_err(|e| anyhow::anyhow!("reference reading failed: {e:?}"))?;
            if let (Some(f), Some(sf)) = (reading.resonance, reading.resonance_sigma) {
                data.push((p.modulus_kpa, f.0 as f64, (sf.0 as f64).max(1e-4)));
            }
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    PowerLaw::fit_robust(&mut data).map_err(|e| anyhow::anyhow!("calibration fit failed: {e:?}"))
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
