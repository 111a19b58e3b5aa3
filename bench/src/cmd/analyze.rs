//! `probe-bench analyze`: a capture from the bench (impedance analyser or DAQ), through the
//! firmware's own estimator and calibration.
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > y)` also rejects NaN, deliberately

use super::{CalibrationArgs, OutputArgs};
use crate::calfile;
use crate::capture::{self, Capture, CaptureError, DemodOptions, Layout, SweepShape};
use crate::{plot, report};
use anyhow::{bail, Context, Result};
use clap::Args;
use pzt_probe::engine::sweep::SweepPoint;
use pzt_probe::estimate::model::Motional;
use pzt_probe::estimate::{self, fit, Estimate, Resonance};
use pzt_probe::linalg::{levenberg_marquardt, spd_inverse, LmStop};
use pzt_probe::reading::{pipeline, Reading};
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::{Failure, Hz, Method, Newtons, Seconds, Status};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct AnalyzeArgs {
    /// Capture: the bench's CSV (header row required, `#` comments) with columns
    /// `freq_hz,z_mag_ohm,z_phase_deg` (Hz, ohm, degrees), `freq_hz,y_re_s,y_im_s` (Hz,
    /// siemens) or `t_s,drive_hz,v_drive_v,i_sense_a` (s, Hz, volts, amperes; stepped or
    /// continuous sweep); or an analyser's own export, recognised from its content: HP/Agilent
    /// 4294A ASCII data file (`"TRACE: A"` blocks) or Keysight E4990A trace-data CSV.
    pub file: PathBuf,
    /// Resonance method: `auto` (the best estimator for the capture's layout: the
    /// Butterworth–Van Dyke fit of the complex admittance for analyser sweeps and for the
    /// demodulated points of DAQ captures, sweep-G on the same points when the fit finds no
    /// trustworthy resonance), or any estimator that works on measured frequency points
    /// (`fit`; `sweep-g`: conductance maximum; `paper`: |Z| minimum). Methods that steer the
    /// drive while measuring (hold) are refused.
    #[arg(long, default_value = "auto")]
    pub method: String,
    /// The calibration and the probe's unit profile.
    #[command(flatten)]
    pub cal: CalibrationArgs,
    /// JSON (one object: the capture, the estimate, the reading) and the plot (the admittance
    /// with the estimate marked).
    #[command(flatten)]
    pub out: OutputArgs,
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
        Layout::Impedance
        | Layout::Admittance
        | Layout::TimeDomain
        | Layout::Hp4294a
        | Layout::E4990a => Method::Fit,
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

/// `est` refused outside the band of `pts` (belt and braces: an estimate outside the measured
/// band is never a reading).
fn in_band(est: Estimate, pts: &[SweepPoint]) -> Result<Estimate, Failure> {
    let f = est.resonance.0;
    match (pts.first(), pts.last()) {
        (Some(first), Some(last)) if f > first.freq.0 && f < last.freq.0 => Ok(est),
        _ => Err(Failure::OutOfBand),
    }
}

/// `method`'s estimate of `pts`, refused outside the measured band; for the BVD fit, with its
/// σ grown by the fit's misfit ([`misfit_scaled`]) and the reduced χ².
fn estimate_in_band(
    method: Method,
    pts: &[SweepPoint],
) -> (Result<Estimate, Failure>, Option<f64>) {
    let est = method.estimate(pts).and_then(|e| in_band(e, pts));
    match (method, est) {
        (Method::Fit, Ok(e)) => match misfit_scaled(e, pts) {
            Ok((e, red)) => (Ok(e), Some(red)),
            Err(f) => (Err(f), None),
        },
        (_, est) => (est, None),
    }
}

/// Points whose conductance `G = Re Y` lies below zero by more than this many of their own
/// standard uncertainties make a capture inconsistent with a passive device.
pub const PASSIVE_SIGMAS: f32 = 5.0;

