//! **paper**: the method of paper 003 — the frequency of the impedance minimum (`|Z|` min, i.e.
//! `|Y|` max), refined by a three-point parabola on `|Z|`.
//!
//! Kept as the baseline. The static capacitance in parallel with the motional branch moves the
//! `|Y|` maximum above the motional resonance, by an amount that depends on `C0`, the coupling
//! and the damping; a calibration on the same unit absorbs the bias only while those stay as
//! they were during calibration. The method gives no quality factor.

use super::{argmax, screen, Estimate};
use crate::status::Failure;
use crate::sweep::SweepPoint;
use crate::units::Hz;

/// Estimate the resonance as the `|Z|` minimum.
pub fn estimate(points: &[SweepPoint]) -> Result<Estimate, Failure> {
    screen(points)?;
    let n = points.len();
    let imax = argmax(points, |p| p.magnitude_s()).ok_or(Failure::NoResonance)?;
    if imax == 0 || imax == n - 1 {
        return Err(Failure::OutOfBand);
    }
    let z = |i: usize| 1.0 / points[i].magnitude_s() as f64;
    let sz = |i: usize| {
        let y = points[i].magnitude_s() as f64;
        points[i].sigma_s as f64 / (y * y)
    };
    let (zm, z0, zp) = (z(imax - 1), z(imax), z(imax + 1));
    let d = zm - 2.0 * z0 + zp;
    let num = zm - zp;
    if !(d > 0.0) {
        return Err(Failure::NoResonance);
    }
    let delta = num / (2.0 * d);
    let step = 0.5 * (points[imax + 1].freq.0 - points[imax - 1].freq.0) as f64;
    let f0 = points[imax].freq.0 as f64 + delta * step;
    let dm = (d - num) / (2.0 * d * d);
    let dp = (-d - num) / (2.0 * d * d);
    let d0 = num / (d * d);
    let sq = |v: f64| v * v;
    let var = sq(dm * sz(imax - 1)) + sq(d0 * sz(imax)) + sq(dp * sz(imax + 1));
    let sigma = step * libm::sqrt(var);
    // A vertex more than a step away from the sampled minimum is not resolved.
    if !sigma.is_finite() || delta.abs() > 1.0 || sigma > step {
        return Err(Failure::LowSnr);
    }
    Ok(Estimate {
        resonance: Hz(f0 as f32),
        sigma: Hz(sigma as f32),
        q: None,
        points_used: 3,
    })
}
