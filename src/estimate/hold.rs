//! **hold**: find the resonance with a short ring-down, then hold the drive on it and fit the
//! motional response window by window.
//!
//! The Cramér–Rao bound of a driven resonance comes from its phase slope `dφ/df = 2πτ`: every
//! second spent driving *on* the resonance, with the motional current at its largest, buys phase
//! information; every second spent elsewhere (settling off-peak points, stepping across the band,
//! listening to a decay that fades within a time constant) buys less. So this method
//!
//! 1. **seeds** with a one-stage ring-down ([`super::ringdown`]): a burst at the seed frequency,
//!    then the free decay, which gives `f0` and `Q` to a small fraction of the linewidth in a few
//!    time constants; when nothing rings (the resonance is far from the seed and the noise high)
//!    it bursts a quarter band below, then a quarter band above;
//! 2. **holds** the drive at that frequency `f_h` for the rest of the reading and demodulates the
//!    current in consecutive gap-free windows of whole cycles;
//! 3. **fits** every window's admittance `Y_k` with the exact response of the
//!    Butterworth–Van Dyke resonator to a sine switched on at `t = 0` from an unknown state:
//!
//!    `Y_k = Y_s + Y_m (1 − E_k) + z E_k`,  `Y_m = g / (1 + j Q (f_h/f0 − f0/f_h))`,
//!
//!    `E_k` = the mean of `exp(λ t)` over window `k`, `λ = −π f0/Q + j 2π (f_d − f_h)`,
//!    `f_d = f0 sqrt(1 − 1/(4Q²))` — the ring-up from the state `z` that the ring-down left
//!    towards the steady state `Y_m`, in the drive's rotating frame.
//!
//! The static admittance `Y_s = G0 + j 2π f_h C0` is **not** fitted: it comes from the air
//! reference (the settings' `static_capacitance`, `static_conductance`). With it known, the
//! steady state's phase alone fixes `f0` (at `f_h = f0` the motional admittance is real), so the
//! whole hold contributes, not only its transient; the transient (free `z`) is modelled rather
//! than waited out. Five parameters `f0, Q, g, Re z, Im z` are fitted by Levenberg–Marquardt
//! (the last three enter linearly), weighted by the windows' common noise variance (measured from
//! the sine-fit residuals of the second half of the windows, where the transient has gone), and
//! `σ(f0)` is the `(JᵀWJ)⁻¹` standard uncertainty — scaled by the reduced χ² only when the fit
//! is grossly wrong, as in the other fits.
//!
//! **Where it breaks** (typed failures, never a silent number): the seed ring-down fails
//! (`no_resonance`, `low_snr`, `out_of_band`, heavy damping with `Q < 2` — the decay is over
//! before a window ends); the hold's resonance leaves the band (`out_of_band`) or moves more
//! than a linewidth from the seed (`not_locked`: the tissue moved); the static admittance no
//! longer matches the air reference (a different cable or a drifted `C0` biases `f0` by
//! `f0 ΔB / (2 Q g)`: this is the method's systematic, documented in `docs/methods.md`).

use super::model::Motional;
use super::ringdown::{Ringdown, RingdownSettings};
use super::Estimate;
use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::dsp::lockin::{solve, ChannelSums, ReferenceSums};
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::linalg::{damped_solve, spd_inverse};
use crate::status::Failure;
use crate::sweep::{amplitude_codes, check_durations, Drive, SettingsError};
use crate::units::{Farads, Hz, Seconds, Siemens, Volts};
use core::f64::consts::PI;
use num_complex::Complex64 as C64;

/// Most windows of the hold.
pub const MAX_WINDOWS: usize = 16;

/// Settings of the hold method.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HoldSettings {
    /// Lowest resonance accepted.
    pub band_start: Hz,
    /// Highest resonance accepted.
    pub band_stop: Hz,
    /// Burst frequency of the seed ring-down (a previous reading, or the band centre).
    pub seed: Hz,
    /// Seed burst length.
    pub seed_burst: Seconds,
    /// Seed ring-down observation length (at least four two-cycle windows are taken; 0: exactly
    /// three, the fewest the decay fit takes).
    pub seed_ring: Seconds,
    /// How long the drive is held on the resonance in all (0.05–10 s).
    pub hold: Seconds,
    /// Length of a first, shorter hold on the seed, after which the drive moves to that hold's
    /// estimate for the rest of `hold` (0: one hold on the seed). Holding within a small
    /// fraction of the linewidth of the resonance makes the estimate insensitive to how far the
    /// resonator departs from the Butterworth–Van Dyke form (viscoelastic tissue does).
    pub refine: Seconds,
    /// Drive amplitude at the PZT.
    pub drive: Volts,
    /// Static capacitance `C0` of the PZT and its wiring, from the air reference.
    pub static_capacitance: Farads,
    /// Static (dielectric and leakage) conductance `G0`, from the air reference.
    pub static_conductance: Siemens,
}

