//! The probe's firmware: the RTIC 2 application.
//!
//! One image, two boards: `--features stm32` for the STM32G474RE (NUCLEO-G474RE) and
//! `--features qemu` for QEMU's mps2-an386 with the simulated probe; both built for
//! `thumbv7em-none-eabihf` with `--no-default-features` (see `docs/firmware.md`). On the host
//! this file compiles to an empty `main` so workspace builds and tests stay simple.
//!
//! # Tasks
//!
//! | task | priority | what |
//! |---|---|---|
//! | `sample` (hardware) | 3 | per batch: demodulate the ADC half, refill the DAC half ([`pzt_probe::engine::SampleEngine`]) |
//! | `uart_rx` (hardware) | 2 | host bytes from LPUART1's DMA ring (ST-LINK virtual COM port) into a channel |
//! | `measure` | 1 | the session ([`pzt_probe::instrument::session`]): profile, settings, the flash store; readings through [`pzt_probe::reading::driver`] |
//! | `command` | 1 | bytes → lines → [`pzt_probe::instrument::command::parse`] → requests to `measure` (QEMU: the boot command line's script or the built-in one, [`pzt_probe::board::sim_script`]) |
//! | `report` | 1 | the only place that logs: one defmt line per event (`pzt_probe::instrument::log`) |
//! | `load_cell` | 1 | every 5 ms: the HX711's conversion, if one is ready (80 a second), into the shared force log, stamped with the sample count |
//! | `guard` | 2 | feeds the independent watchdog every 100 ms while `measure` keeps its liveness promise ([`pzt_probe::instrument::watchdog`]) |
//!
//! Data flow: `command` → requests → `measure` → plans (capacity 2: the double buffer of the
//! interrupt's settings, validated before they reach it) → `sample` → points → `measure` →
//! reports → `report`; the path of one reading is in `docs/architecture.md`, the log lines in
//! `pzt_probe::instrument::log`. A stream's readings (`stream <seconds>`) go to the report channel with
//! `try_send` ([`Io::try_emit`](pzt_probe::instrument::session::Io::try_emit)): a full channel drops the
//! reading (a gap in its `seq`, counted in the `stream end` line) rather than hold up the
//! measurement task's next plan; the sample interrupt never waits on anything.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(all(target_os = "none", not(any(feature = "stm32", feature = "qemu"))))]
compile_error!("the firmware image needs feature `stm32` or `qemu` (with --no-default-features)");

#[cfg(all(target_os = "none", feature = "qemu"))]
use pzt_probe::board::qemu as board;
#[cfg(all(target_os = "none", feature = "stm32"))]
use pzt_probe::board::stm32g474 as board;

// The boards' defmt loggers, panic handlers and fault handlers are in their modules
// (`pzt_probe::board::qemu`, `pzt_probe::board::stm32g474`).

#[cfg(target_os = "none")]
mod shared {
    //! Types and counters shared by the tasks.

    use pzt_probe::engine::PointPlan;

    /// What the measurement task asks of the interrupt: a plan to load, or `None` to stop.
    pub type EngineCmd = Option<PointPlan>;

    pub use pzt_probe::instrument::log::Report;

    use pzt_probe::instrument::watchdog::{Liveness, Millis};

    /// The measurement task's liveness promise, kept by `measure`, read by `guard`. The first
    /// promise covers the boot up to the measurement task's first sign of life (the monotonic
    /// starts at 0 in `init`).
    pub static LIVENESS: Liveness = Liveness::new(Millis(1_000));
}

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::device, peripherals = false, dispatchers = [SPI3, SPI2])]
mod app {
    use crate::board;
    use crate::shared::*;
    use core::sync::atomic::Ordering;
    use pzt_probe::counters::*;
    use pzt_probe::engine::BATCH;
    use pzt_probe::engine::{PointPlan, PointRaw, SampleEngine};
    use pzt_probe::hal::FrontEndScale;
    use pzt_probe::instrument::command::Command;
    use pzt_probe::instrument::session::{Event, Io, Session};
    use pzt_probe::instrument::watchdog::{fit_bound, Millis};
    use pzt_probe::loadcell::ForceLog;
    use pzt_probe::reading::driver::{PointSource, Wanted};
    use pzt_probe::unit::store::{Loaded, Saved, Store, StoreError};
    use pzt_probe::UnitProfile;
    use rtic_monotonics::systick::prelude::*;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    systick_monotonic!(Mono, 1_000);