/// Where `pts` contradict a passive device: the points whose `Re Y` (hence `Re Z`) is below zero
/// by more than [`PASSIVE_SIGMAS`] σ. A passive impedance has `Re Z ≥ 0`, its phase within ±90°;
/// a phase column offset by 180° (or a sign flipped in a hand conversion) gives `Re Z < 0`
/// throughout. `None` when every point is consistent.
pub fn passive_violations(pts: &[SweepPoint]) -> Option<(usize, f32)> {
    let bad: Vec<&SweepPoint> = pts
        .iter()
        .filter(|p| p.g_s < -PASSIVE_SIGMAS * p.sigma_s.max(f32::MIN_POSITIVE))
        .collect();
    bad.first().map(|p| (bad.len(), p.freq.0))
}

/// The reduced χ² of the BVD fit at the estimate `e` (refitted from it:
/// `pzt_probe::estimate::fit::fit_bvd`), and `e` with its σ scaled by `sqrt(χ²/dof)` whenever
/// the residuals exceed the points' noise (`χ²/dof > 1`). The firmware's fit scales only a
/// grossly wrong fit (`pzt_probe::estimate::gross_scale`, above `GROSS_CHI2`): on the probe the
/// per-point σ is measured by the lock-in and modest excess is a repeatable bias the unit's
/// calibration absorbs; a bench capture has no such calibration behind it, so every misfit
/// beyond the noise widens its σ.
pub fn misfit_scaled(e: Estimate, pts: &[SweepPoint]) -> Result<(Estimate, f64), Failure> {
    let q = e.q.map_or(10.0, |q| q as f64);
    let b = fit::fit_bvd(pts, e.resonance.0 as f64, q)?;
    let mut chi2 = 0.0;
    for p in pts {
        let f = p.freq.0 as f64;
        let (mr, mi) = b.motional(f);
        let (sr, si) = b.static_part(f);
        let w = 1.0 / ((p.sigma_s as f64) * (p.sigma_s as f64)).max(1e-60);
        chi2 += w * ((p.g_s as f64 - sr - mr).powi(2) + (p.b_s as f64 - si - mi).powi(2));
    }
    let dof = (2 * pts.len()).saturating_sub(5).max(1) as f64;
    let red = chi2 / dof;
    let scale = (red.max(1.0) / estimate::gross_scale(red)).sqrt();
    let sigma = e.sigma.0 as f64 * scale;
    let f0 = e.resonance.0 as f64;
    estimate::resolved(sigma, f0 / q)?;
    Ok((
        Estimate {
            sigma: Hz(sigma as f32),
            ..e
        },
        red,
    ))
}

/// A Butterworth–Van Dyke fit of the admittance's magnitude alone (the phase is not used): the
/// model's parameters as the complex fit gives them ([`fit::Bvd`]; the uncertainties of `f0` and
/// `Q` scaled by `sqrt(χ²/dof)` when that exceeds 1, those of `G0` and `b0` from the noise alone).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MagnitudeFit {
    /// The fitted parameters.
    pub bvd: fit::Bvd,
    /// χ²/dof.
    pub reduced_chi2: f64,
}

/// `|Y(f)|` of the BVD model `p = [G0, b0, g, f0, Q]` at `f`, and its gradient in `p`.
fn magnitude_model(p: &[f64; 5], f_ref: f64, f: f64) -> (f64, [f64; 5]) {
    let m = Motional::at(p[3], p[4], f);
    let (yr, yi) = (p[0] + p[2] * m.h.re, p[1] * f / f_ref + p[2] * m.h.im);
    let y = yr.hypot(yi).max(1e-300);
    let (df0, dq) = m.derivatives(p[3], p[4], f);
    // d|Y| = Re(conj(Y) dY) / |Y|
    let d = |dr: f64, di: f64| (yr * dr + yi * di) / y;
    (
        y,
        [
            d(1.0, 0.0),
            d(0.0, f / f_ref),
            d(m.h.re, m.h.im),
            d(p[2] * df0.re, p[2] * df0.im),
            d(p[2] * dq.re, p[2] * dq.im),
        ],
    )
}