impl HoldSettings {
    /// Seed 20 + 20 ms, hold 80 + 220 ms over 170–290 Hz, seeded at 230 Hz, 5 V; the static
    /// admittance is the PZT plate's nominal 210 pF and no leakage — a unit's own air reference
    /// must replace it (see `docs/methods.md`).
    pub const DEFAULT: Self = Self {
        band_start: Hz(170.0),
        band_stop: Hz(290.0),
        seed: Hz(230.0),
        seed_burst: Seconds(0.02),
        seed_ring: Seconds(0.02),
        hold: Seconds(0.3),
        refine: Seconds(0.08),
        drive: Volts(5.0),
        static_capacitance: Farads(210e-12),
        static_conductance: Siemens(0.0),
    };

    /// The seed ring-down's settings, bursting at `seed`.
    fn seed_settings(&self, seed: Hz) -> RingdownSettings {
        // The ring-down fit needs three windows of two cycles. A `seed_ring` of 0 asks for
        // exactly those three (5.5 cycles round up to three windows: the shortest seed, auto's);
        // otherwise at least six cycles and a millisecond, which round up to four windows — the
        // fourth keeps a seed whose first window is lost in the noise (the paper's noise, a
        // resonance far from the burst) from failing.
        let min_ring = if self.seed_ring.0 == 0.0 {
            5.5 / seed.0.max(1.0)
        } else {
            6.0 / seed.0.max(1.0) + 0.001
        };
        RingdownSettings {
            band_start: self.band_start,
            band_stop: self.band_stop,
            seed,
            burst: self.seed_burst,
            ring: Seconds(self.seed_ring.0.max(min_ring)),
            stages: 1,
            window_cycles: 2,
            drive: self.drive,
        }
    }

    /// Validate for a board.
    pub fn validate(&self, scale: &FrontEndScale) -> Result<Hold, SettingsError> {
        let seed = self.seed_settings(self.seed).validate(scale)?;
        if !self.hold.0.is_finite()
            || !self.refine.0.is_finite()
            || !self.static_capacitance.0.is_finite()
            || !self.static_conductance.0.is_finite()
        {
            return Err(SettingsError::NotFinite);
        }
        check_durations(Seconds(0.0), self.hold, self.band_start.0)?;
        // Each hold at least 50 ms (four windows of two cycles at the band's bottom); C0 of a
        // plate and its cable (0–100 nF); |G0| up to 1 mS (a fitted G0 may come out a little
        // negative).
        let refine_ok = self.refine.0 == 0.0
            || (self.refine.0 >= MIN_HOLD_S && self.hold.0 - self.refine.0 >= MIN_HOLD_S);
        let knobs_ok = self.hold.0 >= MIN_HOLD_S
            && refine_ok
            && (0.0..=100e-9).contains(&self.static_capacitance.0)
            && (-1e-3..=1e-3).contains(&self.static_conductance.0);
        if !knobs_ok {
            return Err(SettingsError::KnobOutOfRange);
        }
        let amplitude = amplitude_codes(self.drive, scale)?;
        Ok(Hold {
            s: *self,
            fs: scale.sample_rate.0 as f64,
            amplitude,
            seed,
            phase: Phase::Seed,
            pending: false,
            ftw: 0,
            f_hold: 0.0,
            q_seed: 0.0,
            q_seed_sd: 0.0,
            f_seed: 0.0,
            n_windows: 0,
            segment: 0,
            seeds_tried: 1,
            monitor: Default::default(),
            windows: heapless::Vec::new(),
            clipped: false,
            last: None,
        })
    }
}

impl Default for HoldSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
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

