//! The one reading driver: a [`Procedure`] run plan by plan against a [`PointSource`], every
//! window of a plan waited for under one stall rule, ended in the one pipeline.
//!
//! The firmware's measurement task (plans and points through channels to the sample
//! interrupt), the host ([`SyncSource`]: engine and stream in one loop, for `probe-bench` and
//! the tests) and the QEMU cost image all take readings through [`read`].

use crate::engine::sweep::SweepPoint;
use crate::engine::{window_budget_samples, PointPlan, PointRaw, SampleEngine, BATCH};
use crate::hal::{AdcFrame, FrontEndScale, SampleStream, StreamError};
use crate::loadcell::{ForceSource, RawForce};
use crate::reading::{Measurement, Method, Procedure, Reading, Settings};
use crate::status::Failure;
use crate::unit::profile::UnitProfile;
use crate::units::{DacCode, Seconds};

/// Where a reading's points come from: the sample engine behind the board's streams.
#[allow(async_fn_in_trait)] // used with concrete types only, in one task at a time
pub trait PointSource {
    /// The converters' scale (sample rate, volts and amps per code).
    fn scale(&self) -> FrontEndScale;
    /// Batches between a DAC batch and the ADC batch that sees it. The default is every
    /// board's pipeline, [`PIPELINE_BATCHES`](crate::engine::PIPELINE_BATCHES) (the DAC's two
    /// half-buffers); a source over a [`SampleStream`] of its own latency (a test stream) gives
    /// the stream's.
    fn latency_batches(&self) -> usize {
        crate::engine::PIPELINE_BATCHES
    }
    /// The engine's sample count now (the reading's time base).
    fn now_sample(&self) -> u64;
    /// Hand `plan` to the engine; false when the engine can no longer be reached.
    async fn load(&mut self, plan: PointPlan) -> bool;
    /// The next finished window that `wanted` [matches](Wanted::matches) (the plan in progress,
    /// or the open plan before it), or `None` when none came within `budget` samples (stalled)
    /// or the source failed.
    async fn next(&mut self, wanted: &Wanted, budget: u64) -> Option<PointRaw>;
    /// Stop the drive.
    async fn stop(&mut self);
    /// Let `samples` of the engine's samples pass with the drive stopped (the load cell keeps
    /// converting): a wait that is time on the probe, for what is measured without a drive.
    async fn idle(&mut self, samples: u64);
    /// The load cell's counts over the engine's samples `from..=to` (`None`: no load cell, or
    /// it was silent).
    fn contact_force(&mut self, from: u64, to: u64) -> Option<RawForce>;
    /// The failure a stall ends a reading in ([`Failure::of_stall`]): the default, a source
    /// without DMA, `drive_fault`; the firmware's from the board's DMA error count.
    fn stall_failure(&self) -> Failure {
        Failure::of_stall(0)
    }
    /// An admittance point of the reading in progress, with its plan's tag, as it comes (the
    /// firmware logs it; the default ignores it).
    async fn point(&mut self, tag: u16, point: &SweepPoint) {
        let _ = (tag, point);
    }
}

/// The windows a reading waits for: those of the plan in progress, and those of the plan before
/// it when that plan is [open](PointPlan::open) (its windows go on closing until the new plan
/// takes effect). Every other window is stale and dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Wanted {
    /// The plan in progress.
    pub plan: PointPlan,
    /// The open plan before it, if any.
    pub open_before: Option<PointPlan>,
}

impl Wanted {
    /// Only the windows of `plan`.
    pub fn plan(plan: PointPlan) -> Self {
        Self {
            plan,
            open_before: None,
        }
    }

    /// True when `raw` answers the plan in progress or the open plan before it.
    pub fn matches(&self, raw: &PointRaw) -> bool {
        raw.plan == self.plan || Some(raw.plan) == self.open_before
    }
}

/// Why a reading stopped before its procedure ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// A window did not arrive within its budget: the plan's tag.
    Stalled(u16),
}

