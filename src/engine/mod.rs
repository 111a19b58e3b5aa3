//! The sample engine: everything the sample interrupt does, and nothing else.
//!
//! Per batch it fills the next DAC batch from the DDS ([`generate`](SampleEngine::generate)) and
//! demodulates the ADC batch that was captured while an earlier DAC batch played
//! ([`demodulate`](SampleEngine::demodulate)). A measurement asks for one point at a time with a
//! [`PointPlan`] (frequency, amplitude, settling, whole cycles to integrate); the engine switches
//! frequency phase-continuously at the next batch, waits the settling samples, starts integrating
//! at the next cycle boundary of the reference, integrates exactly `cycles` whole cycles and
//! hands back the integer [`LockInSums`] as a [`PointRaw`]. Work per sample is bounded (integer
//! only, no branches on data except rail detection); nothing here allocates, logs or panics.

pub mod sweep;

use crate::dsp::dds::{run_to_wrap, sin_q15, Dds};
use crate::dsp::lockin::{LockInSums, RUN_MAX};
use crate::hal::AdcFrame;
use crate::units::{DacCode, MAX_CODE, MID_CODE};

/// Samples per batch (one DMA half-buffer on the STM32: 2.5 ms at 10 kHz). Short, because every
/// plan waits [`PIPELINE_BATCHES`] of them (and the rest of the batch it was loaded in) before it
/// plays: with 50-sample batches a hold's first segment drove 10 ms longer off the resonance
/// and the default read at 1.38× the Cramér–Rao bound at 9.9 τ; with 25, 1.28× at 9.8 τ
/// (docs/methods.md). The sample interrupt's overhead per batch doubles with it
/// (docs/firmware.md).
pub const BATCH: usize = 25;

/// Batches between the sample engine's generating a DAC batch and the ADC batch captured while
/// it played, on every board: the DAC's DMA runs over two half-buffers, both filled before it
/// starts, and the sample interrupt refills the half that just played, which plays again two
/// periods later (the STM32's circular DMA, the QEMU board's emulation of it, and the host's
/// simulated board, so that a plan takes effect as late on the host as on the target).
pub const PIPELINE_BATCHES: usize = 2;

/// The stall rule: samples a window of `plan` may take before it counts as lost — its
/// settling, its cycles and two more (to find the window's boundary), and the stream's
/// pipeline of `latency_batches` plus two batches of margin.
pub fn window_budget_samples(plan: &PointPlan, fs: f64, latency_batches: usize) -> u64 {
    let f = crate::dsp::dds::frequency_hz(plan.ftw, fs).max(1.0);
    let period = fs / f;
    plan.settle_samples as u64
        + ((plan.cycles as f64 + 2.0) * period) as u64
        + (BATCH * (latency_batches + 2)) as u64
}

/// What the measurement asks the interrupt for: one point.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PointPlan {
    /// DDS tuning word of the drive.
    pub ftw: u32,
    /// Drive amplitude in DAC codes (0..=2047).
    pub amplitude_codes: u16,
    /// Samples to wait after the switch before integration may start.
    pub settle_samples: u32,
    /// Whole drive cycles to integrate per window (0: drive only, never complete).
    pub cycles: u32,
    /// Consecutive integration windows (0 and 1 both mean one). Window `k + 1` starts at the
    /// cycle boundary where window `k` ends, with no gap: a ring-down is demodulated this way.
    /// Each window must be at least half a batch long ([`MIN_WINDOW_SAMPLES`]) so that at most
    /// [`MAX_POINTS_PER_BATCH`] complete per batch; a further one is dropped and counted as an
    /// overrun.
    pub windows: u16,
    /// Open: after its `windows`, keep closing windows of the same length, numbered on, until
    /// the next plan takes effect (the batch a later [`SampleEngine::load`] reaches the DAC).
    /// A measurement that chooses its next plan from this one's windows then loses no drive time
    /// to the DAC's pipeline: the windows that close while the next plan is on its way are
    /// data of this plan's drive (a cut-off last one is dropped with the switch).
    pub open: bool,
    /// Aligned: when the drive was off before this plan (from quiet), it comes on at phase 0,
    /// a zero crossing of its sine (no step in the DAC's output, which would ring every mode
    /// and filter), whatever phase the previous plans left; its first window starts at the
    /// first cycle boundary after `settle_samples`. After a drive a plan keeps the phase
    /// (phase-continuous), aligned or not.
    pub aligned: bool,
    /// Caller's tag, echoed in the result (must differ from the previous plan's).
    pub tag: u16,
}

