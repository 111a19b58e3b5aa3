//! The measurement: a method, its validated settings, the points it asks the sample engine for,
//! and the typed [`Reading`] it ends in.
//!
//! The same state machine runs in the firmware's measurement task and on the host (through
//! [`crate::reading::runner`]): it hands out one [`PointPlan`] at a time, takes back each finished
//! [`PointRaw`], and at the end estimates the resonance and maps it through the calibration.

pub mod driver;
pub mod pipeline;
pub mod runner;

use crate::engine::sweep::{
    point_from_raw, PointError, SettingsError, Sweep, SweepPoint, SweepSettings, MAX_POINTS,
};
use crate::engine::{PointPlan, PointRaw};
use crate::estimate::hold::{Hold, HoldSettings};
use crate::estimate::staged::{Staged, StagedSettings};
use crate::estimate::{self, Estimate, Resonance};
use crate::hal::FrontEndScale;
use crate::loadcell::RawForce;
use crate::reading::driver::Plans;
use crate::reading::pipeline::conclude;
use crate::status::{Failure, Status};
use crate::unit::profile::{Reference, UnitProfile};
use crate::units::{Hz, KPa, Seconds, Volts};
use heapless::Vec;

/// Resonance estimation method.
///
/// Every build (host, QEMU and STM32 images) carries every method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Method {
    /// Paper 003: stepped sweep 200–300 Hz in 1 Hz steps, `|Z|` minimum.
    Paper,
    /// Stepped sweep, conductance maximum with a weighted `1/G` fit.
    SweepG,
    /// A few points, Butterworth–Van Dyke fit of the complex admittance.
    Fit,
    /// Seed with a ring-down, then hold the drive on the resonance and fit its response.
    Hold,
    /// The default strategy: the fast hold over the band (no seed), falling back to fit and
    /// then to sweep-G while the resonance is not found or not resolved; the reading names the
    /// method that produced it.
    Auto,
}

/// Settings of a method: stepped sweeps, the fit method's two stages, or hold.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Settings {
    /// paper, sweep-g.
    Sweep(SweepSettings),
    /// fit (and auto, whose fit stage it sets).
    Staged(StagedSettings),
    /// hold.
    Hold(HoldSettings),
}

/// The default method of every caller: the firmware's measurement task and `probe-bench`.
pub const DEFAULT_METHOD: Method = Method::Auto;

/// The names of [`Method::ALL`], as the firmware's `help` lists them (a test checks they are
/// the same list).
pub const METHOD_NAMES: &str = "paper,sweep-g,fit,hold,auto";

/// `Settings::from(&s)` for each method family's settings.
macro_rules! settings_from {
    ($($t:ty => $v:ident),*) => {$(
        impl From<&$t> for Settings {
            fn from(s: &$t) -> Self {
                Settings::$v(*s)
            }
        }
    )*};
}
settings_from!(
    SweepSettings => Sweep,
    StagedSettings => Staged,
    HoldSettings => Hold
);
impl From<&Settings> for Settings {
    fn from(s: &Settings) -> Self {
        *s
    }
}

impl Method {
    /// Every method.
    pub const ALL: [Method; 5] = [
        Method::Paper,
        Method::SweepG,
        Method::Fit,
        Method::Hold,
        Method::Auto,
    ];

