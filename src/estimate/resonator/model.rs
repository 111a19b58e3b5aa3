//! The resonator's model for the fit: the windows in `f32`, the drive model (steady state,
//! transient and their derivatives), the state carried between segments, χ² with its Jacobian,
//! the normal equations and the covariance.

use super::{Carry, Segment, MAX_SEGMENTS, MAX_WINDOWS};
use num_complex::Complex64 as C64;

/// A window as the fit's inner loop uses it: start relative to its segment's first window,
/// length, the admittance without its static part, all `f32`; `gap` when it does not start where
/// the previous one ended; `seg` its segment.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Win32 {
    pub(super) a: f32,
    pub(super) len: f32,
    pub(super) y: num_complex::Complex32,
    pub(super) gap: bool,
    seg: u8,
    /// Weight relative to a window of the mean length (the noise variance of a window's mean
    /// falls as its length).
    pub(super) wl: f32,
}

/// The segments' windows in `f32` (less their static admittance) and the scale of their
/// admittances.
///
/// Only the starts' difference from the segment's first is taken in `f64` (times from the
/// reading's start, seconds of probe time): the rest in `f32` (`f64` is emulated on the
/// Cortex-M4F). The admittances come from [`super::to_admittance`] in `f32` already, so `y − y_s`
/// rounds once, to 6e-8 of itself, far below any window's noise; a start relative to its
/// segment (under a second) is held to 6e-8 s, a gap of a sample (1e-4 s) stands out of that.
pub(super) fn prepare(segs: &[Segment]) -> (heapless::Vec<Win32, MAX_WINDOWS>, f32) {
    let mut out = heapless::Vec::new();
    let mut big = 0.0f32;
    let all = || segs.iter().flat_map(|s| s.windows.iter());
    let n = all().count();
    let total: f32 = all().map(|x| x.len as f32).sum();
    let mean32 = if n > 0 && total > 0.0 {
        total / n as f32
    } else {
        1.0
    };
    for (s, seg) in segs.iter().enumerate() {
        let t0 = seg.windows.first().map_or(0.0, |x| x.t0);
        let y_s = c32(seg.y_s);
        let mut next = 0.0f32;
        for (k, x) in seg.windows.iter().enumerate() {
            let a = (x.t0 - t0) as f32;
            let y = c32(x.y) - y_s;
            big = big.max(y.norm_sqr());
            let len = x.len as f32;
            let _ = out.push(Win32 {
                a,
                len,
                y,
                gap: k == 0 || libm::fabsf(a - next) > 1e-6,
                seg: s as u8,
                wl: len / mean32,
            });
            next = a + len;
        }
    }
    (out, crate::dsp::trig::sqrtf(big).max(1e-30))
}

/// The model's parameters: resonance, quality factor, motional peak conductance, and the state
/// at the start of the first window.
#[derive(Clone, Copy, Debug)]
pub(super) struct Params {
    pub(super) f0: f64,
    pub(super) q: f64,
    pub(super) g: f64,
    pub(super) z: C64,
}

impl Params {
    /// `self` moved by `step` over (f0, Q, g, Re z, Im z).
    pub(super) fn stepped(&self, step: &[f64; 5]) -> Self {
        Self {
            f0: self.f0 + step[0],
            q: self.q + step[1],
            g: self.g + step[2],
            z: self.z + C64::new(step[3], step[4]),
        }
    }
}

/// The model of one drive frequency at `p`: steady state `h = 1/(1 + jQu)`, the transient's
/// exponent `λ = −π f0/Q + j 2π (f_d − f_h)`, `f_d = f0 sqrt(1 − 1/(4Q²))`, and their
/// derivatives with respect to `f0` and `Q` — the one model's (`crate::estimate::model`),
/// formed and kept in `f32` for the inner loop and the carry ([`DriveModel::new`]; relative error
/// ~1e-7, far below any window's noise; `f64` arithmetic is emulated in software on the
/// Cortex-M4F).
#[derive(Clone, Copy, Debug)]
pub(super) struct DriveModel {
    pub(super) h: C32,
    dh: [C32; 2],
    pub(super) lam: C32,
    dlam: [C32; 2],
    /// `λ̄ − j 4π f_h`: the mirror image's exponent in the drive's frame.
    pub(super) mu: C32,
}