/// A finished point: the plan it answers and the exact demodulator sums.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PointRaw {
    /// The plan this point answers.
    pub plan: PointPlan,
    /// Demodulator sums over the integration window.
    pub sums: LockInSums,
    /// Engine sample count at the end of the window.
    pub end_sample: u64,
    /// Index of the window within the plan (0 for the first).
    pub window: u16,
    /// Samples from the start of the batch in which the plan took effect (its frequency switch,
    /// phase-continuous) to the end of this window (saturating).
    pub since_load: u32,
    /// The drive's phase at the window's first sample (2³² a turn): within one phase step
    /// (`plan.ftw`) after the cycle boundary the window starts at. The phase after its last
    /// sample is this plus `ftw` times its samples (`sums.reference.n`), wrapping.
    pub start_phase: u32,
    /// Samples the drive had been off (amplitude 0, or no plan) when the plan took effect,
    /// saturating; [`u32::MAX`] when the engine has not driven since it started; 0: the drive
    /// was on up to the switch. A drive off for many of the resonator's time constants left it
    /// at rest.
    pub quiet_before: u32,
}

#[derive(Clone, Copy, Debug, Default)]
struct BatchInfo {
    start_phase: u32,
    ftw: u32,
    plan: Option<PointPlan>,
    /// Which load of the engine the batch belongs to ([`SampleEngine::load`] or `stop`).
    load: u32,
    /// Samples the drive had been off before this batch ([`PointRaw::quiet_before`]).
    quiet: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    Idle,
    Settling(u32),
    AwaitBoundary,
    Integrating(u32),
    Done,
}

const RING: usize = 4;

/// Most windows that close in one batch: a window of at least [`MIN_WINDOW_SAMPLES`].
pub const MAX_POINTS_PER_BATCH: usize = 2;

/// Shortest window a plan may ask for, samples: half a batch (rounded up), so that at most
/// [`MAX_POINTS_PER_BATCH`] close in one (one cycle at up to 769 Hz at 10 kHz).
pub const MIN_WINDOW_SAMPLES: u32 = crate::engine::BATCH.div_ceil(2) as u32;

/// The windows that closed in one batch, in order.
pub type Points = heapless::Vec<PointRaw, MAX_POINTS_PER_BATCH>;

/// Engine errors (reported, never silent).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EngineError {
    /// More DAC batches were generated than the ring remembers before being demodulated.
    RingOverrun,
}

/// State of the sample interrupt.
#[derive(Clone, Debug)]
pub struct SampleEngine {
    dds: Dds,
    amplitude: i32,
    /// Samples generated with the drive off since it was last on (saturating; `u32::MAX`: never
    /// on since the start).
    quiet: u32,
    plan: Option<PointPlan>,
    pending: Option<Option<PointPlan>>,
    ring: [BatchInfo; RING],
    generated: u32,
    demodulated: u32,
    demod_tag: Option<u16>,
    /// Loads applied by `generate` (the batch's [`BatchInfo::load`]).
    loads: u32,
    /// The load of the batches being demodulated: a new load restarts the point even when its
    /// plan has the same tag (a new reading's first plan after an abandoned one).
    demod_load: u32,
    stage: Stage,
    sums: LockInSums,
    window: u16,
    /// The drive's phase at the first sample of the window being integrated.
    window_phase: u32,
    samples: u64,
    /// Sample count when the demodulated plan took effect.
    load_sample: u64,
    /// [`BatchInfo::quiet`] of the batch in which the plan being demodulated took effect.
    load_quiet: u32,
    overruns: u32,
    /// Scratch of [`LockInSums::integrate`]: a run's reference.
    run_reference: [u32; RUN_MAX],
}

