//! `probe-bench analyze`: a capture from the bench (impedance analyser or DAQ), through the
//! firmware's own estimator and calibration.
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > y)` also rejects NaN, deliberately

use crate::calfile;
use crate::capture::{self, Capture, CaptureError, DemodOptions, Layout, SweepShape};
use crate::{plot, report};
use anyhow::{bail, Context, Result};
use clap::Args;
use pzt_probe::engine::sweep::SweepPoint;
use pzt_probe::estimate::Estimate;
use pzt_probe::reading::Reading;
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::{Failure, Method, Newtons, Seconds, Status};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct AnalyzeArgs {
    /// Capture (CSV, header row required, `#` comments). Layouts: `freq_hz,z_mag_ohm,z_phase_deg`
    /// (Hz, ohm, degrees), `freq_hz,y_re_s,y_im_s` (Hz, siemens) or
    /// `t_s,drive_hz,v_drive_v,i_sense_a` (s, Hz, volts, amperes; stepped or continuous sweep).
    pub file: PathBuf,
    /// Resonance method: `auto` (the best estimator for the capture's layout: the
    /// Butterworth–Van Dyke fit of the complex admittance for analyser sweeps and for the
    /// demodulated points of DAQ captures, sweep-G on the same points when the fit finds no
    /// trustworthy resonance), or any estimator that works on measured frequency points
    /// (`fit`; `sweep-g`: conductance maximum; `paper`: |Z| minimum). Methods that steer the
    /// drive while measuring (hold) are refused.
    #[arg(long, default_value = "auto")]
    pub method: String,
    /// Calibration curve from resonance (Hz) to modulus (kPa): `paper-experiment` (paper 003
    /// eq. 5), `paper-simulation` (eq. 4), or `unit` (the profile's own curve).
    #[arg(long, default_value = "paper-experiment")]
    pub calibration: String,
    /// Unit profile of the probe that made the capture (`probe-bench calibrate --out`): its
    /// air reference and contact condition check the reading. Default: the simulated unit's.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Plot the admittance with the estimate marked (.svg or .png).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Time-domain stepped sweeps: settling time discarded at the start of each step, s
    /// (default: the first half of each step).
    #[arg(long)]
    pub settle_s: Option<f64>,
    /// Time-domain continuous sweeps: whole drive cycles per demodulation window.
    #[arg(long, default_value_t = capture::DEFAULT_CYCLES_PER_WINDOW)]
    pub cycles_per_window: usize,
    /// The contact force the capture was taken at, mN (a capture carries no load-cell data:
    /// the force set by a balance and a stage, as paper 003 set its 30 mN).
    #[arg(long, default_value_t = 30.0)]
    pub force_mn: f64,
}

/// The method called `name`, if it can analyse recorded frequency points
/// ([`Method::works_on_points`], or `auto`: [`auto_method`] per capture); methods that steer
/// the drive while they measure (they choose their next frequency from the last answer, track a
/// phase or watch a ring-down) are refused.
pub fn offline_method(name: &str) -> Result<Method> {
    let offline: Vec<&str> = Method::ALL
        .iter()
        .filter(|m| m.works_on_points() || **m == Method::Auto)
        .map(|m| m.name())
        .collect();
    let Some(m) = Method::from_name(name) else {
        bail!(
            "unknown method `{name}` (methods that analyse a capture: {})",
            offline.join(", ")
        );
    };
    if !m.works_on_points() && m != Method::Auto {
        bail!(
            "method `{name}` steers the drive while it measures and cannot analyse a recorded capture (use one of: {})",
            offline.join(", ")
        );
    }
    Ok(m)
}

/// Fewest points `method` needs (every estimator screens for three).
pub fn min_points(_method: Method) -> usize {
    3
}