/// Samples the converters' filters need after the drive comes back on (2 ms: > 10 time
/// constants of the 1 kHz two-pole filters).
const ON_SETTLE_S: f64 = 0.002;
/// Shortest hold, s.
const MIN_HOLD_S: f32 = 0.05;
/// Fewest cycles in a window of a single hold (no refine segment).
const MIN_SINGLE_CYCLES: f64 = 4.0;
/// Relative standard uncertainty given to the seed ring-down's `Q` as the first hold's prior
/// (a one-stage ring-down of two to four windows measures the decay to 5–20 %).
const SEED_Q_SD: f64 = 0.25;
/// Tag of the hold plan (the seed's tags count up from 1).
const HOLD_TAG: u16 = 0xC0DE;

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
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Seed,
    Hold,
    Done,
}

/// A hold measurement in progress.
#[derive(Clone, Debug)]
pub struct Hold {
    s: HoldSettings,
    fs: f64,
    amplitude: u16,
    seed: Ringdown,
    phase: Phase,
    pending: bool,
    ftw: u32,
    f_hold: f64,
    q_seed: f64,
    q_seed_sd: f64,
    f_seed: f64,
    n_windows: u16,
    segment: u8,
    seeds_tried: u8,
    monitor: (ChannelSums, ReferenceSums),
    windows: heapless::Vec<HoldWindow, MAX_WINDOWS>,
    clipped: bool,
    last: Option<Result<Estimate, Failure>>,
}

impl Hold {
    /// The next plan, or `None` while a plan is running or when done.
    pub fn next_plan(&mut self) -> Option<PointPlan> {
        match self.phase {
            Phase::Seed => self.seed.next_plan(),
            Phase::Done => None,
            Phase::Hold => {
                if self.pending {
                    return None;
                }
                self.pending = true;
                // Windows of whole cycles, at least two, at most MAX_WINDOWS of them; a single
                // hold (no refine segment, auto's) takes windows of at least four cycles: five or
                // six windows, each fitted window costs the same on the target whatever its
                // length, and the window means lose almost nothing of the slow envelope (the
                // per-reading work of a 134 ms reading stays within 2 % of the core).
                let per_cycle = 1.0 / self.f_hold;
                let hold = self.segment_length() - ON_SETTLE_S;
                let fewest = if self.s.refine.0 > 0.0 {
                    2.0
                } else {
                    MIN_SINGLE_CYCLES
                };
                let cycles = libm::ceil(hold / per_cycle / MAX_WINDOWS as f64).max(fewest);
                let n = libm::floor(hold / (cycles * per_cycle)).clamp(2.0, MAX_WINDOWS as f64);
                self.n_windows = n as u16;
                Some(PointPlan {
                    ftw: self.ftw,
                    amplitude_codes: self.amplitude,
                    settle_samples: (ON_SETTLE_S * self.fs) as u32,
                    cycles: cycles as u32,
                    windows: self.n_windows,
                    tag: HOLD_TAG + self.segment as u16,
                })
            }
        }
    }

    /// Take a finished window.
    pub fn accept(&mut self, raw: &PointRaw, scale: &FrontEndScale) {
        match self.phase {
            Phase::Seed => {
                self.seed.accept(raw, scale);
                if self.seed.is_complete() {
                    self.after_seed(scale);
                }
            }
            Phase::Hold => {
                if raw.plan.tag != HOLD_TAG + self.segment as u16 {
                    return;
                }
                // Each window's current phasor; the drive is steady during a hold, so its monitor
                // sums are added up and solved once at the end (half the work per window).
                let s = &raw.sums;
                self.clipped |= s.current_rail_hits > 0;
                add_sums(&mut self.monitor, &s.monitor, &s.reference);
                match solve(&s.current, &s.reference) {
                    Some(p) => {
                        let ai = scale.amps_per_code as f64;
                        let len = s.reference.n as f64 / self.fs;
                        let end = raw.end_sample as f64 / self.fs;
                        let _ = self.windows.push(HoldWindow {
                            t0: end - len,
                            len,
                            y: p.value * ai,
                            var: p.variance * ai * ai,
                        });
                    }
                    None => self.finish(Err(Failure::BadSettings)),
                }
                if raw.window + 1 >= self.n_windows && self.phase == Phase::Hold {
                    if let Err(f) = self.currents_to_admittances(scale) {
                        self.finish(Err(f));
                        return;
                    }
                    let est = self.estimate_hold();
                    match est {
                        Ok(h) if self.segment == 0 && self.s.refine.0 > 0.0 => {
                            // Move onto this hold's estimate for the rest of the reading.
                            let e = h.estimate;
                            self.segment = 1;
                            self.f_seed = e.resonance.0 as f64;
                            self.q_seed = e.q.map_or(self.q_seed, |q| q as f64);
                            self.q_seed_sd = h.sigma_q.max(1e-3 * self.q_seed);
                            self.ftw = tuning_word(self.f_seed, self.fs);
                            self.f_hold = frequency_hz(self.ftw, self.fs);
                            self.windows.clear();
                            self.monitor = Default::default();
                            self.pending = false;
                        }
                        _ => self.finish(est.map(|h| h.estimate)),
                    }
                }
            }
            Phase::Done => {}
        }
    }