    const PLAN_CAP: usize = 2;
    const POINT_CAP: usize = 4;
    const REQUEST_CAP: usize = 4;
    /// Reports buffered between the tasks and the report task (11: the static RAM budget of
    /// 55 KiB, scripts/ci-firmware, keeps the stack 41 KiB; a stream's reading that finds the
    /// channel full is dropped and counted, never waited for).
    const REPORT_CAP: usize = 11;
    const DONE_CAP: usize = 1;
    /// Received bytes buffered between the UART interrupt and the command task (STM32).
    const RX_CAP: usize = 64;
    /// The guard task feeds the watchdog this often while the measurement task keeps its
    /// promise; the measurement task wakes at least this often while it waits for requests (ms).
    const FEED_MS: u32 = 100;
    /// After a `sim` line of the QEMU script, the command task waits this long (ms): two
    /// batches, so that the sample interrupt has put the probe on its new scene.
    #[cfg(feature = "qemu")]
    const SCENE_SETTLE_MS: u32 = 10;
    /// The load-cell task looks for a conversion this often (ms): above the HX711's 80 a
    /// second, so each is read before the next overwrites it.
    const LOAD_CELL_POLL_MS: u32 = 5;
    /// What the measurement task promises between signs of life outside waits and the fit: a
    /// measurement call's work (at most 100 ms, `tests/qemu_cost.rs`), a store's flash erase
    /// and program, and the other priority-1 tasks' turns, with room to spare (ms).
    const ALIVE_MS: u32 = 3 * FEED_MS;

    /// The QEMU image has no host link: it runs this script through the same line parser — a
    /// reading with the default method (auto), one with sweep-G over a sweep of its own, back to
    /// auto with two-stage settings of its own, store, status.
    #[cfg(feature = "qemu")]
    const SCRIPT: &str = "status;measure;method sweep-g;sweep 200 260 2 0.02 0.03 5;measure;method auto;staged 180 280 6 0.02 0.03 5 0.8 5 4;store;status";

    /// The load cell's conversions, stamped with the engine's sample count: written by
    /// `load_cell`, read by `measure` for each reading's window.
    #[shared]
    struct Shared {
        forces: &'static mut ForceLog,
    }

    #[local]
    struct Local {
        stream: board::Stream,
        engine: SampleEngine,
        plan_rx: Receiver<'static, EngineCmd, PLAN_CAP>,
        point_tx: Sender<'static, PointRaw, POINT_CAP>,
        isr: BatchStats,
        watchdog: board::Watchdog,
        store: Store<board::StoreFlash>,
        scale: FrontEndScale,
        uart: board::Uart,
        rx_tx: Sender<'static, u8, RX_CAP>,
        load_cell: Option<board::LoadCell>,
    }