pub(super) type C32 = num_complex::Complex32;

/// `x` in `f32`.
pub(super) fn c32(x: C64) -> C32 {
    C32::new(x.re as f32, x.im as f32)
}

impl DriveModel {
    /// The model at `p`'s `f0`, `Q` for a drive at `f_h`: [`crate::estimate::model::Motional`]'s
    /// `h` and derivatives and the transient's `λ`, formed in `f32` from the detuning `f0 − f_h`
    /// (taken in `f64`, the one difference of near-equal numbers):
    /// `u = −(f0 − f_h)(f_h + f0)/(f0 f_h)` and `f_d − f_h = (f0 − f_h) − f0 (1 − sqrt(1 − 1/(4Q²)))`
    /// lose nothing to cancellation, so every value keeps `f32`'s relative precision (1e-7) —
    /// what the `f64` model rounded to `f32` gives, at a sixth of the work on the Cortex-M4F
    /// (whose FPU is single precision).
    pub(super) fn new(p: &Params, f_h: f64) -> Self {
        use core::f32::consts::PI as PI32;
        let d = (p.f0 - f_h) as f32;
        let (f0, q, fh) = (p.f0 as f32, p.q as f32, f_h as f32);
        let u = -d * (fh + f0) / (f0 * fh);
        let x = q * u;
        let den = 1.0 + x * x;
        let h = C32::new(1.0 / den, -x / den);
        // ∂h/∂f0 = −j Q h² ∂u/∂f0, ∂h/∂Q = −j u h²
        // ([`crate::estimate::model::Motional::derivatives`]).
        let h2 = h * h;
        let du_df0 = -fh / (f0 * f0) - 1.0 / fh;
        let minus_j = |x: f32| C32::new(x * h2.im, -x * h2.re);
        let quarter = 0.25 / (q * q);
        let root = crate::dsp::trig::sqrtf((1.0 - quarter).max(1e-12));
        // 1 − root, without the cancellation.
        let one_less = if quarter < 1.0 {
            quarter / (1.0 + root)
        } else {
            1.0 - root
        };
        let lam = C32::new(-PI32 * f0 / q, 2.0 * PI32 * (d - f0 * one_less));
        Self {
            h,
            dh: [minus_j(q * du_df0), minus_j(u)],
            lam,
            mu: C32::new(lam.re, -lam.im - 4.0 * PI32 * fh),
            dlam: [
                C32::new(-PI32 / q, 2.0 * PI32 * root),
                C32::new(PI32 * f0 / (q * q), 2.0 * PI32 * f0 * quarter / (q * root)),
            ],
        }
    }

    /// The state `d` seconds after one `z`, driven here, and its derivatives with respect to
    /// (f0, Q, g) and to `z` itself (`y = g h + (z − g h) e^{λd}`).
    fn advance(&self, g: f32, z: C32, d: f32) -> (C32, [C32; 3], C32) {
        let e = cexp(self.lam * d);
        let one = C32::new(1.0, 0.0);
        let gh = self.h * g;
        let y = gh + (z - gh) * e;
        let d_of = |i: usize| self.dh[i] * g * (one - e) + (z - gh) * e * self.dlam[i] * d;
        (y, [d_of(0), d_of(1), self.h * (one - e)], e)
    }
}

/// One segment's constants for the inner loop: the model at its drive, its initial state `z`
/// and that state's derivatives `dz` with respect to (f0, Q, g, Re z₀, Im z₀) — `z₀` itself for
/// the first segment, the carried state for the second.
struct SegModel {
    h: C32,
    gh: C32,
    g_dh: [C32; 2],
    lam: C32,
    inv_lam: C32,
    dl: [C32; 2],
    z: C32,
    dz: [C32; 5],
    /// The segment's [`super::mirror`] factor and `1/μ` of [`DriveModel::mu`].
    mirror: C32,
    inv_mu: C32,
}

