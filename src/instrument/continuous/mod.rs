//! Continuous reading: one fast acquisition, then the resonance followed without stopping the
//! drive, a numbered, time-stamped reading per segment.
//!
//! ```text
//! acquire (hold: ring-down seed + short hold) ──ok──▶ track: segment k at f_h,k
//!    ▲                                                   │ windows → Y − (G0 + j2πf C0)
//!    │ lost (misses in a row, stall)                      │ resonator fit (f0, Q, g, z)
//!    │                                                    │ filter (f0, Q) ← fit, covariance
//!    └───────────────────────────────────────────────────┤ pipeline::conclude → reading seq k
//!                                                        └ f_h,k+1 = f0 ± dither · f0/(2Q)
//! ```
//!
//! **Acquisition** is the `hold` method itself ([`crate::estimate::hold`]) with a short hold: a
//! ring-down seed (searching a quarter band below and above when nothing rings), then a hold on
//! the seed and one on its estimate. Its estimate is the stream's first reading. When no seed
//! rang (`no_resonance`, `low_snr`: a resonance far from every burst, or outside the band, where
//! a burst barely excites it) the tracker **searches** with the fit method's stages over its band
//! ([`crate::estimate::staged`], auto's second stage): a resonance found in the band seeds one
//! more acquisition there; otherwise the search's failure is the reading, so tissue whose
//! resonance lies outside the band reads `out_of_band` as a single reading does, not `low_snr`.
//!
//! **Tracking** keeps the drive on: every segment is one [`PointPlan`] of gap-free whole-cycle
//! windows at one frequency `f_h`, loaded phase-continuously as the previous one ends (a gap of
//! at most one batch and one cycle). The segment's windows are turned into admittances with the
//! segment's drive phasor, the air reference's static branch `G0 + j2πf_h C0` is removed, and
//! the motional remainder is fitted with the resonator's model ([`crate::estimate::resonator`]:
//! `Y_m (1 − E_k) + z E_k`, `Y_m = g/(1 + jQu)`): the steady state's phase gives the detuning
//! (`Y_m` is real at `f_h = f0`), the switch-on transient from the state the previous segment
//! left (`z`) gives `Q`. Between segments the drive is retuned to the new estimate, offset by
//! `±dither` half-linewidths `f0/(2Q)` alternately: a drive on the resonance sees almost no
//! transient when it is retuned by a small fraction of a linewidth, so `Q` — which the pipeline
//! needs for its contact checks (`no_contact` on lift-off, the Q model) — would rest on the prior
//! alone; the alternating offset makes every segment's transient measure it.
//!
//! **What the tracker carries** ([`crate::estimate::track`]): each segment's fit, with its
//! covariance of `f0` and `Q`, is one measurement of a Kalman filter over `(f0, Q)` whose
//! process model lets them drift at [`TrackerConfig::drift`] and [`TrackerConfig::q_drift`];
//! the reading is the filter's estimate, and its σ adds the lag behind that drift. Off the
//! resonance a segment's `f0` error follows its `Q` error (the offset drive measures the
//! detuning through `Q`); the pooled `Q` takes that part out. An innovation past the gate (a
//! step, a new contact) restarts the filter from the segment. A plan may hold several segments
//! ([`TrackerConfig::plan_segments`]): the later ones are fitted with the plan's windows so far
//! — as an update of the plan's first fit with their new windows alone
//! ([`resonator::Linearised`]), refitted when the update's step is too long for it — and give
//! the filter what they add.
//!
//! **Lock**: a segment whose fit fails, leaves the band, or moves the resonance by more than one
//! linewidth `f0/Q` from the estimate it was driven from is not locked (its reading fails
//! `not_locked` or with the fit's failure); the drive still follows a moved estimate, and after
//! [`TrackerConfig::lost_after`] such segments in a row the tracker acquires again (so a new
//! contact after a lift-off is found without a command). Every reading, acquisition or segment,
//! is concluded by the one pipeline ([`crate::reading::pipeline::conclude`], in [`conclude`] here) with
//! the unit's profile: lift-off becomes `no_contact`, a light touch `bad_contact`, and so on.