/// Fit the BVD admittance's magnitude, `|G0 + j b0 f/f_ref + g / (1 + jQ(f/f0 − f0/f))|`, to
/// `|Y|` of `pts` (weights `1/σ²`, σ the points' per-component noise, which is that of `|Y|`
/// too): the resonance from |Z| alone, for a capture whose phase cannot be trusted.
/// Levenberg–Marquardt (`pzt_probe::linalg`) from several starts read off the magnitude curve
/// (the dispersive swing of |Y| about its chord: its maximum and minimum lie at `f0 ∓ f0/2Q`
/// when C0 dominates, its peak at `f0` when the motional branch does); the lowest χ² wins.
/// `out_of_band` outside the points' span, `low_snr` when σ exceeds a quarter linewidth.
pub fn fit_magnitude(pts: &[SweepPoint]) -> Result<MagnitudeFit, Failure> {
    let n = pts.len();
    if n < 8 {
        return Err(Failure::NoResonance);
    }
    let data: Vec<(f64, f64, f64)> = pts
        .iter()
        .map(|p| {
            let s = (p.sigma_s as f64).max(1e-30);
            (p.freq.0 as f64, p.magnitude_s() as f64, 1.0 / (s * s))
        })
        .collect();
    if data.iter().any(|d| !(d.0.is_finite() && d.1.is_finite())) {
        return Err(Failure::NoResonance);
    }
    let (fa, ya) = (data[0].0, data[0].1);
    let (fb, yb) = (data[n - 1].0, data[n - 1].1);
    let span = fb - fa;
    if !(span > 0.0) {
        return Err(Failure::NoResonance);
    }
    let f_ref = 0.5 * (fa + fb);
    let dev = |d: &(f64, f64, f64)| d.1 - (ya + (d.0 - fa) / span * (yb - ya));
    let (mut imax, mut imin) = (0, 0);
    for (i, d) in data.iter().enumerate() {
        if dev(d) > dev(&data[imax]) {
            imax = i;
        }
        if dev(d) < dev(&data[imin]) {
            imin = i;
        }
    }
    let swing = (dev(&data[imax]) - dev(&data[imin])).max(1e-30);
    let b0_start = 0.5 * (ya * f_ref / fa + yb * f_ref / fb);
    let (f_hi, f_lo) = (data[imax].0, data[imin].0);
    let mid = 0.5 * (f_hi + f_lo);
    let q_mid = (mid / (f_hi - f_lo).abs().max(span / n as f64)).clamp(1.0, 200.0);
    let starts = [
        (mid, q_mid, b0_start, swing),
        (f_hi, 10.0, 0.0, dev(&data[imax]).max(swing * 0.5)),
        (f_hi, 10.0, b0_start, swing),
        (mid, 10.0, b0_start, swing),
    ];
    let chi2_of = |p: &[f64; 5]| -> f64 {
        if !(p[2] > 0.0 && p[3] > 0.0 && p[4] > 0.0) {
            return f64::INFINITY;
        }
        data.iter()
            .map(|&(f, y, w)| w * (y - magnitude_model(p, f_ref, f).0).powi(2))
            .sum()
    };
    let normal = |p: &[f64; 5]| -> ([[f64; 5]; 5], [f64; 5]) {
        let mut jtj = [[0.0; 5]; 5];
        let mut jtr = [0.0; 5];
        for &(f, y, w) in &data {
            let (m, j) = magnitude_model(p, f_ref, f);
            let r = y - m;
            for a in 0..5 {
                jtr[a] += w * j[a] * r;
                for b in 0..5 {
                    jtj[a][b] += w * j[a] * j[b];
                }
            }
        }
        (jtj, jtr)
    };
    let mut best: Option<([f64; 5], f64)> = None;
    for (f0, q, b0, g) in starts {
        for qm in [0.5, 1.0, 2.0] {
            let p0 = [0.0, b0, g, f0, (q * qm).clamp(1.0, 500.0)];
            let (p, c) = levenberg_marquardt(p0, chi2_of, normal, LmStop::new(200, 1e-12, 1e12));
            if c.is_finite() && best.is_none_or(|(_, cb)| c < cb) {
                best = Some((p, c));
            }
        }
    }
    let (p, chi2) = best.ok_or(Failure::NoResonance)?;
    let (jtj, _) = normal(&p);
    let cov = spd_inverse(&jtj).ok_or(Failure::NoResonance)?;
    let red = chi2 / n.saturating_sub(5).max(1) as f64;
    let sigma = |k: usize, scale: f64| (cov[k][k] * scale).max(0.0).sqrt();
    let s = red.max(1.0);
    let bvd = fit::Bvd::new(
        &p,
        f_ref,
        [sigma(3, s), sigma(4, s), sigma(0, 1.0), sigma(1, 1.0)],
    );
    if !p.iter().all(|v| v.is_finite()) || !bvd.sigma_f0.is_finite() {
        return Err(Failure::NoResonance);
    }
    if !(p[3] > fa && p[3] < fb) {
        return Err(Failure::OutOfBand);
    }
    estimate::resolved(bvd.sigma_f0, p[3] / p[4])?;
    Ok(MagnitudeFit {
        bvd,
        reduced_chi2: red,
    })
}