impl SegModel {
    fn new(g: f32, m: &DriveModel, z: C32, dz: [C32; 5], mirror: C32) -> Self {
        let one = C32::new(1.0, 0.0);
        Self {
            h: m.h,
            gh: m.h * g,
            g_dh: [m.dh[0] * g, m.dh[1] * g],
            lam: m.lam,
            inv_lam: one / m.lam,
            dl: m.dlam,
            z,
            dz,
            mirror,
            inv_mu: one / m.mu,
        }
    }
}

/// The segments' models at `p` into `out` (the caller's: a returned list is copied out): the
/// first starts from `p.z`; the second (with `carry`) from the first's state carried to the
/// switch and on under the second's drive to its first window.
fn seg_models(
    p: &Params,
    segs: &[(f64, f64, C32)],
    carry: Option<&Carry>,
    out: &mut heapless::Vec<SegModel, MAX_SEGMENTS>,
) {
    let zero = C32::new(0.0, 0.0);
    let one = C32::new(1.0, 0.0);
    let j = C32::new(0.0, 1.0);
    let g = p.g as f32;
    let Some(&(f_first, t_first, mirror0)) = segs.first() else {
        return;
    };
    let m0 = DriveModel::new(p, f_first);
    let z0 = c32(p.z);
    let _ = out.push(SegModel::new(
        g,
        &m0,
        z0,
        [zero, zero, zero, one, j],
        mirror0,
    ));
    if let (Some(&(f_second, t_second, mirror1)), Some(c)) = (segs.get(1), carry) {
        let m1 = DriveModel::new(p, f_second);
        let rho = c32(c.rho);
        // To the switch under the first drive, then to the second's first window under its own.
        let (u, du, eu) = m0.advance(g, z0, (c.t_switch - t_first).max(0.0) as f32);
        let (z1, dz1, e1) = m1.advance(g, rho * u, (t_second - c.t_switch).max(0.0) as f32);
        let via = rho * e1;
        let _ = out.push(SegModel::new(
            g,
            &m1,
            z1,
            [
                dz1[0] + via * du[0],
                dz1[1] + via * du[1],
                dz1[2] + via * du[2],
                via * eu,
                via * eu * j,
            ],
            mirror1,
        ));
    }
}

