//! The resonator's driven response and its fit, shared by hold, the continuous mode and the interference checks. May import the leaves, engine and estimate's shared rules (`Estimate`, `interference`); no method.
//!
//! A drive held at `f_h` and demodulated in gap-free windows of whole cycles gives one
//! admittance `Y_k` a window ([`HoldWindow`]). A segment of such windows ([`Segment`]) is fitted
//! with the exact response of the Butterworth–Van Dyke resonator to a sine switched on at
//! `t = 0` from an unknown state:
//!
//! `Y_k = Y_s + Y_m (1 − E_k) + z E_k`,  `Y_m = g / (1 + j Q (f_h/f0 − f0/f_h))`,
//!
//! `E_k` = the mean of `exp(λ t)` over window `k`, `λ = −π f0/Q + j 2π (f_d − f_h)`,
//! `f_d = f0 sqrt(1 − 1/(4Q²))`, plus the transient's mirror image that a window of whole cycles
//! lets through ([`mirror`]). The static admittance `Y_s` is the caller's (the air reference).
//! `f0, Q, g, Re z, Im z` are fitted by Levenberg–Marquardt with a prior on `Q`, weighted by the
//! windows' common noise variance, and `σ(f0)` is the `(JᵀWJ)⁻¹` standard uncertainty
//! ([`HoldFit`]). Two segments at different drives are fitted jointly, the state carried through
//! the switch ([`Carry`], [`fit_two`]); a segment with no start is searched for one
//! ([`fit_searched`]).
//!
//! Here: the windows, the segments, the mirror term, the carry and the fit's result. `model`:
//! the drive model, χ² and its Jacobian, the normal equations and the covariance. `solver`: the
//! starts (linear, given, searched) and the Levenberg–Marquardt iteration.

pub(crate) mod model;
mod solver;

#[cfg(test)]
mod fixtures;

#[cfg(test)]
pub(crate) use model::rest_state;
pub use solver::{fit, fit_linearised, fit_searched, fit_two, Linearised};

use super::Estimate;
use crate::dsp::lockin::{solve_value_scaled, ChannelSums, ReferenceSums};
use crate::engine::PointRaw;
use crate::hal::FrontEndScale;
use model::c32;
use num_complex::Complex64 as C64;

/// Most windows of the hold.
pub const MAX_WINDOWS: usize = 16;

/// Windows of a hold's first segment with no seed: the fewest its searched fit takes
/// ([`fit_searched`]; `hold::HoldSettings::min_first`): four numbers for `f0`, `g` and the start
/// state with the start from rest ([`SwitchOn`]) and the prior on `Q`; with the state free,
/// only a rough placement for the second segment.
pub(crate) const FIRST_WINDOWS: usize = 2;

/// Whole cycles of the shortest window the engine passes on at `f` Hz sampled at `fs` (a
/// hold's first segment's, a tracker segment's): the fewest that span half a batch
/// (`engine::MIN_WINDOW_SAMPLES`; one cycle up to 769 Hz at 10 kHz).
pub fn first_cycles(f: f64, fs: f64) -> f64 {
    let per_cycle = fs / f.max(1.0);
    libm::ceil(crate::engine::MIN_WINDOW_SAMPLES as f64 / per_cycle).max(1.0)
}

/// Add one window's monitor and reference sums to a segment's (saturating: never overflows).
pub(crate) fn add_sums(acc: &mut (ChannelSums, ReferenceSums), m: &ChannelSums, r: &ReferenceSums) {
    let (a, b) = acc;
    a.xc = a.xc.saturating_add(m.xc);
    a.xs = a.xs.saturating_add(m.xs);
    a.x = a.x.saturating_add(m.x);
    a.xx = a.xx.saturating_add(m.xx);
    b.cc = b.cc.saturating_add(r.cc);
    b.ss = b.ss.saturating_add(r.ss);
    b.cs = b.cs.saturating_add(r.cs);
    b.c = b.c.saturating_add(r.c);
    b.s = b.s.saturating_add(r.s);
    b.n = b.n.saturating_add(r.n);
}

/// A finished window's current phasor (A) and its variance per component, its start and length
/// (s) from the engine's sample count at the sample period `dt` (s); `None` when its sums do not
/// solve. The
/// amplitude and its variance alone ([`solve_value_scaled`] in amperes): a window's offset and residual are not
/// the fit's.
pub(crate) fn current_window(raw: &PointRaw, scale: &FrontEndScale, dt: f64) -> Option<HoldWindow> {
    let s = &raw.sums;
    let (y, var) = solve_value_scaled(&s.current, &s.reference, scale.amps_per_code as f64)?;
    // Times from whole sample counts (no division, no difference of two times).
    let n = s.reference.n as u64;
    // The window's span in the windows' time base (each sample the period centred on it)
    // starts half a phase step before its first sample's phase and ends `n` steps later.
    let ftw = raw.plan.ftw;
    let start = raw.start_phase.wrapping_sub(ftw / 2);
    Some(HoldWindow {
        t0: raw.end_sample.saturating_sub(n) as f64 * dt,
        len: n as f64 * dt,
        y,
        var,
        phase: [start, start.wrapping_add(ftw.wrapping_mul(s.reference.n))],
    })
}

