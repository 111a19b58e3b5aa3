//! **sweep-G**: resonance from the maximum of the conductance `G = Re(Y)`.
//!
//! The static capacitance `C0` adds only susceptance, so the conductance peak sits exactly at the
//! motional branch's undamped resonance `w0 = sqrt(k/m)` however large `C0` is (the |Z| minimum
//! does not: see [`super::paper`]). Near the peak the motional conductance obeys
//! `1/G = (c² + (w m − k/w)²) / (α² c) = A + B w² + C / w²` exactly, a model linear in
//! `(A, B, C)`. A weighted least-squares fit over the half-power points gives
//! `w0 = (C/B)^(1/4)`, `Q = w0 sqrt(B G_peak)` and, by the delta method, the standard
//! uncertainty of `w0` from the per-point uncertainties (inflated by the reduced χ² when the
//! residuals grossly exceed them).
//!
//! Fails with `out_of_band` when the largest conductance is at a band edge or the peak does not
//! fall on both sides within the band (by 5 σ), `no_resonance` when
//! no peak stands 5 σ out of the floor, `low_snr` when the fit's relative uncertainty is too large.

use super::{argmax, screen, Estimate};
use crate::engine::sweep::SweepPoint;
use crate::linalg::Lsq3;
use crate::status::Failure;
use crate::units::Hz;

/// Reduced χ² above which the fit is a gross misfit and its uncertainty is scaled by it.
pub const GROSS_CHI2: f64 = 16.0;

/// `Q = x0 sqrt(B / (1/G_peak))` of the fitted `1/G = A + B x² + C / x²`, with
/// `x0 = (C/B)^(1/4)` and `1/G_peak = A + 2 sqrt(B C)`; NaN where the peak is not positive.
fn q_of(a: f64, b: f64, c: f64) -> f64 {
    let x0 = libm::sqrt(libm::sqrt(c / b));
    let inv_g_peak = a + 2.0 * libm::sqrt(b * c);
    if inv_g_peak > 0.0 {
        x0 * libm::sqrt(b / inv_g_peak)
    } else {
        f64::NAN
    }
}

/// Estimate the resonance of a stepped sweep from its conductance.
pub fn estimate(points: &[SweepPoint]) -> Result<Estimate, Failure> {
    screen(points)?;
    let n = points.len();
    let imax = argmax(points, |p| p.g_s).ok_or(Failure::NoResonance)?;
    let gmax = points[imax].g_s as f64;
    let gmin = points
        .iter()
        .map(|p| p.g_s as f64)
        .fold(f64::INFINITY, f64::min);
    let sigma_peak = points[imax].sigma_s as f64;
    if !(gmax > 0.0) || !(gmax - gmin > 5.0 * sigma_peak) {
        return Err(Failure::NoResonance);
    }
    if imax == 0 || imax == n - 1 {
        return Err(Failure::OutOfBand);
    }
    // The peak must be measured on both sides: on each, some point falls below it by more than
    // the peak's own noise (5 σ). A conductance still falling from a band edge (the resonance
    // beyond it) with a noise bump next to the edge is no peak.
    let floor = gmax - 5.0 * sigma_peak;
    let side_min = |s: &[SweepPoint]| s.iter().map(|p| p.g_s as f64).fold(f64::INFINITY, f64::min);
    if !(side_min(&points[..imax]) < floor) || !(side_min(&points[imax + 1..]) < floor) {
        return Err(Failure::OutOfBand);
    }
    // Contiguous half-power window around the maximum.
    let half = 0.5 * gmax;
    let mut lo = imax;
    while lo > 0 && points[lo - 1].g_s as f64 >= half {
        lo -= 1;
    }
    let mut hi = imax;
    while hi + 1 < n && points[hi + 1].g_s as f64 >= half {
        hi += 1;
    }
    if hi - lo < 2 {
        lo = imax - 1;
        hi = imax + 1;
    }
    let f_ref = points[imax].freq.0 as f64;
    let mut lsq = Lsq3::default();
    for p in &points[lo..=hi] {
        let g = p.g_s as f64;
        if !(g > 0.0) {
            continue;
        }
        let x = p.freq.0 as f64 / f_ref;
        let x2 = x * x;
        let sigma_y = (p.sigma_s as f64).max(1e-30) / (g * g);
        lsq.add([1.0, x2, 1.0 / x2], 1.0 / g, 1.0 / (sigma_y * sigma_y));
    }
    let fit = lsq.solve().ok_or(Failure::NoResonance)?;
    let [a, b, c] = fit.p;
    if !(b > 0.0) || !(c > 0.0) {
        return Err(Failure::NoResonance);
    }
    let x0 = libm::sqrt(libm::sqrt(c / b));
    let f0 = f_ref * x0;
    let (f_lo, f_hi) = (points[lo].freq.0 as f64, points[hi].freq.0 as f64);
    if !(f0 > f_lo) || !(f0 < f_hi) {
        return Err(Failure::NoResonance);
    }
    // The per-point uncertainties are measured, so the propagated sigma is the statistical
    // uncertainty. Residuals far beyond them (a gross misfit: interference, a knock, a
    // non-resonant curve) scale it up. Modest excess from settling transients is a repeatable
    // bias that the calibration absorbs; inflating by it would overstate the scatter.
    let chi2 = fit.reduced_chi2();
    let scale = super::gross_scale(chi2);
    let (db, dc) = (-x0 / (4.0 * b), x0 / (4.0 * c));
    let var_x0 =
        scale * (db * db * fit.cov[1][1] + 2.0 * db * dc * fit.cov[1][2] + dc * dc * fit.cov[2][2]);
    let sigma = f_ref * libm::sqrt(var_x0.max(0.0));
    let q = q_of(a, b, c);
    // σ(Q) by the delta method, the gradient by central differences of `q_of`.
    let grad: [f64; 3] = core::array::from_fn(|i| {
        let h = 1e-6 * libm::fabs(fit.p[i]).max(1e-30);
        let (mut lo, mut hi) = (fit.p, fit.p);
        lo[i] -= h;
        hi[i] += h;
        (q_of(hi[0], hi[1], hi[2]) - q_of(lo[0], lo[1], lo[2])) / (2.0 * h)
    });
    let var_q = scale
        * (0..3)
            .map(|i| {
                (0..3)
                    .map(|j| grad[i] * fit.cov[i][j] * grad[j])
                    .sum::<f64>()
            })
            .sum::<f64>();
    let linewidth = if q.is_finite() && q > 0.0 {
        f0 / q
    } else {
        f_hi - f_lo
    };
    super::resolved(sigma, linewidth)?;
    Ok(Estimate {
        resonance: Hz(f0 as f32),
        sigma: Hz(sigma as f32),
        q: q.is_finite().then_some(q as f32),
        q_sigma: (q.is_finite() && var_q.is_finite()).then(|| libm::sqrt(var_q.max(0.0)) as f32),
        points_used: fit.n as u16,
    })
}