/// One reading with `method` and `settings`, ended in the pipeline with `unit`. `on_point`
/// sees every admittance point with its plan's tag. A stall ends the reading as the source's
/// [`PointSource::stall_failure`] (`drive_fault`, or `dma_error`; `on_stop` hears of it);
/// settings the method refuses as `bad_settings`.
pub async fn read<S: PointSource>(
    src: &mut S,
    method: Method,
    settings: &Settings,
    unit: &UnitProfile,
    on_point: impl FnMut(u16, &SweepPoint),
    on_stop: impl FnMut(Stop),
) -> Reading {
    let start = src.now_sample();
    match Procedure::new(method, settings, &src.scale(), start, unit) {
        Ok(mut m) => drive(src, &mut m, method, unit, on_point, on_stop).await,
        Err(_) => Reading::failed(method, Failure::BadSettings, Seconds(0.0), 0),
    }
}

/// What the plan loop ([`run_plans`]) needs of a measurement: its plans, one at a time, and
/// the windows that answer them. Every [`Measurement`] is one; the power-on self-test
/// ([`crate::instrument::selftest`]) is one without a reading at its end.
pub trait Plans {
    /// The next point to ask for, or `None` (done, or waiting for the point in flight).
    fn next_plan(&mut self) -> Option<PointPlan>;
    /// Take a finished window; returns it in physical units when it is an admittance point of
    /// a reading (it then goes to the point sinks).
    fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint>;
    /// True when no more windows are needed.
    fn is_complete(&self) -> bool;
}

/// The plan loop under the one stall rule: `m`'s plans handed to `src` one by one, every
/// window of a plan waited for within [`window_budget_samples`], each accepted by `m`; the
/// admittance points go to `on_point` and to the source's own sink ([`PointSource::point`]).
/// The drive is stopped at the end either way. Returns the points accepted, or the stall
/// with the points accepted before it.
pub async fn run_plans<S: PointSource, P: Plans>(
    src: &mut S,
    m: &mut P,
    mut on_point: impl FnMut(u16, &SweepPoint),
) -> Result<u16, (Stop, u16)> {
    let fs = src.scale().sample_rate.0 as f64;
    let mut points: u16 = 0;
    let mut open_before = None;
    while !m.is_complete() {
        let Some(plan) = m.next_plan() else { break };
        if !src.load(plan).await {
            break;
        }
        let budget = window_budget_samples(&plan, fs, src.latency_batches());
        let wanted = Wanted { plan, open_before };
        let mut got = 0u16;
        // Each of the plan's windows within its budget; the open plan's before it (the drive
        // time while this plan is on its way) are accepted as they come, not counted.
        let mut deadline = src.now_sample().saturating_add(budget);
        while got < plan.windows.max(1) {
            let left = deadline.saturating_sub(src.now_sample());
            let Some(raw) = src.next(&wanted, left).await else {
                src.stop().await;
                return Err((Stop::Stalled(plan.tag), points));
            };
            if raw.plan == plan {
                got += 1;
                deadline = src.now_sample().saturating_add(budget);
            }
            if let Some(p) = m.accept(&raw) {
                points = points.saturating_add(1);
                on_point(raw.plan.tag, &p);
                src.point(raw.plan.tag, &p).await;
            }
        }
        open_before = plan.open.then_some(plan);
    }
    src.stop().await;
    Ok(points)
}

/// Run the measurement `m` of `method` (validated, started at the source's present sample)
/// plan by plan against `src` under the stall rule ([`run_plans`]), and end it with `unit`:
/// the loop of [`read`], open to a measurement wrapped for counting (the QEMU cost image).
pub async fn drive<S: PointSource, M: Measurement>(
    src: &mut S,
    m: &mut M,
    method: Method,
    unit: &UnitProfile,
    on_point: impl FnMut(u16, &SweepPoint),
    mut on_stop: impl FnMut(Stop),
) -> Reading {
    let fs = src.scale().sample_rate.0 as f64;
    let start = src.now_sample();
    match run_plans(src, m, on_point).await {
        Ok(_) => m.finish(unit, src.contact_force(start, src.now_sample())),
        Err((stop, points)) => {
            on_stop(stop);
            let elapsed = Seconds(src.now_sample().saturating_sub(start) as f32 / fs as f32);
            Reading::failed(method, src.stall_failure(), elapsed, points)
        }
    }
}