    // The force log lives in init's static (1.5 KiB), not on its stack: the shared resource is
    // a reference to it.
    #[init(local = [forces: ForceLog = ForceLog::new()])]
    fn init(mut cx: init::Context) -> (Shared, Local) {
        let parts = board::init(&mut cx.core);
        Mono::start(cx.core.SYST, board::SYSCLK_HZ);
        // SysTick below the sample interrupt so the timer queue never delays a batch.
        // SAFETY: priorities are set before any task runs.
        unsafe {
            cx.core.SCB.set_priority(
                cortex_m::peripheral::scb::SystemHandler::SysTick,
                pzt_probe::board::nvic_priority(2, board::device::NVIC_PRIO_BITS),
            );
        }

        let (plan_tx, plan_rx) = make_channel!(EngineCmd, PLAN_CAP);
        let (point_tx, point_rx) = make_channel!(PointRaw, POINT_CAP);
        let (request_tx, request_rx) = make_channel!(Command, REQUEST_CAP);
        let (report_tx, report_rx) = make_channel!(Report, REPORT_CAP);
        let (done_tx, done_rx) = make_channel!(bool, DONE_CAP);

        let mut stream = parts.stream;
        let scale = stream.scale();
        let mut engine = SampleEngine::new();
        stream.start(&mut engine);
        defmt::info!(
            "boot board={=str} fs_hz={=f32} batch={=u32}",
            board::NAME,
            scale.sample_rate.0,
            BATCH as u32
        );
        // A bring-up step that failed (bounded waits, docs/firmware.md): said, not a reset loop.
        if let Some(e) = board::boot_error() {
            let clock = board::clock_name();
            defmt::error!("boot fault={=str} clock={=str}", e.code(), clock);
        }

        let store = match Store::new(parts.flash, board::STORE_BASE) {
            Ok(s) => s,
            Err(_) => defmt::panic!("store geometry"),
        };

        guard::spawn().ok();
        measure::spawn(request_rx, plan_tx, point_rx, report_tx.clone(), done_tx).ok();
        report::spawn(report_rx).ok();
        load_cell::spawn().ok();

        let (rx_tx, rx_rx) = make_channel!(u8, RX_CAP);
        command::spawn(request_tx, report_tx, done_rx, rx_rx).ok();

        (
            Shared {
                forces: cx.local.forces,
            },
            Local {
                stream,
                engine,
                plan_rx,
                point_tx,
                isr: BatchStats::default(),
                watchdog: parts.watchdog,
                store,
                scale,
                uart: parts.uart,
                rx_tx,
                load_cell: parts.load_cell,
            },
        )
    }

    /// Runs when no task has work: sleep until the next interrupt.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        // The stack's high-water mark of the running tasks and interrupts apart from the
        // boot's (`stack` line): paint again below this frame.
        pzt_probe::stack::repaint();
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// The sample interrupt: one batch ([`BATCH`] samples, 2.5 ms at 10 kHz) per call.
    ///
    /// Bound to the ADC DMA half/full-transfer interrupt `DMA1_CHANNEL1` on the STM32; on QEMU the
    /// same vector is the batch timer, whose driver first emulates the DMA of the period. It
    /// takes any queued plan (`Load`/`Stop`) from the plan channel, demodulates the ADC
    /// half-buffer just captured ([`SampleEngine::demodulate`]), refills the DAC half-buffer
    /// just played ([`SampleEngine::generate`], which applies the plan phase-continuously) and
    /// hands a finished point to the measurement task with a non-blocking send. It never logs,
    /// allocates or waits.
    ///
    /// **Budget** 2 % of the core per batch (17 000 cycles at 170 MHz); **overruns** (late
    /// batch, ring, full point channel) are counted ([`pzt_probe::counters`]) and reported,
    /// never silent: `docs/firmware.md`.
    #[task(binds = DMA1_CHANNEL1, priority = 3, local = [stream, engine, plan_rx, point_tx, isr])]
    fn sample(cx: sample::Context) {
        let stream = cx.local.stream;
        let engine = cx.local.engine;
        let (adc, dac) = stream.capture();
        let t0 = board::stamp();
        while let Ok(cmd) = cx.local.plan_rx.try_recv() {
            match cmd {
                Some(plan) => engine.load(plan),
                None => engine.stop(),
            }
        }
        let points = engine.demodulate(adc);
        engine.generate(dac);
        for p in points {
            if cx.local.point_tx.try_send(p).is_err() {
                DROPPED.fetch_add(1, Ordering::Relaxed);
            }
        }
        cx.local
            .isr
            .batch(board::elapsed(t0), engine.overruns(), stream.late());
    }

    /// Host bytes from the UART into the command task's channel.
    #[task(binds = LPUART1, priority = 2, local = [uart, rx_tx])]
    fn uart_rx(cx: uart_rx::Context) {
        while let Some(b) = cx.local.uart.read_byte() {
            // A full channel drops the byte; the line then fails to parse and is reported.
            let _ = cx.local.rx_tx.try_send(b);
        }
    }