/// The estimator `auto` reads a capture of `layout` with. Every layout carries the complex
/// admittance at each point (an analyser's directly, a DAQ's after demodulation), so the
/// Butterworth–Van Dyke fit applies to all: it models the static capacitance and conductance
/// (`pzt_probe::estimate::fit`), which bias the conductance peak's `1/G` fit (sweep-G) and the
/// |Z| dip (paper) when `C0` is large (`docs/bench.md`, heavy-C0 sweeps).
pub const fn auto_method(layout: Layout) -> Method {
    match layout {
        Layout::Impedance | Layout::Admittance | Layout::TimeDomain => Method::Fit,
    }
}

/// Failures of `auto`'s fit after which sweep-G reads the same points, as the firmware's
/// `auto` falls back to a sweep-G sweep (`pzt_probe::reading`): the resonance missed or not
/// resolved.
fn fit_failure_retryable(f: Failure) -> bool {
    matches!(
        f,
        Failure::NoResonance | Failure::LowSnr | Failure::OutOfBand | Failure::NotLocked
    )
}

/// `method`'s estimate of `pts`, refused outside the measured band.
fn estimate_in_band(method: Method, pts: &[SweepPoint]) -> Result<Estimate, Failure> {
    let est = method.estimate(pts)?;
    // Belt and braces: an estimate outside the measured band is never a reading.
    let f = est.resonance.0;
    match (pts.first(), pts.last()) {
        (Some(first), Some(last)) if f > first.freq.0 && f < last.freq.0 => Ok(est),
        _ => Err(Failure::OutOfBand),
    }
}

/// A capture and the reading the firmware's estimator and calibration make of it.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The capture as points.
    pub capture: Capture,
    /// The reading.
    pub reading: Reading,
}

/// Analyse capture text with `method` (`auto`: [`auto_method`] for the capture's layout, then
/// sweep-G when the fit fails as the firmware's `auto` retries) and the unit's profile `unit`,
/// taken at the contact force `force` (set by other means than the unit's load cell). The
/// reading names the estimator that made it.
pub fn analyze(
    text: &str,
    method: Method,
    unit: &UnitProfile,
    opts: &DemodOptions,
    force: Newtons,
) -> Result<Analysis, CaptureError> {
    let capture = capture::parse(text, min_points(method), opts)?;
    let pts = &capture.points;
    let (method, est) = if method == Method::Auto {
        let first = auto_method(capture.layout);
        match estimate_in_band(first, pts) {
            Err(f) if fit_failure_retryable(f) => {
                (Method::SweepG, estimate_in_band(Method::SweepG, pts))
            }
            est => (first, est),
        }
    } else {
        (method, estimate_in_band(method, pts))
    };
    let probe_time = match (capture.sample_rate_hz, capture.layout) {
        (Some(fs), Layout::TimeDomain) => Seconds(capture.rows as f32 / fs as f32),
        _ => Seconds(0.0),
    };
    let n = pts.len().min(u16::MAX as usize) as u16;
    let force = unit.load_cell.map(|c| c.stated(force));
    let reading = pzt_probe::reading::pipeline::conclude(method, est, unit, probe_time, n, force);
    Ok(Analysis { capture, reading })
}

/// The profile `analyze` reads a capture with: the file given, else the simulated unit's
/// (calibrated with `method` on A–E × 20 at bench noise; `auto` as the firmware's default), its
/// curve replaced by a built-in one when `calibration` names one.
pub fn profile(profile: Option<&Path>, calibration: &str, method: Method) -> Result<UnitProfile> {
    calfile::resolve(profile, calibration, || crate::unit::default_for(method))
}