    /// Stable name.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Paper => "paper",
            Method::SweepG => "sweep-g",
            Method::Fit => "fit",
            Method::Hold => "hold",
            Method::Auto => "auto",
        }
    }

    /// Which resonance the method reports: every method but `paper` the motional one; `paper`
    /// the |Z| dip, which C0 and the coupling pull several hertz off it. A calibration maps
    /// one of them, so it serves only the methods that report that one.
    pub const fn resonance(self) -> Resonance {
        match self {
            Method::Paper => Resonance::ImpedanceDip,
            _ => Resonance::Motional,
        }
    }

    /// True for the methods that work on a given set of stepped-sweep points (and so on
    /// captured frequency-domain data); the others steer the drive while they measure.
    pub const fn works_on_points(self) -> bool {
        matches!(self, Method::Paper | Method::SweepG | Method::Fit)
    }

    /// The method's default settings.
    pub const fn default_settings(self) -> Settings {
        match self {
            Method::Paper | Method::SweepG => Settings::Sweep(self.default_sweep()),
            Method::Fit | Method::Auto => Settings::Staged(StagedSettings::DEFAULT),
            Method::Hold => Settings::Hold(HoldSettings::DEFAULT),
        }
    }

    /// Parse a [`name`](Self::name).
    pub fn from_name(s: &str) -> Option<Method> {
        Self::ALL.into_iter().find(|m| m.name() == s)
    }

    /// The method's default sweep.
    ///
    /// * paper: the paper's band 200–300 Hz in 1 Hz steps; every point settles 50 ms and
    ///   integrates 50 ms (the prototype's dwell is not published; 100 ms a point is typical
    ///   of a LabVIEW stepped sweep).
    /// * sweep-G: 170–290 Hz (covers 100–3000 kPa with the half-power width to spare) in 2 Hz
    ///   steps, 50 ms settle (3.5 time constants at Q = 10), 40 ms integration.
    pub const fn default_sweep(self) -> SweepSettings {
        match self {
            Method::Paper => SweepSettings {
                start: Hz(200.0),
                stop: Hz(300.0),
                step: Hz(1.0),
                settle: Seconds(0.05),
                integrate: Seconds(0.05),
                drive: Volts(5.0),
            },
            _ => SweepSettings {
                start: Hz(170.0),
                stop: Hz(290.0),
                step: Hz(2.0),
                settle: Seconds(0.05),
                integrate: Seconds(0.04),
                drive: Volts(5.0),
            },
        }
    }

    /// Run this method's estimator on stepped-sweep points (the methods that
    /// [`work on points`](Self::works_on_points); the others give `bad_settings`).
    pub fn estimate(self, points: &[SweepPoint]) -> Result<Estimate, Failure> {
        match self {
            Method::Paper => estimate::paper::estimate(points),
            // On given points the strategy's fallback is what applies.
            Method::SweepG | Method::Auto => estimate::conductance::estimate(points),
            Method::Fit => {
                let i = estimate::argmax(points, |p| p.g_s).ok_or(Failure::NoResonance)?;
                let f = points[i].freq.0 as f64;
                estimate::fit::estimate(points, f, 10.0)
            }
            _ => Err(Failure::BadSettings),
        }
    }
}

pub use crate::unit::profile::AirReference;

/// The outcome of one reading: a number with its uncertainty, or a failure code.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading {
    /// `Ok` or the failure code.
    pub status: Status,
    /// Method used.
    pub method: Method,
    /// Resonance, when one was estimated (also for out-of-range readings).
    pub resonance: Option<Hz>,
    /// Standard uncertainty of the resonance.
    pub resonance_sigma: Option<Hz>,
    /// Elastic modulus; present only when `status` is `Ok`.
    pub modulus: Option<KPa>,
    /// Combined standard uncertainty of the modulus (repeatability and calibration).
    pub modulus_sigma: Option<KPa>,
    /// Repeatability part of the modulus uncertainty (what repeated readings scatter by).
    pub modulus_sigma_repeat: Option<KPa>,
    /// Quality factor, where the method measures it.
    pub q: Option<f32>,
    /// The tissue's loss tangent `tan δ = E''/E'` at the resonance, beyond the reference
    /// phantoms' (present with the modulus, when the unit has a contact law and the method
    /// measures Q with its uncertainty; [`crate::unit::profile::UnitProfile::tissue_loss`]).
    pub loss_tangent: Option<f32>,
    /// Its standard uncertainty.
    pub loss_tangent_sigma: Option<f32>,
    /// Probe time the reading took (drive on to last sample).
    pub probe_time: Seconds,
    /// Points measured.
    pub points: u16,
    /// The contact force over the reading's window, when the unit has a load cell and it
    /// answered (also on failed readings that got as far as the force).
    pub force: Option<crate::loadcell::ContactForce>,
}

impl Reading {
    /// The reference a reading on a phantom of `modulus` gives, when it has a resonance with
    /// its uncertainty and a Q, and — with a load cell — a steady force inside the window
    /// (its status does not matter otherwise: the uncalibrated unit refuses the modulus, not
    /// the resonance; a reference pressed too lightly, too hard, unsteadily or not at all is
    /// no reference).
    pub fn reference(&self, modulus: KPa) -> Option<Reference> {
        let r = self;
        if let crate::status::Status::Failed(f) = r.status {
            if f.is_press() {
                return None;
            }
        }
        match (r.resonance, r.resonance_sigma, r.q) {
            (Some(f), Some(s), Some(q)) if f.0.is_finite() && s.0.is_finite() && q > 0.0 => {
                Some(Reference {
                    modulus_kpa: modulus.0 as f64,
                    resonance_hz: f.0 as f64,
                    sigma_hz: (s.0 as f64).max(1e-4),
                    q: q as f64,
                    force_n: r
                        .force
                        .map(|w| w.mean.0 as f64)
                        .filter(|f| f.is_finite() && *f > 0.0)
                        .unwrap_or(0.0),
                })
            }
            _ => None,
        }
    }