/// The unit a capture is read with.
#[derive(Clone, Debug)]
pub enum Unit {
    /// A probe's profile (`--profile`, or a profile file given as `--calibration`): every check
    /// of `reading::pipeline::conclude` (air reference, Q model, calibrated range), as on the
    /// probe.
    Profile(Box<UnitProfile>),
    /// A calibration curve alone (`--calibration` without `--profile`): the modulus through it,
    /// and no check that needs a probe's unit data (no Q model, no air reference).
    Curve(Box<UnitProfile>),
    /// Nothing (neither option): the capture's resonance and Q, no modulus.
    Bare,
}

impl Unit {
    /// Short name for the JSON (`profile`, `curve`, `none`).
    pub fn name(&self) -> &'static str {
        match self {
            Unit::Profile(_) => "profile",
            Unit::Curve(_) => "curve",
            Unit::Bare => "none",
        }
    }
    /// For humans.
    pub fn describe(&self) -> String {
        match self {
            Unit::Profile(p) => calfile::describe_profile(p),
            Unit::Curve(p) => format!(
                "{} (curve only: no Q model, no air reference)",
                calfile::describe(&p.calibration)
            ),
            Unit::Bare => {
                "none: resonance and Q only (a modulus needs --profile or --calibration)".into()
            }
        }
    }
}

/// A capture and the reading the firmware's estimator and calibration make of it.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The capture as points.
    pub capture: Capture,
    /// The reading.
    pub reading: Reading,
    /// The resonance and Q came from the magnitude alone ([`fit_magnitude`]): the phase was
    /// inconsistent with a passive device.
    pub magnitude_only: bool,
    /// χ²/dof of the fit that made the reading (BVD fit, complex or magnitude), when known.
    pub reduced_chi2: Option<f64>,
    /// What the reader should know about the data (one line each).
    pub warnings: Vec<String>,
    /// `profile`, `curve` or `none` ([`Unit::name`]).
    pub unit: &'static str,
}