/// χ² of `p` against the windows (`y` already without the static part) of segments driven at
/// `segs[s].0` whose first window starts at `segs[s].1`, and, when `jac` is set, the normal
/// equations `JᵀWJ`, `JᵀW r` over (f0, Q, g, Re z, Im z).
///
/// Cost: two complex `f32` exponentials per segment (the windows are gap-free, so `exp(λ t)` is
/// carried from one to the next), the rest complex `f32` arithmetic; sums in `f64`. On the
/// Cortex-M4F's single-precision FPU this is a few hundred instructions per window
/// (`docs/firmware.md` has the measured totals). `f32` carries the model values with a relative
/// error of about 1e-7 of `g`, far below the noise of any window (1e-3 of `g` at the bench noise
/// and the longest hold).
pub(super) fn evaluate(
    pb: &Problem,
    p: &Params,
    jac: bool,
    mut res: Option<&mut [C32]>,
) -> (f64, Normal) {
    let (w, gs, wt) = (&pb.w[..], pb.gs, pb.wt);
    let (segs, carry) = (&pb.segs[..], pb.carry);
    let one = C32::new(1.0, 0.0);
    let (f0, q) = (p.f0, p.q);
    let mut models = heapless::Vec::new();
    seg_models(p, segs, carry, &mut models);
    // The normal equations' sums (at most 16 products each) in f32, each column scaled to about
    // unit size first ([`Normal`]); f32's relative precision (1e-7) is far finer than what the
    // steps and the covariance need. (Any scale serves: it is undone by the same numbers.)
    let (q32, f32_0) = (q as f32, f0 as f32);
    let scale: [f32; 5] = [1.0 / (gs * (q32 / f32_0)), 1.0 / (gs / q32), 1.0, 1.0, 1.0];
    // Summed in place (a finished pair of arrays would be copied into the result).
    let mut normal = Normal {
        jtj: [[0.0f32; 5]; 5],
        jtr: [0.0f32; 5],
        scale,
    };
    let (jtj32, jtr32) = (&mut normal.jtj, &mut normal.jtr);
    let mut seg = u8::MAX;
    // exp(λ a) carried from window to window (they are gap-free), exp(λ len) cached per window
    // length (they differ by at most a sample): no transcendental per window.
    let mut ea = one;
    // Whole-cycle windows alternate between two lengths a sample apart: two cache entries.
    let mut cache: [(f32, C32); 2] = [(-1.0, one); 2];
    let mut chi2 = 0.0f32;
    for (i, x) in w.iter().enumerate() {
        let Some(m) = models.get(x.seg as usize) else {
            return (f64::INFINITY, Normal::default());
        };
        if x.seg != seg {
            seg = x.seg;
            cache = [(-1.0, one); 2];
        }
        let (a, len) = (x.a, x.len);
        if x.gap {
            // A segment's first window starts at its origin: exp(0) = 1 exactly.
            ea = if a == 0.0 { one } else { cexp(m.lam * a) };
        }
        let decay = if cache[0].0 == len {
            cache[0].1
        } else if cache[1].0 == len {
            cache[1].1
        } else {
            cache[1] = cache[0];
            cache[0] = (len, cexp(m.lam * len));
            cache[0].1
        };
        // exp(λ a), exp(λ (a + len)); their mean over the window and its λ-derivative.
        let eb = ea * decay;
        let e = (eb - ea) * m.inv_lam / len;
        // The transient at the window's start and its mirror image's mean over the window
        // (`mirror`): `P = (e^{λ̄ len} − 1) / (μ len)`.
        let tr = (m.z - m.gh) * ea;
        let pm = (decay.conj() - one) * m.inv_mu / len;
        let model = m.gh * (one - e) + m.z * e + m.mirror * pm * tr.conj();
        let r = x.y - model;
        if let Some(o) = res.as_deref_mut().and_then(|o| o.get_mut(i)) {
            *o = r;
        }
        chi2 += x.wl * r.norm_sqr();
        if jac {
            let de = ((eb * (a + len) - ea * a) / len - e) * m.inv_lam;
            let k = (m.z - m.gh) * de;
            // The image: d(tr)/dp and d(P)/dp = (e^{λ̄ len} − P)/μ · conj(dλ/dp) (real p).
            let dp = (decay.conj() - pm) * m.inv_mu;
            // The image's derivative `mirror (dP conj(dλ) conj(tr) + P conj(d tr))`, `d tr =
            // (dz − d(gh)) e^{λa} + tr a dλ`, with its common factors taken once and the terms
            // that vanish (g and z do not move λ; z does not move gh) left out.
            let (ia, ib, ta) = (m.mirror * dp * tr.conj(), m.mirror * pm, tr * a);
            let moving = |i: usize| {
                let dtr = (m.dz[i] - m.g_dh[i]) * ea + ta * m.dl[i];
                ia * m.dl[i].conj() + ib * dtr.conj()
            };
            let one_e = one - e;
            let cols = [
                (m.g_dh[0] * one_e + k * m.dl[0] + e * m.dz[0] + moving(0)) * scale[0],
                (m.g_dh[1] * one_e + k * m.dl[1] + e * m.dz[1] + moving(1)) * scale[1],
                // The linear parameters' columns are not scaled.
                m.h * one_e + e * m.dz[2] + ib * ((m.dz[2] - m.h) * ea).conj(),
                e * m.dz[3] + ib * (m.dz[3] * ea).conj(),
                e * m.dz[4] + ib * (m.dz[4] * ea).conj(),
            ];
            let rw = r * x.wl;
            for i in 0..5 {
                let ci = cols[i];
                jtr32[i] += ci.re * rw.re + ci.im * rw.im;
                let cw = ci * x.wl;
                // (`0..i + 1`: `0..=i` is an out-of-line iterator call at `opt-level = "z"`.)
                for j in 0..i + 1 {
                    jtj32[i][j] += cw.re * cols[j].re + cw.im * cols[j].im;
                }
            }
        }
        ea = eb;
    }
    (chi2 as f64 * wt, normal)
}

