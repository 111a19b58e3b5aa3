//! Stepped sweeps: validated settings in physical units, the plan of each point, and the
//! conversion of a finished point into admittance.

use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::dsp::lockin::{solve, solve_value};
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::units::{Hz, Seconds, Volts};
use num_complex::Complex64;

/// Most points a sweep may have (bounded memory: the points are kept for the estimator).
pub const MAX_POINTS: usize = 256;

/// Settings of a stepped sweep, as a user gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SweepSettings {
    /// First frequency.
    pub start: Hz,
    /// Last frequency (inclusive when the step lands on it).
    pub stop: Hz,
    /// Frequency step (> 0).
    pub step: Hz,
    /// Settling wait after each frequency step, before integration starts.
    pub settle: Seconds,
    /// Integration time per point, rounded up to whole drive cycles (at least one cycle).
    pub integrate: Seconds,
    /// Drive amplitude at the PZT (peak).
    pub drive: Volts,
}

/// Why settings were rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingsError {
    /// A value is NaN or infinite.
    NotFinite,
    /// A frequency is zero or negative.
    FrequencyNotPositive,
    /// `stop` is not above `start`.
    EmptyBand,
    /// `step` is zero or negative.
    StepNotPositive,
    /// More than [`MAX_POINTS`] points.
    TooManyPoints,
    /// Fewer than three points: no interior maximum can exist.
    TooFewPoints,
    /// A frequency above 0.4 of the sample rate (the reconstruction and anti-alias filters'
    /// band).
    AboveNyquist,
    /// Integration time shorter than one drive cycle at the lowest frequency.
    IntegrationShorterThanCycle,
    /// Negative settling time.
    SettleNegative,
    /// Drive amplitude zero, negative or beyond the DAC range.
    DriveOutOfRange,
    /// Settling or integration longer than 10 s per point.
    TooLong,
    /// A method knob (stages, window cycles, point counts, spans) is outside its range.
    KnobOutOfRange,
    /// The settings given are for another method.
    WrongMethod,
}

impl SettingsError {
    /// One line for a human.
    pub const fn message(self) -> &'static str {
        match self {
            SettingsError::NotFinite => "a setting is NaN or infinite",
            SettingsError::FrequencyNotPositive => "frequencies must be above 0 Hz",
            SettingsError::EmptyBand => "stop frequency must be above start frequency",
            SettingsError::StepNotPositive => "frequency step must be above 0 Hz",
            SettingsError::TooManyPoints => "too many sweep points (at most 256)",
            SettingsError::TooFewPoints => "a sweep needs at least three points",
            SettingsError::AboveNyquist => "frequency above 0.4 of the sample rate",
            SettingsError::IntegrationShorterThanCycle => {
                "integration shorter than one drive cycle"
            }
            SettingsError::SettleNegative => "settling time must not be negative",
            SettingsError::DriveOutOfRange => "drive amplitude out of the DAC range",
            SettingsError::TooLong => "settle or integration longer than 10 s per point",
            SettingsError::KnobOutOfRange => "a method setting is outside its range",
            SettingsError::WrongMethod => "these settings belong to another method",
        }
    }
}

impl core::fmt::Display for SettingsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())
    }
}

/// Drive amplitude in DAC codes for `drive` volts, validated.
pub fn amplitude_codes(drive: Volts, scale: &FrontEndScale) -> Result<u16, SettingsError> {
    let v = drive.0;
    if !v.is_finite() {
        return Err(SettingsError::NotFinite);
    }
    let codes = v / scale.drive_volts_per_code;
    if !(codes >= 1.0) || codes > FrontEndScale::MAX_AMPLITUDE_CODES as f32 + 0.5 {
        return Err(SettingsError::DriveOutOfRange);
    }
    Ok((codes + 0.5) as u16)
}

