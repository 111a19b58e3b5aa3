//! The resonator's model for the fit: the windows in `f32`, the drive model (steady state,
//! transient and their derivatives), the state carried between segments, χ² with its Jacobian,
//! the normal equations and the covariance.

use super::{Carry, Filters, Segment, MAX_SEGMENTS, MAX_WINDOWS};
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
    /// The sine fit's view of the window ([`SineFit`]).
    fit: SineFit,
}

/// How the lock-in's sine fit (`Re(P e^{jφ}) +` offset, least squares over the window:
/// [`crate::dsp::lockin::solve_value`]) sees a varying current over a window that starts at
/// the drive's phase `φ_a` and ends at `φ_b` ([`super::HoldWindow::phase`]), within a phase
/// step of whole cycles: `e^{jφ_a}`, `e^{j(φ_b − φ_a)}`, and the means `m1 = ⟨e^{−jφ}⟩`,
/// `m2 = ⟨e^{−2jφ}⟩` over the window, which set the fit's normal equations. For a current
/// `Re(c(t) e^{jφ})` the fit's `P` solves `p P + q P̄ = R`, `p = 1 − |m1|²`, `q = m2 − m1²`,
/// `R = ⟨c⟩ + ⟨c̄ e^{−2jφ}⟩ − 2 m1 ⟨Re(c e^{jφ})⟩` (the normal equations of the cosine, the
/// sine and the offset over the window's span, the samples' sums as its integral: their
/// difference is of order `(ω T)²`). A steady `c` comes out exact; whole cycles from phase 0
/// (`m1 = m2 = 0`) leave `⟨c⟩ + ⟨c̄ e^{−2jφ}⟩`. Ours, from the least-squares normal
/// equations.
#[derive(Clone, Copy, Debug, Default)]
struct SineFit {
    u1: C32,
    rb: C32,
    /// `e^{−2jφ_a}` and `e^{−2j(φ_b − φ_a)}`.
    pa: C32,
    pb: C32,
    m1: C32,
    q: C32,
    p: f32,
    inv_det: f32,
}

impl Win32 {
    /// [`SineFit::transient`] of this window.
    pub(super) fn transient(&self, decay: C32, r: &Rates, jac: bool) -> [C32; 4] {
        self.fit.transient(decay, self.len, r, jac)
    }

    /// [`SineFit::origin`] of this window.
    pub(super) fn origin(&self, mirror: C32) -> C32 {
        self.fit.origin(mirror)
    }
}

impl SineFit {
    /// The fit of a window of `len` s at `w_h` rad/s ([`omega`]) from phase `pa` to `pb` (2³² a
    /// turn).
    fn new(pa: u32, pb: u32, w_h: f32, len: f32) -> Self {
        let turn = |phi: u32| {
            // The phase in (−π, π]: the full turn's bits kept in f32's 24.
            let x = (phi as i32 as f32) * (core::f32::consts::TAU / 4_294_967_296.0);
            let (sin, cos) = crate::dsp::trig::sincos(x);
            C32::new(cos, sin)
        };
        let (u1, ub) = (turn(pa), turn(pb));
        // ⟨e^{−jkφ}⟩ = (e^{−jkφ_b} − e^{−jkφ_a}) / (−jkωL) = (…) · j/(kωL).
        let wl = w_h * len;
        let mean = |k: f32, a: C32, b: C32| (b - a) * C32::new(0.0, 1.0 / (k * wl));
        let m1 = mean(1.0, u1.conj(), ub.conj());
        let m2 = mean(2.0, (u1 * u1).conj(), (ub * ub).conj());
        let p = 1.0 - m1.norm_sqr();
        let q = m2 - m1 * m1;
        let det = p * p - q.norm_sqr();
        let rb = ub * u1.conj();
        Self {
            u1,
            rb,
            pa: (u1 * u1).conj(),
            pb: (rb * rb).conj(),
            m1,
            q,
            p,
            inv_det: if det > 0.0 { 1.0 / det } else { 1.0 },
        }
    }