    /// The engine's sample count now: the time base of readings and of the force log.
    fn now_sample() -> u64 {
        BATCHES.load(Ordering::Relaxed) as u64 * BATCH as u64
    }

    /// The load-cell task: a conversion of the HX711, when one is ready, into the force log.
    /// The read (25 clock pulses, about 50 µs) runs with interrupts masked: a pulse stretched
    /// past 60 µs by the sample interrupt would power the chip down and lose the conversion
    /// (`src/loadcell.rs`). Driver errors are counted, never logged from here.
    #[task(priority = 1, shared = [forces], local = [load_cell])]
    async fn load_cell(mut cx: load_cell::Context) {
        let Some(hx) = cx.local.load_cell.as_mut() else {
            return;
        };
        loop {
            Mono::delay(LOAD_CELL_POLL_MS.millis()).await;
            match cortex_m::interrupt::free(|_| hx.read()) {
                Ok(Some(c)) => {
                    let at = now_sample();
                    cx.shared.forces.lock(|f| f.push(at, c));
                }
                Ok(None) => {}
                Err(_) => {
                    LOAD_CELL_ERRORS.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// The measurement task's board: the interrupt's channels as the session's point source,
    /// the force log, the flash store, the report channel as its event sink.
    struct FwIo<'a, F> {
        plans: &'a mut Sender<'static, EngineCmd, PLAN_CAP>,
        points: &'a mut Receiver<'static, PointRaw, POINT_CAP>,
        reports: &'a mut Sender<'static, Report, REPORT_CAP>,
        store: &'a mut Store<board::StoreFlash>,
        scale: FrontEndScale,
        forces: F,
        /// When the last window arrived (`board::stamp`), until the next plan is loaded.
        window_at: Option<u32>,
        /// The most work from a window to the next plan's load ([`Io::take_plan_work`]).
        plan_work: u32,
    }

    impl<F: rtic::Mutex<T = &'static mut ForceLog>> PointSource for FwIo<'_, F> {
        fn scale(&self) -> FrontEndScale {
            self.scale
        }
        /// The interrupt's double buffer: a plan applies from the batch after the one playing.
        fn latency_batches(&self) -> usize {
            pzt_probe::engine::PIPELINE_BATCHES
        }
        fn now_sample(&self) -> u64 {
            now_sample()
        }
        async fn load(&mut self, plan: PointPlan) -> bool {
            if let Some(t0) = self.window_at.take() {
                self.plan_work = self.plan_work.max(board::elapsed(t0));
            }
            self.plans.send(Some(plan)).await.is_ok()
        }
        async fn next(&mut self, wanted: &Wanted, budget: u64) -> Option<PointRaw> {
            // The budget in ms, with a watchdog period of margin for this task's own delay.
            let ms = (budget as f32 / self.scale.sample_rate.0 * 1000.0) as u32 + FEED_MS;
            let got = loop {
                promise(ms + ALIVE_MS);
                match Mono::timeout_after(ms.millis(), self.points.recv()).await {
                    Ok(Ok(raw)) if wanted.matches(&raw) => break Some(raw),
                    Ok(Ok(_stale)) => continue,
                    _ => break None,
                }
            };
            promise(ALIVE_MS);
            self.window_at = Some(board::stamp());
            got
        }
        async fn stop(&mut self) {
            let _ = self.plans.send(None).await;
        }
        async fn idle(&mut self, samples: u64) {
            let _ = self.plans.send(None).await;
            let ms = (samples as f32 / self.scale.sample_rate.0 * 1000.0) as u32;
            promise(ms + ALIVE_MS);
            Mono::delay(ms.millis()).await;
            promise(ALIVE_MS);
        }
        fn contact_force(&mut self, from: u64, to: u64) -> Option<pzt_probe::loadcell::RawForce> {
            let fs = self.scale.sample_rate.0;
            self.forces.lock(|f| f.over(from, to, fs))
        }
        async fn point(&mut self, tag: u16, point: &pzt_probe::engine::sweep::SweepPoint) {
            let e = Event::Point { tag, point: *point };
            let _ = self.reports.send(Report::Event(e)).await;
        }
    }

    impl<F: rtic::Mutex<T = &'static mut ForceLog>> Io for FwIo<'_, F> {
        async fn emit(&mut self, e: Event) {
            // The report task only ends with the image; a closed channel is not an error here.
            let _ = self.reports.send(Report::Event(e)).await;
            if matches!(e, Event::Reading(_) | Event::Status { .. }) {
                let _ = self.reports.send(Report::Counters).await;
            }
        }
        fn try_emit(&mut self, e: Event) -> bool {
            // Never waits: a full channel drops the event (a stream's reading; its seq gap
            // shows it).
            self.reports.try_send(Report::Event(e)).is_ok()
        }
        fn save(&mut self, p: &UnitProfile) -> Result<Saved, StoreError> {
            self.store.save(p)
        }
        fn load_profile(&mut self) -> Loaded {
            self.store.load()
        }
        fn boot_error(&self) -> Option<pzt_probe::boot::BootError> {
            board::boot_error()
        }
        fn take_plan_work(&mut self) -> Option<u32> {
            self.window_at = None;
            Some(core::mem::take(&mut self.plan_work))
        }
    }

    /// The monotonic's time in ms (`Mono` ticks at 1 kHz).
    fn now() -> Millis {
        use rtic_monotonics::rtic_time::monotonic::TimerQueueBasedInstant;
        Millis(Mono::now().ticks())
    }

    /// The measurement task is alive now and promises its next sign of life within `ms`.
    fn promise(ms: u32) {
        LIVENESS.promise(now(), Millis(ms));
    }

    /// The watchdog's guard: every [`FEED_MS`] it feeds the independent watchdog, as long as
    /// the measurement task keeps its liveness promise ([`pzt_probe::instrument::watchdog`]). Above the
    /// measurement task's priority, so it runs through a long `calibrate fit`; a measurement
    /// task that hangs breaks its promise, the feeding stops and the watchdog resets the core.
    #[task(priority = 2, local = [watchdog])]
    async fn guard(cx: guard::Context) {
        loop {
            if LIVENESS.alive(now()) {
                cx.local.watchdog.feed();
            } else {
                cx.local.watchdog.starved();
            }
            Mono::delay(FEED_MS.millis()).await;
        }
    }

    /// The measurement task: the session (src/session.rs) served one request at a time; it
    /// keeps the watchdog's liveness promise (`guard`) while alive.
    #[task(priority = 1, shared = [forces], local = [store, scale])]
    async fn measure(
        cx: measure::Context,
        mut requests: Receiver<'static, Command, REQUEST_CAP>,
        mut plans: Sender<'static, EngineCmd, PLAN_CAP>,
        mut points: Receiver<'static, PointRaw, POINT_CAP>,
        mut reports: Sender<'static, Report, REPORT_CAP>,
        mut done: Sender<'static, bool, DONE_CAP>,
    ) {
        let mut io = FwIo {
            plans: &mut plans,
            points: &mut points,
            reports: &mut reports,
            store: cx.local.store,
            scale: *cx.local.scale,
            forces: cx.shared.forces,
            window_at: None,
            plan_work: 0,
        };
        // Power-on: the profile, then the self-test (every reading refused while it fails).
        let mut session = Session::boot(&mut io).await;
        // The QEMU script starts once the boot is done; elsewhere the slot just stays full.
        let _ = done.try_send(session.selftest_outcome() == Some(Ok(())));
        loop {
            promise(FEED_MS + ALIVE_MS);
            let req = match Mono::timeout_after(FEED_MS.millis(), requests.recv()).await {
                Ok(Ok(r)) => r,
                Ok(Err(_)) => {
                    // No command source any more: stay alive for the watchdog, serve nothing.
                    loop {
                        promise(FEED_MS + ALIVE_MS);
                        Mono::delay(FEED_MS.millis()).await;
                    }
                }
                Err(_) => continue,
            };
            // The fit's synchronous work grows with the references held: 2.2 s on the M4 for
            // 10, up to 4.5 minutes for 32 (docs/firmware.md); bounded, so promised.
            promise(match req {
                Command::CalibrateFit => fit_bound(session.references()).0,
                _ => ALIVE_MS,
            });
            let ok = session.handle(req, &mut io).await;
            // Only the QEMU script waits for this; elsewhere the slot just stays full.
            let _ = done.try_send(ok);
        }
    }

    /// The command task: host bytes → lines → requests, one request at a time.
    ///
    /// On QEMU there is no host on the line: the task runs the boot command line's script (or
    /// the built-in [`SCRIPT`]), waits for each request to finish, then ends the run with
    /// success iff every request succeeded and no overrun happened.
    #[task(priority = 1)]
    async fn command(
        _cx: command::Context,
        mut requests: Sender<'static, Command, REQUEST_CAP>,
        mut reports: Sender<'static, Report, REPORT_CAP>,
        mut done: Receiver<'static, bool, DONE_CAP>,
        rx: Receiver<'static, u8, RX_CAP>,
    ) {
        let scale = board::scale();
        #[cfg(feature = "qemu")]
        {
            use pzt_probe::board::sim_script::{lines, step, Step};
            // The boot command line's script, else the built-in one: `sim` lines move the
            // simulated probe, the others are parsed as host lines are.
            let mut cmdline = [0u8; board::CMDLINE_MAX];
            let script = board::boot_script(&mut cmdline).unwrap_or(SCRIPT);
            let mut sim = board::sim_state();
            // After the power-on self-test (on the script's leading `sim` lines' scene).
            let mut ok = done.recv().await.unwrap_or(false);
            for line in lines(script) {
                match step(line, &mut sim, &scale) {
                    Step::Sim => {
                        board::set_scene(sim.scene(), sim.seed);
                        // The probe is on its new scene from the next batch: the next command's
                        // reading starts after it (a hand presses, then asks), so its force
                        // window does not straddle the change.
                        Mono::delay(SCENE_SETTLE_MS.millis()).await;
                    }
                    Step::Command(c) if requests.send(c).await.is_ok() => {
                        ok &= done.recv().await.unwrap_or(false);
                    }
                    Step::Command(_) => ok = false,
                    Step::BadSim(e) => {
                        let _ = reports.send(Report::Rejected(e.message())).await;
                        ok = false;
                    }
                    Step::BadCommand(e) => {
                        let _ = reports.send(Report::Rejected(e.message())).await;
                        ok = false;
                    }
                }
            }
            ok &= !Overruns::now().any();
            let _ = reports.send(Report::Exit(ok)).await;
            drop(rx);
        }
        #[cfg(not(feature = "qemu"))]
        let (mut rx, mut lines) = (rx, pzt_probe::instrument::command::LineBuffer::new());
        #[cfg(not(feature = "qemu"))]
        while let Ok(b) = rx.recv().await {
            // A stale completion from an earlier request is of no interest here.
            let _ = done.try_recv();
            // A parse error is reported and the line dropped.
            match lines
                .push(b)
                .map(|l| l.and_then(|l| pzt_probe::instrument::command::parse(l, &scale)))
            {
                Some(Ok(c)) => {
                    let _ = requests.send(c).await;
                }
                Some(Err(e)) => {
                    let _ = reports.send(Report::Rejected(e.message())).await;
                }
                None => {}
            }
        }
    }

    /// The report task: the only task that logs. Formats are listed in the crate docs.
    #[task(priority = 1)]
    async fn report(_cx: report::Context, mut rx: Receiver<'static, Report, REPORT_CAP>) {
        let mut seen = Overruns::default();
        while let Ok(r) = rx.recv().await {
            #[allow(unused_variables)] // the exit status ends only the QEMU image
            if let Some(ok) = pzt_probe::instrument::log::report(r, board::ELAPSED_UNIT, &mut seen)
            {
                #[cfg(feature = "qemu")]
                board::exit(ok);
            }
        }
    }
}