use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::dsp::lockin::{solve_value, ChannelSums, ReferenceSums};
use crate::engine::sweep::{amplitude_codes, Drive, SettingsError};
use crate::engine::window_budget_samples;
use crate::engine::{PointPlan, PointRaw};
use crate::estimate::conductance::GROSS_CHI2;
use crate::estimate::hold::{Hold, HoldSettings};
use crate::estimate::resonator::{self, HoldWindow, MAX_WINDOWS};
use crate::estimate::staged::{Staged, StagedSettings};
use crate::estimate::track::{Measurement, Process, Sym2, Track, Update};
use crate::estimate::Estimate;
use crate::hal::FrontEndScale;
use crate::loadcell::RawForce;
use crate::reading::driver::{PointSource, Wanted};
use crate::reading::{Method, Reading};
use crate::status::{Failure, Status};
use crate::unit::profile::{UnitProfile, FREE_RESONANCE_DRIFT_HZ_S};
use crate::units::bounded;
use crate::units::{Hz, Seconds, Volts};
use core::f64::consts::PI;
use num_complex::Complex64 as C64;

/// The method a stream's readings are concluded as: their resonance is hold's (the motional
/// resonance of the same fit), so the unit's hold calibration maps it.
pub const METHOD: Method = Method::Hold;

/// Settings of the continuous tracker (the state is [`Tracker`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TrackerConfig {
    /// Lowest resonance accepted.
    pub band_start: Hz,
    /// Highest resonance accepted.
    pub band_stop: Hz,
    /// Where the first acquisition's ring-down bursts.
    pub seed: Hz,
    /// The acquisition's hold in all (first half on the seed, second on its estimate).
    pub acquire_hold: Seconds,
    /// Length of one tracking segment: one reading each (8–1000 ms). A segment is at least
    /// four windows of one cycle (the resonator's fit needs four windows; an engine window must
    /// span half a batch), 17 ms at 238 Hz.
    pub segment: Seconds,
    /// Segments a plan holds (1–8): the drive moves only between plans, so the segments after
    /// a plan's first see no retuning and lose nothing to the DAC's pipeline (the two batches
    /// and the wait for a cycle boundary between plans are spent once a plan); each is fitted
    /// with the plan's windows so far and adds what they know beyond the previous fit. The
    /// first segment takes at least four windows, a later one at least two; a plan at most 16
    /// (fewer segments when they do not fit).
    pub plan_segments: u8,
    /// Offset of the drive from the estimate, alternately above and below, in half-linewidths
    /// `f0/(2Q)` (0–2).
    pub dither: f32,
    /// Relative standard uncertainty of the previous segment's `Q` as the next fit's prior.
    pub q_prior: f32,
    /// Segments in a row without lock before the tracker acquires again (1–20).
    pub lost_after: u8,
    /// How fast the resonance may move between segments, Hz/s (0.01–100): the tracker's
    /// process model ([`crate::estimate::track`]) takes a random step of this rate times the
    /// time between segments; the larger it is, the fewer segments a reading pools.
    pub drift: f32,
    /// How fast `Q` may move between segments, as a fraction of it per s (0.01–100).
    pub q_drift: f32,
    /// Drive amplitude at the PZT.
    pub drive: Volts,
}

impl TrackerConfig {
    /// Band 170–290 Hz seeded at 230 Hz, acquisition 20 + 20 ms seed and 100 ms hold, segments
    /// of 30 ms (seven one-cycle windows at 240 Hz; each plan also waits two batches in the DAC's
    /// pipeline and for a cycle boundary: the readings' spacing is in docs/methods.md),
    /// one a plan, with the drive a quarter half-linewidth off the resonance alternately, Q prior
    /// ±50 %, the resonance drifting at the probe's specified thermal drift
    /// ([`FREE_RESONANCE_DRIFT_HZ_S`]) and `Q` at 20 %/s (ours: `Q` follows the contact; faster
    /// changes are the gate's), re-acquire after three unlocked segments in a row, 5 V.
    pub const DEFAULT: Self = Self {
        band_start: Hz(170.0),
        band_stop: Hz(290.0),
        seed: Hz(230.0),
        acquire_hold: Seconds(0.1),
        segment: Seconds(0.03),
        plan_segments: 1,
        dither: 0.25,
        q_prior: 0.5,
        lost_after: 3,
        drift: FREE_RESONANCE_DRIFT_HZ_S,
        q_drift: 0.2,
        drive: Volts(5.0),
    };