/// The normal equations of the fit over (f0, Q, g, Re z, Im z) in `f32`, each column of the
/// Jacobian multiplied by `scale` (to about unit size) and the weight `1/var` left out:
/// `JᵀWJ = wt S⁻¹ jtj S⁻¹`, `JᵀW r = wt S⁻¹ jtr` (`S = diag(scale)`). The steps are solved
/// in these units ([`crate::linalg::spd_solve`] in `f32`: on the Cortex-M4F's single-precision
/// FPU, where an `f64` solve is emulated, a tenth of the work); only the covariance is formed in
/// `f64`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Normal {
    /// `JᵀJ` (scaled), lower triangle.
    pub(super) jtj: [[f32; 5]; 5],
    /// `Jᵀ r` (scaled).
    pub(super) jtr: [f32; 5],
    /// The columns' scale.
    pub(super) scale: [f32; 5],
}

impl Normal {
    /// The variances of `f0` and `Q` and their covariance (the upper-left 2 × 2 block of
    /// `(JᵀWJ)⁻¹`: `[var f0, var Q, cov(f0, Q)]`) for weight `wt`: the linear parameters
    /// `(g, Re z, Im z)` eliminated from the scaled matrix (the first three pivots of its
    /// `L D Lᵀ`, no square roots, in `f32` like the sums they start from), which leaves the
    /// Schur complement `S` of `(f0, Q)`, whose inverse is that block; its determinant (where
    /// `f0` and `Q` correlate it cancels) and the unscaling by `scale_i scale_j / wt` in `f64`.
    /// `None` when the matrix is not positive definite. (`gradcheck` holds it to the `f64`
    /// inverse over the tracker's and the holds' windows.)
    #[allow(clippy::needless_range_loop)] // triangular index arithmetic reads best as indices
    pub(super) fn variances(&self, wt: f64) -> Option<[f64; 3]> {
        const N: usize = 5;
        // The linear parameters first, then (f0, Q).
        const ORDER: [usize; N] = [2, 3, 4, 0, 1];
        let mut m = [[0.0f32; N]; N];
        for i in 0..N {
            for j in 0..i + 1 {
                let (a, b) = (ORDER[i], ORDER[j]);
                m[i][j] = self.jtj[a.max(b)][a.min(b)];
            }
        }
        // Lower triangle: m[i][j], j ≤ i.
        for k in 0..3 {
            let d = m[k][k];
            if !(d > 0.0) || !d.is_finite() {
                return None;
            }
            let inv = 1.0 / d;
            for i in k + 1..N {
                let l = m[i][k] * inv;
                for j in k + 1..i + 1 {
                    m[i][j] -= l * m[j][k];
                }
            }
        }
        let (a, b, c) = (m[3][3] as f64, m[4][3] as f64, m[4][4] as f64);
        let det = a * c - b * b;
        if !(a > 0.0) || !(det > 0.0) || !det.is_finite() {
            return None;
        }
        let k = 1.0 / (det * wt);
        let (s0, s1) = (self.scale[0] as f64, self.scale[1] as f64);
        let out = [c * k * s0 * s0, a * k * s1 * s1, -b * k * s0 * s1];
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// `JᵀWJ` and `JᵀW r` in `f64`, unscaled, for weight `wt`.
    #[cfg(test)]
    fn unscaled(&self, wt: f64) -> ([[f64; 5]; 5], [f64; 5]) {
        let (mut jtj, mut jtr) = ([[0.0f64; 5]; 5], [0.0f64; 5]);
        let inv: [f64; 5] = core::array::from_fn(|i| 1.0 / self.scale[i] as f64);
        for i in 0..5 {
            let wi = wt * inv[i];
            jtr[i] = wi * self.jtr[i] as f64;
            for j in 0..=i {
                let v = wi * inv[j] * self.jtj[i][j] as f64;
                jtj[i][j] = v;
                jtj[j][i] = v;
            }
        }
        (jtj, jtr)
    }
}

/// The problem a fit solves: the windows, their segments' drives and start times, the carry.
pub(super) struct Problem<'a> {
    pub(super) w: heapless::Vec<Win32, MAX_WINDOWS>,
    pub(super) gs: f32,
    pub(super) segs: heapless::Vec<(f64, f64, C32), MAX_SEGMENTS>,
    pub(super) carry: Option<&'a Carry>,
    pub(super) wt: f64,
}