/// Run a future that never waits (every [`PointSource`] call of a [`SyncSource`] completes at
/// once) to its end: the host's and single-threaded images' way to call [`read`].
pub fn block_on<F: core::future::Future>(f: F) -> F::Output {
    let mut f = core::pin::pin!(f);
    let mut cx = core::task::Context::from_waker(core::task::Waker::noop());
    loop {
        if let core::task::Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// A source that runs the engine batch by batch itself ([`SyncSource`], the QEMU cost image's):
/// its [`PointSource::next`] is [`next_window`](Self::next_window), its [`PointSource::idle`]
/// the engine stopped and then [`pass`](Self::pass).
pub trait BatchSource {
    /// One batch of the engine against the stream: the windows it closed, `Ok(None)` while the
    /// stream's pipeline is still filling, an error when the stream failed.
    fn batch(&mut self) -> Result<Option<crate::engine::Points>, StreamError>;
    /// A second window that closed in the batch of the one [`next_window`](Self::next_window)
    /// returned.
    fn held(&mut self) -> &mut Option<PointRaw>;

    /// The window kept in [`held`](Self::held) if `wanted` matches it, else one batch after
    /// another (an error ends the wait) until one closes a wanted window, within `budget`
    /// samples; a second wanted window of that batch is kept for the next call.
    fn next_window(&mut self, wanted: &Wanted, budget: u64) -> Option<PointRaw> {
        if let Some(raw) = self.held().take().filter(|r| wanted.matches(r)) {
            return Some(raw);
        }
        let mut used = 0u64;
        while used <= budget {
            // A batch still filling the pipeline counts against the budget too, so that a
            // stream that never plays is a stall, not a hang.
            let played = self.batch().ok()?;
            used += BATCH as u64;
            let Some(points) = played else {
                continue;
            };
            let mut points = points.into_iter();
            if let Some(raw) = points.by_ref().find(|r| wanted.matches(r)) {
                *self.held() = points.find(|r| wanted.matches(r));
                return Some(raw);
            }
        }
        None
    }

    /// Let `samples` of the engine's samples pass, one batch after another (an error ends the
    /// wait); a window kept in [`held`](Self::held) is dropped once a batch has played.
    fn pass(&mut self, samples: u64) {
        let mut done = 0u64;
        while done < samples {
            let Ok(played) = self.batch() else {
                return;
            };
            done += BATCH as u64;
            if played.is_some() {
                *self.held() = None;
            }
        }
    }
}

/// The [`PointSource`] methods of a [`BatchSource`] whose [`SampleEngine`] is its field
/// `$engine`, expanded inside its `impl PointSource`: `next` is the window wait
/// ([`BatchSource::next_window`]), `stop` stops the engine, `idle` stops it and lets the
/// samples [`pass`](BatchSource::pass). The host's [`SyncSource`] and the QEMU cost image's
/// source use it.
#[macro_export]
macro_rules! batch_source_waits {
    ($engine:ident) => {
        async fn next(
            &mut self,
            wanted: &$crate::reading::driver::Wanted,
            budget: u64,
        ) -> Option<$crate::engine::PointRaw> {
            $crate::reading::driver::BatchSource::next_window(self, wanted, budget)
        }
        async fn stop(&mut self) {
            self.$engine.stop();
        }
        async fn idle(&mut self, samples: u64) {
            self.$engine.stop();
            $crate::reading::driver::BatchSource::pass(self, samples);
        }
    };
}

/// A [`PointSource`] that runs the engine and a [`SampleStream`] in one loop: batch by batch,
/// generate, exchange, demodulate.
pub struct SyncSource<'a, S> {
    /// The stream.
    pub stream: &'a mut S,
    /// The sample engine.
    pub engine: &'a mut SampleEngine,
    /// The first error the stream reported.
    pub error: Option<StreamError>,
    /// A second window that closed in the batch of the one [`PointSource::next`] returned (a
    /// caller that makes a new source per call carries it over).
    pub held: Option<PointRaw>,
}

impl<'a, S: SampleStream> SyncSource<'a, S> {
    /// Wrap `stream` and `engine`, the stream's pipeline filled from the engine first if it is
    /// not yet (as a board fills its DAC buffers before starting the DMA): a plan then takes
    /// effect [`SampleStream::latency_batches`] batches after it is loaded, as on the target.
    pub fn new(stream: &'a mut S, engine: &'a mut SampleEngine) -> Self {
        let mut src = Self {
            stream,
            engine,
            error: None,
            held: None,
        };
        // At most one batch per batch of latency (a stream that claims more than the engine's
        // ring holds cannot loop here for ever); a stream that plays at once has no pipeline to
        // fill.
        for _ in 0..src.stream.latency_batches() {
            if src.engine.in_flight() as usize >= src.stream.latency_batches() {
                break;
            }
            match src.batch() {
                Ok(None) => {}
                Ok(Some(_)) | Err(_) => break,
            }
        }
        src
    }
}

impl<S: SampleStream> BatchSource for SyncSource<'_, S> {
    /// One batch: the engine fills the next DAC batch, the stream queues it, and the engine
    /// demodulates what played — `Ok(None)` while the stream's pipeline is still filling
    /// (nothing played yet). A stream error is kept in [`SyncSource::error`].
    fn batch(&mut self) -> Result<Option<crate::engine::Points>, StreamError> {
        let mut dac = [DacCode::MID; BATCH];
        let mut adc = [AdcFrame::default(); BATCH];
        self.engine.generate(&mut dac);
        match self.stream.exchange(&dac, &mut adc) {
            Ok(true) => Ok(Some(self.engine.demodulate(&adc))),
            Ok(false) => Ok(None),
            Err(e) => {
                self.error = Some(e);
                Err(e)
            }
        }
    }
    fn held(&mut self) -> &mut Option<PointRaw> {
        &mut self.held
    }
}