    /// The acquisition's hold settings, seeded at `seed`, with the unit's static admittance.
    fn acquisition(&self, seed: Hz, unit: &UnitProfile) -> HoldSettings {
        let mut h = HoldSettings {
            band_start: self.band_start,
            band_stop: self.band_stop,
            seed,
            hold: self.acquire_hold,
            refine: Seconds(0.5 * self.acquire_hold.0),
            drive: self.drive,
            ..HoldSettings::DEFAULT
        };
        if let Some(air) = unit.air {
            h.static_capacitance = air.static_capacitance;
            h.static_conductance = air.static_conductance;
        }
        h
    }

    /// The search's settings: the fit method's defaults over the tracker's band and drive.
    fn search(&self) -> StagedSettings {
        StagedSettings {
            band_start: self.band_start,
            band_stop: self.band_stop,
            drive: self.drive,
            ..StagedSettings::DEFAULT
        }
    }

    /// [`TrackerConfig::validate`] into `slot`, out of line: the tracker (about 4 KiB) is
    /// built in this call's frame and moved into `slot` (the firmware's measurement task keeps
    /// it in its future), not in the caller's frame, which would grow the stack of every
    /// command the caller serves.
    #[inline(never)]
    pub fn validate_into(
        &self,
        scale: &FrontEndScale,
        unit: &UnitProfile,
        slot: &mut Option<Tracker>,
    ) -> Result<(), SettingsError> {
        *slot = Some(self.validate(scale, unit)?);
        Ok(())
    }

    /// Validate for a board and a unit (whose air reference supplies the static admittance;
    /// without one the readings fail `no_air_reference` in the pipeline).
    pub fn validate(
        &self,
        scale: &FrontEndScale,
        unit: &UnitProfile,
    ) -> Result<Tracker, SettingsError> {
        let finite = [
            self.segment.0,
            self.dither,
            self.q_prior,
            self.acquire_hold.0,
            self.drift,
            self.q_drift,
        ]
        .iter()
        .all(|x| x.is_finite());
        if !finite {
            return Err(SettingsError::NotFinite);
        }
        let knobs_ok = (0.008..=1.0).contains(&self.segment.0)
            && (1..=8).contains(&self.plan_segments)
            && (0.0..=2.0).contains(&self.dither)
            && (0.05..=2.0).contains(&self.q_prior)
            && (1..=20).contains(&self.lost_after)
            && (0.01..=100.0).contains(&self.drift)
            && (0.01..=100.0).contains(&self.q_drift)
            && self.acquire_hold.0 >= 0.1;
        if !knobs_ok {
            return Err(SettingsError::KnobOutOfRange);
        }
        let acquisition = self.acquisition(self.seed, unit);
        let hold = acquisition.validate(scale)?;
        // The search is validated now: the interrupt never sees settings that were not.
        self.search().validate(scale)?;
        let amplitude = amplitude_codes(self.drive, scale)?;
        let fs = scale.sample_rate.0 as f64;
        Ok(Tracker {
            cfg: *self,
            fs,
            dt: 1.0 / fs,
            amplitude,
            static_g: acquisition.static_conductance.0 as f64,
            static_c: acquisition.static_capacitance.0 as f64,
            mode: Mode::Acquire(hold),
            searched: false,
            f_est: self.seed.0 as f64,
            q_est: 0.0,
            side: 1.0,
            f_h: 0.0,
            plan: None,
            tag: 0,
            windows: heapless::Vec::new(),
            monitor: Default::default(),
            clipped: false,
            misses: 0,
            seq: 0,
            segment_start: 0,
            track: Track::EMPTY,
            first_segment: 0,
            per_segment: 0,
            plan_prior: (0.0, 0.0, 0.0),
            plan_fit: None,
            plan_state: None,
        })
    }
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// One reading of the stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamReading {
    /// Number in the stream, from 0 without gaps.
    pub seq: u32,
    /// Probe time at the end of the reading's last window (the engine's sample count).
    pub t_s: Seconds,
    /// True when the tracker was locked on the resonance for this reading (an acquisition
    /// that found one, or a segment that stayed within a linewidth of its estimate).
    pub locked: bool,
    /// The reading through the one pipeline: status, resonance, modulus and their σ, Q.
    pub reading: Reading,
}

/// (No boxing: `no_std` without an allocator; the tracker holds one acquisition's state
/// either way.)
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
enum Mode {
    Acquire(Hold),
    /// The acquisition's seeds did not ring: the fit method's stages over the band.
    Search(Staged),
    Track,
}

