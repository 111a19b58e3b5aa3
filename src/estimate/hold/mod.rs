//! The hold method: its settings and its state machine (seed ring-down, hold segments, their fit). May import the resonator, ringdown, estimate's shared rules, engine and the leaves.
//!
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
//!    towards the steady state `Y_m`, in the drive's rotating frame — plus the transient's
//!    **mirror image** that a window of whole cycles lets through (its counter-rotating part,
//!    [`super::resonator::mirror`]; about `|λ|/(4·2πf_h)` of the transient, 2 % at `Q` 10,
//!    which, left out of the model, biases a detuned segment's `f0` by about 4 % of the
//!    detuning).
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
//!
//! The model and its fit are [`super::resonator`]'s; here are the settings ([`HoldSettings`])
//! and the plans, windows and segments of one reading ([`Hold`]).

mod settings;

pub use settings::HoldSettings;

use super::resonator::{
    add_sums, current_window, first_cycles, fit, fit_searched, fit_two, mirror, to_admittance,
    Carry, HoldFit, HoldWindow, Segment, SwitchOn, MAX_WINDOWS,
};
use super::ringdown::Ringdown;
use super::Estimate;
use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::dsp::lockin::{solve_value, ChannelSums, ReferenceSums};
use crate::engine::sweep::Drive;
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::status::Failure;
use crate::units::bounded;
use crate::units::Hz;
use core::f64::consts::PI;
use num_complex::Complex64 as C64;

/// Samples the converters' filters need after the drive comes back on (2 ms: > 10 time
/// constants of the 1 kHz two-pole filters).
const ON_SETTLE_S: f64 = 0.002;
/// Shortest hold, s.
const MIN_HOLD_S: f32 = 0.05;
/// Most windows of the seed ring-down (it uses three or four of two cycles; eight cover a
/// `seed_ring` of 55 ms at the band's top).
const SEED_WINDOWS: usize = 8;
/// The `Q` a hold with no seed starts from, and its prior's relative standard uncertainty (weak:
/// tissue gives 5–20).
const NOMINAL_Q: f64 = 10.0;
const NOMINAL_Q_SD: f64 = 1.0;
/// Fewest cycles in a window of a single hold (no refine segment).
const MIN_SINGLE_CYCLES: f64 = 4.0;
/// Relative standard uncertainty given to the seed ring-down's `Q` as the first hold's prior
/// (a one-stage ring-down of two to four windows measures the decay to 5–20 %).
const SEED_Q_SD: f64 = 0.25;
/// Tag of the hold plan (the seed's tags count up from 1); the second segment's is one more, a
/// first segment's continuation ([`FREE_FIRST_WINDOWS`]) two more.
const HOLD_TAG: u16 = 0xC0DE;
const MORE_TAG: u16 = HOLD_TAG + 2;
/// Standard uncertainty of the start state from rest ([`SwitchOn`]), relative to the windows'
/// admittance scale, with the resonator quiet: what the model leaves out of the response from
/// rest (the static branch's own switch-on transient, the DAC's codes), above the residue
/// measured on the simulated probe's exact chain across moduli, loss tangents and the drive's
/// phase at switch-on (test `the_start_from_rest_is_the_resonators_response`).
const REST_WIDTH: f32 = 0.002;
/// `Q` of the longest ring a drive can leave behind in the band: the free probe's (about 40).
const RING_Q: f32 = 40.0;
/// One-cycle windows a seedless first segment takes when its start from rest is not known (the
/// drive was on shortly before — a power-on self-test, a reading just ended — and what it may
/// have left ringing outweighs [`REST_WIDTH`]): with the start state free, two windows do not
/// place the second segment at the band's edges. The first plan's own windows are continued by
/// a plan at the same drive ([`MORE_TAG`]; the drive goes on phase-continuously, the window its
/// switch cuts is dropped).
const FREE_FIRST_WINDOWS: u16 = 4;
/// Ring times after which what a drive left is within `√3` [`REST_WIDTH`] (the start from rest's
/// width within twice its own): `ln(1/(√3 · 0.002))`.
const UNKNOWN_RING: f32 = 5.67;

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
    /// The sample period, s (`1/fs`, formed once).
    dt: f64,
    amplitude: u16,
    /// The seed ring-down (`None`: no seed, see [`HoldSettings::seed_burst`]).
    seed: Option<Ringdown<SEED_WINDOWS>>,
    phase: Phase,
    pending: bool,
    ftw: u32,
    f_hold: f64,
    q_seed: f64,
    q_seed_sd: f64,
    f_seed: f64,
    /// Windows of the first segment kept for the joint fit (the second's follow them).
    first_len: u8,
    /// Most windows the first segment may keep: its own and those its open plan closes while
    /// the second's plan is on its way through the DAC's pipeline ([`PointPlan::open`]).
    first_cap: u8,
    /// The first segment's drive frequency, and its fit's `Q`.
    f_first: f64,
    q_first: f64,
    /// The first segment's fitted `g` and `z` ([`HoldFit::linear`]).
    linear_first: (f64, C64),
    /// The first segment's drive phasor, V, and the variance of each of its components, V².
    v_first: C64,
    var_v_first: f64,
    /// The latest segment's drive phasor, V.
    v_hold: C64,
    /// How the state passes into the second segment (its switch time known from its first
    /// window; `rho` once its drive is known).
    carry: Carry,
    /// When the first segment's plan took effect (the drive's switch-on), s, and how long the
    /// drive had been off before it, s (infinite: not since the engine started).
    t_on: f64,
    quiet: f32,
    /// The first segment's fit took its start state from rest: the joint fit may too.
    at_rest: bool,
    /// Windows of the first segment's continuation still to plan (0: none, or planned), and
    /// whether it has been planned.
    more: u16,
    continued: bool,
    /// The hold's latest plan.
    plan: PointPlan,
    n_windows: u16,
    segment: u8,
    seeds_tried: u8,
    /// Seeds that did not ring and heard a steady tone instead of noise.
    seed_tones: u8,
    monitor: (ChannelSums, ReferenceSums),
    windows: heapless::Vec<HoldWindow, MAX_WINDOWS>,
    clipped: bool,
    last: Option<Result<Estimate, Failure>>,
}