impl Default for SampleEngine {
    fn default() -> Self {
        Self::new()
    }
}

impl SampleEngine {
    /// An idle engine (drive off).
    pub const fn new() -> Self {
        Self {
            dds: Dds { phase: 0, ftw: 0 },
            amplitude: 0,
            quiet: u32::MAX,
            plan: None,
            pending: None,
            ring: [BatchInfo {
                start_phase: 0,
                ftw: 0,
                plan: None,
                load: 0,
                quiet: u32::MAX,
            }; RING],
            generated: 0,
            demodulated: 0,
            demod_tag: None,
            loads: 0,
            demod_load: 0,
            stage: Stage::Idle,
            sums: LockInSums {
                current: crate::dsp::lockin::ChannelSums {
                    xc: 0,
                    xs: 0,
                    x: 0,
                    xx: 0,
                },
                monitor: crate::dsp::lockin::ChannelSums {
                    xc: 0,
                    xs: 0,
                    x: 0,
                    xx: 0,
                },
                reference: crate::dsp::lockin::ReferenceSums {
                    cc: 0,
                    ss: 0,
                    cs: 0,
                    c: 0,
                    s: 0,
                    n: 0,
                },
                current_rail_hits: 0,
                monitor_rail_hits: 0,
            },
            window: 0,
            window_phase: 0,
            samples: 0,
            load_sample: 0,
            load_quiet: u32::MAX,
            overruns: 0,
            run_reference: [0; RUN_MAX],
        }
    }

    /// Ask for `plan`, applied from the next generated batch on (phase-continuous).
    pub fn load(&mut self, plan: PointPlan) {
        self.pending = Some(Some(plan));
    }

    /// The drive's phase accumulator set to `phase` (a turn is 2³²): the drive comes on at
    /// whatever phase the engine's previous plans left, which the tests vary.
    #[cfg(test)]
    pub(crate) fn set_phase(&mut self, phase: u32) {
        self.dds.phase = phase;
    }

    /// Switch the drive off from the next generated batch on.
    pub fn stop(&mut self) {
        self.pending = Some(None);
    }

    /// Samples demodulated since start (the probe's clock).
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// DAC batches generated and not yet demodulated: those in the board's pipeline.
    pub fn in_flight(&self) -> u32 {
        self.generated.wrapping_sub(self.demodulated)
    }

    /// Ring overruns seen since start.
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// True while a loaded point is still being measured (an open plan's windows after its
    /// `windows` are extra: it is no longer busy).
    pub fn busy(&self) -> bool {
        self.pending.is_some()
            || self.plan.is_some_and(|p| {
                let finished = self.stage == Stage::Done || self.window >= p.windows.max(1);
                p.cycles > 0 && (!finished || self.demod_tag != Some(p.tag))
            })
    }

    /// Fill the next DAC batch.
    pub fn generate(&mut self, dac: &mut [DacCode]) {
        if let Some(p) = self.pending.take() {
            self.plan = p;
            self.loads = self.loads.wrapping_add(1);
            match p {
                Some(p) => {
                    if p.aligned && self.amplitude == 0 {
                        // From quiet: sample `k` of the plan plays `k ftw`, from a zero crossing.
                        self.dds.phase = 0;
                    }
                    self.dds.ftw = p.ftw;
                    self.amplitude = p.amplitude_codes.min(2047) as i32;
                }
                None => {
                    self.amplitude = 0;
                }
            }
        }
        if self.generated.wrapping_sub(self.demodulated) >= RING as u32 {
            // The consumer fell behind: forget the oldest batch and say so.
            self.demodulated = self.demodulated.wrapping_add(1);
            self.overruns = self.overruns.saturating_add(1);
        }
        self.ring[self.generated as usize % RING] = BatchInfo {
            start_phase: self.dds.phase,
            ftw: self.dds.ftw,
            plan: self.plan,
            load: self.loads,
            quiet: self.quiet,
        };
        self.quiet = if self.amplitude == 0 {
            self.quiet.saturating_add(dac.len() as u32)
        } else {
            0
        };
        self.generated = self.generated.wrapping_add(1);
        let amp = self.amplitude;
        // The DDS stepped on a copy (in registers), stored back once.
        let mut dds = self.dds;
        for out in dac.iter_mut() {
            let ph = dds.step();
            let v = MID_CODE as i32 + ((amp * sin_q15(ph)) >> 15);
            *out = DacCode(v.clamp(0, MAX_CODE as i32) as u16);
        }
        self.dds = dds;
    }