/// Failures of an acquisition that say no seed rang, which a search over the band may cure (a
/// resonance outside the band reads so to a hold whose bursts lie in the band); the others
/// (out of band, moved, clipped, a tone, the drive) the acquisition names itself.
fn search_may_cure(e: &Result<Estimate, Failure>) -> bool {
    matches!(e, Err(Failure::NoResonance | Failure::LowSnr))
}

/// Tags of the tracking plans (the hold's count up from 1 and from 0xC0DE).
const TRACK_TAG: u16 = 0x5700;

/// A continuous tracker in progress: plans out, windows in, readings out.
#[derive(Clone, Debug)]
pub struct Tracker {
    cfg: TrackerConfig,
    fs: f64,
    /// The sample period, s (`1/fs`, formed once).
    dt: f64,
    amplitude: u16,
    static_g: f64,
    static_c: f64,
    mode: Mode,
    /// True when the acquisition in progress was seeded by a search (it searches no more).
    searched: bool,
    f_est: f64,
    q_est: f64,
    side: f64,
    f_h: f64,
    plan: Option<PointPlan>,
    tag: u16,
    windows: heapless::Vec<HoldWindow, MAX_WINDOWS>,
    monitor: (ChannelSums, ReferenceSums),
    clipped: bool,
    misses: u8,
    seq: u32,
    segment_start: u64,
    track: Track,
    /// Windows of the plan in progress's first segment, and of each later one.
    first_segment: u16,
    per_segment: u16,
    /// The plan's fits start from: `f0`, and `Q` with its prior's σ (the estimate when the plan
    /// was made: the same prior for every fit of the plan, so that their difference is data).
    plan_prior: (f64, f64, f64),
    /// The last fit of the plan in progress (of all its windows until then).
    plan_fit: Option<Measurement>,
    /// That fit's normal equations, which the plan's next segment updates
    /// ([`resonator::Linearised`]).
    plan_state: Option<resonator::Linearised>,
}

/// The one place a stream's estimate becomes a reading: the pipeline with the unit's profile
/// and the load cell's counts over the reading's force window ([`force_window`]).
pub fn conclude(
    est: Result<Estimate, Failure>,
    unit: &UnitProfile,
    took: Seconds,
    points: u16,
    force: Option<RawForce>,
) -> Reading {
    crate::reading::pipeline::conclude(METHOD, est, unit, took, points, force)
}

/// Shortest stretch of time a stream reading's contact force is taken over, s: eight of the
/// load cell's conversions at 80 SPS (a 30 ms segment holds two or three, too few to tell a
/// steady press from a moving one).
pub const FORCE_WINDOW_S: f64 = 0.1;

/// The samples `from..=to` a stream reading ending at sample `end` after a segment from
/// `start` takes its contact force over: the segment, or the last [`FORCE_WINDOW_S`] when the
/// segment is shorter.
pub fn force_window(start: u64, end: u64, fs: f64) -> (u64, u64) {
    let min = (FORCE_WINDOW_S * fs) as u64;
    (end.saturating_sub(end.saturating_sub(start).max(min)), end)
}

impl Tracker {
    /// True while acquiring (the seed and the first holds).
    pub fn acquiring(&self) -> bool {
        matches!(self.mode, Mode::Acquire(_) | Mode::Search(_))
    }

    /// True while a tracking plan has windows to come (a reading ended one of its segments,
    /// not the plan).
    pub fn plan_running(&self) -> bool {
        matches!(self.mode, Mode::Track) && self.plan.is_some()
    }

    /// Readings emitted so far (the next reading's `seq`).
    pub fn emitted(&self) -> u32 {
        self.seq
    }