    /// What the fit makes of a transient `tr e^{λs}` over the window (`s` from its start, `tr`
    /// there) in the admittance: `α tr + mirror β conj(tr)`, `mirror` the drive phasor's
    /// ([`super::mirror`]), with `decay = e^{λL}` and the segment's [`Rates`]; and (`jac`) the
    /// derivatives `α' = dα/dλ`, `β' = dβ/dλ̄`. The means over the window: `E = ⟨e^{λs}⟩`,
    /// `P = ⟨e^{λ̄s} e^{−2jφ}⟩`, `B = ⟨e^{λs} e^{jφ}⟩`;
    /// `α = (p (E − m1 B) − q (P̄ − m̄1 B)) / det`, `β = (p (P − m1 B̄) − q (Ē − m̄1 B̄)) / det`,
    /// `det = p² − |q|²`.
    fn transient(&self, decay: C32, len: f32, r: &Rates, jac: bool) -> [C32; 4] {
        let one = C32::new(1.0, 0.0);
        let pa = self.pa;
        let end_p = pa * decay.conj() * self.pb;
        let end_b = self.u1 * decay * self.rb;
        let e = (decay - one) * r.inv_lam / len;
        let pm = (end_p - pa) * r.inv_mu / len;
        let b = (end_b - self.u1) * r.inv_lw / len;
        let (p, q, m1) = (self.p, self.q, self.m1);
        let comb = |e: C32, pm: C32, b: C32| {
            let eb = e - m1 * b;
            (
                (eb * p - q * (pm.conj() - m1.conj() * b)) * self.inv_det,
                ((pm - m1 * b.conj()) * p - q * eb.conj()) * self.inv_det,
            )
        };
        let (alpha, beta) = comb(e, pm, b);
        if !jac {
            return [alpha, beta, C32::new(0.0, 0.0), C32::new(0.0, 0.0)];
        }
        // d/dλ of (e^{λL} − 1)/(λL), (e^{(λ+jω)L} − 1)/((λ + jω)L) and d/dλ̄ of P: each
        // (its end value − itself) over its exponent.
        let de = (decay - e) * r.inv_lam;
        let dpm = (end_p - pm) * r.inv_mu;
        let db = (end_b - b) * r.inv_lw;
        // α' takes P̄'s derivative in λ (conj of P's in λ̄); β' takes Ē's and B̄'s in λ̄.
        let eb = de - m1 * db;
        let d_alpha = (eb * p - q * (dpm.conj() - m1.conj() * db)) * self.inv_det;
        let d_beta = ((dpm - m1 * db.conj()) * p - q * eb.conj()) * self.inv_det;
        [alpha, beta, d_alpha, d_beta]
    }

    /// `mirror · e^{−2jφ_a}`: the drive's counter-rotating phase at the window's start.
    fn origin(&self, mirror: C32) -> C32 {
        mirror * self.pa
    }
}

/// The drive's angular frequency `2π f_h` (rad/s) for [`SineFit::new`], in `f32` (its 6e-8 and
/// a window's length's set the means `m1`, `m2` to 2e-7 of themselves, which are below
/// `1/(π × cycles)` of the window).
fn omega(f_h: f64) -> f32 {
    (core::f64::consts::TAU * f_h) as f32
}

/// A segment's rates for [`SineFit::transient`]: `1/λ`, `1/μ` ([`DriveModel::mu`]) and
/// `1/(λ + jω)`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Rates {
    inv_lam: C32,
    inv_mu: C32,
    inv_lw: C32,
}