/// Validate one drive frequency (used by every method); returns its tuning word.
pub fn check_frequency(f: f32, scale: &FrontEndScale) -> Result<u32, SettingsError> {
    if !f.is_finite() {
        return Err(SettingsError::NotFinite);
    }
    if !(f > 0.0) {
        return Err(SettingsError::FrequencyNotPositive);
    }
    if f > 0.4 * scale.sample_rate.0 {
        return Err(SettingsError::AboveNyquist);
    }
    Ok(tuning_word(f as f64, scale.sample_rate.0 as f64))
}

/// Validate a band: both edges drive frequencies ([`check_frequency`]), the stop above the
/// start (used by every method with a band).
pub fn check_band(start: Hz, stop: Hz, scale: &FrontEndScale) -> Result<(), SettingsError> {
    check_frequency(start.0, scale)?;
    check_frequency(stop.0, scale)?;
    if !(stop.0 > start.0) {
        return Err(SettingsError::EmptyBand);
    }
    Ok(())
}

/// Validate a settling and an integration time against the lowest frequency they apply to.
pub fn check_durations(
    settle: Seconds,
    integrate: Seconds,
    lowest: f32,
) -> Result<(), SettingsError> {
    if !settle.0.is_finite() || !integrate.0.is_finite() {
        return Err(SettingsError::NotFinite);
    }
    if settle.0 < 0.0 {
        return Err(SettingsError::SettleNegative);
    }
    if settle.0 > 10.0 || integrate.0 > 10.0 {
        return Err(SettingsError::TooLong);
    }
    if !(integrate.0 * lowest >= 1.0) {
        return Err(SettingsError::IntegrationShorterThanCycle);
    }
    Ok(())
}

/// A validated sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sweep {
    settings: SweepSettings,
    points: u16,
    sample_rate_hz: f32,
    settle_samples: u32,
    amplitude_codes: u16,
}

impl SweepSettings {
    /// Check every setting; the result is what the interrupt may be given.
    pub fn validate(&self, scale: &FrontEndScale) -> Result<Sweep, SettingsError> {
        let (a, b, s) = (self.start.0, self.stop.0, self.step.0);
        if !a.is_finite() || !b.is_finite() || !s.is_finite() {
            return Err(SettingsError::NotFinite);
        }
        check_band(self.start, self.stop, scale)?;
        if !(s > 0.0) {
            return Err(SettingsError::StepNotPositive);
        }
        let n = ((b - a) / s + 1e-4) as f64;
        if n + 1.0 > MAX_POINTS as f64 {
            return Err(SettingsError::TooManyPoints);
        }
        let points = n as u16 + 1;
        if points < 3 {
            return Err(SettingsError::TooFewPoints);
        }
        check_durations(self.settle, self.integrate, a)?;
        let amplitude_codes = amplitude_codes(self.drive, scale)?;
        Ok(Sweep {
            settings: *self,
            points,
            sample_rate_hz: scale.sample_rate.0,
            settle_samples: (self.settle.0 * scale.sample_rate.0 + 0.5) as u32,
            amplitude_codes,
        })
    }
}

impl Sweep {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points as usize
    }
    /// Always false: a valid sweep has at least three points.
    pub fn is_empty(&self) -> bool {
        self.points == 0
    }
    /// The settings this sweep was validated from.
    pub fn settings(&self) -> &SweepSettings {
        &self.settings
    }
    /// Nominal frequency of point `i`.
    pub fn frequency(&self, i: usize) -> Hz {
        Hz(self.settings.start.0 + i as f32 * self.settings.step.0)
    }
    /// Plan of point `i`. The first point settles four times longer (the resonator starts from
    /// rest).
    pub fn plan(&self, i: usize, tag: u16) -> PointPlan {
        let f = self.frequency(i).0;
        let cycles = libm::ceilf(self.settings.integrate.0 * f).max(1.0) as u32;
        let settle = if i == 0 {
            self.settle_samples.saturating_mul(4)
        } else {
            self.settle_samples
        };
        PointPlan {
            ftw: tuning_word(f as f64, self.sample_rate_hz as f64),
            amplitude_codes: self.amplitude_codes,
            settle_samples: settle,
            cycles,
            windows: 1,
            open: false,
            aligned: false,
            tag,
        }
    }
}