    /// The next plan, or `None` while one is running.
    pub fn next_plan(&mut self) -> Option<PointPlan> {
        match &mut self.mode {
            Mode::Acquire(h) => h.next_plan(),
            Mode::Search(s) => s.next_plan(),
            Mode::Track => {
                if self.plan.is_some() {
                    return None;
                }
                let (lo, hi) = (self.cfg.band_start.0 as f64, self.cfg.band_stop.0 as f64);
                let half_width = self.f_est / (2.0 * self.q_est.max(1.0));
                let f = bounded(
                    self.f_est + self.side * self.cfg.dither as f64 * half_width,
                    lo,
                    hi,
                );
                self.side = -self.side;
                let ftw = tuning_word(f, self.fs);
                self.f_h = frequency_hz(ftw, self.fs);
                // Windows of whole cycles, the shortest the engine passes on (one cycle in the
                // band; longer for a single long segment), at most MAX_WINDOWS a plan: its first
                // segment at least four (the fit's fewest), each later one at least two (its
                // fit takes the plan's windows so far).
                let per_cycle = 1.0 / self.f_h.max(1.0);
                let seg = self.cfg.segment.0 as f64;
                let most = MAX_WINDOWS as f64;
                let mut cycles = resonator::first_cycles(self.f_h, self.fs);
                if self.cfg.plan_segments <= 1 {
                    cycles = cycles.max(libm::ceil(seg / per_cycle / most));
                }
                let n = bounded(libm::floor(seg / (cycles * per_cycle)), 2.0, most) as u16;
                let first = n.max(4);
                let later = (self.cfg.plan_segments.max(1) as u16 - 1)
                    .min((MAX_WINDOWS as u16).saturating_sub(first) / n);
                self.per_segment = n;
                self.first_segment = first;
                self.tag = self.tag.wrapping_add(1);
                let plan = PointPlan {
                    ftw,
                    amplitude_codes: self.amplitude,
                    settle_samples: 0,
                    cycles: cycles as u32,
                    windows: first + later * n,
                    open: false,
                    aligned: false,
                    tag: TRACK_TAG | (self.tag & 0xff),
                };
                self.plan = Some(plan);
                self.plan_prior = (self.f_est, self.q_est, self.cfg.q_prior as f64 * self.q_est);
                self.plan_fit = None;
                self.plan_state = None;
                self.windows.clear();
                self.monitor = Default::default();
                self.clipped = false;
                Some(plan)
            }
        }
    }

    /// Take a finished window; returns a reading when it ended one, concluded with `unit` and
    /// the load cell's counts `force(from, to)` over its force window ([`force_window`]).
    pub fn accept(
        &mut self,
        raw: &PointRaw,
        scale: &FrontEndScale,
        unit: &UnitProfile,
        force: impl FnOnce(u64, u64) -> Option<RawForce>,
    ) -> Option<StreamReading> {
        let t = raw.end_sample;
        match &mut self.mode {
            Mode::Acquire(h) => {
                h.accept(raw, scale);
                if !h.is_complete() {
                    return None;
                }
                let est = h.estimate();
                if search_may_cure(&est) && !self.searched {
                    // The reading waits for the search; its time counts to the reading.
                    if let Ok(s) = self.cfg.search().validate(scale) {
                        self.mode = Mode::Search(s);
                        return None;
                    }
                }
                let points = h.windows().len() as u16;
                let took = self.seconds(t.saturating_sub(self.segment_start));
                let locked = match est {
                    Ok(e) => {
                        self.f_est = e.resonance.0 as f64;
                        self.q_est = bounded(e.q.map_or(10.0, |q| q as f64), 2.0, 200.0);
                        // The filter starts from the acquisition (its `Q`'s σ, when it has one).
                        self.track.clear();
                        let sq = e.q_sigma.unwrap_or(0.0);
                        let sf = e.sigma.0;
                        self.track.update(
                            &Measurement {
                                f0: self.f_est,
                                q: self.q_est,
                                cov: Sym2 {
                                    a: sf * sf,
                                    b: 0.0,
                                    c: sq * sq,
                                },
                                t: t as f64 / self.fs,
                            },
                            &self.process(),
                        );
                        self.mode = Mode::Track;
                        self.plan = None;
                        self.misses = 0;
                        self.side = 1.0;
                        true
                    }
                    Err(_) => {
                        self.reacquire(scale, unit);
                        false
                    }
                };
                let (from, to) = force_window(self.segment_start, t, self.fs);
                self.segment_start = t;
                Some(self.emit(est, unit, t, took, points, locked, force(from, to)))
            }
            Mode::Search(s) => {
                s.accept(raw, scale);
                if !s.is_complete() {
                    return None;
                }
                let est = s.estimate();
                let points = s.len() as u16;
                if let Ok(e) = est {
                    // Found in the band: one more acquisition, seeded there.
                    let h = self.cfg.acquisition(e.resonance, unit).validate(scale);
                    if let Ok(h) = h {
                        self.mode = Mode::Acquire(h);
                        self.searched = true;
                        return None;
                    }
                }
                // Nothing in the band, or no hold to seed: the search's answer is the reading.
                let took = self.seconds(t.saturating_sub(self.segment_start));
                let (from, to) = force_window(self.segment_start, t, self.fs);
                self.segment_start = t;
                self.reacquire(scale, unit);
                let est = est.and(Err(Failure::BadSettings));
                Some(self.emit(est, unit, t, took, points, false, force(from, to)))
            }
            Mode::Track => {
                let plan = self.plan?;
                if raw.plan != plan {
                    return None;
                }
                let s = &raw.sums;
                self.clipped |= s.current_rail_hits > 0;
                resonator::add_sums(&mut self.monitor, &s.monitor, &s.reference);
                if let Some(w) = resonator::current_window(raw, scale, self.dt) {
                    let _ = self.windows.push(w);
                }
                let done = raw.window + 1;
                let ends_segment = done == self.first_segment
                    || (done > self.first_segment
                        && (done - self.first_segment).is_multiple_of(self.per_segment.max(1)));
                if !ends_segment && done < plan.windows {
                    return None;
                }
                if done >= plan.windows {
                    self.plan = None;
                }
                let est = self.segment_estimate(scale, t as f64 / self.fs);
                let locked = est.is_ok();
                self.misses = if locked {
                    0
                } else {
                    self.misses.saturating_add(1)
                };
                let took = self.seconds(t.saturating_sub(self.segment_start));
                let (from, to) = force_window(self.segment_start, t, self.fs);
                self.segment_start = t;
                let points = if self.plan_fit.is_some() && done > self.first_segment {
                    self.per_segment
                } else {
                    self.first_segment
                };
                let r = self.emit(est, unit, t, took, points, locked, force(from, to));
                if self.misses >= self.cfg.lost_after {
                    self.reacquire(scale, unit);
                }
                Some(r)
            }
        }
    }