impl Rates {
    pub(super) fn of(m: &DriveModel) -> Self {
        let one = C32::new(1.0, 0.0);
        // λ + jω = (λ + conj(μ)) / 2, conj(μ) = λ + 2jω.
        Self {
            inv_lam: one / m.lam,
            inv_mu: one / m.mu,
            inv_lw: one / ((m.lam + m.mu.conj()) * 0.5),
        }
    }
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
        let w_h = omega(seg.f_h);
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
                fit: SineFit::new(x.phase[0], x.phase[1], w_h, len),
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

impl DriveModel {
    /// What a switch-on of this drive leaves beyond the envelope's limit, per unit `g`: the
    /// resonator's free response at its pole `s_p = λ + jω` to the drive `Re(U e^{jωt})` switched
    /// on at `t = 0` from rest, through the front end's filters, divided by the measured drive
    /// `H(jω) U` and expressed as a start state, less the envelope's start state from rest (0):
    ///
    /// `k = h + T`,  `T = A R [S(λ) + M S(λ + 2jω)]`,  `A = (ω0/Q) s_p / (2j ω_d)` (the pole's
    /// residue of the motional admittance `(g ω0/Q) s / ((s − s_p)(s − s̄_p))` per `g`),
    /// `R = H(s_p)/H(jω)`, `M = mirror · (H/H̄)(jω) · e^{2jωd}` (`Ū/U` at the switch-on, `d`
    /// seconds before the segment's frame origin, whose drive phase `mirror` carries:
    /// [`SineFit::origin`]), `S(x) = T/(1 − e^{−xT})` the sum over the switched sine's samples
    /// (its Laplace transform at the pole: `1/x + T/2 + O(xT²)`, where the continuous sine has
    /// `1/x`),
    ///
    /// `H` the zero-order hold `(1 − e^{−sT})/(sT)` of the DAC (sample period `T`), the
    /// reconstruction filter and the anti-alias filter (two real poles each). In the envelope's
    /// limit `T → −h` (`R → 1`, `M → 0`) and `k → 0`. Ours, from the equation of motion and
    /// the Laplace transform of the sampled switched sine through the hold; `hal_sim::plant`
    /// integrates the same chain exactly (tests `the_frequency_switch_is_carried_by_the_full_response`,
    /// `the_start_from_rest_is_the_resonators_response`). Returns `k` and its derivatives with
    /// respect to (f0, Q).
    pub(super) fn switch_on(
        &self,
        q: f32,
        f_h: f32,
        d: f32,
        mirror: C32,
        filters: &Filters,
    ) -> (C32, [C32; 2]) {
        use core::f32::consts::PI as PI32;
        let one = C32::new(1.0, 0.0);
        let w = 2.0 * PI32 * f_h;
        let jw = C32::new(0.0, w);
        let lam = self.lam;
        let s_p = lam + jw;
        // A = s_p (ω0/Q)/(2j ω_d) = s_p c, c = 1/(2j Q sqrt(1 − 1/(4Q²))) (no f0 in c).
        let root2 = (1.0 - 0.25 / (q * q)).max(1e-12);
        let c = one / C32::new(0.0, 2.0 * q * crate::dsp::trig::sqrtf(root2));
        let dc_dq = -c * (1.0 / q + 0.25 / (q * q * q * root2));
        let a = s_p * c;
        // One filter's two poles: `r² = 1/(1 + λ/(ω_c + jω))²`, the ratio of its response at
        // s_p to that at jω, its derivative in λ `−2 r³/(ω_c + jω)`, and its phase turn
        // `(H/H̄)(jω) = ((1 − jω/ω_c)/(1 + jω/ω_c))²`.
        let pole = |w_c: f32| {
            let k = one / C32::new(w_c, w);
            let r = one / (one + lam * k);
            let t = C32::new(1.0, -w / w_c) / C32::new(1.0, w / w_c);
            (r * r, -r * r * r * k * 2.0, t * t)
        };
        let (rr, drr, tr) = pole(filters.w_r);
        let (ra, dra, ta) = pole(filters.w_a);
        // The hold: `H(s_p)/H(jω) = e^{−λT/2} · sinh(s_pT/2)/(s_pT/2) · (jωT/2)/sin(ωT/2)`
        // = `e^{−λT/2}` to `(λT)²/24` (1e-5 in any band the engine drives), its derivative in λ
        // `−T/2` of it, its phase turn `e^{−jωT}`.
        let half = 0.5 * filters.t_hold;
        let rz = cexp(-lam * half);
        let (sz, cz) = crate::dsp::trig::sincos(-w * filters.t_hold);
        let (sn, cs) = crate::dsp::trig::sincos(2.0 * w * d);
        let m = mirror * tr * ta * C32::new(cz, sz) * C32::new(cs, sn);
        // The samples' sums `S(x) = T y/(1 − e^{−y})/y` (`y = xT`) by the Bernoulli series of
        // `y/(1 − e^{−y})`, `1 + y/2 + y²/12 − y⁴/720`, and `dS/dx = T² (−1/y² + 1/12 − y²/240)`:
        // no cancellation in f32 where `λT` is small; `|y| < 0.4` in any band the engine drives,
        // where the series' remainder `y⁶/30240` is below 2e-7.
        let sum = |x: C32| {
            let t = filters.t_hold;
            let y = x * t;
            let inv = one / y;
            let y2 = y * y;
            (
                (inv + 0.5 + y * (one / 12.0 - y2 / 720.0)) * t,
                (one / 12.0 - inv * inv - y2 / 240.0) * (t * t),
            )
        };
        let (s1, ds1) = sum(lam);
        let (s2, ds2) = sum(lam + jw * 2.0);
        let big_r = rr * ra * rz;
        let b = s1 + m * s2;
        let t = a * big_r * b;
        // ∂/∂λ of R B, then of the whole: ∂k/∂p = ∂h/∂p + ∂A/∂p R B + A ∂(RB)/∂λ ∂λ/∂p.
        let d_big_r = (drr * ra + rr * dra) * rz - big_r * half;
        let d_rb = d_big_r * b + big_r * (ds1 + m * ds2);
        let via_lam = a * d_rb;
        let rb = big_r * b;
        let da = [self.dlam[0] * c, self.dlam[1] * c + s_p * dc_dq];
        let dk = core::array::from_fn(|i| self.dh[i] + da[i] * rb + via_lam * self.dlam[i]);
        (self.h + t, dk)
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
    dl: [C32; 2],
    z: C32,
    dz: [C32; 5],
    /// The segment's [`super::mirror`] factor and its [`Rates`].
    mirror: C32,
    rates: Rates,
}

impl SegModel {
    fn new(g: f32, m: &DriveModel, z: C32, dz: [C32; 5], mirror: C32) -> Self {
        Self {
            h: m.h,
            gh: m.h * g,
            g_dh: [m.dh[0] * g, m.dh[1] * g],
            lam: m.lam,
            dl: m.dlam,
            z,
            dz,
            mirror,
            rates: Rates::of(m),
        }
    }
}

/// The segments' models at `p` into `out` (the caller's: a returned list is copied out): the
/// first starts from `p.z`; the second (with `carry`) from the first's state carried to the
/// switch and on under the second's drive to its first window (the drive's phase at each
/// segment's origin from its first window in `w`).
fn seg_models(
    p: &Params,
    segs: &[(f64, f64, C32)],
    carry: Option<&Carry>,
    w: &[Win32],
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
        let (ds, d2) = (
            (c.t_switch - t_first).max(0.0) as f32,
            (t_second - c.t_switch).max(0.0) as f32,
        );
        let (z1, dz1, e1) = m1.advance(g, rho * u, d2);
        let via = rho * e1;
        // The switch beyond the envelope's limit: drive 1 switched off (its switch-on's `k`
        // with the phase it has there, `ds` after the first segment's origin), drive 2 switched
        // on, the difference carried to the second segment's origin
        // ([`DriveModel::switch_on`]).
        let q = p.q as f32;
        let origin = |s: u8, mirror: C32| {
            w.iter()
                .find(|x| x.seg == s)
                .map_or(mirror, |x| x.origin(mirror))
        };
        let (k1, dk1) = m0.switch_on(q, f_first as f32, -ds, origin(0, mirror0), &c.filters);
        let (k2, dk2) = m1.switch_on(q, f_second as f32, d2, origin(1, mirror1), &c.filters);
        let jump = k2 - rho * k1;
        let x = jump * g * e1;
        let dx = |i: usize| (dk2[i] - rho * dk1[i]) * g * e1 + x * m1.dlam[i] * d2;
        let _ = out.push(SegModel::new(
            g,
            &m1,
            z1 + x,
            [
                dz1[0] + via * du[0] + dx(0),
                dz1[1] + via * du[1] + dx(1),
                dz1[2] + via * du[2] + jump * e1,
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
    seg_models(p, segs, carry, w, &mut models);
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
        // The transient at the window's start, `tr`, and what the window's sine fit makes of it
        // ([`SineFit::transient`]): `α tr + mirror β conj(tr)`.
        let eb = ea * decay;
        let tr = (m.z - m.gh) * ea;
        let [alpha, beta, d_alpha, d_beta] = x.transient(decay, &m.rates, jac);
        let mb = m.mirror * beta;
        let model = m.gh + alpha * tr + mb * tr.conj();
        let r = x.y - model;
        if let Some(o) = res.as_deref_mut().and_then(|o| o.get_mut(i)) {
            *o = r;
        }
        chi2 += x.wl * r.norm_sqr();
        if jac {
            // d model = d(gh) + α d tr + α' tr dλ + mirror (β' conj(dλ) conj(tr) + β conj(d tr)),
            // d tr = (dz − d(gh)) e^{λa} + tr a dλ, with the terms that vanish (g and z do not
            // move λ; z does not move gh) left out.
            let (ta, at, ia) = (tr * a, d_alpha * tr, m.mirror * d_beta * tr.conj());
            let moving = |i: usize| {
                let dtr = (m.dz[i] - m.g_dh[i]) * ea + ta * m.dl[i];
                m.g_dh[i] + alpha * dtr + at * m.dl[i] + ia * m.dl[i].conj() + mb * dtr.conj()
            };
            let linear = |d: C32| {
                let dtr = d * ea;
                alpha * dtr + mb * dtr.conj()
            };
            let cols = [
                moving(0) * scale[0],
                moving(1) * scale[1],
                // The linear parameters' columns are not scaled.
                m.h + linear(m.dz[2] - m.h),
                linear(m.dz[3]),
                linear(m.dz[4]),
            ];
            add_row(jtj32, jtr32, &cols, r, x.wl);
        }
        ea = eb;
    }
    if let Some(rest) = &pb.rest {
        let (r, cols) = rest.residual(p, jac, &scale);
        chi2 += rest.w * r.norm_sqr();
        if jac {
            add_row(jtj32, jtr32, &cols, r, rest.w);
        }
    }
    (chi2 as f64 * wt, normal)
}

/// One complex row (a window's, the start's prior) into the normal equations' sums: its
/// columns `cols`, residual `r` and weight `w`.
fn add_row(jtj: &mut [[f32; 5]; 5], jtr: &mut [f32; 5], cols: &[C32; 5], r: C32, w: f32) {
    let rw = r * w;
    for i in 0..5 {
        let ci = cols[i];
        jtr[i] += ci.re * rw.re + ci.im * rw.im;
        let cw = ci * w;
        // (`0..i + 1`: `0..=i` is an out-of-line iterator call at `opt-level = "z"`.)
        for j in 0..i + 1 {
            jtj[i][j] += cw.re * cols[j].re + cw.im * cols[j].im;
        }
    }
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
    /// The prior on the first segment's start state, when the drive came on from rest.
    pub(super) rest: Option<RestPrior>,
}

/// The prior on the state at the first segment's first window: the resonator's response from
/// rest to the segment's drive switched on `d` seconds earlier, `g K(f0, Q)`,
/// `K = h + (k − h) e^{λd}` ([`DriveModel::switch_on`]'s `k` from the state 0, the drive's
/// phase at the switch-on from the segment's origin, `origin` = [`SineFit::origin`] of its first
/// window), with weight `w` per unit of the windows' weighted squared residual (`1/σ_z²` over
/// the windows' `1/var`: the same units as the windows' terms of χ²).
#[derive(Clone, Copy, Debug)]
pub(super) struct RestPrior {
    pub(super) f_h: f64,
    pub(super) d: f32,
    pub(super) origin: C32,
    pub(super) filters: Filters,
    pub(super) w: f32,
}

impl RestPrior {
    /// `K(f0, Q)` and its derivatives with respect to (f0, Q).
    pub(super) fn k(&self, f0: f64, q: f64) -> (C32, [C32; 2]) {
        let at = Params {
            f0,
            q,
            g: 0.0,
            z: C64::new(0.0, 0.0),
        };
        let m = DriveModel::new(&at, self.f_h);
        let (k, dk) = m.switch_on(
            q as f32,
            self.f_h as f32,
            self.d,
            self.origin,
            &self.filters,
        );
        let e = cexp(m.lam * self.d);
        let t = (k - m.h) * e;
        let dk = core::array::from_fn(|i| m.dh[i] + (dk[i] - m.dh[i]) * e + t * m.dlam[i] * self.d);
        (m.h + t, dk)
    }

    /// The prior's residual `g K − z` at `p` and, with `jac`, its columns over (f0, Q, g, Re z,
    /// Im z) — those of the model `z − g K` — the first two multiplied by `scale` as
    /// [`evaluate`]'s.
    pub(super) fn residual(&self, p: &Params, jac: bool, scale: &[f32; 5]) -> (C32, [C32; 5]) {
        let g = p.g as f32;
        let (k, dk) = self.k(p.f0, p.q);
        let r = k * g - c32(p.z);
        let zero = C32::new(0.0, 0.0);
        if !jac {
            return (r, [zero; 5]);
        }
        let cols = [
            -dk[0] * g * scale[0],
            -dk[1] * g * scale[1],
            -k,
            C32::new(1.0, 0.0),
            C32::new(0.0, 1.0),
        ];
        (r, cols)
    }
}

/// The state per unit `g` at `d` seconds after a drive at `f_h` came on with the resonator at
/// rest, in the frame of a segment whose first window is `first` and whose drive phasor's
/// [`super::mirror`] factor is `mirror` ([`RestPrior::k`]), for the tests.
#[cfg(test)]
pub(crate) fn rest_state(
    (f0, q): (f64, f64),
    f_h: f64,
    d: f64,
    first: &super::HoldWindow,
    mirror: C64,
    filters: &Filters,
) -> C64 {
    let fit = SineFit::new(first.phase[0], first.phase[1], omega(f_h), first.len as f32);
    let r = RestPrior {
        f_h,
        d: d as f32,
        origin: fit.origin(c32(mirror)),
        filters: *filters,
        w: 0.0,
    };
    let k = r.k(f0, q).0;
    C64::new(k.re as f64, k.im as f64)
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
                                    phase: [0, 0],
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
                                rest: None,
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
                        phase: [0, 0],
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
    /// included (a rotated drive, a transient far from the fit's point, windows off their
    /// cycle boundaries), against central
    /// differences of χ² (f64 reference on the same windows).
    #[test]
    fn gradient_matches_finite_differences() {
        let y_s = C64::new(0.0, 0.0);
        for (f_h, m) in [
            (241.3, C64::new(1.0, 0.0)),
            (238.0, mirror(C64::new(0.6, 0.8))),
        ] {
            let mut w = synthetic(241.3, 10.4, 1.5e-7, f_h, C64::new(1e-8, 0.0), y_s, 16);
            off_the_boundary(&mut w);
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
                rest: None,
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
            check_gradient(&pb, &p, &jtr, 0.05);
        }
    }

    /// Windows starting and ending off their cycle boundaries (within ±6° of it), so that the
    /// windows' sine fit ([`SineFit`]) is in the gradient.
    fn off_the_boundary(w: &mut [crate::estimate::resonator::HoldWindow]) {
        for (k, x) in w.iter_mut().enumerate() {
            let step = 0x0100_0000u32;
            x.phase = [
                (k as u32 * 7 % 9).wrapping_mul(step).wrapping_sub(4 * step),
                (k as u32 * 5 % 9).wrapping_mul(step).wrapping_sub(4 * step),
            ];
        }
    }

    /// The analytic gradient `−2 JᵀW r` (`jtr`) of χ² at `p` against central differences of
    /// χ² over all five parameters, each component within `tol` of itself.
    fn check_gradient(pb: &Problem, p: &Params, jtr: &[f64; 5], tol: f64) {
        for (i, g) in jtr.iter().enumerate() {
            let mut step = [0.0; 5];
            step[i] = [1e-2, 1e-2, 1e-9, 1e-9, 1e-9][i];
            let (a, b) = (p.stepped(&step), p.stepped(&step.map(|x| -x)));
            let num = (evaluate(pb, &a, false, None).0 - evaluate(pb, &b, false, None).0)
                / (2.0 * step[i]);
            let ana = -2.0 * g;
            std::eprintln!("param {i}: numeric {num:e} analytic {ana:e}");
            assert!(
                (ana / num - 1.0).abs() < tol,
                "param {i}: {ana:e} vs {num:e}"
            );
        }
    }

    /// The same check for a joint fit of two segments: the state carried through the switch,
    /// the switch's full response ([`DriveModel::switch_on`]) and its derivatives included,
    /// and the prior on the start state from rest ([`RestPrior`]), to 5e-4 of each component.
    #[test]
    fn gradient_through_the_switch_matches_finite_differences() {
        use crate::estimate::resonator::{Carry, Filters};
        let y_s = C64::new(0.0, 0.0);
        let (f1, f2) = (230.0, 241.0);
        let mut w1 = synthetic(241.3, 10.4, 1.5e-7, f1, C64::new(0.0, 0.0), y_s, 6);
        let mut w2 = synthetic(241.3, 10.4, 1.5e-7, f2, C64::new(5e-8, 2e-8), y_s, 10);
        off_the_boundary(&mut w1);
        off_the_boundary(&mut w2);
        let t_switch = w1[5].t0 + w1[5].len;
        let mut w2 = w2[..10].to_vec();
        for x in &mut w2 {
            x.t0 += t_switch + 0.001;
        }
        let (m1, m2) = (mirror(C64::new(0.6, 0.8)), mirror(C64::new(0.8, -0.6)));
        let segs = [
            Segment {
                windows: &w1[..6],
                f_h: f1,
                y_s,
                mirror: m1,
            },
            Segment {
                windows: &w2,
                f_h: f2,
                y_s,
                mirror: m2,
            },
        ];
        let carry = Carry {
            t_switch,
            rho: C64::new(0.9, 0.1),
            filters: Filters::of(&crate::hal::FrontEndScale::PROBE),
        };
        let (w, gs) = prepare(&segs);
        let pb = Problem {
            w,
            gs,
            segs: [(f1, w1[0].t0, c32(m1)), (f2, w2[0].t0, c32(m2))]
                .into_iter()
                .collect(),
            carry: Some(&carry),
            wt: 1e14,
            // The start from rest's prior, its derivatives through the switch-on's.
            rest: Some(RestPrior {
                f_h: f1,
                d: 0.004,
                origin: c32(m1),
                filters: carry.filters,
                w: 0.5,
            }),
        };
        let p = Params {
            f0: 240.6,
            q: 9.1,
            g: 1.3e-7,
            z: C64::new(2e-8, -1e-8),
        };
        let jtr = evaluate(&pb, &p, true, None).1.unscaled(pb.wt).1;
        // f32 model arithmetic leaves 3e-4 at most here; leaving out the switch's own
        // derivatives moves the f0 component by 1e-3.
        check_gradient(&pb, &p, &jtr, 5e-4);
    }
}

#[cfg(test)]
mod sine_fit {
    use super::*;
    use crate::dsp::dds::{frequency_hz, tuning_word};
    use core::f64::consts::PI;

    /// [`SineFit::transient`] against the lock-in's own least squares on the samples (f64
    /// reference: the cosine, sine and offset fit of `Re(T e^{λt} e^{jφ})` at each sample's
    /// phase, solved by [`crate::linalg::inverse3`]): windows of one, two and four cycles at
    /// 170–290 Hz (the band) starting anywhere within the phase step after their cycle
    /// boundary, `Q` 6–30, the drive on the resonance and two half-widths either side. Within
    /// 6e-4 of the transient: the samples' sums against the span's integral differ by about
    /// `(μT)²/24` of the mirror image (`μ ≈ −2jω`, 1 % at 290 Hz) and `(λT)²/24` of the rest.
    /// Whole cycles from phase 0 (the model without the windows' phases) miss by more than
    /// 1e-3 somewhere.
    #[test]
    fn the_sine_fit_of_a_transient_is_modelled() {
        let fs = 10_000.0;
        let mut rng = probe_rng::Rng::new(11);
        let (mut worst, mut worst_whole) = (0.0f64, 0.0f64);
        for f_set in [170.0, 241.0, 290.0] {
            let ftw = tuning_word(f_set, fs);
            let f_h = frequency_hz(ftw, fs);
            for q in [6.0, 10.0, 30.0] {
                for offset in [-2.0, 0.0, 2.0] {
                    let f0 = f_h * (1.0 - offset / (2.0 * q));
                    let lam = C64::new(
                        -PI * f0 / q,
                        2.0 * PI * (f0 * (1.0 - 0.25 / (q * q)).sqrt() - f_h),
                    );
                    let m = DriveModel::new(
                        &Params {
                            f0,
                            q,
                            g: 0.0,
                            z: C64::new(0.0, 0.0),
                        },
                        f_h,
                    );
                    let rates = Rates::of(&m);
                    for cycles in [1u64, 2, 4] {
                        for _ in 0..20 {
                            let start = (rng.uniform() * ftw as f64) as u32;
                            // Samples to the `cycles`-th wrap.
                            let n = ((cycles << 32) - start as u64).div_ceil(ftw as u64);
                            let t = C64::from_polar(1.0, 2.0 * PI * rng.uniform());
                            let (mut m3, mut rhs) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
                            for k in 0..n {
                                let ph = start.wrapping_add((k as u32).wrapping_mul(ftw));
                                let ph = ph as f64 / 4_294_967_296.0 * 2.0 * PI;
                                let b = [ph.cos(), ph.sin(), 1.0];
                                let tk = k as f64 / fs;
                                let x = (t * (lam * tk).exp() * C64::from_polar(1.0, ph)).re;
                                for i in 0..3 {
                                    rhs[i] += b[i] * x;
                                    for j in 0..3 {
                                        m3[i][j] += b[i] * b[j];
                                    }
                                }
                            }
                            let inv = crate::linalg::inverse3(&m3).unwrap();
                            let ab: [f64; 3] = core::array::from_fn(|i| {
                                (0..3).map(|j| inv[i][j] * rhs[j]).sum::<f64>()
                            });
                            let want = C64::new(ab[0], -ab[1]);
                            // The window's span starts half a sample before its first sample,
                            // half a phase step before its phase.
                            let len = n as f64 / fs;
                            let tr = t * (-lam * (0.5 / fs)).exp();
                            let pa = start.wrapping_sub(ftw / 2);
                            let pb = pa.wrapping_add(ftw.wrapping_mul(n as u32));
                            let decay = c32((lam * len).exp());
                            let got = |fit: SineFit| {
                                let [a, b, ..] = fit.transient(decay, len as f32, &rates, false);
                                let tr = c32(tr);
                                let v = a * tr + b * tr.conj();
                                C64::new(v.re as f64, v.im as f64)
                            };
                            let exact = got(SineFit::new(pa, pb, omega(f_h), len as f32));
                            let whole = got(SineFit::new(0, 0, omega(f_h), len as f32));
                            worst = worst.max((exact - want).norm());
                            worst_whole = worst_whole.max((whole - want).norm());
                        }
                    }
                }
            }
        }
        std::eprintln!("worst: {worst:e} of the transient ({worst_whole:e} as whole cycles)");
        assert!(worst < 6e-4, "{worst:e}");
        assert!(worst_whole > 1e-3, "{worst_whole:e}");
    }
}