/// `exp(z)` by the `libm` crate's `expf` and [`crate::dsp::trig::sincos`] (`f32` arithmetic
/// alone: `libm`'s `sincosf` computes in `f64`, 2 400 instructions a call on the Cortex-M4F):
/// the same bits on the host and the target, whatever `num-traits` features another crate of
/// the build enables (with `std` its `Float::exp` is the platform's, which differs in the last
/// bits and would make the host's readings depend on which binary took them).
pub(super) fn cexp(z: num_complex::Complex32) -> num_complex::Complex32 {
    let m = libm::expf(z.re);
    let (sin, cos) = crate::dsp::trig::sincos(z.im);
    num_complex::Complex32::new(m * cos, m * sin)
}

#[cfg(test)]
mod gradcheck {
    use super::*;
    use crate::estimate::resonator::fixtures::synthetic;
    use crate::estimate::resonator::mirror;
    use crate::estimate::resonator::{HoldWindow, MAX_WINDOWS};

    /// How far [`Normal::variances`] (`f32` elimination) may lie from the `f64` inverse of the
    /// same normal equations: var `f0` and var `Q` relative to themselves, their covariance
    /// relative to `sqrt(var f0 var Q)` — one and a half times the worst measured over
    /// [`variances_agree_with_the_f64_inverse`]'s windows (where `f0` or `Q` correlates with
    /// the linear parameters, the elimination cancels a thousandfold; the `f32` sums it starts
    /// from carry the same 1e-7 rounding through the same cancellation), and far below what a
    /// variance is known to (its χ² scatter, tens of percent for the tracker's 14 numbers).
    const VARIANCE_TOL: f64 = 1e-4;