    /// A plan's window did not come (the stream stalled): a reading that failed with `failure`
    /// (the source's [`PointSource::stall_failure`]), and the tracker acquires again.
    pub fn stalled(
        &mut self,
        now_sample: u64,
        failure: Failure,
        scale: &FrontEndScale,
        unit: &UnitProfile,
    ) -> StreamReading {
        let took = self.seconds(now_sample.saturating_sub(self.segment_start));
        self.segment_start = now_sample;
        self.reacquire(scale, unit);
        self.emit(Err(failure), unit, now_sample, took, 0, false, None)
    }

    fn seconds(&self, samples: u64) -> Seconds {
        Seconds((samples as f64 / self.fs) as f32)
    }

    #[allow(clippy::too_many_arguments)] // one reading's parts, each named
    fn emit(
        &mut self,
        est: Result<Estimate, Failure>,
        unit: &UnitProfile,
        t: u64,
        took: Seconds,
        points: u16,
        locked: bool,
        force: Option<RawForce>,
    ) -> StreamReading {
        let reading = conclude(est, unit, took, points, force);
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        StreamReading {
            seq,
            t_s: self.seconds(t),
            locked: locked && reading.status != Status::Failed(Failure::NotLocked),
            reading,
        }
    }

    /// Start a new acquisition, seeded at the last estimate when it lies in the band.
    fn reacquire(&mut self, scale: &FrontEndScale, unit: &UnitProfile) {
        let (lo, hi) = (self.cfg.band_start.0 as f64, self.cfg.band_stop.0 as f64);
        let seed = if (lo..=hi).contains(&self.f_est) {
            Hz(self.f_est as f32)
        } else {
            self.cfg.seed
        };
        let s = self.cfg.acquisition(seed, unit);
        // The configuration validated with its own seed; a seed within the band validates too.
        if let Ok(h) = s
            .validate(scale)
            .or_else(|_| self.cfg.acquisition(self.cfg.seed, unit).validate(scale))
        {
            self.mode = Mode::Acquire(h);
        }
        self.plan = None;
        self.misses = 0;
        self.searched = false;
        self.track.clear();
    }

    /// The filter's process model: the configured rates, and the gate at the χ² of two degrees
    /// of freedom that a measurement consistent with the prediction exceeds once in a thousand
    /// (`−2 ln 10⁻³`).
    fn process(&self) -> Process {
        Process {
            f0_rate: self.cfg.drift as f64,
            q_rate: self.cfg.q_drift as f64,
            gate: 13.8155,
        }
    }