/// One measured point of admittance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SweepPoint {
    /// Exact drive frequency (from the tuning word).
    pub freq: Hz,
    /// Conductance `Re(Y)` in siemens.
    pub g_s: f32,
    /// Susceptance `Im(Y)` in siemens.
    pub b_s: f32,
    /// Standard uncertainty of each of `g_s` and `b_s`, in siemens.
    pub sigma_s: f32,
    /// Sense current amplitude in amperes (peak).
    pub current_a: f32,
    /// Drive amplitude at the PZT in volts (peak), as measured by the monitor.
    pub drive_v: f32,
    /// Fraction of current samples at a converter rail.
    pub clip_fraction: f32,
    /// RMS of the current channel's residual after the sine fit, in amperes.
    pub residual_a: f32,
}

impl SweepPoint {
    /// `|Y|` in siemens.
    pub fn magnitude_s(&self) -> f32 {
        libm::hypotf(self.g_s, self.b_s)
    }
}

/// Why a raw point could not be turned into admittance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PointError {
    /// The window was degenerate (too short).
    Degenerate,
    /// No drive voltage was measured (DAC or amplifier fault).
    NoDrive,
}

/// The measured drive voltage of a point or a hold segment: the one place a current becomes an
/// admittance `Y = I / V`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// Drive phasor, V.
    pub v: Complex64,
    /// Variance of each of its components, V².
    pub var_v: f64,
}

/// An admittance and the variance of each of its components.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Admittance {
    /// `Y = G + jB`, S.
    pub y: Complex64,
    /// Variance of each of `G` and `B`, S².
    pub var: f64,
}

impl Drive {
    /// The drive from the monitor channel's amplitude `value` (codes) and the variance of each
    /// of its components ([`crate::dsp::lockin::solve_value`]); `None` below 2 monitor codes
    /// (no drive: DAC or amplifier fault).
    pub fn from_value(value: Complex64, variance: f64, scale: &FrontEndScale) -> Option<Self> {
        let av = scale.monitor_volts_per_code as f64;
        let v = value * av;
        // |value| > 2 codes (squared: no square root).
        if !(value.norm_sqr() > 4.0) || !(v.norm_sqr() > 0.0) {
            return None;
        }
        Some(Self {
            v,
            var_v: variance * av * av,
        })
    }

    /// `Y = I / V` for current `i` (A) with component variance `var_i` (A²); the variance
    /// takes both channels' noise, `dY = dI / V − Y dV / V`.
    pub fn admittance(&self, i: Complex64, var_i: f64) -> Admittance {
        let y = i / self.v;
        Admittance {
            y,
            var: (var_i + y.norm_sqr() * self.var_v) / self.v.norm_sqr(),
        }
    }
}

/// Admittance of a finished point.
pub fn point_from_raw(raw: &PointRaw, scale: &FrontEndScale) -> Result<SweepPoint, PointError> {
    let r = &raw.sums.reference;
    let pi = solve(&raw.sums.current, r).ok_or(PointError::Degenerate)?;
    let (v, var_v) = solve_value(&raw.sums.monitor, r).ok_or(PointError::Degenerate)?;
    let drive = Drive::from_value(v, var_v, scale).ok_or(PointError::NoDrive)?;
    let ai = scale.amps_per_code as f64;
    let i = pi.value * ai;
    let y = drive.admittance(i, pi.variance * ai * ai);
    let n = r.n.max(1) as f32;
    Ok(SweepPoint {
        freq: Hz(frequency_hz(raw.plan.ftw, scale.sample_rate.0 as f64) as f32),
        g_s: y.y.re as f32,
        b_s: y.y.im as f32,
        sigma_s: libm::sqrt(y.var) as f32,
        current_a: i.norm() as f32,
        drive_v: drive.v.norm() as f32,
        clip_fraction: raw.sums.current_rail_hits as f32 / n,
        residual_a: (pi.residual_rms * ai) as f32,
    })
}
