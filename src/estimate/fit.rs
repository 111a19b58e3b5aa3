//! **fit** estimator: least-squares fit of the Butterworth–Van Dyke admittance to complex points.
//!
//! `Y(f) = G0 + j b0 (f / f_ref) + g / (1 + j Q (f/f0 − f0/f))`: a parallel conductance `G0`
//! (dielectric leakage), the static capacitance as susceptance `b0` at `f_ref`, and the motional
//! branch with peak conductance `g`, resonance `f0` and quality factor `Q` — the admittance
//! circle. Real and imaginary parts of every point enter with weight `1/σ²` (each point's own
//! uncertainty), so a handful of points anywhere near the resonance determine `f0`, `Q` and `C0`
//! with their covariance (`(JᵀWJ)⁻¹`, Levenberg–Marquardt from a linear start). The uncertainty
//! is scaled by the reduced χ² only when the fit is grossly wrong (as for sweep-G).

use super::model::Motional;
use super::{screen, Estimate};
use crate::engine::sweep::SweepPoint;
use crate::linalg::{levenberg_marquardt, spd_inverse, Fit3, LmStop, Lsq3};
use crate::status::Failure;
use crate::units::bounded;
use crate::units::Hz;

/// Fitted Butterworth–Van Dyke parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bvd {
    /// Parallel conductance `G0`, S.
    pub g0: f64,
    /// Static susceptance at `f_ref`, S.
    pub b0: f64,
    /// Reference frequency of `b0`, Hz.
    pub f_ref: f64,
    /// Motional peak conductance, S.
    pub g: f64,
    /// Resonance, Hz.
    pub f0: f64,
    /// Quality factor.
    pub q: f64,
    /// Standard uncertainty of `f0`, Hz.
    pub sigma_f0: f64,
    /// Standard uncertainty of `Q`.
    pub sigma_q: f64,
    /// Standard uncertainty of `G0` from the noise alone (not scaled by χ²), S.
    pub sigma_g0: f64,
    /// Standard uncertainty of `b0` from the noise alone (not scaled by χ²), S: the part of its
    /// error that changes from reading to reading (a misfit's part repeats and is calibrated).
    pub sigma_b0: f64,
}

impl Bvd {
    /// The parameters `p = [G0, b0, g, f0, Q]` of a fit (`b0` at `f_ref`) with the standard
    /// uncertainties `[f0, Q, G0, b0]`.
    pub fn new(p: &[f64; 5], f_ref: f64, sigma: [f64; 4]) -> Self {
        let [sigma_f0, sigma_q, sigma_g0, sigma_b0] = sigma;
        Self {
            g0: p[0],
            b0: p[1],
            f_ref,
            g: p[2],
            f0: p[3],
            q: p[4],
            sigma_f0,
            sigma_q,
            sigma_g0,
            sigma_b0,
        }
    }

    /// Motional admittance (re, im) at `f`.
    pub fn motional(&self, f: f64) -> (f64, f64) {
        motional(self.g, self.f0, self.q, f)
    }
    /// Static (non-motional) admittance (re, im) at `f`.
    pub fn static_part(&self, f: f64) -> (f64, f64) {
        (self.g0, self.b0 * f / self.f_ref)
    }
}

fn motional(g: f64, f0: f64, q: f64, f: f64) -> (f64, f64) {
    let h = Motional::at(f0, q, f).h;
    (g * h.re, g * h.im)
}

/// The linear part of the BVD fit: `G0`, `b0` (at `f_ref`) and `g` by weighted least squares
/// (`1/σ²` on real and imaginary parts) with the resonance `f0` and quality `q` held, and the
/// number of points used. `None` when the system is singular.
pub fn linear_part<'a>(
    points: impl Iterator<Item = &'a SweepPoint>,
    f0: f64,
    q: f64,
    f_ref: f64,
) -> Option<(Fit3, usize)> {
    let mut l = Lsq3::default();
    let mut n = 0;
    for pt in points {
        let f = pt.freq.0 as f64;
        let w = 1.0 / ((pt.sigma_s as f64) * (pt.sigma_s as f64)).max(1e-60);
        let h = Motional::at(f0, q, f).h;
        l.add([1.0, 0.0, h.re], pt.g_s as f64, w);
        l.add([0.0, f / f_ref, h.im], pt.b_s as f64, w);
        n += 1;
    }
    Some((l.solve()?, n))
}

