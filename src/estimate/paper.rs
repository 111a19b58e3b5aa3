//! **paper**: the method of paper 003 — the frequency where the impedance dips (`|Z|` minimum,
//! i.e. `|Y|` maximum), refined by a three-point parabola.
//!
//! Kept as the baseline. The static capacitance `C0` in parallel with the motional branch makes
//! `|Y| ≈ w C0` rise across the band, so the dip is taken as the largest maximum of `|Y|` above
//! the straight line through the band's end points (a global `|Z|` minimum would sit on the
//! band edge whenever `C0` dominates). The dip lies between the motional (series) resonance and
//! the parallel resonance, moved by an amount that depends on `C0`, the coupling and the damping;
//! a calibration on the same unit absorbs the bias only while those stay as they were during
//! calibration. The method gives no quality factor.

use super::{screen, Estimate};
use crate::status::Failure;
use crate::sweep::SweepPoint;
use crate::units::Hz;

/// Estimate the resonance as the `|Z|` dip.
pub fn estimate(points: &[SweepPoint]) -> Result<Estimate, Failure> {
    screen(points)?;
    let n = points.len();
    let (f_a, y_a) = (points[0].freq.0 as f64, points[0].magnitude_s() as f64);
    let (f_b, y_b) = (
        points[n - 1].freq.0 as f64,
        points[n - 1].magnitude_s() as f64,
    );
    let span = f_b - f_a;
    if !(span > 0.0) || !y_a.is_finite() || !y_b.is_finite() {
        return Err(Failure::NoResonance);
    }
    let d = |i: usize| {
        let p = &points[i];
        let t = (p.freq.0 as f64 - f_a) / span;
        p.magnitude_s() as f64 - (y_a + t * (y_b - y_a))
    };
    let mut imax = 0;
    let mut best = f64::NEG_INFINITY;
    for i in 0..n {
        let v = d(i);
        if !v.is_finite() {
            return Err(Failure::NoResonance);
        }
        if v > best {
            best = v;
            imax = i;
        }
    }
    if imax == 0 || imax == n - 1 {
        return Err(Failure::OutOfBand);
    }
    let (ym, y0, yp) = (d(imax - 1), d(imax), d(imax + 1));
    let s = |i: usize| points[i].sigma_s as f64;
    if !(y0 > 5.0 * s(imax)) {
        return Err(Failure::NoResonance);
    }
    // Parabola through the three detrended |Y| values; vertex offset in steps.
    let curv = ym - 2.0 * y0 + yp;
    let num = ym - yp;
    if !(curv < 0.0) {
        return Err(Failure::NoResonance);
    }
    let delta = num / (2.0 * curv);
    let step = 0.5 * (points[imax + 1].freq.0 - points[imax - 1].freq.0) as f64;
    let f0 = points[imax].freq.0 as f64 + delta * step;
    let dm = (curv - num) / (2.0 * curv * curv);
    let dp = (-curv - num) / (2.0 * curv * curv);
    let d0 = num / (curv * curv);
    let sq = |v: f64| v * v;
    let var = sq(dm * s(imax - 1)) + sq(d0 * s(imax)) + sq(dp * s(imax + 1));
    let sigma = step * libm::sqrt(var);
    // A vertex more than a step away from the sampled maximum is not resolved.
    if !sigma.is_finite() || !f0.is_finite() || delta.abs() > 1.0 || sigma > step {
        return Err(Failure::LowSnr);
    }
    Ok(Estimate {
        resonance: Hz(f0 as f32),
        sigma: Hz(sigma as f32),
        q: None,
        points_used: 3,
    })
}