/// Analyse capture text with `method` (`auto`: [`auto_method`] for the capture's layout, then
/// sweep-G when the fit fails as the firmware's `auto` retries) and `unit`, taken at the
/// contact force `force` (set by other means than the unit's load cell; used with a profile
/// only). The reading names the estimator that made it.
///
/// When the points contradict a passive device ([`passive_violations`]) no estimator that reads
/// the phase is trusted: the resonance and Q come from [`fit_magnitude`] (reported as `fit`,
/// with `magnitude_only` and a warning); `paper` reads |Z| alone anyway and keeps its estimate,
/// with the warning.
pub fn analyze(
    text: &str,
    method: Method,
    unit: &Unit,
    opts: &DemodOptions,
    force: Newtons,
) -> Result<Analysis, CaptureError> {
    let capture = capture::parse(text, min_points(method), opts)?;
    let pts = &capture.points;
    let mut warnings = Vec::new();
    let mut magnitude_only = false;
    let violations = passive_violations(pts);
    let (method, est, red) = if let Some((count, f_first)) = violations {
        warnings.push(format!(
            "phase inconsistent with a passive device: Re Z < 0 (G below zero by more than {PASSIVE_SIGMAS} sigma) at {count} of {} points, first at {f_first:.3} Hz (a phase offset by 180 degrees or a flipped sign?)",
            pts.len()
        ));
        if method == Method::Paper {
            warnings.push("paper reads |Z| alone: its estimate stands".into());
            let (est, _) = estimate_in_band(Method::Paper, pts);
            (Method::Paper, est, None)
        } else {
            magnitude_only = true;
            warnings.push(format!(
                "resonance and Q from |Z| alone (BVD magnitude fit){}",
                if matches!(method, Method::Auto | Method::Fit) {
                    String::new()
                } else {
                    format!(", not {} as asked", method.name())
                }
            ));
            match fit_magnitude(pts) {
                Ok(m) => (
                    Method::Fit,
                    Ok(Estimate {
                        resonance: Hz(m.bvd.f0 as f32),
                        sigma: Hz(m.bvd.sigma_f0 as f32),
                        q: Some(m.bvd.q as f32),
                        q_sigma: None,
                        points_used: pts.len().min(u16::MAX as usize) as u16,
                    }),
                    Some(m.reduced_chi2),
                ),
                Err(f) => (Method::Fit, Err(f), None),
            }
        }
    } else if method == Method::Auto {
        let first = auto_method(capture.layout);
        match estimate_in_band(first, pts) {
            (Err(f), _) if fit_failure_retryable(f) => {
                let (est, red) = estimate_in_band(Method::SweepG, pts);
                (Method::SweepG, est, red)
            }
            (est, red) => (first, est, red),
        }
    } else {
        let (est, red) = estimate_in_band(method, pts);
        (method, est, red)
    };
    let probe_time = match (capture.domain.time(), capture.layout) {
        (Some(t), Layout::TimeDomain) => Seconds(capture.rows as f32 / t.sample_rate_hz as f32),
        _ => Seconds(0.0),
    };
    let n = pts.len().min(u16::MAX as usize) as u16;
    let reading = match unit {
        Unit::Profile(p) => {
            let force = p.load_cell.map(|c| c.stated(force));
            pzt_probe::reading::pipeline::conclude(method, est, p, probe_time, n, force)
        }
        Unit::Curve(p) => conclude_without_unit(method, est, Some(p), probe_time, n),
        Unit::Bare => conclude_without_unit(method, est, None, probe_time, n),
    };
    Ok(Analysis {
        capture,
        reading,
        magnitude_only,
        reduced_chi2: red,
        warnings,
        unit: unit.name(),
    })
}

/// The reading of `est` without a probe's unit data: the resonance and Q as measured (`ok`),
/// `broad_resonance` below the readable Q (a property of the resonance, not of a unit); with a
/// `curve`, the modulus through it (`uncalibrated` if the curve maps another resonance, the
/// curve's range failures, `low_snr` above the pipeline's repeatability limit).
fn conclude_without_unit(
    method: Method,
    est: Result<Estimate, Failure>,
    curve: Option<&UnitProfile>,
    probe_time: Seconds,
    points: u16,
) -> Reading {
    let est = match est {
        Ok(e) => e,
        Err(f) => return Reading::failed(method, f, probe_time, points),
    };
    let mut r = Reading::estimated(method, &est, probe_time, points, None);
    if est.q.is_some_and(|q| q < pipeline::MIN_READABLE_Q) {
        r.status = Status::Failed(Failure::BroadResonance);
        return r;
    }
    let Some(u) = curve else { return r };
    if method.resonance() != u.resonance {
        r.status = Status::Failed(Failure::Uncalibrated);
        return r;
    }
    match u.invert(est.resonance, est.sigma, None, probe_time) {
        Ok(m) if m.sigma_repeat.0 <= pipeline::MAX_RELATIVE_REPEATABILITY * m.value.0 => {
            r.modulus = Some(m.value);
            r.modulus_sigma = Some(m.sigma);
            r.modulus_sigma_repeat = Some(m.sigma_repeat);
        }
        Ok(_) => r.status = Status::Failed(Failure::LowSnr),
        Err(f) => r.status = Status::Failed(f),
    }
    r
}