    /// [`Normal::variances`] against the `f64` inverse of the unscaled normal equations
    /// (`linalg::spd_inverse`), at the point of every window layout the tracker and the holds
    /// fit: the resonance, `Q` and motional peak of phantoms A–E and of lossy tissue (490 kPa at
    /// loss tangent 0.3, 2000 kPa at 0.5; `hal-sim`'s scenes), driven on the resonance and 0.25,
    /// 1 and 3 half-linewidths either side, 2–16 windows of one and of four cycles, from rest and
    /// from a ringing state — the Jacobian's products depend on the windows' times and the
    /// point, not on the data. Four windows and more (the fit's fewest without a search; fewer
    /// leave the matrix singular to rounding).
    #[test]
    fn variances_agree_with_the_f64_inverse() {
        use hal_sim::{phantoms, Scene};
        let mut scenes: std::vec::Vec<Scene> = [
            phantoms::A,
            phantoms::B,
            phantoms::C,
            phantoms::D,
            phantoms::E,
        ]
        .iter()
        .map(Scene::on_phantom)
        .collect();
        scenes.push(Scene::on_modulus_kpa(490.0).with_loss_tangent(0.3));
        scenes.push(Scene::on_modulus_kpa(2000.0).with_loss_tangent(0.5));
        let (mut worst, mut worst_cov, mut cases) = (0.0f64, 0.0f64, 0);
        for scene in &scenes {
            let (f0, q) = (scene.resonance_hz(), scene.q());
            let g = scene.pzt.motional_peak_s(&scene.kelvin());
            for offset in [-3.0, -1.0, -0.25, 0.0, 0.25, 1.0, 3.0] {
                let f_h = f0 * (1.0 + offset / (2.0 * q));
                for cycles in [1.0, 4.0] {
                    let len = cycles / f_h;
                    for n in 4..=MAX_WINDOWS {
                        for z in [C64::new(0.0, 0.0), C64::new(0.3 * g, -0.4 * g)] {
                            let w: std::vec::Vec<HoldWindow> = (0..n)
                                .map(|k| HoldWindow {
                                    t0: 3.0 + k as f64 * len,
                                    len,
                                    y: C64::new(g, 0.0),
                                    var: 1e-20,
                                })
                                .collect();
                            let seg = Segment {
                                windows: &w,
                                f_h,
                                y_s: C64::new(0.0, 0.0),
                                mirror: mirror(C64::new(0.6, 0.8)),
                            };
                            let (w32, gs) = prepare(&[seg]);
                            let pb = Problem {
                                w: w32,
                                gs,
                                segs: [(f_h, 3.0, c32(seg.mirror))].into_iter().collect(),
                                carry: None,
                                wt: 1e20,
                            };
                            let p = Params { f0, q, g, z };
                            let n = evaluate(&pb, &p, true, None).1;
                            let (jtj, _) = n.unscaled(pb.wt);
                            // Fewer windows than parameters leave the matrix singular: both
                            // refuse it or neither.
                            let Some(inv) = crate::linalg::spd_inverse(&jtj) else {
                                continue;
                            };
                            let ok = [inv[0][0], inv[1][1]].iter().all(|v| *v > 0.0);
                            let Some(v) = n.variances(pb.wt).filter(|_| ok) else {
                                continue;
                            };
                            cases += 1;
                            worst = worst
                                .max((v[0] / inv[0][0] - 1.0).abs())
                                .max((v[1] / inv[1][1] - 1.0).abs());
                            let sd = (inv[0][0] * inv[1][1]).sqrt();
                            worst_cov = worst_cov.max((v[2] - inv[0][1]).abs() / sd);
                        }
                    }
                }
            }
        }
        std::eprintln!("{cases} layouts: variances within {worst:e}, covariance {worst_cov:e}");
        assert!(cases > 1000, "{cases}");
        assert!(worst < VARIANCE_TOL, "{worst:e}");
        assert!(worst_cov < VARIANCE_TOL, "{worst_cov:e}");
    }

    /// [`prepare`]'s `f32` against the `f64` differences it stands for, over segments of 4–16
    /// windows of one to four cycles at 170–290 Hz starting anywhere in the first 1000 s of
    /// probe time (sample-aligned at 10 kHz, a gap of one sample now and then), admittances of
    /// 1e-8–1e-6 S (from `f32`, as [`super::super::to_admittance`] leaves them) and a static
    /// part up to three times theirs: each start within 1e-7 s of its segment's (sample
    /// boundaries are 1e-4 s apart), `y − y_s` within 2e-7 of `|y| + |y_s|`, every gap found and
    /// no other.
    #[test]
    fn prepare_agrees_with_the_f64_differences() {
        let mut rng = probe_rng::Rng::new(5);
        let fs = 10_000.0;
        let (mut worst_a, mut worst_y) = (0.0f64, 0.0f64);
        for _ in 0..2000 {
            let f_h = 170.0 + 120.0 * rng.uniform();
            let cycles = 1.0 + (4.0 * rng.uniform()).floor();
            let n = 4 + (13.0 * rng.uniform()) as usize;
            let mag = 1e-8 * 100f64.powf(rng.uniform());
            let polar = |r: f64, a: f64| C64::new(r * a.cos(), r * a.sin());
            let y_s = polar(3.0 * mag * rng.uniform(), 6.3 * rng.uniform());
            let mut sample = (1e7 * rng.uniform()).floor();
            let mut gaps = [false; MAX_WINDOWS];
            let w: std::vec::Vec<HoldWindow> = (0..n)
                .map(|k| {
                    let len_samples = (cycles * fs / f_h).round() + (k % 2) as f64;
                    let gap = k > 0 && rng.uniform() < 0.1;
                    gaps[k] = gap;
                    sample += gap as u8 as f64;
                    let y = polar(mag * (0.5 + rng.uniform()), 6.3 * rng.uniform());
                    let y = C64::new(y.re as f32 as f64, y.im as f32 as f64);
                    let x = HoldWindow {
                        t0: (sample + len_samples) / fs - len_samples / fs,
                        len: len_samples / fs,
                        y,
                        var: 1e-20,
                    };
                    sample += len_samples;
                    x
                })
                .collect();
            let seg = Segment {
                windows: &w,
                f_h,
                y_s,
                mirror: C64::new(1.0, 0.0),
            };
            let (p, _) = prepare(&[seg]);
            for (k, (x, o)) in w.iter().zip(p.iter()).enumerate() {
                worst_a = worst_a.max((o.a as f64 - (x.t0 - w[0].t0)).abs());
                let want = x.y - y_s;
                let got = C64::new(o.y.re as f64, o.y.im as f64);
                worst_y = worst_y.max((got - want).norm() / (x.y.norm() + y_s.norm()));
                assert_eq!(o.gap, k == 0 || gaps[k], "window {k}");
            }
        }
        std::eprintln!("worst: start {worst_a:e} s, y {worst_y:e}");
        assert!(worst_a < 1e-7, "{worst_a:e}");
        assert!(worst_y < 2e-7, "{worst_y:e}");
    }

