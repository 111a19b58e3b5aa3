//! The subcommands of `probe-bench`, one file each, and what they share.

pub mod accuracy;
pub mod analyze;
pub mod calibrate;
pub mod connect;
pub mod generate;
pub mod log;
pub mod measure;
pub mod pareto;
pub mod physics;
pub mod scan;
pub mod selftest;
pub mod slide;
pub mod stability;
pub mod stream;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pzt_probe::engine::sweep::SweepSettings;
use pzt_probe::reading::Settings;
use pzt_probe::{Hz, Method, Seconds, Volts};
use std::path::{Path, PathBuf};

/// Where `measure` and `stream` run: on the host's simulated probe (neither flag), or with a
/// firmware image on its emulated board, on the same scene and with the same output.
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct ImageArgs {
    /// Run on the firmware image in QEMU instead: the scene, its events, noise, seed, method and
    /// settings go to the image as its command script (`sim` lines); the image reads with its
    /// factory profile (`src/board/sim_factory.rs`) and streams with its default tracker; a
    /// stream's `t_s` is counted from its start. Needs qemu-system-arm, defmt-print and the
    /// thumbv7em-none-eabihf target.
    #[arg(long)]
    pub qemu: bool,
    /// Run on the STM32 image (`cargo fw`) on the emulated NUCLEO-G474RE instead (`emu/`, run as
    /// a subprocess): the unit takes its air reference, weighs its load cell with 10 g and is
    /// calibrated on A–E (with the method and settings asked for), then reads the target (a
    /// phantom at the preload, or free air) or streams on it with its default tracker, the
    /// scene's events as the emulator's scene changes; a stream's `t_s` is counted from its
    /// start. Needs the thumbv7em-none-eabihf target, flip-link, defmt-print, cmake and
    /// libclang (scripts/setup).
    #[arg(long, conflicts_with = "qemu")]
    pub stm32: bool,
}