    /// The reading of an estimate, before any unit data: `Ok`, the resonance with its
    /// uncertainty and the Q as estimated, no modulus or loss yet.
    pub fn estimated(
        method: Method,
        est: &Estimate,
        probe_time: Seconds,
        points: u16,
        force: Option<crate::loadcell::ContactForce>,
    ) -> Self {
        Self {
            status: Status::Ok,
            resonance: Some(est.resonance),
            resonance_sigma: Some(est.sigma),
            q: est.q,
            force,
            // The rest empty, as on a reading with no estimate (its status replaced above).
            ..Self::failed(method, Failure::LowSnr, probe_time, points)
        }
    }

    /// A reading that failed before any estimate.
    pub fn failed(method: Method, failure: Failure, probe_time: Seconds, points: u16) -> Self {
        Self {
            status: Status::Failed(failure),
            method,
            resonance: None,
            resonance_sigma: None,
            modulus: None,
            modulus_sigma: None,
            modulus_sigma_repeat: None,
            q: None,
            loss_tangent: None,
            loss_tangent_sigma: None,
            probe_time,
            points,
            force: None,
        }
    }
}

/// A stepped-sweep measurement in progress.
#[derive(Clone, Debug)]
pub struct SweepMeasurement {
    method: Method,
    sweep: Sweep,
    scale: FrontEndScale,
    next: usize,
    points: Vec<SweepPoint, MAX_POINTS>,
    /// Sweep indices around the conductance peak measured again after the sweep.
    revisit: Vec<usize, REVISITS>,
    /// Their second measurement.
    again: Vec<SweepPoint, REVISITS>,
    start_sample: u64,
    end_sample: u64,
    failure: Option<Failure>,
}

/// Points around the peak a stepped sweep measures again at its end ([`SweepMeasurement`]).
pub const REVISITS: usize = 3;

/// Least shift of the resonance between the sweep and its revisits, as a fraction of the
/// linewidth `f0/Q`, that counts as the resonance having moved: 1 % (0.23 Hz at Q = 10), a
/// tenth of what a 0.3 Hz/s drift makes over a 6 s sweep and far above the reading's own
/// uncertainty (0.005 Hz at bench noise).
pub const REVISIT_SHIFT: f32 = 0.01;

impl SweepMeasurement {
    /// Validate `settings` for `method` on a board of `scale`; `now_sample` is the engine's
    /// sample count when the reading starts.
    pub fn new(
        method: Method,
        settings: &SweepSettings,
        scale: &FrontEndScale,
        now_sample: u64,
    ) -> Result<Self, SettingsError> {
        let sweep = settings.validate(scale)?;
        Ok(Self {
            method,
            sweep,
            scale: *scale,
            next: 0,
            points: Vec::new(),
            revisit: Vec::new(),
            again: Vec::new(),
            start_sample: now_sample,
            end_sample: now_sample,
            failure: None,
        })
    }

    /// The validated sweep.
    pub fn sweep(&self) -> &Sweep {
        &self.sweep
    }

    /// The next point to ask the engine for, or `None` when the sweep is complete. After the
    /// sweep, the points around the conductance peak are measured again (from the top down,
    /// settled four times as long after the jump back): a resonance that moved during the
    /// sweep (thermal drift, a creeping contact) shows as a change there.
    pub fn next_plan(&mut self) -> Option<PointPlan> {
        if self.failure.is_some() {
            return None;
        }
        if self.next < self.sweep.len() {
            let plan = self.sweep.plan(self.next, self.next as u16 + 1);
            self.next += 1;
            return Some(plan);
        }
        if self.revisit.is_empty() && self.points.len() >= 3 {
            let i = estimate::argmax(&self.points, |p| p.g_s)?;
            let n = self.points.len();
            for k in [i + 1, i, i.wrapping_sub(1)] {
                if k < n {
                    let _ = self.revisit.push(k);
                }
            }
        }
        let &k = self.revisit.get(self.again.len())?;
        let mut plan = self
            .sweep
            .plan(k, (self.sweep.len() + 1 + self.again.len()) as u16);
        plan.settle_samples = plan.settle_samples.saturating_mul(4);
        Some(plan)
    }