impl<S: SampleStream + ForceSource> PointSource for SyncSource<'_, S> {
    fn scale(&self) -> FrontEndScale {
        self.stream.scale()
    }
    fn latency_batches(&self) -> usize {
        self.stream.latency_batches()
    }
    fn now_sample(&self) -> u64 {
        self.engine.samples()
    }
    async fn load(&mut self, plan: PointPlan) -> bool {
        self.engine.load(plan);
        self.error.is_none()
    }
    crate::batch_source_waits!(engine);
    fn contact_force(&mut self, from: u64, to: u64) -> Option<RawForce> {
        self.stream.contact_force(from, to)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::PIPELINE_BATCHES;
    use crate::hal::FrontEndScale;

    /// A stream whose pipeline never delivers frames, claiming `latency` batches.
    struct NeverPlays {
        latency: usize,
        calls: u32,
    }

    impl SampleStream for NeverPlays {
        fn exchange(&mut self, _: &[DacCode], _: &mut [AdcFrame]) -> Result<bool, StreamError> {
            self.calls += 1;
            Ok(false)
        }
        fn latency_batches(&self) -> usize {
            self.latency
        }
        fn scale(&self) -> FrontEndScale {
            FrontEndScale::PROBE
        }
    }

    impl ForceSource for NeverPlays {
        fn contact_force(&self, _: u64, _: u64) -> Option<RawForce> {
            None
        }
    }

    /// A stream that never plays is a stall within the window's budget, not a hang, whatever
    /// latency it claims (the budget and the fill both grow with it: bounded by about twice
    /// the latency plus the first window's own budget).
    #[test]
    fn a_stream_that_never_plays_stalls() {
        for latency in [2, 1000] {
            let mut stream = NeverPlays { latency, calls: 0 };
            let mut engine = SampleEngine::new();
            let unit = UnitProfile::fallback();
            let r = crate::reading::runner::run_reading(
                &mut stream,
                &mut engine,
                Method::Hold,
                &Method::Hold.default_settings(),
                &unit,
                |_| {},
            );
            assert_eq!(r.err(), Some(crate::reading::runner::RunError::Stalled));
            assert!(stream.calls < 2 * latency as u32 + 100, "{}", stream.calls);
        }
    }
    /// A stream that plays each DAC batch back into both ADC channels
    /// [`PIPELINE_BATCHES`] batches after it was queued, as every board does.
    struct Loopback {
        queued: std::collections::VecDeque<[DacCode; BATCH]>,
    }

    impl SampleStream for Loopback {
        fn exchange(&mut self, dac: &[DacCode], adc: &mut [AdcFrame]) -> Result<bool, StreamError> {
            let mut batch = [DacCode::MID; BATCH];
            batch.copy_from_slice(dac);
            self.queued.push_back(batch);
            if self.queued.len() <= PIPELINE_BATCHES {
                return Ok(false);
            }
            let played = self.queued.pop_front().ok_or(StreamError::Overrun)?;
            for (a, d) in adc.iter_mut().zip(played) {
                let code = crate::units::AdcCode(d.0);
                *a = AdcFrame {
                    current: code,
                    monitor: code,
                };
            }
            Ok(true)
        }
        fn latency_batches(&self) -> usize {
            PIPELINE_BATCHES
        }
        fn scale(&self) -> FrontEndScale {
            FrontEndScale::PROBE
        }
    }

    impl ForceSource for Loopback {
        fn contact_force(&self, _: u64, _: u64) -> Option<RawForce> {
            None
        }
    }

    /// Two plans, the first open: records every window the plan loop hands on.
    struct TwoPlans {
        plans: std::vec::Vec<PointPlan>,
        next: usize,
        got: std::vec::Vec<(u16, u16)>,
    }

    impl Plans for TwoPlans {
        fn next_plan(&mut self) -> Option<PointPlan> {
            let p = self.plans.get(self.next).copied();
            self.next += 1;
            p
        }
        fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
            self.got.push((raw.plan.tag, raw.window));
            None
        }
        fn is_complete(&self) -> bool {
            self.next >= self.plans.len() && self.got.iter().filter(|g| g.0 == 2).count() >= 2
        }
    }

    /// The plan loop hands on the windows an open plan closes while the next one passes the
    /// pipeline (after its own, before the next plan's), and counts only each plan's own
    /// towards its end: one-cycle windows at 241 Hz (41 samples) in a wait of two to three
    /// 25-sample batches give one or two.
    #[test]
    fn the_windows_of_an_open_plan_come_before_the_next_plans() {
        let a = PointPlan {
            ftw: crate::dsp::dds::tuning_word(241.0, 10_000.0),
            amplitude_codes: 800,
            settle_samples: 10,
            cycles: 1,
            windows: 2,
            open: true,
            aligned: false,
            tag: 1,
        };
        let b = PointPlan {
            tag: 2,
            open: false,
            aligned: false,
            ..a
        };
        let mut m = TwoPlans {
            plans: std::vec![a, b],
            next: 0,
            got: std::vec::Vec::new(),
        };
        let mut stream = Loopback {
            queued: Default::default(),
        };
        let mut engine = SampleEngine::new();
        let mut src = SyncSource::new(&mut stream, &mut engine);
        assert_eq!(block_on(run_plans(&mut src, &mut m, |_, _| {})), Ok(0));
        let extra = m.got.len() - 4;
        assert!((1..=2).contains(&extra), "{:?}", m.got);
        let expected: std::vec::Vec<(u16, u16)> = (0..2 + extra as u16)
            .map(|k| (1, k))
            .chain([(2, 0), (2, 1)])
            .collect();
        assert_eq!(m.got, expected);
    }
}