    /// Turn the windows' currents into admittances with the segment's drive phasor.
    fn currents_to_admittances(&mut self, scale: &FrontEndScale) -> Result<(), Failure> {
        let (m, r) = &self.monitor;
        let pv = solve(m, r).ok_or(Failure::BadSettings)?;
        let drive = Drive::from_monitor(&pv, scale).ok_or(Failure::DriveFault)?;
        for x in self.windows.iter_mut() {
            // The segment's drive (its variance that of the whole segment) for every window.
            let y = drive.admittance(x.y, x.var);
            (x.y, x.var) = (y.y, y.var);
        }
        Ok(())
    }

    fn finish(&mut self, r: Result<Estimate, Failure>) {
        if self.last.is_none() {
            self.last = Some(r);
        }
        self.phase = Phase::Done;
        self.pending = false;
    }

    fn after_seed(&mut self, scale: &FrontEndScale) {
        let result = self.seed.estimate();
        if matches!(result, Err(Failure::NoResonance | Failure::LowSnr)) && self.seeds_tried < 3 {
            // Nothing rang: the resonance is far from the seed. Try a quarter band below, then a
            // quarter band above (a burst excites a resonance within about a quarter band).
            self.seeds_tried += 1;
            let quarter = 0.25 * (self.s.band_stop.0 - self.s.band_start.0);
            let f = if self.seeds_tried == 2 {
                self.s.seed.0 - quarter
            } else {
                self.s.seed.0 + quarter
            };
            let next = self
                .s
                .seed_settings(Hz(f.clamp(self.s.band_start.0, self.s.band_stop.0)));
            if let Ok(r) = next.validate(scale) {
                self.seed = r;
                return;
            }
        }
        match result {
            Ok(e) => {
                let q = e.q.unwrap_or(0.0) as f64;
                // A decay shorter than two windows is no seed to hold on.
                if !(q >= 2.0) {
                    self.finish(Err(Failure::LowSnr));
                    return;
                }
                self.f_seed = e.resonance.0 as f64;
                self.q_seed = q;
                self.q_seed_sd = SEED_Q_SD * q;
                self.ftw = tuning_word(self.f_seed, self.fs);
                self.f_hold = frequency_hz(self.ftw, self.fs);
                self.windows.clear();
                self.phase = Phase::Hold;
                self.pending = false;
            }
            Err(f) => self.finish(Err(f)),
        }
    }

    /// True when finished.
    pub fn is_complete(&self) -> bool {
        self.phase == Phase::Done
    }

    /// Length of the current hold segment, s.
    fn segment_length(&self) -> f64 {
        let (hold, refine) = (self.s.hold.0 as f64, self.s.refine.0 as f64);
        match (refine > 0.0, self.segment) {
            (false, _) => hold,
            (true, 0) => refine,
            (true, _) => hold - refine,
        }
    }

    /// The current hold's windows (empty until the hold runs).
    pub fn windows(&self) -> &[HoldWindow] {
        &self.windows
    }

    fn estimate_hold(&self) -> Result<HoldFit, Failure> {
        if self.clipped {
            return Err(Failure::Clipped);
        }
        let y_s = C64::new(
            self.s.static_conductance.0 as f64,
            2.0 * PI * self.f_hold * self.s.static_capacitance.0 as f64,
        );
        let h = fit(
            &self.windows,
            self.f_hold,
            y_s,
            self.f_seed,
            (self.q_seed, self.q_seed_sd),
        )?;
        let (f0, q) = (
            h.estimate.resonance.0 as f64,
            h.estimate.q.unwrap_or(1.0) as f64,
        );
        if libm::fabs(f0 - self.f_seed) > f0 / q {
            return Err(Failure::NotLocked);
        }
        Ok(h)
    }

