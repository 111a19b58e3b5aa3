//! The firmware's measurement task apart from RTIC: its board ([`FwIo`], the session's
//! [`Io`] over the links to the sample interrupt and the other tasks) and its loop
//! ([`FwIo::serve`]), both under the watchdog's rules ([`crate::instrument::watchdog`]).
//!
//! The tasks' RTIC side (`src/board/tasks.rs`, `MeasureLinks`) implements [`Link`] over the
//! channels and the monotonic; everything the task decides — which windows it takes, how long it waits for one,
//! what it promises the watchdog before each wait and each command, when it tells the report
//! task the counters, how it measures the work from a window to the next plan — is here, and
//! is tested on the host over a scripted link.

use crate::boot::BootError;
use crate::engine::sweep::SweepPoint;
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::instrument::command::Command;
use crate::instrument::session::{Event, Io, Session};
use crate::instrument::watchdog::{self, Liveness, Millis, ALIVE, FEED};
use crate::loadcell::RawForce;
use crate::reading::driver::{PointSource, Wanted};
use crate::status::Failure;
use crate::unit::profile::UnitProfile;
use crate::unit::store::{Loaded, Saved, Store, StoreError};
use embedded_storage::nor_flash::NorFlash;

/// What a wait on a channel came to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Recv<T> {
    /// A message.
    Got(T),
    /// Nothing within the time given.
    Timeout,
    /// The sender is gone.
    Closed,
}

impl<T> Recv<T> {
    /// A receive raced against a timeout, as RTIC gives it (`timeout_after(d, rx.recv())`):
    /// the timeout's error outside, the channel's inside.
    pub fn of<C, E>(r: Result<Result<T, C>, E>) -> Self {
        match r {
            Ok(Ok(v)) => Recv::Got(v),
            Ok(Err(_)) => Recv::Closed,
            Err(_) => Recv::Timeout,
        }
    }
}

/// The measurement task's links: the sample interrupt's plan and point channels, the request
/// and completion channels of the command task, the report channel, the monotonic, the
/// board's work clock and the load cell's force log.
#[allow(async_fn_in_trait)] // used with concrete types only, in one task
pub trait Link {
    /// Hand the sample interrupt a plan to load, or `None` to stop the drive (waits for room);
    /// false when the interrupt can no longer be reached.
    async fn plan(&mut self, plan: Option<PointPlan>) -> bool;
    /// The interrupt's next finished window, waiting at most `within` (`None`: none came, or
    /// the interrupt can no longer be reached).
    async fn point(&mut self, within: Millis) -> Option<PointRaw>;
    /// The command task's next request, waiting at most `within`.
    async fn request(&mut self, within: Millis) -> Recv<Command>;
    /// Tell the command task a request (or the power-on self-test) ended, `ok` or not, without
    /// waiting: only the QEMU script waits for it; elsewhere the slot just stays full.
    fn done(&mut self, ok: bool);
    /// A session event for the report task, waiting for room (the report task ends only with
    /// the image: a closed channel is not an error).
    async fn report(&mut self, e: Event);
    /// A request was served (`ok` as the session returned), after every event it caused: the
    /// host link's reply to it follows them ([`crate::instrument::link::LinkEvent::Served`]),
    /// waiting for room. Links without a host link do nothing.
    async fn served(&mut self, _ok: bool) {}
    /// The health counters for the report task, waiting for room.
    async fn counters(&mut self);
    /// A session event for the report task if it has room now; false when it was dropped.
    fn try_report(&mut self, e: Event) -> bool;
    /// Wait `ms`.
    async fn delay(&mut self, ms: Millis);
    /// The monotonic's time.
    fn now(&self) -> Millis;
    /// The engine's sample count now.
    fn now_sample(&self) -> u64;
    /// A reading of the board's work clock (`board::stamp`).
    fn stamp(&self) -> u32;
    /// The board's work since `since`, a [`Link::stamp`] (`board::elapsed`).
    fn elapsed(&self, since: u32) -> u32;
    /// The load cell's counts over the engine's samples `from..=to` at `fs_hz`.
    fn contact_force(&mut self, from: u64, to: u64, fs_hz: f32) -> Option<RawForce>;
    /// DMA transfer errors the board counted since boot ([`crate::counters::DMA_ERRORS`]);
    /// none on a link without DMA.
    fn dma_errors(&self) -> u32 {
        0
    }
}

