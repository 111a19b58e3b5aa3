//! `probe-bench measure`: one or more readings on the simulated probe.

use super::{progress, ImageArgs, MethodArgs, OutputArgs};
use crate::calfile;
use crate::scene::{parse_noise, print_scene_header, SceneArgs, Target};
use crate::{plot, report};
use anyhow::{bail, Result};
use clap::Args;
use hal_sim::NoiseScene;
use pzt_probe::board::sim as simboard;
use pzt_probe::engine::sweep::SweepPoint;
use pzt_probe::reading::{Method, Procedure, Settings};
use pzt_probe::unit::profile::UnitProfile;
use std::path::PathBuf;

#[derive(Args)]
pub struct MeasureArgs {
    /// What the probe is on, and the preload.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Seed of the simulated noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Readings to take (seeds seed, seed+1, ...); more than one prints their statistics.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    #[command(flatten)]
    pub m: MethodArgs,
    /// Unit profile file written by `probe-bench calibrate --out` (calibration, Q model, air
    /// reference). Default: the simulated unit's own, made first (its air reference, then A–E
    /// × 20 with the same method, settings and noise).
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Calibration curve: `unit` (the profile's), `paper-experiment` (eq. 5) or
    /// `paper-simulation` (eq. 4) in place of the profile's curve.
    #[arg(long, default_value = "unit")]
    pub calibration: String,
    /// JSON and the plot (the first reading's admittance sweep).
    #[command(flatten)]
    pub out: OutputArgs,
    /// The firmware image to read with instead of the host's simulated probe.
    #[command(flatten)]
    pub image: ImageArgs,
}

/// A measurement the command line asks for, parsed and validated: what `--qemu` and `--stm32`
/// take it to their image with.
#[derive(Clone, Copy)]
pub struct Request<'a> {
    /// The arguments as given.
    pub args: &'a MeasureArgs,
    /// What the probe is on.
    pub target: &'a Target,
    /// The method.
    pub method: Method,
    /// Its settings.
    pub settings: &'a Settings,
    /// The front end's noise.
    pub noise: NoiseScene,
}

/// Run the subcommand.
pub fn run(a: MeasureArgs) -> Result<()> {
    let method = a.m.method()?;
    let settings = a.m.settings(method);
    let noise = parse_noise(&a.m.noise)?;
    let (target, scene) = a.scene.scene(noise, false)?;
    if a.repeat == 0 || a.repeat > 10_000 {
        bail!("--repeat must be 1 to 10000");
    }
    // Validate the settings before any work (the firmware does the same).
    let scale = simboard::scale_of(&scene.front_end);
    Procedure::new(method, &settings, &scale, 0, &UnitProfile::fallback())
        .map_err(|e| anyhow::anyhow!("bad settings: {e}"))?;
    let request = Request {
        args: &a,
        target: &target,
        method,
        settings: &settings,
        noise,
    };
    if a.image.qemu {
        return crate::qemu::measure(request);
    }
    if a.image.stm32 {
        return crate::stm32::measure(request);
    }
    // The simulated unit's profile is made as a unit's profile is made once: with the
    // method's own default settings at bench noise, whatever this reading's settings and noise
    // (a reading with a band that misses the resonance, or in heavy noise, must fail as a
    // reading, not as a calibration).
    let unit = calfile::resolve(a.profile.as_deref(), &a.calibration, || {
        crate::unit::default_for(method)
    })?;
    if !a.out.json {
        print_scene_header("measure", &target, a.scene.preload_n, noise, &scene);
        println!(
            "  simulator ground truth: resonance {:.3} Hz, Q {:.2}",
            scene.resonance_hz(),
            scene.q()
        );
        println!(
            "  unit profile {}: {}",
            match (&a.profile, a.calibration.as_str()) {
                (Some(p), _) => p.display().to_string(),
                (None, "unit") =>
                    "of the simulated unit (air reference, A–E × 20, default settings, bench noise)"
                        .to_owned(),
                (None, c) => c.to_owned(),
            },
            calfile::describe_profile(&unit)
        );
        println!(
            "  method {}: {}",
            method.name(),
            describe_settings(&settings)
        );
    }
    let pb = (a.repeat > 1 && !a.out.json).then(|| progress(a.repeat as u64, "measuring"));
    let mut moduli = Vec::new();
    let mut first_points: Vec<SweepPoint> = Vec::new();
    let mut first_resonance = None;
    for k in 0..a.repeat {
        let mut pts = Vec::new();
        let reading = simboard::read(&scene, a.seed + k as u64, method, settings, &unit, |p| {
            if k == 0 {
                pts.push(*p)
            }
        })
        .map_err(|e| anyhow::anyhow!("reading failed: {e}"))?;
        if k == 0 {
            first_points = pts;
            first_resonance = reading.resonance.map(|f| f.0);
        }
        if a.out.json {
            println!("{}", report::reading_json(&reading));
        } else if a.repeat == 1 {
            println!("{}", report::reading_line(&reading));
        }
        if let Some(e) = reading.modulus {
            moduli.push(e.0 as f64);
        }
        if let Some(pb) = &pb {
            pb.inc(1);
        }
    }
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    if a.repeat > 1 && !a.out.json {
        let n = moduli.len();
        println!("  {n} of {} readings ok", a.repeat);
        if n >= 2 {
            let mean = moduli.iter().sum::<f64>() / n as f64;
            let sd =
                (moduli.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0)).sqrt();
            print!("  modulus mean {mean:.2} kPa, sd {sd:.3} kPa");
            if let Some(t) = target.modulus_kpa() {
                print!(", error of the mean {:+.2} %", 100.0 * (mean - t) / t);
            }
            println!();
        }
    }
    a.out.plot_with(|path| {
        let title = format!("{} — {}", target.describe(), method.name());
        plot::sweep_svg(path, &title, &first_points, first_resonance)
    })
}

/// One line describing a method's settings.
pub fn describe_settings(s: &Settings) -> String {
    let ms = |t: pzt_probe::Seconds| t.0 * 1e3;
    match s {
        Settings::Sweep(s) => {
            let (f0, f1, df, drive) = (s.start.0, s.stop.0, s.step.0, s.drive.0);
            let (settle, int) = (ms(s.settle), ms(s.integrate));
            format!("sweep {f0}–{f1} Hz step {df} Hz, settle {settle} ms, integrate {int} ms, drive {drive} V")
        }
        Settings::Staged(s) => {
            let (f0, f1, drive) = (s.band_start.0, s.band_stop.0, s.drive.0);
            let (coarse, refine) = (s.coarse_points, s.refine_points);
            let (settle, int) = (ms(s.coarse_settle), ms(s.integrate));
            let (span, tau) = (s.refine_span, s.settle_tau);
            format!("band {f0}–{f1} Hz, {coarse} coarse points (settle {settle} ms), {refine} refine points (span {span} linewidths, settle {tau} tau), integrate {int} ms, drive {drive} V")
        }
        Settings::Hold(s) => {
            let (f0, f1, seed, drive) = (s.band_start.0, s.band_stop.0, s.seed.0, s.drive.0);
            let (burst, ring) = (ms(s.seed_burst), ms(s.seed_ring));
            let (hold, refine) = (ms(s.hold), ms(s.refine));
            let c0 = s.static_capacitance.0 * 1e12;
            let g0 = s.static_conductance.0 * 1e9;
            format!("band {f0}–{f1} Hz, seed {seed} Hz ({burst} ms burst + {ring} ms ring), hold {hold} ms (first {refine} ms on the seed), drive {drive} V, C0 {c0:.2} pF, G0 {g0:.3} nS")
        }
    }
}