    /// True when the revisits show the resonance moved during the sweep: their change from
    /// the first measurement is a frequency shift `Δf` along the sweep's own slope `dY/df`
    /// (least squares over the revisited points; a shift moves them all along it, a tone or a
    /// knock does not), larger than five of its standard uncertainties and than
    /// [`REVISIT_SHIFT`] of the linewidth, and it explains most of the change. A sweep that does
    /// not settle (settling under three time constants of the estimated resonance: free air, a
    /// rigid contact) is not judged: its points carry transients of their own.
    fn moved(&self, e: &Estimate) -> bool {
        let (f0, q) = (e.resonance.0, e.q.unwrap_or(0.0));
        let tau = q / (core::f32::consts::PI * f0);
        let settle = self.sweep.settings().settle.0;
        if !(tau > 0.0 && settle >= 3.0 * tau) {
            return false;
        }
        let n = self.points.len();
        let (mut dd, mut dy, mut yy, mut var) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (&k, b) in self.revisit.iter().zip(&self.again) {
            let (Some(a), Some(lo), Some(hi)) = (
                self.points.get(k),
                self.points.get(k.saturating_sub(1)),
                self.points.get((k + 1).min(n - 1)),
            ) else {
                return false;
            };
            let df = hi.freq.0 - lo.freq.0;
            if !(df > 0.0) {
                return false;
            }
            let (dg, db) = ((hi.g_s - lo.g_s) / df, (hi.b_s - lo.b_s) / df);
            let (cg, cb) = (b.g_s - a.g_s, b.b_s - a.b_s);
            dd += dg * dg + db * db;
            dy += dg * cg + db * cb;
            yy += cg * cg + cb * cb;
            var += a.sigma_s * a.sigma_s + b.sigma_s * b.sigma_s;
        }
        if !(dd > 0.0) {
            return false;
        }
        let shift = dy / dd;
        let sigma = libm::sqrtf(var / self.again.len().max(1) as f32 / dd);
        let explained = shift * shift * dd;
        libm::fabsf(shift) > (5.0 * sigma).max(REVISIT_SHIFT * f0 / q.max(1.0))
            && explained >= 0.5 * yy
    }

    /// Take a finished point; returns it in physical units (for the log).
    pub fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
        self.end_sample = raw.end_sample;
        match point_from_raw(raw, &self.scale) {
            // A revisit: kept for the check, not a point of the sweep.
            Ok(p) if self.points.len() >= self.sweep.len() => {
                let _ = self.again.push(p);
                None
            }
            Ok(p) => {
                // Capacity equals the largest valid sweep, so this push cannot fail.
                let _ = self.points.push(p);
                Some(p)
            }
            Err(PointError::NoDrive) => {
                self.failure = Some(Failure::DriveFault);
                None
            }
            Err(PointError::Degenerate) => {
                self.failure = Some(Failure::BadSettings);
                None
            }
        }
    }

    /// True when every point and revisit is in (or the sweep was abandoned).
    pub fn is_complete(&self) -> bool {
        self.failure.is_some()
            || (self.points.len() >= self.sweep.len()
                && (self.points.len() < 3
                    || (!self.revisit.is_empty() && self.again.len() >= self.revisit.len())))
    }

    /// Points measured so far.
    pub fn points(&self) -> &[SweepPoint] {
        &self.points
    }

    /// Engine sample count at the last point.
    pub fn end_sample(&self) -> u64 {
        self.end_sample
    }

    /// Probe time so far.
    pub fn probe_time(&self) -> Seconds {
        Seconds(
            (self.end_sample.saturating_sub(self.start_sample)) as f32 / self.scale.sample_rate.0,
        )
    }

    /// The estimate of the points (or the failure that ended the sweep); `unstable` when the
    /// revisits show that the resonance moved during the sweep.
    pub fn estimate(&self) -> Result<Estimate, Failure> {
        match self.failure {
            Some(f) => Err(f),
            None => {
                let e = self.method.estimate(&self.points)?;
                if self.moved(&e) {
                    return Err(Failure::Unstable);
                }
                Ok(e)
            }
        }
    }

    /// The reading, through the one [`pipeline`] with the unit's profile and
    /// the load cell's counts over the reading's window.
    pub fn finish(&self, unit: &UnitProfile, force: Option<RawForce>) -> Reading {
        conclude(
            self.method,
            self.estimate(),
            unit,
            self.probe_time(),
            self.points.len() as u16,
            force,
        )
    }
}