/// The JSON object of an analysis: the reading's fields plus the capture's.
pub fn analysis_json(a: &Analysis, file: &str) -> Value {
    let mut v = report::reading_json(&a.reading);
    let c = &a.capture;
    let band = match (c.points.first(), c.points.last()) {
        (Some(f), Some(l)) => json!([f.freq.0, l.freq.0]),
        _ => Value::Null,
    };
    if let Some(o) = v.as_object_mut() {
        o.insert("file".into(), json!(file));
        o.insert("layout".into(), json!(c.layout.name()));
        o.insert("band_hz".into(), band);
        o.insert("rows".into(), json!(c.rows));
        o.insert(
            "noise_sigma_s".into(),
            c.noise_sigma_s.map_or(Value::Null, |s| json!(s)),
        );
        o.insert(
            "sample_rate_hz".into(),
            c.sample_rate_hz.map_or(Value::Null, |s| json!(s)),
        );
        o.insert(
            "sweep".into(),
            match c.shape {
                Some(SweepShape::Stepped) => json!("stepped"),
                Some(SweepShape::Continuous) => json!("continuous"),
                None => Value::Null,
            },
        );
        if c.layout != Layout::TimeDomain {
            o.insert("probe_time_ms".into(), Value::Null);
        }
    }
    v
}

/// Run the subcommand.
pub fn run(a: AnalyzeArgs) -> Result<()> {
    let method = offline_method(&a.method)?;
    let unit = profile(a.profile.as_deref(), &a.calibration, method)?;
    if a.cycles_per_window == 0 || a.cycles_per_window > 1000 {
        bail!("--cycles-per-window must be 1 to 1000");
    }
    if let Some(s) = a.settle_s {
        if !(s.is_finite() && s >= 0.0) {
            bail!("--settle-s must be 0 s or more");
        }
    }
    let opts = DemodOptions {
        settle_s: a.settle_s,
        cycles_per_window: a.cycles_per_window,
    };
    let text = std::fs::read_to_string(&a.file)
        .with_context(|| format!("cannot read {}", a.file.display()))?;
    if !(a.force_mn.is_finite() && a.force_mn > 0.0 && a.force_mn <= 1000.0) {
        bail!("--force-mn {} is out of range (0 to 1000 mN)", a.force_mn);
    }
    let an = analyze(
        &text,
        method,
        &unit,
        &opts,
        Newtons((a.force_mn * 1e-3) as f32),
    )
    .map_err(|e| anyhow::anyhow!("{}: {e}", a.file.display()))?;
    let c = &an.capture;
    if a.json {
        println!("{}", analysis_json(&an, &a.file.display().to_string()));
    } else {
        println!(
            "probe-bench analyze: {} ({} capture, {} rows → {} points)",
            a.file.display(),
            c.layout.name(),
            c.rows,
            c.points.len()
        );
        if let (Some(f), Some(l)) = (c.points.first(), c.points.last()) {
            println!("  band {:.3}–{:.3} Hz", f.freq.0, l.freq.0);
        }
        if let Some(s) = c.noise_sigma_s {
            println!(
                "  noise per component (estimated from local cubic fits): {:.3e} S",
                s
            );
        }
        if let (Some(fs), Some(shape)) = (c.sample_rate_hz, c.shape) {
            println!(
                "  sample rate {fs:.2} Hz, {} sweep{}",
                match shape {
                    SweepShape::Stepped => "stepped",
                    SweepShape::Continuous => "continuous",
                },
                if c.skipped_steps > 0 {
                    format!(", {} short steps skipped", c.skipped_steps)
                } else {
                    String::new()
                }
            );
        }
        println!(
            "  method {}, calibration {}: {}",
            if method == Method::Auto {
                format!("auto → {}", an.reading.method.name())
            } else {
                method.name().to_owned()
            },
            a.calibration,
            calfile::describe_profile(&unit)
        );
        println!("{}", report::reading_line(&an.reading));
    }
    if let Some(path) = &a.plot {
        let title = format!(
            "{} — {} ({})",
            a.file
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            an.reading.method.name(),
            match an.reading.status {
                Status::Ok => "ok".to_owned(),
                Status::Failed(f) => f.code().to_owned(),
            }
        );
        plot::sweep_svg(path, &title, &c.points, an.reading.resonance.map(|f| f.0))?;
        if !a.json {
            println!("  plot: {}", path.display());
        }
    }
    Ok(())
}