/// The windows' currents `I` (and their variances) into admittances with the drive phasor `v`
/// (the variance of each of its components `var_v`): `Y = I / V` and
/// `var = (var_I + |Y|² var_V) / |V|²` ([`crate::engine::sweep::Drive::admittance`]) with `1/V`
/// and `1/|V|²` formed once, each window's in f32 (emulated f64 is dear on the Cortex-M4F; f32's
/// 1e-7 is far below any window's noise, 1e-3 of |Y| and more).
pub(crate) fn to_admittance(windows: &mut [HoldWindow], v: C64, var_v: f64) {
    // 1/V = V̄/|V|², 1/|V|² once.
    let inv_n64 = 1.0 / v.norm_sqr();
    let inv_v = v.conj() * inv_n64;
    let (inv_v32, inv_n) = (c32(inv_v), inv_n64 as f32);
    let var_v = var_v as f32;
    for x in windows {
        let y = c32(x.y) * inv_v32;
        let var = (x.var as f32 + y.norm_sqr() * var_v) * inv_n;
        (x.y, x.var) = (C64::new(y.re as f64, y.im as f64), var as f64);
    }
}

/// One demodulated window of the hold.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HoldWindow {
    /// Start, seconds after the first window's start.
    pub t0: f64,
    /// Length, seconds.
    pub len: f64,
    /// Measured admittance, S.
    pub y: C64,
    /// Variance of each component of `y` (the window's sine-fit residual), S².
    pub var: f64,
    /// The drive's reference phase at the window's start and at its end (2³² a turn), in the
    /// windows' time base: a window starts within a sample's phase step of its cycle boundary
    /// and spans whole cycles to within one step, which its sine fit's view of a transient
    /// depends on ([`mirror`]). `[0, 0]`: whole cycles from the boundary.
    pub phase: [u32; 2],
}

/// A hold fit: the estimate and the standard uncertainty of its `Q`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HoldFit {
    /// Resonance, its uncertainty and `Q`.
    pub estimate: Estimate,
    /// Standard uncertainty of `Q`.
    pub sigma_q: f64,
    /// Covariance of `f0` and `Q` (Hz): off the resonance the steady state's phase gives the
    /// detuning only through `Q`, so their errors are correlated with the offset's sign.
    pub cov_f0_q: f64,
    /// χ² per degree of freedom at the fit (above [`crate::estimate::conductance::GROSS_CHI2`]
    /// the model does not explain the windows and `sigma` has been scaled by it).
    pub reduced_chi2: f64,
    /// The fitted motional peak conductance `g` (S) and state `z` at the start of the first
    /// window (S): a joint fit that takes these windows goes on from them ([`fit_two`]).
    pub linear: (f64, C64),
    /// The start state was the resonator's response from rest ([`SwitchOn`]); false when no
    /// switch-on was given or the windows disagreed with it.
    pub at_rest: bool,
}

/// One segment of a hold: consecutive windows driven at one frequency `f_h`, with the static
/// admittance `y_s` at that frequency (from the air reference).
#[derive(Clone, Copy, Debug)]
pub struct Segment<'a> {
    /// The segment's windows, in time order.
    pub windows: &'a [HoldWindow],
    /// Drive frequency, Hz.
    pub f_h: f64,
    /// Static admittance at `f_h`, S.
    pub y_s: C64,
    /// `e^{−2j arg V}` of the segment's drive phasor `V` ([`mirror`]): how a transient's
    /// counter-rotating part leaks into the windows.
    pub mirror: C64,
}

/// `e^{−2j arg v}` (`v̄ / v`) of a drive phasor `v`; 1 for a zero phasor.
///
/// A window of whole cycles demodulates `Re(c(t) e^{jφ(t)})` — the current `c = Y V` in the
/// drive's rotating frame — into the mean of `c` **plus** the mean of `c̄(t) e^{−2jφ(t)}`, the
/// counter-rotating (mirror) image. A steady `c` leaves no image over whole cycles; a transient
/// `T e^{λt}` does: `mirror · conj(T e^{λ a}) · (e^{λ̄ L} − 1) / ((λ̄ − j4π f_h) L)` in the
/// admittance, about `|λ| / (4 ω_h)` of the transient (2 % at `Q` 10), which, left out of the
/// model, biases a detuned first segment's `f0` by 4 % of the detuning. A window that starts
/// off its cycle boundary and spans whole cycles only to within a phase step
/// ([`HoldWindow::phase`]) sees the transient through its sine fit's normal equations
/// (`model::SineFit`).
pub fn mirror(v: C64) -> C64 {
    // `v̄² / |v|²` from the squares of its parts, once each.
    let (rr, ii) = (v.re * v.re, v.im * v.im);
    let n = rr + ii;
    if n > 0.0 && n.is_finite() {
        let inv = 1.0 / n;
        C64::new((rr - ii) * inv, -2.0 * (v.re * v.im) * inv)
    } else {
        C64::new(1.0, 0.0)
    }
}