/// The measurement task's board: its [`Link`]s as the session's point source and event sink,
/// the flash store, and the watchdog's liveness promise it keeps.
pub struct FwIo<'a, L, F> {
    link: L,
    store: &'a mut Store<F>,
    scale: FrontEndScale,
    liveness: &'a Liveness,
    boot_error: Option<BootError>,
    /// When the last window arrived ([`Link::stamp`]), until the next plan is loaded.
    window_at: Option<u32>,
    /// The most work from a window to the next plan's load ([`Io::take_plan_work`]).
    plan_work: u32,
}

impl<'a, L: Link, F: NorFlash> FwIo<'a, L, F> {
    /// The board over `link`, `store` and the converters' `scale`, keeping its promises in
    /// `liveness`; `boot_error` is the board's first failed bring-up step.
    pub fn new(
        link: L,
        store: &'a mut Store<F>,
        scale: FrontEndScale,
        liveness: &'a Liveness,
        boot_error: Option<BootError>,
    ) -> Self {
        Self {
            link,
            store,
            scale,
            liveness,
            boot_error,
            window_at: None,
            plan_work: 0,
        }
    }

    /// The task is alive now and promises its next sign of life within `within`. Not inlined:
    /// the monotonic's reading is a critical section, and six call sites would each carry it.
    #[inline(never)]
    fn promise(&self, within: Millis) {
        self.liveness.promise(self.link.now(), within);
    }

    /// The measurement task: the session's boot (the profile, then the self-test; its outcome
    /// told to the command task, whose QEMU script starts then), then requests served one at a
    /// time for ever, each one's outcome told to the command task. It waits for a request a
    /// feed period at a time ([`watchdog::after_wait`] promised) and promises each command its
    /// work ([`watchdog::before`]); with no command source left it stays alive for the watchdog
    /// and serves nothing.
    pub async fn serve(&mut self) -> ! {
        let mut session = Session::boot(self).await;
        self.link.done(session.selftest_outcome() == Some(Ok(())));
        loop {
            self.promise(watchdog::after_wait(FEED));
            let req = match self.link.request(FEED).await {
                Recv::Got(r) => r,
                Recv::Timeout => continue,
                Recv::Closed => loop {
                    self.promise(watchdog::after_wait(FEED));
                    self.link.delay(FEED).await;
                },
            };
            self.promise(watchdog::before(&req, session.references()));
            let ok = session.handle(req, self).await;
            self.link.served(ok).await;
            self.link.done(ok);
        }
    }
}

impl<L: Link, F: NorFlash> PointSource for FwIo<'_, L, F> {
    fn scale(&self) -> FrontEndScale {
        self.scale
    }
    fn now_sample(&self) -> u64 {
        self.link.now_sample()
    }
    async fn load(&mut self, plan: PointPlan) -> bool {
        if let Some(t0) = self.window_at.take() {
            self.plan_work = self.plan_work.max(self.link.elapsed(t0));
        }
        self.link.plan(Some(plan)).await
    }
    /// Waits for a window [`watchdog::window_wait`] at a time, promised; a stale window (one
    /// `wanted` does not match) is dropped and the wait starts again.
    async fn next(&mut self, wanted: &Wanted, budget: u64) -> Option<PointRaw> {
        let wait = watchdog::window_wait(budget, self.scale.sample_rate.0);
        let got = loop {
            self.promise(watchdog::after_wait(wait));
            match self.link.point(wait).await {
                Some(raw) if wanted.matches(&raw) => break Some(raw),
                Some(_stale) => continue,
                None => break None,
            }
        };
        self.promise(ALIVE);
        self.window_at = Some(self.link.stamp());
        got
    }
    async fn stop(&mut self) {
        self.link.plan(None).await;
    }
    async fn idle(&mut self, samples: u64) {
        self.link.plan(None).await;
        let ms = watchdog::samples_ms(samples, self.scale.sample_rate.0);
        self.promise(watchdog::after_wait(ms));
        self.link.delay(ms).await;
        self.promise(ALIVE);
    }
    fn contact_force(&mut self, from: u64, to: u64) -> Option<RawForce> {
        self.link.contact_force(from, to, self.scale.sample_rate.0)
    }
    fn stall_failure(&self) -> Failure {
        Failure::of_stall(self.link.dma_errors())
    }
    async fn point(&mut self, tag: u16, point: &SweepPoint) {
        self.link.report(Event::Point { tag, point: *point }).await;
    }
}

