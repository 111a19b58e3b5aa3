//! Resonance estimators: one per file, one result type.
//!
//! Every estimator takes the measured points and returns either an [`Estimate`] with an honest
//! standard uncertainty or a [`Failure`] code. The checks every sweep shares (clipping, missing
//! drive, no current, knocks) live here in [`screen`]; the detectors of interference and of lost
//! contact that the estimators call on their final points are in [`interference`] and
//! [`contact`]; the model of the resonator's driven response and its fit, which hold and the
//! continuous mode share, in [`resonator`].

pub mod conductance;
pub mod contact;
pub mod fit;
pub mod hold;
pub mod interference;
pub mod model;
pub mod paper;
pub mod resonator;
pub mod ringdown;
pub mod staged;
pub mod track;

use crate::engine::sweep::SweepPoint;
use crate::status::Failure;
use crate::units::Hz;

/// Which resonance a method reports and a calibration curve maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Resonance {
    /// The motional (series) resonance of the mode: every method but `paper`, and the papers'
    /// published curves (the simulated unit's motional resonance follows paper 003's `f_e`).
    Motional,
    /// The |Z| dip of paper 003's method, between the series and the parallel resonance.
    ImpedanceDip,
}

impl Resonance {
    /// Stable name (`motional`, `impedance-dip`).
    pub const fn name(self) -> &'static str {
        match self {
            Resonance::Motional => "motional",
            Resonance::ImpedanceDip => "impedance-dip",
        }
    }
}

/// A resonance estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Estimate {
    /// Resonance frequency.
    pub resonance: Hz,
    /// Its standard uncertainty.
    pub sigma: Hz,
    /// Quality factor, where the method measures it.
    pub q: Option<f32>,
    /// Standard uncertainty of the quality factor, where the method gives one.
    pub q_sigma: Option<f32>,
    /// Points the estimate used.
    pub points_used: u16,
}

/// Largest fraction of current samples allowed at a converter rail: none. A sample at a rail
/// means the signal reached full scale; the points near it are distorted even when only the
/// noise peaks clip.
pub const MAX_CLIP_FRACTION: f32 = 0.0;

/// Below this sense current (A, peak) at every point no current flows: the PZT or its wiring is
/// open. (A 210 pF plate driven at 1 V and 170 Hz already carries 220 nA; 20 nA is 7 ADC codes.)
pub const OPEN_CIRCUIT_A: f32 = 20e-9;

/// The factor an estimator's covariance is scaled by for a fit with reduced χ² `reduced`: the
/// reduced χ² itself when the fit is grossly wrong (above [`conductance::GROSS_CHI2`]), else 1
/// (the per-point uncertainties are measured; modest excess from settling transients is a
/// repeatable bias the calibration absorbs, and inflating by it would overstate the scatter).
pub fn gross_scale(reduced: f64) -> f64 {
    if reduced > conductance::GROSS_CHI2 {
        reduced
    } else {
        1.0
    }
}

/// Largest standard uncertainty of a resonance accepted, as a fraction of its linewidth `f0/Q`.
pub const MAX_RELATIVE_SIGMA: f64 = 0.25;

/// The low-SNR rule every estimator applies to its result: a resonance whose standard
/// uncertainty `sigma` (Hz) is not finite or exceeds [`MAX_RELATIVE_SIGMA`] of the peak's
/// `linewidth` (Hz, `f0/Q`) is not resolved — `low_snr`. A quarter linewidth is where the
/// peak's position is no longer better known than its width: the modulus would then be set by
/// the noise, not by the tissue.
pub fn resolved(sigma: f64, linewidth: f64) -> Result<(), Failure> {
    if sigma.is_finite() && sigma <= MAX_RELATIVE_SIGMA * linewidth {
        Ok(())
    } else {
        Err(Failure::LowSnr)
    }
}

/// `e` if its resonance lies within `[start, stop]`, else `out_of_band`.
pub fn in_band(e: Estimate, start: Hz, stop: Hz) -> Result<Estimate, Failure> {
    let f = e.resonance.0;
    if f < start.0 || f > stop.0 {
        return Err(Failure::OutOfBand);
    }
    Ok(e)
}

/// Checks every sweep must pass before any estimator looks at it: enough points, no clipping, a
/// current at all, no knock ([`interference::transients`]).
pub fn screen(points: &[SweepPoint]) -> Result<(), Failure> {
    if points.len() < 3 {
        return Err(Failure::NoResonance);
    }
    if points.iter().any(|p| p.clip_fraction > MAX_CLIP_FRACTION) {
        return Err(Failure::Clipped);
    }
    if points.iter().all(|p| !(p.current_a >= OPEN_CIRCUIT_A)) {
        return Err(Failure::OpenCircuit);
    }
    interference::transients(points)
}

/// Index of the largest value of `key` over `points` (first on ties); `None` on empty input or
/// when any key is not finite.
pub fn argmax(points: &[SweepPoint], key: impl Fn(&SweepPoint) -> f32) -> Option<usize> {
    let mut best: Option<(usize, f32)> = None;
    for (i, p) in points.iter().enumerate() {
        let v = key(p);
        if !v.is_finite() {
            return None;
        }
        if best.is_none_or(|(_, b)| v > b) {
            best = Some((i, v));
        }
    }
    best.map(|(i, _)| i)
}

/// The tests' own reference for the resonance model, independent of [`model`].
#[cfg(test)]
pub(crate) mod reference {
    /// The motional branch as the circuit it models: `1 / (R + jωL + 1/(jωC))` with `R = 1`,
    /// `L = Q R / ω0`, `C = 1/(ω0² L)` — the branch's admittance over its peak conductance, as
    /// `(Re, Im)`. Written from the circuit, not from the estimators' `1/(1 + jQu)` form.
    pub fn rlc_shape(f0: f64, q: f64, f: f64) -> (f64, f64) {
        let tau = 2.0 * core::f64::consts::PI;
        let (w0, w) = (tau * f0, tau * f);
        let r = 1.0;
        let l = q * r / w0;
        let c = 1.0 / (w0 * w0 * l);
        let x = w * l - 1.0 / (w * c);
        // 1 / (r + jx) = (r − jx) / (r² + x²)
        let d = r * r + x * x;
        (r / d, -x / d)
    }
}