/// Anything that asks the sample engine for points (its [`Plans`]) and ends in a reading.
pub trait Measurement: Plans {
    /// The reading, through the one [`pipeline`] with the unit's profile and
    /// the load cell's counts over the reading's window (`None`: no load cell, or it was
    /// silent).
    fn finish(&self, unit: &UnitProfile, force: Option<RawForce>) -> Reading;
}

impl Plans for SweepMeasurement {
    fn next_plan(&mut self) -> Option<PointPlan> {
        SweepMeasurement::next_plan(self)
    }
    fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
        SweepMeasurement::accept(self, raw)
    }
    fn is_complete(&self) -> bool {
        SweepMeasurement::is_complete(self)
    }
}

impl Measurement for SweepMeasurement {
    fn finish(&self, unit: &UnitProfile, force: Option<RawForce>) -> Reading {
        SweepMeasurement::finish(self, unit, force)
    }
}

// One procedure lives at a time (statically in the firmware, no allocator): the size spread
// between variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
enum Inner {
    Sweep(SweepMeasurement),
    Staged(Staged),
    Hold(Hold),
    Auto {
        /// The first stage, hold (`None` when the band does not suit it).
        hold: Option<Hold>,
        /// Its estimate, computed once when it completes.
        hold_result: Option<Result<Estimate, Failure>>,
        /// The second stage, fit.
        first: Staged,
        /// Its estimate, computed once when it completes.
        first_result: Option<Result<Estimate, Failure>>,
        /// The last, sweep-G over its default band.
        fallback: Option<SweepMeasurement>,
    },
}

/// Hold's settings as the first stage of [`Method::Auto`]: the fast hold over auto's band,
/// seeded at its centre.
///
/// The fast hold ([`HoldSettings::FAST`]: no seed, four one-cycle windows at the band's centre,
/// then on their estimate, one joint fit): its speed against the Cramér–Rao bound is in
/// docs/speed-accuracy.md, its cost on the M4 in docs/firmware.md (`tests/qemu_cost.rs`).
fn auto_hold(s: &StagedSettings) -> HoldSettings {
    HoldSettings {
        band_start: s.band_start,
        band_stop: s.band_stop,
        seed: Hz(0.5 * (s.band_start.0 + s.band_stop.0)),
        ..HoldSettings::FAST
    }
}

/// Failures of the first method of [`Method::Auto`] that the fallback may cure (the resonance
/// was missed or not resolved); the others (clipping, drive, open circuit, settings) it cannot.
fn retryable(e: &Result<Estimate, Failure>) -> bool {
    matches!(
        e,
        Err(Failure::NoResonance | Failure::LowSnr | Failure::OutOfBand | Failure::NotLocked)
    )
}

/// A reading by any method: the method's own procedure behind one interface.
#[derive(Clone, Debug)]
pub struct Procedure {
    method: Method,
    inner: Inner,
    scale: FrontEndScale,
    start_sample: u64,
    end_sample: u64,
    windows: u16,
}

impl Procedure {
    /// Validate `settings` for `method` on a board of `scale`; `now_sample` is the engine's
    /// sample count when the reading starts. `unit` supplies the unit data a method measures
    /// with: hold subtracts the air reference's static admittance (its settings' own `C0`, `G0`
    /// apply only to a unit without one, whose readings the pipeline then refuses).
    pub fn new(
        method: Method,
        settings: &Settings,
        scale: &FrontEndScale,
        now_sample: u64,
        unit: &UnitProfile,
    ) -> Result<Self, SettingsError> {
        let with_air;
        let settings = match (settings, unit.air) {
            (Settings::Hold(h), Some(air)) => {
                with_air = Settings::Hold(HoldSettings {
                    static_capacitance: air.static_capacitance,
                    static_conductance: air.static_conductance,
                    ..*h
                });
                &with_air
            }
            _ => settings,
        };
        let inner = match (method, settings) {
            (Method::Paper | Method::SweepG, Settings::Sweep(s)) => {
                Inner::Sweep(SweepMeasurement::new(method, s, scale, now_sample)?)
            }
            (Method::Fit, Settings::Staged(s)) => Inner::Staged(s.validate(scale)?),
            (Method::Hold, Settings::Hold(s)) => Inner::Hold(s.validate(scale)?),
            (Method::Auto, Settings::Staged(s)) => {
                // Validate every stage now: the interrupt must never see bad settings.
                Method::SweepG.default_sweep().validate(scale)?;
                let mut hold = auto_hold(s);
                if let Some(air) = unit.air {
                    hold.static_capacitance = air.static_capacitance;
                    hold.static_conductance = air.static_conductance;
                }
                Inner::Auto {
                    hold: hold.validate(scale).ok(),
                    hold_result: None,
                    first: s.validate(scale)?,
                    first_result: None,
                    fallback: None,
                }
            }
            _ => return Err(SettingsError::WrongMethod),
        };
        Ok(Self {
            method,
            inner,
            scale: *scale,
            start_sample: now_sample,
            end_sample: now_sample,
            windows: 0,
        })
    }