    /// The analytic gradient of χ² over all five parameters, the mirror image's terms
    /// included (a rotated drive, a transient far from the fit's point), against central
    /// differences of χ² (f64 reference on the same windows).
    #[test]
    fn gradient_matches_finite_differences() {
        let y_s = C64::new(0.0, 0.0);
        for (f_h, m) in [
            (241.3, C64::new(1.0, 0.0)),
            (238.0, mirror(C64::new(0.6, 0.8))),
        ] {
            let w = synthetic(241.3, 10.4, 1.5e-7, f_h, C64::new(1e-8, 0.0), y_s, 16);
            let w = &w[..16];
            let w0 = w[0].t0;
            let p = Params {
                f0: 241.0,
                q: 8.0,
                g: 1.4e-7,
                z: C64::new(4e-8, -3e-8),
            };
            let seg = Segment {
                windows: w,
                f_h,
                y_s,
                mirror: m,
            };
            let (w, gs) = prepare(&[seg]);
            let pb = Problem {
                w,
                gs,
                segs: [(f_h, w0, c32(m))].into_iter().collect(),
                carry: None,
                wt: 1e14,
            };
            let n = evaluate(&pb, &p, true, None).1;
            let (jtj, jtr) = n.unscaled(pb.wt);
            // The variances of f0 and Q and their covariance by LDLᵀ of the scaled matrix,
            // against the f64 inverse of the unscaled one.
            let inv = crate::linalg::spd_inverse(&jtj).unwrap();
            let v = n.variances(pb.wt).unwrap();
            for (k, (i, j)) in [(0, 0), (1, 1), (0, 1)].into_iter().enumerate() {
                assert!(
                    (v[k] / inv[i][j] - 1.0).abs() < VARIANCE_TOL,
                    "{i}{j}: {} vs {}",
                    v[k],
                    inv[i][j]
                );
            }
            for (i, g) in jtr.iter().enumerate() {
                let mut step = [0.0; 5];
                step[i] = [1e-2, 1e-2, 1e-10, 1e-10, 1e-10][i];
                let (a, b) = (p.stepped(&step), p.stepped(&step.map(|x| -x)));
                let num = (evaluate(&pb, &a, false, None).0 - evaluate(&pb, &b, false, None).0)
                    / (2.0 * step[i]);
                let ana = -2.0 * g;
                std::eprintln!("{f_h} param {i}: numeric {num:e} analytic {ana:e}");
                assert!(
                    (ana / num - 1.0).abs() < 0.05,
                    "{f_h} param {i}: {ana:e} vs {num:e}"
                );
            }
        }
    }
}