    /// The reading's estimate.
    pub fn estimate(&self) -> Result<Estimate, Failure> {
        let e = self.last.unwrap_or(Err(Failure::NoResonance))?;
        super::in_band(e, self.s.band_start, self.s.band_stop)
    }
}

/// Noise variance per component common to all windows: the mean of the second half's own
/// residual variances (earlier windows' residuals also hold the transient).
fn noise_variance(w: &[HoldWindow]) -> f64 {
    let tail = &w[w.len() / 2..];
    tail.iter().map(|x| x.var).sum::<f64>() / tail.len().max(1) as f64
}

/// A hold fit: the estimate and the standard uncertainty of its `Q`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HoldFit {
    /// Resonance, its uncertainty and `Q`.
    pub estimate: Estimate,
    /// Standard uncertainty of `Q`.
    pub sigma_q: f64,
}

/// A window as the fit's inner loop uses it: start relative to the first window, length, the
/// admittance without its static part, all `f32`; `gap` when it does not start where the
/// previous one ended.
#[derive(Clone, Copy, Debug, Default)]
struct Win32 {
    a: f32,
    len: f32,
    y: num_complex::Complex32,
    gap: bool,
}

/// The windows in `f32` (less the static admittance `y_s`) and the scale of their admittances.
fn prepare(w: &[HoldWindow], y_s: C64) -> (heapless::Vec<Win32, MAX_WINDOWS>, f32) {
    let mut out = heapless::Vec::new();
    let t0 = w.first().map_or(0.0, |x| x.t0);
    let mut next = 0.0f64;
    let mut big = 0.0f64;
    for (k, x) in w.iter().enumerate() {
        let a = x.t0 - t0;
        let y = x.y - y_s;
        big = big.max(y.norm_sqr());
        let _ = out.push(Win32 {
            a: a as f32,
            len: x.len as f32,
            y: num_complex::Complex32::new(y.re as f32, y.im as f32),
            gap: k == 0 || libm::fabs(a - next) > 1e-6,
        });
        next = a + x.len;
    }
    (out, (libm::sqrt(big) as f32).max(1e-30))
}

/// The model's parameters: resonance, quality factor, motional peak conductance, initial state.
#[derive(Clone, Copy, Debug)]
struct Params {
    f0: f64,
    q: f64,
    g: f64,
    z: C64,
}