/// The output options of the commands that report a result (`measure`, `stream`, `analyze`,
/// `log`): JSON for a program in place of the report for a person, and a plot.
#[derive(Args, Clone, Debug, Default)]
pub struct OutputArgs {
    /// Print JSON on stdout instead of the report (one object per reading for measure and
    /// stream, one object for analyze and log), nothing else.
    #[arg(long)]
    pub json: bool,
    /// Write the command's plot to this file (SVG, or PNG when it ends in `.png`): measure and
    /// analyze the admittance sweep with the estimate marked, stream modulus and lock against
    /// time, log the logged sweeps and the reading history.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

impl OutputArgs {
    /// With `--plot`: `draw` the plot to its file, then name the file in the report (not in
    /// JSON).
    pub fn plot_with(&self, draw: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
        if let Some(path) = &self.plot {
            draw(path)?;
            if !self.json {
                println!("  plot: {}", path.display());
            }
        }
        Ok(())
    }
}

/// The calibration a command reads with, where it is chosen by options that default in the
/// command (`scan`, `analyze`): a built-in curve or a unit profile file.
#[derive(Args, Clone, Debug, Default)]
pub struct CalibrationArgs {
    /// Calibration curve from resonance (Hz) to modulus (kPa): `paper-experiment` (paper 003
    /// eq. 5), `paper-simulation` (eq. 4), `unit` (the profile's own curve; without `--profile`
    /// the simulated unit's), or a profile file. Default: scan `paper-experiment`, and `unit` on
    /// lossy tissue, whose loss tangent is read through the unit's contact law, which the
    /// papers' curves do not have; analyze with `--profile` `paper-experiment`, without it none
    /// (the reading is the capture's resonance and Q, no modulus; the curve alone: no Q model,
    /// no air reference).
    #[arg(long)]
    pub calibration: Option<String>,
    /// Unit profile file (`probe-bench calibrate --out`): calibration, Q model, air reference.
    /// Default: scan the simulated unit's; analyze none, so no check that needs a probe's unit
    /// data (its air reference and contact condition) is applied.
    #[arg(long)]
    pub profile: Option<PathBuf>,
}

#[derive(Args, Clone)]
pub struct MethodArgs {
    /// Resonance method: `auto` (the default, as in the firmware: hold, falling back to fit,
    /// then sweep-g), `paper` (|Z| minimum, 200–300 Hz in 1 Hz steps), `sweep-g` (conductance
    /// maximum), `fit` or `hold` (see docs/methods.md). For fit `--start-hz/--stop-hz` set
    /// the band, `--settle-s` the coarse settling and `--integrate-s` the integration per
    /// point; for hold the band.
    #[arg(long, default_value = pzt_probe::reading::DEFAULT_METHOD.name())]
    pub method: String,
    /// Sweep start frequency, Hz (default: the method's).
    #[arg(long)]
    pub start_hz: Option<f32>,
    /// Sweep stop frequency, Hz.
    #[arg(long)]
    pub stop_hz: Option<f32>,
    /// Sweep step, Hz.
    #[arg(long)]
    pub step_hz: Option<f32>,
    /// Settling time after each frequency step, s.
    #[arg(long)]
    pub settle_s: Option<f32>,
    /// Integration time per point, s (rounded up to whole drive cycles).
    #[arg(long)]
    pub integrate_s: Option<f32>,
    /// Drive amplitude at the PZT, V (peak).
    #[arg(long)]
    pub drive_v: Option<f32>,
    /// Front-end noise: `quiet`, `paper`, `bench`, or a current-noise density in A/sqrt(Hz).
    #[arg(long, default_value = "bench")]
    pub noise: String,
}

impl MethodArgs {
    pub fn method(&self) -> Result<Method> {
        Method::from_name(&self.method).with_context(|| {
            let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
            format!(
                "unknown method `{}` (known: {})",
                self.method,
                names.join(", ")
            )
        })
    }
    /// The stepped-sweep settings: the method's default sweep with the options given applied.
    pub fn sweep_settings(&self, method: Method) -> SweepSettings {
        let d = method.default_sweep();
        SweepSettings {
            start: self.start_hz.map(Hz).unwrap_or(d.start),
            stop: self.stop_hz.map(Hz).unwrap_or(d.stop),
            step: self.step_hz.map(Hz).unwrap_or(d.step),
            settle: self.settle_s.map(Seconds).unwrap_or(d.settle),
            integrate: self.integrate_s.map(Seconds).unwrap_or(d.integrate),
            drive: self.drive_v.map(Volts).unwrap_or(d.drive),
        }
    }

    /// The settings of `method`: its defaults with the options given applied.
    pub fn settings(&self, method: Method) -> Settings {
        match method.default_settings() {
            Settings::Sweep(_) => Settings::Sweep(self.sweep_settings(method)),
            Settings::Staged(mut s) => {
                s.band_start = self.start_hz.map(Hz).unwrap_or(s.band_start);
                s.band_stop = self.stop_hz.map(Hz).unwrap_or(s.band_stop);
                s.coarse_settle = self.settle_s.map(Seconds).unwrap_or(s.coarse_settle);
                s.integrate = self.integrate_s.map(Seconds).unwrap_or(s.integrate);
                s.drive = self.drive_v.map(Volts).unwrap_or(s.drive);
                Settings::Staged(s)
            }
            Settings::Hold(_) => {
                // The static admittance comes from the unit profile's air reference.
                let mut s = pzt_probe::estimate::hold::HoldSettings::DEFAULT;
                s.band_start = self.start_hz.map(Hz).unwrap_or(s.band_start);
                s.band_stop = self.stop_hz.map(Hz).unwrap_or(s.band_stop);
                s.seed = Hz(0.5 * (s.band_start.0 + s.band_stop.0));
                s.hold = self.integrate_s.map(Seconds).unwrap_or(s.hold);
                s.drive = self.drive_v.map(Volts).unwrap_or(s.drive);
                Settings::Hold(s)
            }
        }
    }
}

/// A progress bar for `n` steps.
pub fn progress(n: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(n);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}