impl Hold {
    /// The next plan, or `None` while a plan is running or when done.
    pub fn next_plan(&mut self) -> Option<PointPlan> {
        match self.phase {
            Phase::Seed => self.seed.as_mut().and_then(|s| s.next_plan()),
            Phase::Done => None,
            Phase::Hold => {
                if self.pending {
                    return None;
                }
                self.pending = true;
                if self.more > 0 {
                    // The first segment's continuation: its plan, no settle.
                    self.continued = true;
                    return Some(PointPlan {
                        settle_samples: 0,
                        windows: core::mem::take(&mut self.more),
                        tag: MORE_TAG,
                        ..self.plan
                    });
                }
                // Windows of whole cycles, at least two, at most MAX_WINDOWS of them in all; a
                // first segment (refine) takes at most half of them, the second the rest. A
                // single hold (no refine segment) takes windows of at least four cycles: five or
                // six windows, each fitted window costs the same on the target whatever its
                // length, and the window means lose almost nothing of the slow envelope.
                // The drive stays on from the first segment into the second (the frequency
                // moves phase-continuously): the filters need no settle, and the resonator's
                // state is carried across the switch by the joint fit.
                let settle = if self.segment == 0 { ON_SETTLE_S } else { 0.0 };
                let per_cycle = 1.0 / self.f_hold;
                let hold = self.segment_length() - settle;
                // A first segment (it only places the second, and it is short) takes windows as
                // short as the engine passes on (half a batch: one cycle in any band), the
                // second two cycles, a single hold four.
                let fewest = match (self.s.refine.0 > 0.0, self.segment) {
                    (true, 0) => first_cycles(self.f_hold, self.fs),
                    (true, _) => 2.0,
                    (false, _) => MIN_SINGLE_CYCLES,
                };
                let room = match (self.s.refine.0 > 0.0, self.segment) {
                    (true, 0) => MAX_WINDOWS / 2,
                    _ => MAX_WINDOWS - self.first_cap as usize,
                }
                .max(2) as f64;
                let cycles = libm::ceil(hold / per_cycle / room).max(fewest);
                let n = bounded(libm::floor(hold / (cycles * per_cycle)), 2.0, room);
                self.n_windows = n as u16;
                // A first segment stays open: its windows go on while the second's plan, chosen
                // from them, passes the DAC's pipeline (at most the pipeline and the batch its
                // last window closed in), and the joint fit takes them. Room is kept for as many
                // as fit whole in that wait.
                let open = self.s.refine.0 > 0.0 && self.segment == 0;
                if open {
                    let window = cycles * per_cycle * self.fs;
                    let wait = (crate::engine::PIPELINE_BATCHES + 1) * crate::engine::BATCH;
                    let extra = libm::floor(wait as f64 / window) as u8;
                    self.first_cap = (self.n_windows as u8).saturating_add(extra);
                }
                // A seedless first segment from rest comes on aligned (`PointPlan::aligned`): at
                // a zero crossing, whatever phase earlier plans left, so that no step in the
                // DAC's output rings another mode into its windows.
                let aligned = self.seed.is_none() && self.segment == 0;
                self.plan = PointPlan {
                    ftw: self.ftw,
                    amplitude_codes: self.amplitude,
                    settle_samples: (settle * self.fs) as u32,
                    cycles: cycles as u32,
                    windows: self.n_windows,
                    open,
                    aligned,
                    tag: HOLD_TAG + self.segment as u16,
                };
                Some(self.plan)
            }
        }
    }