    /// Demodulate the ADC batch captured while the oldest not yet demodulated DAC batch played.
    /// Returns the points whose integration windows closed in this batch (at most
    /// [`MAX_POINTS_PER_BATCH`]; a window shorter than [`MIN_WINDOW_SAMPLES`] could close a
    /// third, which is dropped and counted in [`overruns`](Self::overruns)).
    pub fn demodulate(&mut self, adc: &[AdcFrame]) -> Points {
        let mut out = Points::new();
        self.demodulate_into(adc, |p| {
            let _ = out.push(p);
        });
        out
    }

    /// [`demodulate`](Self::demodulate), each closed window handed to `point` as it closes (the
    /// sample interrupt's hand-off, without a batch's list of points to copy): at most
    /// [`MAX_POINTS_PER_BATCH`] a batch, a further one dropped and counted in
    /// [`overruns`](Self::overruns).
    pub fn demodulate_into(&mut self, adc: &[AdcFrame], mut point: impl FnMut(PointRaw)) {
        let info = self.next_batch();
        let mut phase = info.start_phase;
        let ftw = info.ftw;
        let mut closed = 0;
        let mut rest = adc;
        // Run by run: a stage's samples up to its next event (the end of the settling, a cycle
        // boundary) at once, the same stage changes at the same samples as stepping each one.
        while !rest.is_empty() {
            // The samples skipped: the phase steps over them.
            let skip = |phase: &mut u32, n: usize| {
                *phase = phase.wrapping_add(ftw.wrapping_mul(n as u32));
                n
            };
            let (used, wrapped) = match self.stage {
                // Settling(n) turns into AwaitBoundary at the start of its (n + 1)-th sample,
                // which may wrap: the n samples before it are skipped.
                Stage::Settling(n) => {
                    let m = (n as usize).min(rest.len());
                    self.stage = if m < rest.len() {
                        Stage::AwaitBoundary
                    } else {
                        Stage::Settling(n - m as u32)
                    };
                    (skip(&mut phase, m), false)
                }
                Stage::Integrating(_) => {
                    self.sums
                        .integrate(rest, &mut phase, ftw, &mut self.run_reference)
                }
                // Up to the sample whose step wraps.
                Stage::AwaitBoundary => {
                    let (n, wrapped) = run_to_wrap(phase, ftw, rest.len());
                    (skip(&mut phase, n), wrapped)
                }
                Stage::Idle | Stage::Done => (skip(&mut phase, rest.len()), false),
            };
            rest = rest.get(used..).unwrap_or_default();
            self.samples += used as u64;
            if wrapped {
                // `phase` is now the next sample's: the first of a window that starts here.
                if let Some(p) = self.boundary(&info, phase) {
                    closed += 1;
                    if closed <= MAX_POINTS_PER_BATCH {
                        point(p);
                    } else {
                        self.overruns = self.overruns.saturating_add(1);
                    }
                }
            }
        }
    }

    /// The record of the batch to demodulate, the oldest generated and not yet demodulated
    /// (none: the drive was off); a new plan or load starts its point afresh.
    fn next_batch(&mut self) -> BatchInfo {
        let info = if self.demodulated != self.generated {
            let i = self.ring[self.demodulated as usize % RING];
            self.demodulated = self.demodulated.wrapping_add(1);
            i
        } else {
            BatchInfo::default()
        };
        let tag = info.plan.map(|p| p.tag);
        if tag != self.demod_tag || info.load != self.demod_load {
            self.demod_tag = tag;
            self.demod_load = info.load;
            self.load_sample = self.samples;
            self.load_quiet = info.quiet;
            self.sums = LockInSums::default();
            self.window = 0;
            self.stage = match info.plan {
                Some(p) if p.cycles > 0 => Stage::Settling(p.settle_samples),
                _ => Stage::Idle,
            };
        }
        info
    }