    /// The finished segment's estimate (ending at `t_end`, s), pooled with what the tracker
    /// knows ([`Track`]); moves the estimate the drive follows.
    fn segment_estimate(&mut self, scale: &FrontEndScale, t_end: f64) -> Result<Estimate, Failure> {
        if self.clipped {
            return Err(Failure::Clipped);
        }
        let (m, r) = &self.monitor;
        let (value, variance) = solve_value(m, r).ok_or(Failure::DriveFault)?;
        let drive = Drive::from_value(value, variance, scale).ok_or(Failure::DriveFault)?;
        let y_s = C64::new(self.static_g, 2.0 * PI * self.f_h * self.static_c);
        let mirror = resonator::mirror(drive.v);
        // A later segment of a plan whose fit so far stands: that fit updated with the new
        // windows alone, as admittances with the drive phasor measured so far (`None`: no
        // update, or one declined as too long a step for the kept linearisation).
        let updated = match &mut self.plan_state {
            Some(k) if self.plan_fit.is_some() => {
                let mut w: heapless::Vec<HoldWindow, MAX_WINDOWS> =
                    self.windows.iter().skip(k.windows()).copied().collect();
                resonator::to_admittance(&mut w, drive.v, drive.var_v);
                k.update(resonator::Segment {
                    windows: &w,
                    f_h: self.f_h,
                    y_s,
                    mirror,
                })?
            }
            _ => None,
        };
        let h = match updated {
            Some(h) => h,
            // The fit of the plan's windows so far: its first segment, or the first that fits.
            None => {
                let mut w = self.windows.clone();
                resonator::to_admittance(&mut w, drive.v, drive.var_v);
                let (f_start, q_start, q_sd) = self.plan_prior;
                let seg = resonator::Segment {
                    windows: &w,
                    f_h: self.f_h,
                    y_s,
                    mirror,
                };
                // Its normal equations kept only when later segments will update them.
                if self.plan.is_some() {
                    let (h, k) = resonator::fit_linearised(seg, f_start, (q_start, q_sd))?;
                    self.plan_state = Some(k);
                    h
                } else {
                    resonator::fit(seg, f_start, (q_start, q_sd))?
                }
            }
        };
        // A segment the resonator's model does not explain (a knock, a tone) is no reading,
        // and the drive does not follow it: the next segment (30 ms on by default) will be clean.
        if h.reduced_chi2 > GROSS_CHI2 {
            return Err(Failure::Interference);
        }
        let e = h.estimate;
        let (f0, q) = (e.resonance.0 as f64, e.q.unwrap_or(0.0) as f64);
        let (lo, hi) = (self.cfg.band_start.0 as f64, self.cfg.band_stop.0 as f64);
        if !(lo..=hi).contains(&f0) || !(2.0..=200.0).contains(&q) {
            return Err(Failure::OutOfBand);
        }
        let moved = libm::fabs(f0 - self.f_est);
        // Follow the estimate either way; a jump of more than a linewidth is no lock, and what
        // the filter knew is of another resonance.
        self.f_est = f0;
        self.q_est = q;
        if moved > f0 / q {
            self.track.clear();
            return Err(Failure::NotLocked);
        }
        let (sf, sq) = (e.sigma.0, h.sigma_q as f32);
        let fit = Measurement {
            f0,
            q,
            cov: Sym2 {
                a: sf * sf,
                b: h.cov_f0_q as f32,
                c: sq * sq,
            },
            t: t_end,
        };
        // A plan's later segments are fitted with all its windows so far (their starting state
        // is the plan's, not a free one); what they add is the information the earlier fit did
        // not have: `Y = C⁻¹ − C_prev⁻¹`, `Y z = C⁻¹ x − C_prev⁻¹ x_prev`.
        let m = match self.plan_fit.replace(fit) {
            None => Some(fit),
            Some(prev) => added_information(&fit, &prev),
        };
        let update = match m {
            None => Update::Refused,
            Some(m) => match self.track.update(&m, &self.process()) {
                // What a later segment added failed the filter's gate: a real change, or a
                // difference of two fits too thin to stand alone (nearly singular, linearised
                // where the fits are not linear). The filter restarts from the plan's whole fit,
                // which stands alone, never from the difference.
                Update::Restarted if m != fit => {
                    self.track.clear();
                    self.track.update(&fit, &self.process())
                }
                u => u,
            },
        };
        let pooled = match update {
            // Nothing the filter can take (a later segment that adds no information the
            // linearised fits tell apart): what it knows, predicted to the segment's end.
            Update::Refused => self.track.predicted(t_end, &self.process()),
            Update::Pooled | Update::Restarted => self.track.estimate(),
        };
        let Some(p) = pooled else {
            self.track.clear();
            return Ok(e);
        };
        if !(lo..=hi).contains(&p.f0) || !(2.0..=200.0).contains(&p.q) {
            self.track.clear();
            return Ok(e);
        }
        self.f_est = p.f0;
        self.q_est = p.q;
        // The σ states the lag behind a drift at the configured rate besides the covariance.
        let lag = self.track.drift_lag(self.cfg.drift as f64);
        Ok(Estimate {
            resonance: Hz(p.f0 as f32),
            sigma: Hz(crate::dsp::trig::sqrtf(
                p.cov.a.max(0.0) + (lag * lag) as f32,
            )),
            q: Some(p.q as f32),
            q_sigma: Some(crate::dsp::trig::sqrtf(p.cov.c.max(0.0))),
            ..e
        })
    }
}