/// The unit `analyze` reads a capture with:
///
/// * `--profile FILE`: that probe's profile with every check (its curve replaced by a built-in
///   one when `calibration` names one; default `paper-experiment`, as before);
/// * no `--profile`, `--calibration NAME`: the curve alone — `paper-experiment`,
///   `paper-simulation`, or `unit` (the simulated unit's own curve, calibrated with `method`);
///   a profile file given as `--calibration` is a profile;
/// * neither: [`Unit::Bare`] — the capture's resonance and Q, no check that needs another
///   probe's unit data.
pub fn profile(profile: Option<&Path>, calibration: Option<&str>, method: Method) -> Result<Unit> {
    let sim = || crate::unit::default_for(method);
    Ok(match (profile, calibration) {
        (Some(p), c) => Unit::Profile(Box::new(calfile::resolve(
            Some(p),
            c.unwrap_or("paper-experiment"),
            sim,
        )?)),
        (None, None) => Unit::Bare,
        (None, Some("unit")) => {
            let mut u = UnitProfile::fallback();
            let s = sim()?;
            u.use_power_law(s.calibration, s.resonance);
            Unit::Curve(Box::new(u))
        }
        (None, Some(c)) => match calfile::builtin(c) {
            Some(law) => {
                let mut u = UnitProfile::fallback();
                // The papers' curves map the motional resonance (docs/physics.md).
                u.use_power_law(law, Resonance::Motional);
                Unit::Curve(Box::new(u))
            }
            None => Unit::Profile(Box::new(calfile::resolve(None, c, sim)?)),
        },
    })
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
        o.insert(
            "source".into(),
            c.source.as_ref().map_or(Value::Null, |s| json!(s)),
        );
        o.insert("band_hz".into(), band);
        o.insert("rows".into(), json!(c.rows));
        o.insert(
            "noise_sigma_s".into(),
            c.domain.noise_sigma_s().map_or(Value::Null, |s| json!(s)),
        );
        o.insert(
            "sample_rate_hz".into(),
            c.domain
                .time()
                .map_or(Value::Null, |t| json!(t.sample_rate_hz)),
        );
        o.insert(
            "sweep".into(),
            match c.domain.time().map(|t| t.shape) {
                Some(SweepShape::Stepped) => json!("stepped"),
                Some(SweepShape::Continuous) => json!("continuous"),
                None => Value::Null,
            },
        );
        if c.layout != Layout::TimeDomain {
            o.insert("probe_time_ms".into(), Value::Null);
        }
        o.insert("unit".into(), json!(a.unit));
        o.insert("magnitude_only".into(), json!(a.magnitude_only));
        o.insert(
            "reduced_chi2".into(),
            a.reduced_chi2.map_or(Value::Null, |r| json!(r)),
        );
        o.insert("warnings".into(), json!(a.warnings));
    }
    v
}

/// Run the subcommand.
pub fn run(a: AnalyzeArgs) -> Result<()> {
    let method = offline_method(&a.method)?;
    let unit = profile(
        a.cal.profile.as_deref(),
        a.cal.calibration.as_deref(),
        method,
    )?;
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
    if a.out.json {
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
        if let Some(s) = c.domain.noise_sigma_s() {
            println!(
                "  noise per component (estimated from local cubic fits): {:.3e} S",
                s
            );
        }
        if let Some(t) = c.domain.time() {
            println!(
                "  sample rate {:.2} Hz, {} sweep{}",
                t.sample_rate_hz,
                match t.shape {
                    SweepShape::Stepped => "stepped",
                    SweepShape::Continuous => "continuous",
                },
                if t.skipped_steps > 0 {
                    format!(", {} short steps skipped", t.skipped_steps)
                } else {
                    String::new()
                }
            );
        }
        if let Some(src) = &c.source {
            println!("  read: {src}");
        }
        println!(
            "  method {}{}, calibration {}",
            if method == Method::Auto {
                format!("auto → {}", an.reading.method.name())
            } else {
                an.reading.method.name().to_owned()
            },
            if an.magnitude_only {
                " (|Z| alone: BVD magnitude fit)"
            } else {
                ""
            },
            unit.describe()
        );
        if let Some(r) = an.reduced_chi2 {
            println!(
                "  fit: chi2/dof {r:.3}{}",
                if r > 1.0 {
                    " (sigma scaled by its square root)"
                } else {
                    ""
                }
            );
        }
        for w in &an.warnings {
            println!("  warning: {w}");
        }
        println!("{}", report::reading_line(&an.reading));
    }
    a.out.plot_with(|path| {
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
        plot::sweep_svg(path, &title, &c.points, an.reading.resonance.map(|f| f.0))
    })
}