impl<L: Link, F: NorFlash> Io for FwIo<'_, L, F> {
    /// The event, and the health counters after a reading or a status.
    async fn emit(&mut self, e: Event) {
        self.link.report(e).await;
        if matches!(e, Event::Reading(_) | Event::Status(_)) {
            self.link.counters().await;
        }
    }
    /// Never waits: a full channel drops the event (a stream's reading; its seq gap shows it).
    fn try_emit(&mut self, e: Event) -> bool {
        self.link.try_report(e)
    }
    fn save(&mut self, p: &UnitProfile) -> Result<Saved, StoreError> {
        self.store.save(p)
    }
    fn load_profile(&mut self) -> Loaded {
        self.store.load()
    }
    fn boot_error(&self) -> Option<BootError> {
        self.boot_error
    }
    fn take_plan_work(&mut self) -> Option<u32> {
        self.window_at = None;
        Some(core::mem::take(&mut self.plan_work))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reading::driver::block_on;
    use hal_sim::flash::SimFlash;
    use std::collections::VecDeque;
    use std::vec::Vec;

    type Flash = SimFlash<4096, 2048, 8>;

    /// What the task sent to the report task.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    enum Out {
        Point,
        Reading,
        Status,
        Other,
        Counters,
    }

    fn out(e: &Event) -> Out {
        match e {
            Event::Point { .. } => Out::Point,
            Event::Reading(_) => Out::Reading,
            Event::Status(_) => Out::Status,
            _ => Out::Other,
        }
    }

    /// A scripted link: windows and requests queued by the test, a clock that moves only when
    /// the task waits (a timeout takes its whole time), the work clock set by the test.
    #[derive(Default)]
    struct Script<'l> {
        /// The promise the task keeps, to see which deadline each event was sent under.
        liveness: Option<&'l Liveness>,
        /// Deadlines at the events sent, in order.
        deadlines: Vec<u32>,
        now: u32,
        work: u32,
        points: VecDeque<PointRaw>,
        requests: VecDeque<Command>,
        closed: bool,
        room: bool,
        plans: Vec<Option<PointPlan>>,
        waits: Vec<Millis>,
        delays: Vec<Millis>,
        out: Vec<Out>,
        done: Vec<bool>,
        /// The board's DMA error count ([`Link::dma_errors`]).
        dma_errors: u32,
        /// The events sent, in order.
        events: Vec<Event>,
    }

    impl Link for &mut Script<'_> {
        async fn plan(&mut self, plan: Option<PointPlan>) -> bool {
            self.plans.push(plan);
            true
        }
        async fn point(&mut self, within: Millis) -> Option<PointRaw> {
            self.waits.push(within);
            let p = self.points.pop_front();
            if p.is_none() {
                self.now += within.0;
            }
            p
        }
        /// A request, the end of the commands, or a wait that never ends (the test is done).
        async fn request(&mut self, _: Millis) -> Recv<Command> {
            match self.requests.pop_front() {
                Some(c) => Recv::Got(c),
                None if self.closed => Recv::Closed,
                None => core::future::pending().await,
            }
        }
        fn done(&mut self, ok: bool) {
            self.done.push(ok);
        }
        async fn report(&mut self, e: Event) {
            self.out.push(out(&e));
            self.events.push(e);
            if let Some(l) = self.liveness {
                self.deadlines.push(deadline(l));
            }
        }
        async fn counters(&mut self) {
            self.out.push(Out::Counters);
        }
        fn try_report(&mut self, e: Event) -> bool {
            if self.room {
                self.out.push(out(&e));
            }
            self.room
        }
        /// Once the commands have ended, a wait that never ends (the test is done).
        async fn delay(&mut self, ms: Millis) {
            self.delays.push(ms);
            self.now += ms.0;
            if self.closed {
                core::future::pending::<()>().await;
            }
        }
        fn now(&self) -> Millis {
            Millis(self.now)
        }
        fn now_sample(&self) -> u64 {
            self.now as u64 * 10
        }
        fn stamp(&self) -> u32 {
            self.work
        }
        fn elapsed(&self, since: u32) -> u32 {
            self.work - since
        }
        fn contact_force(&mut self, _: u64, _: u64, _: f32) -> Option<RawForce> {
            None
        }
        fn dma_errors(&self) -> u32 {
            self.dma_errors
        }
    }

    fn plan(tag: u16) -> PointPlan {
        PointPlan {
            ftw: crate::dsp::dds::tuning_word(240.0, 10_000.0),
            amplitude_codes: 800,
            settle_samples: 10,
            cycles: 4,
            windows: 1,
            open: false,
            aligned: false,
            tag,
        }
    }

    fn window(plan: PointPlan) -> PointRaw {
        PointRaw {
            plan,
            sums: Default::default(),
            end_sample: 0,
            window: 0,
            since_load: 0,
            start_phase: 0,
            quiet_before: 0,
        }
    }

    /// The board over `link` with an empty store, at the probe's 10 kHz.
    fn with<L: Link, R>(
        link: L,
        liveness: &Liveness,
        f: impl FnOnce(&mut FwIo<'_, L, Flash>) -> R,
    ) -> R {
        let mut store = Store::new(Flash::new(), 0).expect("store geometry");
        let mut io = FwIo::new(link, &mut store, FrontEndScale::PROBE, liveness, None);
        f(&mut io)
    }

    /// The deadline of the last promise: alive up to it, not a ms later.
    fn deadline(l: &Liveness) -> u32 {
        let mut t = 0u32;
        while l.alive(Millis(t)) {
            t += 1;
        }
        t - 1
    }

    #[test]
    fn a_receive_within_a_timeout() {
        assert_eq!(Recv::of::<(), ()>(Ok(Ok(3))), Recv::Got(3));
        assert_eq!(Recv::<u8>::of::<(), ()>(Ok(Err(()))), Recv::Closed);
        assert_eq!(Recv::<u8>::of::<(), ()>(Err(())), Recv::Timeout);
    }

    #[test]
    fn a_window_wait_drops_stale_windows_and_promises_each_wait() {
        let (a, b) = (plan(1), plan(2));
        let mut link = Script {
            now: 50,
            points: [window(b), window(a)].into(),
            ..Default::default()
        };
        let l = Liveness::new(Millis(0));
        let got = with(&mut link, &l, |io| {
            block_on(io.next(&Wanted::plan(a), 1_000))
        });
        assert_eq!(got, Some(window(a)), "the stale window of plan 2 dropped");
        // 1 000 samples at 10 kHz and a feed period: one wait per window taken.
        assert_eq!(link.waits, [Millis(200), Millis(200)]);
        assert_eq!(deadline(&l), 50 + ALIVE.0, "alive again after the window");

        // Nothing comes: a stall after one whole wait, promised for its length.
        let l = Liveness::new(Millis(0));
        let got = with(&mut link, &l, |io| {
            block_on(io.next(&Wanted::plan(a), 1_000))
        });
        assert_eq!(got, None);
        assert_eq!(link.now, 250);
        assert_eq!(deadline(&l), 250 + ALIVE.0);
    }

    #[test]
    fn the_plan_work_is_the_most_from_a_window_to_the_next_load() {
        let a = plan(1);
        let mut link = Script::default();
        let l = Liveness::new(Millis(0));
        let work = with(&mut link, &l, |io| {
            let mut seen = Vec::new();
            for (at_window, at_load) in [(100, 350), (400, 450)] {
                io.link.points.push_back(window(a));
                io.link.work = at_window;
                block_on(io.next(&Wanted::plan(a), 1_000));
                io.link.work = at_load;
                assert!(block_on(io.load(a)));
            }
            seen.push(io.take_plan_work());
            seen.push(io.take_plan_work());
            // A load without a window before it since the last take measures nothing.
            io.link.points.push_back(window(a));
            block_on(io.next(&Wanted::plan(a), 1_000));
            let _ = io.take_plan_work();
            io.link.work = 10_000;
            block_on(io.load(a));
            seen.push(io.take_plan_work());
            seen
        });
        assert_eq!(work, [Some(250), Some(0), Some(0)]);
        assert_eq!(link.plans, [Some(a), Some(a), Some(a)]);
    }

    #[test]
    fn events_go_to_the_report_task_and_the_counters_after_readings_and_status() {
        let mut link = Script::default();
        let l = Liveness::new(Millis(0));
        with(&mut link, &l, |io| {
            let r = crate::reading::Reading::failed(
                crate::reading::Method::Hold,
                crate::status::Failure::DriveFault,
                crate::units::Seconds(0.0),
                0,
            );
            block_on(io.emit(Event::Reading(r)));
            block_on(io.emit(Event::Stalled(3)));
            block_on(PointSource::point(io, 3, &SweepPoint::default()));
            assert!(!io.try_emit(Event::Stalled(4)), "no room: dropped");
            io.link.room = true;
            assert!(io.try_emit(Event::Stalled(5)));
        });
        assert_eq!(
            link.out,
            [
                Out::Reading,
                Out::Counters,
                Out::Other,
                Out::Point,
                Out::Other
            ]
        );
    }

    /// A reading on a stream that delivers no window stalls; it is `dma_error` once the board
    /// counted a DMA transfer error, `drive_fault` otherwise, for each method.
    #[test]
    fn a_stall_after_a_dma_error_is_the_dmas_failure() {
        use crate::reading::{driver::read, Method};
        let unit = crate::board::sim_factory::profile().expect("factory record");
        for method in Method::ALL {
            for (errors, want) in [(0, Failure::DriveFault), (2, Failure::DmaError)] {
                let mut link = Script {
                    dma_errors: errors,
                    ..Default::default()
                };
                let l = Liveness::new(Millis(0));
                let (r, stops) = with(&mut link, &l, |io| {
                    let mut stops = 0;
                    let settings = method.default_settings();
                    let r = block_on(read(
                        io,
                        method,
                        &settings,
                        &unit,
                        |_, _| {},
                        |_| stops += 1,
                    ));
                    (r, stops)
                });
                assert_eq!(
                    r.status,
                    crate::status::Status::Failed(want),
                    "{method:?}, {errors} errors"
                );
                assert_eq!(stops, 1, "{method:?}: the stall is heard once");
            }
        }
        // The stream's first reading on such a stream: the same failure.
        for (errors, want) in [(0, Failure::DriveFault), (1, Failure::DmaError)] {
            let mut link = Script {
                dma_errors: errors,
                ..Default::default()
            };
            let l = Liveness::new(Millis(0));
            let got = with(&mut link, &l, |io| {
                let mut slot = None;
                crate::instrument::continuous::TrackerConfig::DEFAULT
                    .validate_into(&io.scale(), &unit, &mut slot)
                    .expect("default tracker");
                let tracker = slot.as_mut().expect("tracker");
                let mut got = None;
                block_on(crate::instrument::continuous::run(
                    io,
                    tracker,
                    &unit,
                    |r| {
                        got = Some(r.reading.status);
                        false
                    },
                ));
                got
            });
            assert_eq!(
                got,
                Some(crate::status::Status::Failed(want)),
                "stream, {errors} errors"
            );
        }
    }

    /// `air` on a stream a DMA error stopped: refused as `dma_error`, the air reference kept.
    #[test]
    fn air_after_a_dma_error_is_refused_as_the_dmas_failure() {
        use crate::instrument::session::Refusal;
        use crate::unit::store::{LoadSource, SlotState};
        let loaded = Loaded {
            record: crate::board::sim_factory::profile().expect("factory record"),
            source: LoadSource::Stored {
                slot: 0,
                seq: 1,
                other: SlotState::Empty,
            },
        };
        let mut link = Script {
            dma_errors: 1,
            ..Default::default()
        };
        let l = Liveness::new(Millis(0));
        let (served, kept) = with(&mut link, &l, |io| {
            let mut s = Session::new(&loaded);
            let served = block_on(s.handle(Command::Air, io));
            (served, s.profile().air == loaded.record.air)
        });
        assert!(!served);
        assert!(kept, "the air reference was replaced");
        assert_eq!(
            link.events.last(),
            Some(&Event::Refused(Refusal::Air(Failure::DmaError)))
        );
    }

    #[test]
    fn idle_stops_the_drive_and_promises_its_wait() {
        let mut link = Script::default();
        let l = Liveness::new(Millis(0));
        with(&mut link, &l, |io| block_on(io.idle(5_000)));
        assert_eq!(link.plans, [None]);
        assert_eq!(link.delays, [Millis(500)]);
        assert_eq!(deadline(&l), 500 + ALIVE.0);
    }

    /// Polls `f` once: it must be waiting then (for a request that never comes).
    fn poll_once<F: core::future::Future>(f: F) {
        let mut f = core::pin::pin!(f);
        let mut cx = core::task::Context::from_waker(core::task::Waker::noop());
        assert!(f.as_mut().poll(&mut cx).is_pending());
    }

    #[test]
    fn the_task_boots_then_serves_each_request_under_its_promise() {
        let l = Liveness::new(Millis(0));
        let mut link = Script {
            liveness: Some(&l),
            requests: [Command::Status, Command::CalibrateFit].into(),
            ..Default::default()
        };
        with(&mut link, &l, |io| poll_once(io.serve()));
        // The self-test stalls on a probe that sends no windows: `false`, then the requests'.
        assert_eq!(link.done, [false, true, false]);
        // `status` is promised its own work, `calibrate fit` (no references) its bound.
        let status = link
            .out
            .iter()
            .position(|o| *o == Out::Status)
            .expect("status");
        let t = link.now;
        assert_eq!(link.deadlines[status], t + ALIVE.0);
        assert_eq!(link.deadlines.last(), Some(&(t + watchdog::fit_bound(0).0)));
        assert_eq!(link.out[status + 1], Out::Counters);
        // Waiting for the next request, promised a feed period and the work after it.
        assert_eq!(deadline(&l), t + watchdog::after_wait(FEED).0);
    }

    #[test]
    fn without_a_command_source_the_task_stays_alive_and_serves_nothing() {
        let l = Liveness::new(Millis(0));
        let mut link = Script {
            closed: true,
            ..Default::default()
        };
        with(&mut link, &l, |io| poll_once(io.serve()));
        assert_eq!(link.done, [false], "the self-test's only");
        assert_eq!(link.delays, [FEED]);
        assert_eq!(
            deadline(&l),
            link.now - FEED.0 + watchdog::after_wait(FEED).0
        );
    }

    /// The sample interrupt and the load cell on the simulated probe, one batch at a time: the
    /// engine runs ahead of the task only while it waits.
    #[cfg(feature = "sim")]
    struct SimLink {
        board: crate::board::sim::SimBoard,
        engine: crate::engine::SampleEngine,
        points: VecDeque<PointRaw>,
        requests: VecDeque<Command>,
        /// One feed period without a request still to come.
        idle: bool,
        done: Vec<bool>,
        out: Vec<Out>,
    }

    #[cfg(feature = "sim")]
    impl SimLink {
        fn batch(&mut self) {
            use crate::engine::BATCH;
            use crate::hal::{AdcFrame, SampleStream};
            let mut dac = [crate::units::DacCode::MID; BATCH];
            let mut adc = [AdcFrame::default(); BATCH];
            self.engine.generate(&mut dac);
            if self.board.exchange(&dac, &mut adc) == Ok(true) {
                self.points.extend(self.engine.demodulate(&adc));
            }
        }
        fn run(&mut self, ms: Millis) {
            let end = self.engine.samples() + ms.0 as u64 * 10;
            while self.engine.samples() < end {
                self.batch();
            }
        }
    }

    #[cfg(feature = "sim")]
    impl Link for &mut SimLink {
        async fn plan(&mut self, plan: Option<PointPlan>) -> bool {
            match plan {
                Some(p) => self.engine.load(p),
                None => self.engine.stop(),
            }
            true
        }
        async fn point(&mut self, within: Millis) -> Option<PointRaw> {
            let end = self.engine.samples() + within.0 as u64 * 10;
            while self.points.is_empty() && self.engine.samples() < end {
                self.batch();
            }
            self.points.pop_front()
        }
        /// A request, a feed period with none, then a wait that never ends (the test is done).
        async fn request(&mut self, within: Millis) -> Recv<Command> {
            if let Some(c) = self.requests.pop_front() {
                return Recv::Got(c);
            }
            if self.idle {
                self.idle = false;
                self.run(within);
                return Recv::Timeout;
            }
            core::future::pending().await
        }
        fn done(&mut self, ok: bool) {
            self.done.push(ok);
        }
        async fn report(&mut self, e: Event) {
            self.out.push(out(&e));
        }
        async fn counters(&mut self) {
            self.out.push(Out::Counters);
        }
        fn try_report(&mut self, e: Event) -> bool {
            self.out.push(out(&e));
            true
        }
        async fn delay(&mut self, ms: Millis) {
            self.run(ms);
            self.points.clear();
        }
        fn now(&self) -> Millis {
            Millis((self.engine.samples() / 10) as u32)
        }
        fn now_sample(&self) -> u64 {
            self.engine.samples()
        }
        fn stamp(&self) -> u32 {
            0
        }
        fn elapsed(&self, _: u32) -> u32 {
            0
        }
        fn contact_force(&mut self, from: u64, to: u64, _: f32) -> Option<RawForce> {
            crate::loadcell::ForceSource::contact_force(&self.board, from, to)
        }
    }

    /// The factory-calibrated simulated unit on phantom B, through the firmware's board: the
    /// power-on self-test passes (and the command task hears so), `measure` reads, the
    /// reading is followed by the counters, and the task waits on for requests.
    #[cfg(feature = "sim")]
    #[test]
    fn the_task_boots_and_measures_on_the_simulated_probe() {
        use hal_sim::{phantoms, NoiseScene, Scene, SimProbe};
        let scene = Scene::on_phantom(&phantoms::B).with_noise(NoiseScene::Bench);
        let mut link = SimLink {
            board: crate::board::sim::SimBoard::new(SimProbe::new(scene, 1)),
            engine: crate::engine::SampleEngine::new(),
            points: VecDeque::new(),
            requests: [Command::Measure].into(),
            idle: true,
            done: Vec::new(),
            out: Vec::new(),
        };
        let mut store = Store::new(Flash::new(), 0).expect("store geometry");
        let factory = crate::board::sim_factory::profile().expect("factory record");
        store.save(&factory).expect("store");
        let scale = crate::board::sim::scale_of(&scene.front_end);
        let l = Liveness::new(Millis(0));
        poll_once(FwIo::new(&mut link, &mut store, scale, &l, None).serve());
        assert_eq!(link.done, [true, true]);
        assert!(!link.idle, "served a feed period without a request");
        let i = link
            .out
            .iter()
            .position(|o| *o == Out::Reading)
            .expect("a reading");
        assert_eq!(link.out[i + 1], Out::Counters);
    }
}