    /// Take a finished window.
    pub fn accept(&mut self, raw: &PointRaw, scale: &FrontEndScale) {
        match self.phase {
            Phase::Seed => {
                let Some(seed) = self.seed.as_mut() else {
                    return;
                };
                seed.accept(raw, scale);
                if seed.is_complete() {
                    self.after_seed(scale);
                }
            }
            Phase::Hold => {
                let first_tag = matches!(raw.plan.tag, HOLD_TAG | MORE_TAG);
                if first_tag && self.segment == 1 {
                    self.accept_late_first(raw, scale);
                    return;
                }
                if raw.plan.tag != HOLD_TAG + self.segment as u16
                    && !(first_tag && self.segment == 0)
                {
                    return;
                }
                // Each window's current phasor; the drive is steady during a hold, so its monitor
                // sums are added up and solved once at the end (half the work per window).
                let s = &raw.sums;
                if raw.window == 0 && raw.plan.tag != MORE_TAG {
                    // The frequency switch: when this segment's plan took effect, half a
                    // sample after the windows' time base (a window's samples stand for the
                    // sample periods centred on them — the mean of `k` samples of `e^{λt}` is
                    // the mean over that interval to `(λ/fs)²` — and its drive's phase 0 lies
                    // within the half sample before its first; the switch's first new code
                    // holds from its sample on).
                    let t = (raw.end_sample.saturating_sub(raw.since_load as u64) as f64 + 0.5)
                        / self.fs;
                    if self.segment == 0 {
                        // The first segment's: the drive's switch-on.
                        self.t_on = t;
                        self.quiet = match raw.quiet_before {
                            u32::MAX => f32::INFINITY,
                            n => (n as f64 / self.fs) as f32,
                        };
                        // Not known at rest: the first segment goes on.
                        if self.seed.is_none() && self.quiet < self.ring_tau() * UNKNOWN_RING {
                            self.more = FREE_FIRST_WINDOWS.saturating_sub(self.n_windows);
                            // Its windows and as many late ones as the first plan's.
                            let late = self.first_cap.saturating_sub(self.n_windows as u8);
                            self.first_cap = self
                                .first_cap
                                .saturating_add(self.more as u8)
                                .saturating_add(late);
                        }
                    } else {
                        self.carry.t_switch = t;
                    }
                }
                self.clipped |= s.current_rail_hits > 0;
                add_sums(&mut self.monitor, &s.monitor, &s.reference);
                match current_window(raw, scale, self.dt) {
                    Some(w) => {
                        let _ = self.windows.push(w);
                    }
                    None => self.finish(Err(Failure::BadSettings)),
                }
                // The plan's last window (a first segment's continuation: its own last).
                let last = match raw.plan.tag {
                    MORE_TAG => raw.window + 1 >= FREE_FIRST_WINDOWS - self.n_windows,
                    HOLD_TAG if self.continued => false,
                    _ => raw.window + 1 >= self.n_windows,
                };
                if last && self.more > 0 && raw.plan.tag == HOLD_TAG {
                    // The continuation's turn ([`Self::next_plan`]).
                    self.pending = false;
                    return;
                }
                if last && self.phase == Phase::Hold {
                    if let Err(f) = self.currents_to_admittances(scale) {
                        self.finish(Err(f));
                        return;
                    }
                    let est = self.estimate_hold();
                    match est {
                        Ok(h) if self.segment == 0 && self.s.refine.0 > 0.0 => {
                            // Move onto this hold's estimate for the rest of the reading; its
                            // windows stay for the joint fit (the prior on Q stays the seed's:
                            // the first segment's own Q is in its windows).
                            let e = h.estimate;
                            self.segment = 1;
                            self.first_len = self.windows.len() as u8;
                            self.f_first = self.f_hold;
                            self.q_first = e.q.map_or(self.q_seed, |q| q as f64);
                            self.linear_first = h.linear;
                            self.at_rest = h.at_rest;
                            self.f_seed = e.resonance.0 as f64;
                            self.ftw = tuning_word(self.f_seed, self.fs);
                            self.f_hold = frequency_hz(self.ftw, self.fs);
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

    /// A window of the first segment's open plan that closed after the second segment was
    /// planned, before the second's plan took effect: more of the first segment's drive, kept
    /// for the joint fit while none of the second's has come and there is room
    /// ([`Self::first_cap`]); its admittance with the first segment's drive phasor.
    fn accept_late_first(&mut self, raw: &PointRaw, scale: &FrontEndScale) {
        if self.windows.len() != self.first_len as usize || self.first_len >= self.first_cap {
            return;
        }
        self.clipped |= raw.sums.current_rail_hits > 0;
        let Some(mut w) = current_window(raw, scale, self.dt) else {
            return;
        };
        to_admittance(
            core::slice::from_mut(&mut w),
            self.v_first,
            self.var_v_first,
        );
        if self.windows.push(w).is_ok() {
            self.first_len += 1;
        }
    }

    /// Turn the windows' currents into admittances with the segment's drive phasor.
    fn currents_to_admittances(&mut self, scale: &FrontEndScale) -> Result<(), Failure> {
        let (m, r) = &self.monitor;
        let (value, variance) = solve_value(m, r).ok_or(Failure::BadSettings)?;
        let drive = Drive::from_value(value, variance, scale).ok_or(Failure::DriveFault)?;
        self.v_hold = drive.v;
        if self.segment == 0 {
            self.v_first = drive.v;
            self.var_v_first = drive.var_v;
        } else {
            // The monitor's ratio: the PZT voltage's own change (its source, the reconstruction
            // filter) and the anti-alias filter's, which the current channel shares (measured:
            // with it alone, or the voltage's share alone, the fast holds scatter 5–15 % more).
            self.carry.rho = self.v_first / drive.v;
        }
        // The segment's drive (its variance that of the whole segment) for every window: `Y =
        // I / V` and `var = (var_I + |Y|² var_V) / |V|²` ([`Drive::admittance`]) with `1/V` and
        // `1/|V|²` formed once, each window's in f32 (emulated f64 is dear on the Cortex-M4F;
        // f32's 1e-7 is far below any window's noise, 1e-3 of |Y| and more).
        let first = self.first_len as usize;
        to_admittance(&mut self.windows[first..], drive.v, drive.var_v);
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
        let Some(seed) = self.seed.as_ref() else {
            return;
        };
        let result = seed.estimate();
        if result == Err(Failure::NoResonance) {
            self.seed_tones += u8::from(seed.heard_a_tone());
        }
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
            let next =
                self.s
                    .seed_settings(Hz(bounded(f, self.s.band_start.0, self.s.band_stop.0)));
            if let Ok(r) = next.validate(scale) {
                self.seed = Some(r);
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
            // No seed rang, and every one heard a steady tone where noise was due: hum, not an
            // absent resonance.
            Err(Failure::NoResonance) if self.seed_tones >= self.seeds_tried => {
                self.finish(Err(Failure::Interference))
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

    /// The hold's windows (empty until the hold runs; the first segment's, then the second's).
    pub fn windows(&self) -> &[HoldWindow] {
        &self.windows
    }

    /// The static admittance at `f_h`, from the air reference.
    fn static_admittance(&self, f_h: f64) -> C64 {
        C64::new(
            self.s.static_conductance.0 as f64,
            2.0 * PI * f_h * self.s.static_capacitance.0 as f64,
        )
    }

    /// The longest ring in the band, s: [`RING_Q`] at its bottom.
    fn ring_tau(&self) -> f32 {
        RING_Q / (core::f32::consts::PI * self.s.band_start.0.max(1.0))
    }

    /// The switch-on before a seedless first segment: the resonator at rest, up to what the
    /// drive's history may have left ringing — a drive off for `quiet` seconds leaves at most
    /// `e^{−quiet/τ}` of a steady state at most as large as this one (the methods drive at
    /// their default 5 V), `τ` the longest ring in the band ([`Self::ring_tau`]).
    fn switch_on(&self) -> Option<SwitchOn> {
        if self.seed.is_some() {
            return None;
        }
        let left = libm::expf(-self.quiet / self.ring_tau());
        Some(SwitchOn {
            t_on: self.t_on,
            filters: self.carry.filters,
            width: crate::dsp::trig::sqrtf(REST_WIDTH * REST_WIDTH + left * left),
        })
    }

    fn estimate_hold(&self) -> Result<HoldFit, Failure> {
        if self.clipped {
            return Err(Failure::Clipped);
        }
        let rest = self.switch_on();
        let prior = (self.q_seed, self.q_seed_sd);
        let (first, second) = self.windows.split_at(self.first_len as usize);
        let this = Segment {
            windows: second,
            f_h: self.f_hold,
            y_s: self.static_admittance(self.f_hold),
            mirror: mirror(self.v_hold),
        };
        let h = if !first.is_empty() {
            let first = Segment {
                windows: first,
                f_h: self.f_first,
                y_s: self.static_admittance(self.f_first),
                mirror: mirror(self.v_first),
            };
            let rest = rest.as_ref().filter(|_| self.at_rest);
            let h = fit_two(
                first,
                this,
                &self.carry,
                (self.f_seed, self.q_first),
                Some(self.linear_first),
                prior,
                rest,
            )?;
            // The second segment's windows contradict the start from rest that placed it: the
            // resonator is not the model's alone (a second mode answering the switch, a knock);
            // the placement and the reading are not to be trusted. Not locked: auto goes on to
            // its next method.
            if rest.is_some() && !h.at_rest {
                return Err(Failure::NotLocked);
            }
            h
        } else if self.seed.is_none() {
            let band = (self.s.band_start.0 as f64, self.s.band_stop.0 as f64);
            fit_searched(this, band, prior, rest.as_ref())?
        } else {
            fit(this, self.f_seed, prior)?
        };
        let (f0, q) = (
            h.estimate.resonance.0 as f64,
            h.estimate.q.unwrap_or(1.0) as f64,
        );
        // A resonance that moved more than a linewidth from where the drive was placed is not
        // the one held on (the search of a seedless first segment places nothing).
        let searched = self.seed.is_none() && self.segment == 0;
        if !searched && libm::fabs(f0 - self.f_seed) > f0 / q {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::resonator::FIRST_WINDOWS;

    /// The fast hold run to its end on the simulated probe in `scene` (noise seed `seed`).
    #[cfg(feature = "sim")]
    fn run_fast(scene: hal_sim::Scene, seed: u64) -> Hold {
        run_fast_after(scene, seed, None, 0)
    }
    /// The fast hold with the drive coming on at `phase` (the engine's accumulator; the first
    /// plan not [aligned](PointPlan::aligned), so that the drive's phase at switch-on is the
    /// test's).
    #[cfg(feature = "sim")]
    fn run_fast_at(scene: hal_sim::Scene, seed: u64, phase: u32) -> Hold {
        run_fast_after(scene, seed, Some(phase), 0)
    }
    /// [`run_fast`] (`phase` None) or [`run_fast_at`] after `before` fast holds on the same
    /// probe and engine, one after the other (the drive off for a batch or two between them).
    #[cfg(feature = "sim")]
    fn run_fast_after(scene: hal_sim::Scene, seed: u64, phase: Option<u32>, before: usize) -> Hold {
        use crate::reading::driver::{block_on, run_plans, Plans, SyncSource};
        struct P(Hold, FrontEndScale, bool);
        impl Plans for P {
            fn next_plan(&mut self) -> Option<PointPlan> {
                let aligned = self.2;
                self.0.next_plan().map(|p| PointPlan {
                    aligned: p.aligned && aligned,
                    ..p
                })
            }
            fn accept(&mut self, raw: &PointRaw) -> Option<crate::engine::sweep::SweepPoint> {
                self.0.accept(raw, &self.1);
                None
            }
            fn is_complete(&self) -> bool {
                self.0.is_complete()
            }
        }
        let mut board = crate::board::sim::SimBoard::new(hal_sim::SimProbe::new(scene, seed));
        let scale = crate::hal::SampleStream::scale(&board);
        let mut engine = crate::engine::SampleEngine::new();
        engine.set_phase(phase.unwrap_or(0));
        let mut src = SyncSource::new(&mut board, &mut engine);
        let mut run = || {
            let fast = HoldSettings::FAST.validate(&scale).unwrap();
            let mut m = P(fast, scale, phase.is_none());
            assert!(block_on(run_plans(&mut src, &mut m, |_, _| {})).is_ok());
            m.0
        };
        for _ in 0..before {
            run();
        }
        run()
    }

    /// The fast hold on the simulated probe (500 kPa, bench noise): its first segment's open
    /// plan keeps the windows that close while the second's plan passes the DAC's pipeline —
    /// gap-free after the segment's own two, all before the switch, kept for the joint fit —
    /// and the second segment keeps the room it planned.
    #[cfg(feature = "sim")]
    #[test]
    fn the_first_segment_keeps_its_windows_while_the_second_is_on_its_way() {
        let scene = hal_sim::Scene::on_modulus_kpa(500.0).with_noise(hal_sim::NoiseScene::Bench);
        let h = &run_fast(scene, 3);
        assert!(h.estimate().is_ok(), "{:?}", h.estimate());
        let first = &h.windows()[..h.first_len as usize];
        assert!(first.len() > FIRST_WINDOWS, "{} windows", first.len());
        for w in first.windows(2) {
            assert!((w[1].t0 - (w[0].t0 + w[0].len)).abs() < 1.5 / h.fs, "{w:?}");
        }
        let last = first[first.len() - 1];
        assert!(last.t0 + last.len <= h.carry.t_switch);
        assert_eq!(h.windows().len() - first.len(), h.n_windows as usize);
    }

    /// The quiet scenes the model is held to on `hal_sim`'s exact chain (modulus kPa, loss
    /// tangent): across the band, lossless and lossy.
    #[cfg(feature = "sim")]
    const QUIET_SCENES: [(f64, f64); 8] = [
        (200.0, 0.0),
        (500.0, 0.0),
        (1000.0, 0.0),
        (2500.0, 0.0),
        (950.0, 0.41),
        (170.0, 0.23),
        (500.0, 0.5),
        (2300.0, 0.5),
    ];

    /// The joint fit against `hal_sim`'s exactly integrated chain (zero-order hold, both
    /// filters, the resonator) on the quiet scene, the static admittance exact (the settings'
    /// 210 pF is the simulated plate's), the drive coming on at eight phases and aligned (the product's first plan): with the frequency
    /// switch carried by its full response ([`super::super::resonator`]'s `switch_on`, the
    /// windows' half-sample origin) and each window's sine fit of the transient from where
    /// its phase starts and ends (`HoldWindow::phase`), the fast hold's `Q` is within 0.1 % of
    /// the truth on average over the phases and within 0.25 % at each, on lossless and lossy
    /// tissue. Carried in the envelope's limit it reads 0.27–0.34 % high on average; with whole
    /// cycles from phase 0 assumed for every window, up to 0.65 % off at a phase. `f0` within
    /// 0.01 Hz (the steady state's, not the switch's).
    #[cfg(feature = "sim")]
    #[test]
    fn the_frequency_switch_is_carried_by_the_full_response() {
        for (e, eta) in QUIET_SCENES {
            let scene = hal_sim::Scene::on_modulus_kpa(e)
                .with_noise(hal_sim::NoiseScene::Quiet)
                .with_loss_tangent(eta);
            let mut sum = 0.0;
            for k in 0..9u32 {
                // Eight phases, then the drive aligned as the product's (`run_fast`).
                let h = match k {
                    8 => run_fast(scene, 3),
                    _ => run_fast_at(scene, 3, k << 29),
                };
                let r = h.estimate().unwrap();
                let df = r.resonance.0 as f64 - scene.resonance_hz();
                let dq = r.q.unwrap() as f64 / scene.q() - 1.0;
                std::eprintln!(
                    "{e} kPa, tan δ {eta}, phase {k}/8: f0 {df:+.5} Hz, Q {:+.3} %",
                    dq * 100.0
                );
                assert!(dq.abs() < 2.5e-3, "{e} kPa, tan δ {eta}, {k}/8: Q {dq:+e}");
                assert!(
                    df.abs() < 0.01,
                    "{e} kPa, tan δ {eta}, {k}/8: f0 {df:+e} Hz"
                );
                sum += dq;
            }
            let mean = sum / 9.0;
            std::eprintln!("{e} kPa, tan δ {eta}: mean Q {:+.3} %", mean * 100.0);
            assert!(mean.abs() < 1e-3, "{e} kPa, tan δ {eta}: mean Q {mean:+e}");
        }
    }

    /// The start state from rest against the simulated probe's exact chain (`hal_sim::plant`:
    /// the zero-order hold, the filters and the resonator integrated exactly): the fast hold on
    /// the quiet scene at 170–2500 kPa, lossless and lossy (tan δ up to 0.5), the drive coming
    /// on at eight phases and aligned; its joint fit made with the state free gives the state at the first
    /// window. The resonator's response from rest to the drive switched on at `t_on`
    /// (`rest_state`) is within [`REST_WIDTH`] of `g` of it at every one, at most half of it on
    /// average; without the front end's filters more than 0.02 off on average (the test can
    /// fail).
    #[cfg(feature = "sim")]
    #[test]
    fn the_start_from_rest_is_the_resonators_response() {
        use crate::estimate::resonator::{rest_state, Filters};
        let (mut worst, mut sum, mut sum_unfiltered, mut n) = (0.0f64, 0.0, 0.0, 0.0);
        for (e, eta) in QUIET_SCENES {
            let scene = hal_sim::Scene::on_modulus_kpa(e)
                .with_noise(hal_sim::NoiseScene::Quiet)
                .with_loss_tangent(eta);
            for k in 0..9u32 {
                let h = match k {
                    8 => run_fast(scene, 3),
                    _ => run_fast_at(scene, 3, k << 29),
                };
                assert_eq!(h.quiet, f32::INFINITY);
                let (first, second) = h.windows.split_at(h.first_len as usize);
                let seg = |w, f_h, v| Segment {
                    windows: w,
                    f_h,
                    y_s: h.static_admittance(f_h),
                    mirror: mirror(v),
                };
                let fit = fit_two(
                    seg(first, h.f_first, h.v_first),
                    seg(second, h.f_hold, h.v_hold),
                    &h.carry,
                    (h.f_seed, h.q_first),
                    None,
                    (NOMINAL_Q, NOMINAL_Q_SD * NOMINAL_Q),
                    None,
                )
                .unwrap();
                assert!(!fit.at_rest);
                let (g, z) = fit.linear;
                let fq = (
                    fit.estimate.resonance.0 as f64,
                    fit.estimate.q.unwrap() as f64,
                );
                let d = first[0].t0 - h.t_on;
                let v = h.v_first;
                let rest = |f: &Filters| rest_state(fq, h.f_first, d, &first[0], mirror(v), f);
                let off = (z / g - rest(&h.carry.filters)).norm();
                let none = Filters {
                    w_r: 1e9,
                    w_a: 1e9,
                    ..h.carry.filters
                };
                let unfiltered = (z / g - rest(&none)).norm();
                std::eprintln!(
                    "{e} kPa, tan δ {eta}, phase {k}/8: |z/g − K| {off:.5}, unfiltered {unfiltered:.4}"
                );
                assert!(off < REST_WIDTH as f64, "{e} kPa, {eta}, {k}/8: {off}");
                worst = worst.max(off);
                sum += off;
                sum_unfiltered += unfiltered;
                n += 1.0;
            }
        }
        let (mean, unfiltered) = (sum / n, sum_unfiltered / n);
        std::eprintln!("worst {worst:.5}, mean {mean:.5}, unfiltered {unfiltered:.5}");
        assert!(mean < 0.5 * REST_WIDTH as f64, "mean {mean}");
        assert!(unfiltered > 0.02, "unfiltered {unfiltered}");
    }

    /// The switch-on's step rings a second mode: on the stability catalogue's `second-mode` scene
    /// (300 kPa, a 295 Hz mode of `Q` 40 at half the first's peak conductance, bench noise) the
    /// fast hold switched on a quarter turn past a zero crossing (the DAC's full step) reads
    /// `interference` in several of ten readings; aligned (a zero crossing, no step) in none.
    #[cfg(feature = "sim")]
    #[test]
    fn an_aligned_switch_on_does_not_ring_a_second_mode_into_interference() {
        let case = hal_sim::catalogue::catalogue(hal_sim::NoiseScene::Bench)
            .into_iter()
            .find(|c| c.name == "second-mode")
            .expect("the catalogue's second-mode scene");
        let hum = |h: Hold| h.estimate() == Err(Failure::Interference);
        let stepped = (0..10)
            .filter(|&k| hum(run_fast_at(case.scene, 5000 + k, 1 << 30)))
            .count();
        let aligned = (0..10)
            .filter(|&k| hum(run_fast(case.scene, 5000 + k)))
            .count();
        std::eprintln!("interference: {stepped}/10 stepped, {aligned}/10 aligned");
        assert!(stepped >= 3, "{stepped}");
        assert_eq!(aligned, 0);
    }

    /// A fast hold right after another (the drive off for a batch or two, as after a power-on
    /// self-test): its start from rest is not known, so its first segment takes
    /// [`FREE_FIRST_WINDOWS`] windows, continued by a second plan at the same drive, and reads
    /// the resonance within 0.05 Hz (bench noise) from 170 kPa to beyond the range (6000 kPa, at
    /// the band's top); the first of the two, the probe at rest, takes two.
    #[cfg(feature = "sim")]
    #[test]
    fn a_first_segment_not_known_at_rest_takes_more_windows() {
        for e in [170.0, 500.0, 2500.0, 6000.0] {
            let scene = hal_sim::Scene::on_modulus_kpa(e).with_noise(hal_sim::NoiseScene::Bench);
            for seed in 0..4 {
                let h = run_fast_after(scene, seed, None, 1);
                assert!(h.quiet < 0.01, "{e} kPa: quiet {} s", h.quiet);
                assert!(h.continued, "{e} kPa, seed {seed}");
                assert!(h.first_len as u16 >= FREE_FIRST_WINDOWS, "{}", h.first_len);
                let f = h.estimate().unwrap().resonance.0 as f64;
                let truth = scene.resonance_hz();
                assert!(
                    (f - truth).abs() < 0.05,
                    "{e} kPa, seed {seed}: {f} vs {truth}"
                );
                let rested = run_fast(scene, seed);
                assert!(!rested.continued && rested.at_rest, "{e} kPa, seed {seed}");
            }
        }
    }
}