/// Most segments a fit takes (a first hold and the one it placed).
const MAX_SEGMENTS: usize = 2;

/// How the resonator's state passes from the first segment into the second: the drive moved
/// phase-continuously at `t_switch` (the time base of the windows' `t0`), and the drive phasor
/// changed by `rho = V₁/V₂` (the same motional current is `rho` times the first segment's
/// admittance in the second's).
#[derive(Clone, Copy, Debug)]
pub struct Carry {
    /// Time of the frequency switch, s, in the windows' time base, whose windows each stand for
    /// the sample periods centred on their samples: half a sample after the time of the
    /// sample from which the new drive's first code holds.
    pub t_switch: f64,
    /// Ratio of the first segment's drive phasor to the second's.
    pub rho: C64,
    /// The front end the switch passes through.
    pub filters: Filters,
}

/// The front end between the drive's samples and the measured current as a switch sees it
/// (`model::DriveModel::switch_on`): the DAC's zero-order hold, the reconstruction filter
/// between the DAC and the PZT and the anti-alias filter before the ADC, two real poles each
/// (the drive monitor passes an anti-alias filter identical to the current's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filters {
    /// The hold's length (the sample period), s.
    pub t_hold: f32,
    /// Reconstruction filter's corner, rad/s.
    pub w_r: f32,
    /// Anti-alias filter's corner, rad/s.
    pub w_a: f32,
}

/// The drive's switch-on before a first segment with the resonator at rest: the segment's start
/// state is the resonator's response from rest (`model::DriveModel::switch_on` from the state 0,
/// a function of `f0`, `Q`, `g` and the drive), known to within `width` of the windows'
/// admittance scale (the model's own residue and what the drive's history may have left
/// ringing). The fit takes it as a prior and drops it when the windows disagree
/// ([`HoldFit::at_rest`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwitchOn {
    /// When the drive came on, s, in the windows' time base (as [`Carry::t_switch`]).
    pub t_on: f64,
    /// The front end the switch-on passes through.
    pub filters: Filters,
    /// The prior's standard uncertainty of each component of the start state, relative to the
    /// largest windowed admittance less its static part.
    pub width: f32,
}

impl Filters {
    /// The filters of a front end.
    pub fn of(scale: &crate::hal::FrontEndScale) -> Self {
        let w = |f: crate::units::Hz| 2.0 * core::f32::consts::PI * f.0;
        Self {
            t_hold: 1.0 / scale.sample_rate.0.max(1.0),
            w_r: w(scale.reconstruction_corner),
            w_a: w(scale.antialias_corner),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::sweep::Drive;

    /// [`to_admittance`]'s `f32` against the `f64` [`Drive::admittance`] it stands for, over
    /// currents of 1 nA to 10 µA, drives of 0.1 to 10 V at every phase, and window variances
    /// from 1e-8 to 1 of `|I|²` with the drive's from 1e-10 to 1e-2 of `|V|²`: the admittance
    /// within 1e-6 of `|Y|` and the variance within 3e-6 of itself, `f32` rounding (1e-7 an
    /// operation) far below any window's noise.
    #[test]
    fn to_admittance_agrees_with_the_f64_drive_admittance() {
        let mut rng = probe_rng::Rng::new(7);
        let (mut worst_y, mut worst_var) = (0.0f64, 0.0f64);
        for _ in 0..5000 {
            let polar = |r: f64, a: f64| C64::new(r * a.cos(), r * a.sin());
            let tau = core::f64::consts::TAU;
            let i = polar(1e-9 * 1e4f64.powf(rng.uniform()), tau * rng.uniform());
            let v = polar(0.1 * 100f64.powf(rng.uniform()), tau * rng.uniform());
            let var_i = i.norm_sqr() * 1e-8 * 1e8f64.powf(rng.uniform());
            let var_v = v.norm_sqr() * 1e-10 * 1e8f64.powf(rng.uniform());
            let want = Drive { v, var_v }.admittance(i, var_i);
            let mut w = [HoldWindow {
                y: i,
                var: var_i,
                ..HoldWindow::default()
            }];
            to_admittance(&mut w, v, var_v);
            worst_y = worst_y.max((w[0].y - want.y).norm() / want.y.norm());
            worst_var = worst_var.max((w[0].var / want.var - 1.0).abs());
        }
        std::eprintln!("worst: y {worst_y:e}, var {worst_var:e}");
        assert!(worst_y < 1e-6, "{worst_y:e}");
        assert!(worst_var < 3e-6, "{worst_var:e}");
    }
}