/// χ² of `p` against the windows (`y` already without the static part) and, when `jac` is set,
/// the normal equations `JᵀWJ`, `JᵀW r` over (f0, Q, g, Re z, Im z).
///
/// Cost: two complex `f32` exponentials per call (the windows are gap-free, so `exp(λ t)` is
/// carried from one to the next), the rest complex `f32` arithmetic; sums in `f64`. On the Cortex-M4F's single-precision FPU this is a few
/// hundred instructions per window (`docs/firmware.md` has the measured totals). `f32` carries
/// the model values with a relative error of about 1e-7 of `g`, far below the noise of any
/// window (1e-3 of `g` at the bench noise and the longest hold).
fn evaluate(
    w: &[Win32],
    gs: f32,
    f_h: f64,
    p: &Params,
    wt: f64,
    jac: bool,
) -> (f64, [[f64; 5]; 5], [f64; 5]) {
    use num_complex::Complex32 as C32;
    let one = C32::new(1.0, 0.0);
    let (f0, q) = (p.f0, p.q);
    // Steady state h = 1 / (1 + j Q u) and its derivatives (the one model, `super::model`).
    let m = Motional::at(f0, q, f_h);
    let h = C32::new(m.h.re as f32, m.h.im as f32);
    let (dh_df0, dh_dq) = m.derivatives(f0, q, f_h);
    // Transient exponent λ = −π f0/Q + j 2π (f_d − f_h), f_d = f0 sqrt(1 − 1/(4Q²)).
    let root = libm::sqrt((1.0 - 0.25 / (q * q)).max(1e-12));
    let lam64 = C64::new(-PI * f0 / q, 2.0 * PI * (f0 * root - f_h));
    let dlam_df0 = C64::new(-PI / q, 2.0 * PI * root);
    let dlam_dq = C64::new(PI * f0 / (q * q), 2.0 * PI * f0 * 0.25 / (q * q * q * root));
    let lam = C32::new(lam64.re as f32, lam64.im as f32);
    let gh = h * p.g as f32;
    let z = C32::new(p.z.re as f32, p.z.im as f32);
    let c = |x: C64| C32::new(x.re as f32, x.im as f32);
    let (g_dh_df0, g_dh_dq) = (c(dh_df0 * p.g), c(dh_dq * p.g));
    let (dl_f0, dl_q) = (c(dlam_df0), c(dlam_dq));
    let mut jtj = [[0.0f64; 5]; 5];
    let mut jtr = [0.0f64; 5];
    // The normal equations' sums (at most 16 products each) in f32, each column scaled to about
    // unit size first; f32's relative precision (1e-7) is far finer than what the steps and the
    // covariance need.
    let scale: [f32; 5] = [
        1.0 / (gs * (q / f0) as f32),
        1.0 / (gs / q as f32),
        1.0,
        1.0,
        1.0,
    ];
    let mut jtj32 = [[0.0f32; 5]; 5];
    let mut jtr32 = [0.0f32; 5];
    let inv_lam = one / lam;
    // exp(λ a) carried from window to window (they are gap-free), exp(λ len) cached per window
    // length (they differ by at most a sample): no transcendental per window.
    let mut ea = one;
    // Whole-cycle windows alternate between two lengths a sample apart: two cache entries.
    let mut cache: [(f32, C32); 2] = [(-1.0, one); 2];
    let mut chi2 = 0.0f32;
    for x in w {
        let (a, len) = (x.a, x.len);
        if x.gap {
            ea = cexp(lam * a);
        }
        let decay = if cache[0].0 == len {
            cache[0].1
        } else if cache[1].0 == len {
            cache[1].1
        } else {
            cache[1] = cache[0];
            cache[0] = (len, cexp(lam * len));
            cache[0].1
        };
        // exp(λ a), exp(λ (a + len)); their mean over the window and its λ-derivative.
        let eb = ea * decay;
        let e = (eb - ea) * inv_lam / len;
        let m = gh * (one - e) + z * e;
        let r = x.y - m;
        chi2 += r.norm_sqr();
        if jac {
            let de = ((eb * (a + len) - ea * a) / len - e) * inv_lam;
            let k = (z - gh) * de;
            let cols = [
                g_dh_df0 * (one - e) + k * dl_f0,
                g_dh_dq * (one - e) + k * dl_q,
                h * (one - e),
                e,
                C32::new(-e.im, e.re),
            ];
            let cols: [C32; 5] = core::array::from_fn(|i| cols[i] * scale[i]);
            for i in 0..5 {
                let ci = cols[i];
                jtr32[i] += ci.re * r.re + ci.im * r.im;
                for j in 0..=i {
                    jtj32[i][j] += ci.re * cols[j].re + ci.im * cols[j].im;
                }
            }
        }
        ea = eb;
    }
    for (i, v) in jtr.iter_mut().enumerate() {
        *v = wt * jtr32[i] as f64 / scale[i] as f64;
    }
    for (i, row) in jtj.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let x = if j <= i { jtj32[i][j] } else { jtj32[j][i] } as f64;
            *v = wt * x / (scale[i] as f64 * scale[j] as f64);
        }
    }
    (chi2 as f64 * wt, jtj, jtr)
}