/// What `now` (a fit of a plan's windows so far) knows beyond `before` (the fit of fewer of
/// them), as a measurement: the difference of their information matrices over `(f0, Q)`,
/// `A − B`, and of their information vectors, `A x_now − B x_before`, whose solve is
/// `x_before + (A − B)⁻¹ A (x_now − x_before)` — the form taken here, with the difference of
/// the estimates (a few σ) in `f32` like the matrices (formed directly, the information vectors
/// `A x` of a resonance of hundreds of Hz would cancel to that difference beyond `f32`'s
/// digits). `None` when the difference is not positive definite (nothing added that the
/// linearised fits can tell apart).
fn added_information(now: &Measurement, before: &Measurement) -> Option<Measurement> {
    let (a, b) = (now.cov.inverse()?, before.cov.inverse()?);
    let info = Sym2 {
        a: a.a - b.a,
        b: a.b - b.b,
        c: a.c - b.c,
    };
    let cov = info.inverse()?;
    let d = [(now.f0 - before.f0) as f32, (now.q - before.q) as f32];
    let x = cov.mul(a.mul(d));
    Some(Measurement {
        f0: before.f0 + x[0] as f64,
        q: before.q + x[1] as f64,
        cov,
        t: now.t,
    })
}

/// Run `tracker` against `src` until `emit` returns false: plans loaded one by one (the drive
/// never stops between them), every window waited for under the one stall rule
/// ([`window_budget_samples`]), every reading handed to `emit`. A stall is a reading that failed
/// with the source's [`PointSource::stall_failure`] and a new acquisition. The drive is stopped at the end. Returns the readings
/// emitted.
pub async fn run<S: PointSource>(
    src: &mut S,
    tracker: &mut Tracker,
    unit: &UnitProfile,
    mut emit: impl FnMut(&StreamReading) -> bool,
) -> u32 {
    run_with(src, tracker, unit, |_, r| emit(r)).await
}

/// [`run`] with the point source lent to `emit` with each reading (the firmware's session
/// hands the reading to its report channel, which the board holds, without waiting).
pub async fn run_with<S: PointSource>(
    src: &mut S,
    tracker: &mut Tracker,
    unit: &UnitProfile,
    mut emit: impl FnMut(&mut S, &StreamReading) -> bool,
) -> u32 {
    let scale = src.scale();
    let fs = scale.sample_rate.0 as f64;
    tracker.segment_start = src.now_sample();
    // `next_plan` gives a plan whenever the previous one has ended (a plan is taken only after
    // its last window or a reading); `None` would end the stream rather than spin.
    'outer: while let Some(plan) = tracker.next_plan() {
        if !src.load(plan).await {
            break;
        }
        let budget = window_budget_samples(&plan, fs, src.latency_batches());
        for _ in 0..plan.windows.max(1) {
            let r = match src.next(&Wanted::plan(plan), budget).await {
                Some(raw) => tracker.accept(&raw, &scale, unit, |a, b| src.contact_force(a, b)),
                None => {
                    let failure = src.stall_failure();
                    Some(tracker.stalled(src.now_sample(), failure, &scale, unit))
                }
            };
            if let Some(r) = r {
                if !emit(src, &r) {
                    break 'outer;
                }
                // A reading that ends its plan (a plan's last segment, the acquisition's end, a
                // stall): the next plan follows at once.
                if !tracker.plan_running() {
                    continue 'outer;
                }
            }
        }
    }
    src.stop().await;
    tracker.seq
}

#[cfg(test)]
mod tests;