    /// The stage change at a cycle boundary (a sample whose phase step wrapped; `phase` the
    /// next sample's): integration starts, or a cycle is counted, or the window closes and is
    /// returned (and the next one starts when the plan has more, or is open).
    fn boundary(&mut self, info: &BatchInfo, phase: u32) -> Option<PointRaw> {
        match self.stage {
            Stage::AwaitBoundary => {
                let cycles = info.plan.map_or(0, |p| p.cycles);
                self.stage = Stage::Integrating(cycles);
                self.window_phase = phase;
                None
            }
            Stage::Integrating(k) if k <= 1 => {
                self.stage = Stage::Done;
                let plan = info.plan?;
                let point = PointRaw {
                    plan,
                    sums: self.sums,
                    end_sample: self.samples,
                    window: self.window,
                    since_load: (self.samples.saturating_sub(self.load_sample)).min(u32::MAX as u64)
                        as u32,
                    start_phase: self.window_phase,
                    quiet_before: self.load_quiet,
                };
                if plan.open || self.window.saturating_add(1) < plan.windows {
                    self.window = self.window.saturating_add(1);
                    self.sums = LockInSums::default();
                    self.stage = Stage::Integrating(plan.cycles);
                    self.window_phase = phase;
                }
                Some(point)
            }
            Stage::Integrating(k) => {
                self.stage = Stage::Integrating(k - 1);
                None
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dsp::dds::tuning_word;
    use crate::units::AdcCode;

    /// An engine at 10 kHz loaded with the point `f_hz`, `amplitude_codes`, `settle_samples`,
    /// `cycles` a window, `windows`, `tag`.
    fn loaded(
        f_hz: f64,
        amplitude_codes: u16,
        settle_samples: u32,
        cycles: u32,
        windows: u16,
        tag: u16,
    ) -> SampleEngine {
        let mut e = SampleEngine::new();
        e.load(PointPlan {
            ftw: tuning_word(f_hz, 10_000.0),
            amplitude_codes,
            settle_samples,
            cycles,
            windows,
            open: false,
            aligned: false,
            tag,
        });
        e
    }

    /// One batch of 50 samples with the DAC looped straight back into both ADC channels.
    fn loopback_batch(e: &mut SampleEngine) -> Points {
        let mut dac = [DacCode::MID; 50];
        let mut adc = [AdcFrame::default(); 50];
        e.generate(&mut dac);
        for (a, d) in adc.iter_mut().zip(dac.iter()) {
            *a = AdcFrame {
                current: AdcCode(d.0),
                monitor: AdcCode(d.0),
            };
        }
        e.demodulate(&adc)
    }

    /// Loop the DAC straight back into both ADC channels: the point must integrate exactly the
    /// asked number of whole cycles and see a pure sine of the commanded amplitude.
    #[test]
    fn loopback_point() {
        // 237 Hz, 1000 codes, settle 123 samples, 10 cycles, one window, tag 1.
        let mut e = loaded(237.0, 1000, 123, 10, 1, 1);
        let mut got = None;
        for _ in 0..100 {
            if let Some(p) = loopback_batch(&mut e).first() {
                got = Some(*p);
                break;
            }
        }
        let p = got.expect("point completes");
        let n = p.sums.reference.n as f64;
        // 10 cycles of 10000/237 samples: 421.9 -> 421 or 422 samples.
        assert!((n - 10.0 * 10_000.0 / 237.0).abs() <= 1.0, "n = {n}");
        let ph = crate::dsp::lockin::solve(&p.sums.current, &p.sums.reference).unwrap();
        assert!(
            (ph.value.norm() - 1000.0).abs() < 0.5,
            "{}",
            ph.value.norm()
        );
        // settle (123) + wait for boundary (< 43) + window
        assert!(p.end_sample as f64 <= 123.0 + 43.0 + n + 1.0);
        assert!(!e.busy());
    }

    /// An aligned plan from quiet comes on at phase 0 (the window's start phase less its
    /// samples' steps), whatever phase the engine's accumulator held, and its first window
    /// starts at the first boundary after the settle (found by stepping the phase sample by
    /// sample: the first sample after the settle's end whose phase lies within one step past a
    /// wrap), within a cycle of the settle's end; the same plan after a drive keeps the phase.
    #[test]
    fn an_aligned_plan_from_quiet_starts_at_a_zero_crossing() {
        let ftw = tuning_word(229.6, 10_000.0);
        let plan = |settle: u32, aligned: bool, tag: u16| PointPlan {
            ftw,
            amplitude_codes: 900,
            settle_samples: settle,
            cycles: 1,
            windows: 1,
            open: false,
            aligned,
            tag,
        };
        let first_window = |e: &mut SampleEngine| {
            let start = e.samples();
            (0..20)
                .find_map(|_| loopback_batch(e).first().copied())
                .map(|w| (w.end_sample - w.sums.reference.n as u64 - start, w))
                .expect("a window closes")
        };
        // The first window's first sample from a switch-on at `phase0`: the first sample after
        // the settle whose phase is within one step past a wrap.
        let stepped = |phase0: u32, settle: u32| {
            (settle as u64 + 1..)
                .find(|&k| phase0.wrapping_add((k as u32).wrapping_mul(ftw)) < ftw)
                .unwrap()
        };
        let cycle = (10_000.0 / 229.6) as u64 + 2;
        for (k, phase) in [0u32, 1 << 30, 0x9E37_79B9, u32::MAX]
            .into_iter()
            .enumerate()
        {
            for settle in [0u32, 20, 37, 60] {
                let mut e = SampleEngine::new();
                e.set_phase(phase);
                e.load(plan(settle, true, k as u16 + 1));
                let (first, w) = first_window(&mut e);
                let on = w.start_phase.wrapping_sub((first as u32).wrapping_mul(ftw));
                assert_eq!(on, 0, "switched on at {on:#x}");
                assert_eq!(
                    first,
                    stepped(0, settle),
                    "phase {phase:#x}, settle {settle}"
                );
                assert!(first - settle as u64 <= cycle, "{first} after {settle}");
            }
        }
        // After a drive: phase-continuous, whatever the window's start.
        let mut e = SampleEngine::new();
        e.load(plan(0, false, 1));
        let (a, wa) = first_window(&mut e);
        e.load(plan(20, true, 2));
        let start = e.samples();
        let (b, wb) = first_window(&mut e);
        let steps = (start + b - a) as u32;
        assert_eq!(
            wb.start_phase,
            wa.start_phase.wrapping_add(steps.wrapping_mul(ftw))
        );
    }

    /// Consecutive windows follow each other without a gap, each starting at the first sample
    /// after a cycle boundary: its `start_phase` is the drive's phase at that sample (sample
    /// `k` of a drive loaded from phase 0 plays phase `k · ftw`), within one step after the
    /// boundary, and the next window's is this one's `n` steps on.
    #[test]
    fn consecutive_windows() {
        // 241 Hz, 800 codes, settle 10 samples, 2 cycles a window, six windows, tag 3.
        let mut e = loaded(241.0, 800, 10, 2, 6, 3);
        let ftw = tuning_word(241.0, 10_000.0);
        let mut got = std::vec::Vec::new();
        for _ in 0..40 {
            got.extend(loopback_batch(&mut e));
        }
        assert_eq!(got.len(), 6);
        for w in &got {
            let first = w.end_sample - w.sums.reference.n as u64;
            assert_eq!(w.start_phase, (first as u32).wrapping_mul(ftw));
            assert!(w.start_phase < ftw, "{w:?}");
        }
        for (k, w) in got.windows(2).enumerate() {
            assert_eq!(w[0].window as usize, k);
            // The next window ends exactly its own length after the previous one.
            assert_eq!(
                w[1].end_sample - w[0].end_sample,
                w[1].sums.reference.n as u64
            );
            let n = w[0].sums.reference.n;
            assert_eq!(
                w[1].start_phase,
                w[0].start_phase.wrapping_add(ftw.wrapping_mul(n))
            );
        }
        assert!(!e.busy());
    }

    /// Windows of one cycle (4.1 ms at 241 Hz, shorter than the test's 5 ms batch): two may
    /// close in one batch, and every one is handed on, in order, gap-free; none is an overrun.
    #[test]
    fn windows_shorter_than_a_batch_are_all_handed_on() {
        let mut e = loaded(241.0, 800, 10, 1, 12, 5);
        let mut got = std::vec::Vec::new();
        let mut two = 0;
        for _ in 0..40 {
            let batch = loopback_batch(&mut e);
            two += (batch.len() == 2) as usize;
            got.extend(batch);
        }
        assert_eq!(got.len(), 12);
        assert!(two > 0, "no batch closed two windows");
        for (k, w) in got.windows(2).enumerate() {
            assert_eq!(w[0].window as usize, k);
            assert_eq!(
                w[1].end_sample - w[0].end_sample,
                w[1].sums.reference.n as u64
            );
        }
        assert_eq!(e.overruns(), 0);
        assert!(!e.busy());
        // 400 Hz (the top of any band) is slower than the fastest one-cycle window of half a
        // batch.
        assert!(10_000.0 / 400.0 >= MIN_WINDOW_SAMPLES as f64);
    }
    /// The definition `demodulate` is held to: every sample of the batch stepped through the
    /// stages one at a time, its products added straight to the `i64` sums.
    fn demodulate_per_sample(e: &mut SampleEngine, adc: &[AdcFrame]) -> Points {
        let info = e.next_batch();
        let mut phase = info.start_phase;
        let mut out = Points::new();
        for f in adc {
            if let Stage::Settling(n) = e.stage {
                e.stage = if n == 0 {
                    Stage::AwaitBoundary
                } else {
                    Stage::Settling(n - 1)
                };
            }
            if let Stage::Integrating(_) = e.stage {
                let (c, s) = (crate::dsp::dds::cos_q15(phase), sin_q15(phase));
                e.sums
                    .accumulate(c, s, f.current.centered(), f.monitor.centered());
                e.sums.current_rail_hits += f.current.is_rail() as u32;
                e.sums.monitor_rail_hits += f.monitor.is_rail() as u32;
            }
            let next = phase.wrapping_add(info.ftw);
            let wrapped = next < phase;
            phase = next;
            e.samples += 1;
            if let Some(p) = wrapped.then(|| e.boundary(&info, phase)).flatten() {
                if out.push(p).is_err() {
                    e.overruns = e.overruns.saturating_add(1);
                }
            }
        }
        out
    }

    /// A draw below `n` from the tests' generator.
    fn below(rng: &mut probe_rng::Rng, n: u64) -> u64 {
        rng.next_u64() % n
    }

    /// The run-by-run `demodulate` against the per-sample definition: random plans (drive
    /// frequencies from 0 to the tuning word's top, settling, cycles, windows, open or not,
    /// stops, loads faster than the batches, repeated tags), random batch lengths (1–80, across
    /// the 32-sample runs) and random codes (rails, and values beyond 12 bits): the same
    /// windows, sums, stages, sample counts and overruns after every batch.
    #[test]
    fn demodulating_run_by_run_is_demodulating_sample_by_sample() {
        let mut rng = probe_rng::Rng::new(0x5EED);
        let mut closed = 0;
        for case in 0..300 {
            let (mut a, mut b) = (SampleEngine::new(), SampleEngine::new());
            for _ in 0..40 {
                if below(&mut rng, 3) == 0 {
                    let ftw = match below(&mut rng, 6) {
                        0 => 0,
                        1 => u32::MAX - below(&mut rng, 4) as u32,
                        2 => rng.next_u64() as u32,
                        _ => tuning_word(100.0 + below(&mut rng, 400) as f64, 10_000.0),
                    };
                    let plan = PointPlan {
                        ftw,
                        amplitude_codes: below(&mut rng, 2100) as u16,
                        settle_samples: below(&mut rng, 120) as u32,
                        cycles: below(&mut rng, 5) as u32,
                        windows: below(&mut rng, 5) as u16,
                        open: below(&mut rng, 2) == 0,
                        aligned: below(&mut rng, 2) == 0,
                        tag: below(&mut rng, 4) as u16,
                    };
                    if below(&mut rng, 8) == 0 {
                        a.stop();
                        b.stop();
                    } else {
                        a.load(plan);
                        b.load(plan);
                    }
                }
                let len = 1 + below(&mut rng, 80) as usize;
                let mut dac = [DacCode::MID; 80];
                let mut adc = [AdcFrame::default(); 80];
                for f in adc.iter_mut().take(len) {
                    let mut code = || match below(&mut rng, 10) {
                        0 => [0, MAX_CODE, u16::MAX][below(&mut rng, 3) as usize],
                        1 => rng.next_u64() as u16,
                        _ => below(&mut rng, MAX_CODE as u64 + 1) as u16,
                    };
                    *f = AdcFrame {
                        current: AdcCode(code()),
                        monitor: AdcCode(code()),
                    };
                }
                // Now and then a batch generated twice before one is demodulated (an overrun
                // of the ring once it is full).
                for _ in 0..1 + (below(&mut rng, 6) == 0) as usize {
                    a.generate(&mut dac[..len]);
                    b.generate(&mut dac[..len]);
                }
                let (pa, pb) = (
                    a.demodulate(&adc[..len]),
                    demodulate_per_sample(&mut b, &adc[..len]),
                );
                assert_eq!(pa, pb, "case {case}");
                closed += pa.len();
                assert_eq!(
                    (a.samples, a.overruns, a.sums, a.stage, a.window),
                    (b.samples, b.overruns, b.sums, b.stage, b.window),
                    "case {case}"
                );
            }
        }
        assert!(closed > 1000, "{closed} windows closed");
    }

    /// An open plan goes on closing windows of its length after its own, numbered on and
    /// gap-free, until the next plan takes effect: none of it closes after the switch, the one
    /// the switch cut is dropped, and the engine is not busy once the plan's own windows are in.
    #[test]
    fn an_open_plan_closes_windows_until_the_next_plan_takes_effect() {
        let mut e = SampleEngine::new();
        let plan = PointPlan {
            ftw: tuning_word(241.0, 10_000.0),
            amplitude_codes: 800,
            settle_samples: 10,
            cycles: 1,
            windows: 3,
            open: true,
            aligned: false,
            tag: 7,
        };
        e.load(plan);
        let mut got = std::vec::Vec::new();
        while got.len() < 3 {
            got.extend(loopback_batch(&mut e));
        }
        assert!(!e.busy());
        for _ in 0..4 {
            got.extend(loopback_batch(&mut e));
        }
        assert!(got.len() >= 6, "{} windows", got.len());
        for (k, w) in got.iter().enumerate() {
            assert_eq!((w.window as usize, w.plan), (k, plan));
        }
        for w in got.windows(2) {
            assert_eq!(
                w[1].end_sample - w[0].end_sample,
                w[1].sums.reference.n as u64
            );
        }
        // The next plan: the batch it takes effect in starts at the engine's present sample.
        let switch = e.samples();
        e.load(PointPlan {
            tag: 8,
            open: false,
            aligned: false,
            windows: 1,
            ..plan
        });
        let mut after = std::vec::Vec::new();
        for _ in 0..10 {
            after.extend(loopback_batch(&mut e));
        }
        assert!(after.iter().all(|w| w.plan.tag == 8), "{after:?}");
        assert_eq!(after.len(), 1);
        assert!(got.last().is_some_and(|w| w.end_sample <= switch));
    }
}