/// The least-squares fit of the switched-on response (module documentation) to `windows`, driven
/// at `f_h` with static admittance `y_s`, starting from `f_start`, with a prior `Q = q_prior.0 ±
/// q_prior.1` (a hold at one frequency measures the phase well and `Q` poorly; the prior — the
/// seed's `Q` — keeps a noisy hold from trading one for the other).
pub fn fit(
    windows: &[HoldWindow],
    f_h: f64,
    y_s: C64,
    f_start: f64,
    q_prior: (f64, f64),
) -> Result<HoldFit, Failure> {
    let (q_start, q_sd) = q_prior;
    if !(q_start > 0.0) || !(q_sd > 0.0) || !q_sd.is_finite() {
        return Err(Failure::NoResonance);
    }
    let q_w = 1.0 / (q_sd * q_sd);
    if windows.len() < 4 {
        return Err(Failure::NoResonance);
    }
    let var = noise_variance(windows);
    let (w, gs) = prepare(windows, y_s);
    if !(var > 0.0) || !var.is_finite() || !f_start.is_finite() || !(f_start > 0.0) {
        return Err(Failure::NoResonance);
    }
    let wt = 1.0 / var;
    let prior = |q: f64| (q - q_start) * (q - q_start) * q_w;
    // Start: the seed's f0 and Q, the linear parameters from one Gauss–Newton step on them
    // alone (the model is linear in g and z).
    let mut p = Params {
        f0: f_start,
        q: q_start.clamp(2.0, 200.0),
        g: 0.0,
        z: C64::new(0.0, 0.0),
    };
    {
        let (_, jtj, jtr) = evaluate(&w, gs, f_h, &p, wt, true);
        let m3: [[f64; 3]; 3] =
            core::array::from_fn(|i| core::array::from_fn(|j| jtj[i + 2][j + 2]));
        let r3: [f64; 3] = core::array::from_fn(|i| jtr[i + 2]);
        let step = damped_solve(&m3, &r3, 0.0).ok_or(Failure::NoResonance)?;
        p.g = step[0];
        p.z = C64::new(step[1], step[2]);
    }
    let mut c = evaluate(&w, gs, f_h, &p, wt, false).0 + prior(p.q);
    let mut lambda = 1e-3;
    // The normal equations at the current point, with the prior on Q; recomputed only when a
    // step is taken (a rejected step costs one χ² evaluation).
    let normal = |p: &Params| {
        let (_, mut jtj, mut jtr) = evaluate(&w, gs, f_h, p, wt, true);
        jtj[1][1] += q_w;
        jtr[1] += (q_start - p.q) * q_w;
        (jtj, jtr)
    };
    let (mut jtj, mut jtr) = normal(&p);
    for _ in 0..30 {
        let Some(step) = damped_solve(&jtj, &jtr, lambda) else {
            lambda *= 10.0;
            if lambda > 1e6 {
                break;
            }
            continue;
        };
        let t = Params {
            f0: p.f0 + step[0],
            q: p.q + step[1],
            g: p.g + step[2],
            z: p.z + C64::new(step[3], step[4]),
        };
        let tc = if t.f0 > 0.0 && t.q > 0.5 {
            evaluate(&w, gs, f_h, &t, wt, false).0 + prior(t.q)
        } else {
            f64::INFINITY
        };
        if tc < c {
            // Converged when χ² no longer falls by a hundredth of one unit: the parameters then move
            // by less than a tenth of their standard uncertainty.
            let done = c - tc <= 1e-2;
            (p, c) = (t, tc);
            lambda = (lambda * 0.3).max(1e-12);
            (jtj, jtr) = normal(&p);
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e6 {
                break;
            }
        }
    }
    let cov = spd_inverse(&jtj).ok_or(Failure::NoResonance)?;
    let dof = (2 * w.len() + 1).saturating_sub(5).max(1) as f64;
    let red = c / dof;
    let scale = super::gross_scale(red);
    let sigma = libm::sqrt((cov[0][0] * scale).max(0.0));
    let sigma_q = libm::sqrt((cov[1][1] * scale).max(0.0));
    let (f0, q) = (p.f0, p.q);
    if !(p.g > 0.0) || !f0.is_finite() || !q.is_finite() || !sigma.is_finite() {
        return Err(Failure::NoResonance);
    }
    super::resolved(sigma, f0 / q)?;
    Ok(HoldFit {
        estimate: Estimate {
            resonance: Hz(f0 as f32),
            sigma: Hz(sigma as f32),
            q: Some(q as f32),
            points_used: w.len() as u16,
        },
        sigma_q,
    })
}