    /// The method.
    pub fn method(&self) -> Method {
        self.method
    }

    fn probe_time(&self) -> Seconds {
        Seconds(self.end_sample.saturating_sub(self.start_sample) as f32 / self.scale.sample_rate.0)
    }
}

impl Plans for Procedure {
    fn next_plan(&mut self) -> Option<PointPlan> {
        match &mut self.inner {
            Inner::Sweep(m) => m.next_plan(),
            Inner::Staged(m) => m.next_plan(),
            Inner::Hold(m) => m.next_plan(),
            Inner::Auto {
                hold,
                hold_result,
                first,
                first_result,
                fallback,
            } => {
                if let (Some(h), None) = (hold.as_mut(), hold_result.as_ref()) {
                    return h.next_plan();
                }
                if fallback.is_none() && first_result.as_ref().is_some_and(retryable) {
                    let sweep = Method::SweepG.default_sweep();
                    *fallback =
                        SweepMeasurement::new(Method::SweepG, &sweep, &self.scale, self.end_sample)
                            .ok();
                }
                match fallback {
                    Some(f) => f.next_plan(),
                    None => first.next_plan(),
                }
            }
        }
    }

    fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
        self.end_sample = raw.end_sample;
        self.windows = self.windows.saturating_add(1);
        match &mut self.inner {
            Inner::Sweep(m) => m.accept(raw),
            Inner::Staged(m) => m.accept(raw, &self.scale),
            Inner::Hold(m) => {
                m.accept(raw, &self.scale);
                None
            }
            Inner::Auto {
                hold: Some(h),
                hold_result: hold_result @ None,
                ..
            } => {
                h.accept(raw, &self.scale);
                if h.is_complete() {
                    *hold_result = Some(h.estimate());
                }
                None
            }
            Inner::Auto {
                first,
                first_result,
                fallback,
                ..
            } => match fallback {
                Some(f) => f.accept(raw),
                None => {
                    let p = first.accept(raw, &self.scale);
                    if first.is_complete() && first_result.is_none() {
                        *first_result = Some(first.estimate());
                    }
                    p
                }
            },
        }
    }

    fn is_complete(&self) -> bool {
        match &self.inner {
            Inner::Sweep(m) => m.is_complete(),
            Inner::Staged(m) => m.is_complete(),
            Inner::Hold(m) => m.is_complete(),
            Inner::Auto {
                hold,
                hold_result,
                first_result,
                fallback,
                ..
            } => {
                if hold.is_some() {
                    match hold_result {
                        None => return false,
                        Some(r) if !retryable(r) => return true,
                        Some(_) => {}
                    }
                }
                match fallback {
                    Some(f) => f.is_complete(),
                    None => first_result.as_ref().is_some_and(|r| !retryable(r)),
                }
            }
        }
    }
}

impl Measurement for Procedure {
    fn finish(&self, unit: &UnitProfile, force: Option<RawForce>) -> Reading {
        let t = self.probe_time();
        let (method, est, points) = match &self.inner {
            Inner::Sweep(m) => (self.method, m.estimate(), m.points().len() as u16),
            Inner::Staged(m) => (self.method, m.estimate(), m.len() as u16),
            Inner::Hold(m) => (self.method, m.estimate(), self.windows),
            Inner::Auto {
                hold_result: Some(r),
                ..
            } if !retryable(r) => (Method::Hold, *r, self.windows),
            Inner::Auto {
                first,
                first_result,
                fallback,
                ..
            } => match fallback {
                Some(f) => (
                    Method::SweepG,
                    f.estimate(),
                    (f.points().len() + first.len()) as u16,
                ),
                None => (
                    Method::Fit,
                    first_result.unwrap_or_else(|| first.estimate()),
                    first.len() as u16,
                ),
            },
        };
        conclude(method, est, unit, t, points, force)
    }
}