/// Fit the BVD model to `points`, starting from resonance `f_start` and quality `q_start`.
pub fn fit_bvd(points: &[SweepPoint], f_start: f64, q_start: f64) -> Result<Bvd, Failure> {
    screen(points)?;
    let f_ref = f_start;
    let mut p = [0.0, 0.0, 0.0, f_start, bounded(q_start, 1.0, 200.0)];
    // Linear start for (G0, b0, g) at the given f0, Q.
    let (lin, _) = linear_part(points.iter(), p[3], p[4], f_ref).ok_or(Failure::NoResonance)?;
    p[0] = lin.p[0];
    p[1] = lin.p[1];
    p[2] = lin.p[2];
    if !(p[2] > 0.0) {
        return Err(Failure::NoResonance);
    }
    let chi2_of = |p: &[f64; 5]| -> f64 {
        let mut c = 0.0;
        for pt in points {
            let f = pt.freq.0 as f64;
            let (mr, mi) = motional(p[2], p[3], p[4], f);
            let rr = pt.g_s as f64 - (p[0] + mr);
            let ri = pt.b_s as f64 - (p[1] * f / f_ref + mi);
            let w = 1.0 / ((pt.sigma_s as f64) * (pt.sigma_s as f64)).max(1e-60);
            c += w * (rr * rr + ri * ri);
        }
        c
    };
    let normal = |p: &[f64; 5]| -> ([[f64; 5]; 5], [f64; 5]) {
        let mut jtj = [[0.0; 5]; 5];
        let mut jtr = [0.0; 5];
        for pt in points {
            let f = pt.freq.0 as f64;
            let w = 1.0 / ((pt.sigma_s as f64) * (pt.sigma_s as f64)).max(1e-60);
            let (g, f0, q) = (p[2], p[3], p[4]);
            let m = Motional::at(f0, q, f);
            let (hr, hi) = (m.h.re, m.h.im);
            // dY/df0 = g dh/df0, dY/dQ = g dh/dQ
            let (df0, dq) = m.derivatives(f0, q, f);
            let (df0, dq) = (df0 * g, dq * g);
            let jr = [1.0, 0.0, hr, df0.re, dq.re];
            let ji = [0.0, f / f_ref, hi, df0.im, dq.im];
            let rr = pt.g_s as f64 - (p[0] + g * hr);
            let ri = pt.b_s as f64 - (p[1] * f / f_ref + g * hi);
            for a in 0..5 {
                jtr[a] += w * (jr[a] * rr + ji[a] * ri);
                for b in 0..5 {
                    jtj[a][b] += w * (jr[a] * jr[b] + ji[a] * ji[b]);
                }
            }
        }
        (jtj, jtr)
    };
    // Parameters outside their domain (g, f0, Q not positive) are no fit.
    let chi2_in = |p: &[f64; 5]| {
        if p[3] > 0.0 && p[4] > 0.0 && p[2] > 0.0 {
            chi2_of(p)
        } else {
            f64::INFINITY
        }
    };
    let (p, chi2) = levenberg_marquardt(p, chi2_in, normal, LmStop::new(50, 1e-10, 1e10));
    let (jtj, _) = normal(&p);
    let cov = spd_inverse(&jtj).ok_or(Failure::NoResonance)?;
    let dof = (2 * points.len()).saturating_sub(5).max(1) as f64;
    let red = chi2 / dof;
    let scale = super::gross_scale(red);
    let sigma_f0 = libm::sqrt((cov[3][3] * scale).max(0.0));
    let sigma_g0 = libm::sqrt(cov[0][0].max(0.0));
    let sigma_b0 = libm::sqrt(cov[1][1].max(0.0));
    let sigma_q = libm::sqrt((cov[4][4] * scale).max(0.0));
    if !p.iter().all(|v| v.is_finite()) || !sigma_f0.is_finite() {
        return Err(Failure::NoResonance);
    }
    Ok(Bvd::new(&p, f_ref, [sigma_f0, sigma_q, sigma_g0, sigma_b0]))
}

/// Resonance estimate of a BVD fit, checked against the span of the points.
pub fn estimate(points: &[SweepPoint], f_start: f64, q_start: f64) -> Result<Estimate, Failure> {
    let b = fit_bvd(points, f_start, q_start)?;
    let (lo, hi) = points.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
        (lo.min(p.freq.0 as f64), hi.max(p.freq.0 as f64))
    });
    if !(b.f0 > lo) || !(b.f0 < hi) {
        return Err(Failure::OutOfBand);
    }
    super::resolved(b.sigma_f0, b.f0 / b.q)?;
    Ok(Estimate {
        resonance: Hz(b.f0 as f32),
        sigma: Hz(b.sigma_f0 as f32),
        q: Some(b.q as f32),
        q_sigma: Some(b.sigma_q as f32),
        points_used: points.len() as u16,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed-form BVD points (the circuit's f64 admittance, `super::super::reference`) with a
    /// few frequencies off the peak.
    #[test]
    fn recovers_closed_form_bvd() {
        let (g0, b0, g, f0, q) = (2e-9, 3.0e-7, 1.5e-7, 241.94, 10.4);
        let mut pts = [SweepPoint::default(); 6];
        for (k, p) in pts.iter_mut().enumerate() {
            let f = 210.0 + 12.0 * k as f64;
            let (hr, hi) = crate::estimate::reference::rlc_shape(f0, q, f);
            let (mr, mi) = (g * hr, g * hi);
            *p = SweepPoint {
                freq: Hz(f as f32),
                g_s: (g0 + mr) as f32,
                b_s: (b0 * f / 230.0 + mi) as f32,
                sigma_s: 1e-10,
                current_a: 1e-6,
                ..SweepPoint::default()
            };
        }
        let b = fit_bvd(&pts, 230.0, 8.0).unwrap();
        assert!((b.f0 - f0).abs() < 2e-3, "{}", b.f0);
        assert!((b.q / q - 1.0).abs() < 1e-3, "{}", b.q);
        assert!((b.b0 / (b0 * 230.0 / 230.0) - 1.0).abs() < 1e-3);
    }
}