/// `exp(z)` by the `libm` crate's `expf`, `cosf`, `sinf`: the same bits on the host and the
/// target, whatever `num-traits` features another crate of the build enables (with `std` its
/// `Float::exp` is the platform's, which differs in the last bits and made the host's readings
/// depend on which binary took them).
fn cexp(z: num_complex::Complex32) -> num_complex::Complex32 {
    let m = libm::expf(z.re);
    num_complex::Complex32::new(m * libm::cosf(z.im), m * libm::sinf(z.im))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Windows of the closed-form switched-on BVD response (f64 reference, computed here
    /// independently of [`basis`] by integrating the mean with the trapezoid rule).
    pub(super) fn synthetic(
        f0: f64,
        q: f64,
        g: f64,
        f_h: f64,
        z: C64,
        y_s: C64,
        n: usize,
    ) -> [HoldWindow; 24] {
        let mut out = [HoldWindow::default(); 24];
        let len = 4.0 / f_h;
        let s = PI * f0 / q;
        let fd = libm::sqrt(f0 * f0 - (s / (2.0 * PI)) * (s / (2.0 * PI)));
        let u = f_h / f0 - f0 / f_h;
        let ym = C64::new(g, 0.0) / C64::new(1.0, q * u);
        for (k, o) in out.iter_mut().enumerate().take(n) {
            let a = k as f64 * len;
            let steps = 2000;
            let mut acc = C64::new(0.0, 0.0);
            for i in 0..=steps {
                let t = a + len * i as f64 / steps as f64;
                let e = C64::new(-s * t, 2.0 * PI * (fd - f_h) * t).exp();
                let v = ym + (z - ym) * e;
                let wgt = if i == 0 || i == steps { 0.5 } else { 1.0 };
                acc += v * wgt;
            }
            *o = HoldWindow {
                t0: 0.01 + a,
                len,
                y: y_s + acc / steps as f64,
                var: 1e-24,
            };
        }
        out
    }

    #[test]
    fn recovers_resonance_off_and_on_tune() {
        let y_s = C64::new(1e-9, 2.0 * PI * 241.0 * 210e-12);
        for (f_h, z) in [
            (241.3, C64::new(0.0, 0.0)),
            (239.0, C64::new(2e-8, -3e-8)),
            (244.5, C64::new(-1e-8, 1e-8)),
        ] {
            let (f0, q, g) = (241.3, 10.4, 1.5e-7);
            let w = synthetic(f0, q, g, f_h, z, y_s, 24);
            let e = fit(&w, f_h, y_s, f_h, (8.0, 4.0)).unwrap().estimate;
            assert!(
                (e.resonance.0 as f64 - f0).abs() < 2e-3,
                "{f_h}: {}",
                e.resonance.0
            );
            assert!((e.q.unwrap() as f64 / q - 1.0).abs() < 1e-3);
        }
    }

    #[test]
    fn garbage_windows_give_a_failure_not_a_panic() {
        let mut w = [HoldWindow::default(); 8];
        assert!(fit(&w, 230.0, C64::new(0.0, 0.0), 230.0, (10.0, 1.0)).is_err());
        for (k, x) in w.iter_mut().enumerate() {
            x.t0 = k as f64 * 0.01;
            x.len = 0.01;
            x.y = C64::new(f64::NAN, 1.0);
            x.var = 1e-20;
        }
        assert!(fit(&w, 230.0, C64::new(0.0, 0.0), 230.0, (10.0, 1.0)).is_err());
        assert!(fit(&w[..2], 230.0, C64::new(0.0, 0.0), f64::NAN, (10.0, 1.0)).is_err());
        assert!(fit(&w, 230.0, C64::new(0.0, 0.0), 230.0, (10.0, 0.0)).is_err());
    }
}

#[cfg(test)]
mod gradcheck {
    use super::*;

    /// The analytic gradient of χ² against central differences (f64 reference on the same
    /// windows).
    #[test]
    fn gradient_matches_finite_differences() {
        let y_s = C64::new(0.0, 0.0);
        for f_h in [241.3, 238.0] {
            let w = super::tests::synthetic(241.3, 10.4, 1.5e-7, f_h, C64::new(1e-8, 0.0), y_s, 24);
            let p = Params {
                f0: 241.0,
                q: 8.0,
                g: 1.4e-7,
                z: C64::new(0.0, 0.0),
            };
            let (w, gs) = prepare(&w, y_s);
            let (_, _, jtr) = evaluate(&w, gs, f_h, &p, 1.0, true);
            for (i, g) in jtr.iter().take(2).enumerate() {
                let h = 1e-2;
                let (mut a, mut b) = (p, p);
                if i == 0 {
                    a.f0 += h;
                    b.f0 -= h;
                } else {
                    a.q += h;
                    b.q -= h;
                }
                let num = (evaluate(&w, gs, f_h, &a, 1.0, false).0
                    - evaluate(&w, gs, f_h, &b, 1.0, false).0)
                    / (2.0 * h);
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
