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
//! | `measure` | 1 | the session ([`pzt_probe::instrument::session`]): profile, settings, the flash store; readings through [`pzt_probe::reading::driver`]; the task's board and loop are [`pzt_probe::instrument::measure`], over the links here |
//! | `command` | 1 | the host link's receive side: bytes → frames → [`pzt_probe::instrument::command::parse`] → requests to `measure`, each answered ([`pzt_probe::instrument::link`], `docs/protocol.md`); QEMU: first the boot command line's script or the built-in one, run by [`pzt_probe::board::sim_script::Runner`], the link after its `serve` |
//! | `report` | 1 | the only place that logs: one defmt line per event (`pzt_probe::instrument::log`); and each event as the link's frames into the transmit queue (full: dropped and counted) |
//! | `link_tx` | 1 | STM32: the transmit queue to LPUART1 by DMA (QEMU: UART0's transmit interrupt does it; the task ends) |
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

    use pzt_probe::instrument::watchdog::{Liveness, BOOT};

    /// The measurement task's liveness promise, kept by `measure`, read by `guard`.
    pub static LIVENESS: Liveness = Liveness::new(BOOT);
}

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::device, peripherals = false, dispatchers = [SPI3, SPI2])]
mod app {
    use crate::board;
    use crate::shared::*;
    use core::sync::atomic::Ordering;
    use pzt_probe::counters::*;
    use pzt_probe::engine::{PointRaw, SampleEngine, BATCH};
    use pzt_probe::hal::FrontEndScale;
    use pzt_probe::instrument::command::Command;
    use pzt_probe::instrument::link::LinkEvent;
    use pzt_probe::instrument::measure::{FwIo, Link, Recv};
    use pzt_probe::instrument::session::Event;
    use pzt_probe::instrument::watchdog::{self, Millis, FEED};
    use pzt_probe::loadcell::{ForceLog, RawForce};
    use pzt_probe::unit::store::Store;
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
    /// Completions: every request queued and the one in service, so none is lost while the
    /// host link's receive side reads bytes.
    const DONE_CAP: usize = REQUEST_CAP + 1;
    // The host link keeps the id of every command queued, in service, or whose completion
    // waits in the report channel.
    const _: () = assert!(pzt_probe::instrument::link::PENDING >= REQUEST_CAP + 1 + REPORT_CAP);
    /// Received bytes buffered between the UART interrupt and the command task.
    const RX_CAP: usize = 64;

    /// The load-cell task looks for a conversion this often (ms): above the HX711's 80 a
    /// second, so each is read before the next overwrites it.
    const LOAD_CELL_POLL_MS: u32 = 5;

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
        link_tx: board::LinkTx,
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
        link_tx::spawn().ok();
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
                link_tx: parts.link_tx,
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

    /// Host bytes from the UART into the command task's channel while it has room; then the
    /// board holds the rest (`Uart::hold`: QEMU keeps the host's stream back in its receive
    /// register; the STM32 drops what its DMA ring holds, the line then fails to parse and is
    /// reported), and the command task pends this interrupt after each byte it takes
    /// ([`rx_taken`]).
    #[task(binds = LPUART1, priority = 2, local = [uart, rx_tx])]
    fn uart_rx(cx: uart_rx::Context) {
        loop {
            if cx.local.rx_tx.is_full() {
                cx.local.uart.hold();
                break;
            }
            let Some(b) = cx.local.uart.read_byte() else {
                break;
            };
            let _ = cx.local.rx_tx.try_send(b);
        }
    }

    /// The command task took a byte: let `uart_rx` move the next ones in.
    fn rx_taken() {
        rtic::pend(board::device::interrupt::LPUART1);
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

    /// The measurement task's links ([`Link`]): the channels it was spawned with, the
    /// monotonic, the force log.
    struct Links<F> {
        requests: Receiver<'static, Command, REQUEST_CAP>,
        plans: Sender<'static, EngineCmd, PLAN_CAP>,
        points: Receiver<'static, PointRaw, POINT_CAP>,
        reports: Sender<'static, Report, REPORT_CAP>,
        done: Sender<'static, bool, DONE_CAP>,
        forces: F,
    }

    impl<F: rtic::Mutex<T = &'static mut ForceLog>> Link for Links<F> {
        async fn plan(&mut self, plan: EngineCmd) -> bool {
            self.plans.send(plan).await.is_ok()
        }
        async fn point(&mut self, within: Millis) -> Option<PointRaw> {
            let got = Mono::timeout_after(within.0.millis(), self.points.recv()).await;
            got.ok()?.ok()
        }
        async fn request(&mut self, within: Millis) -> Recv<Command> {
            Recv::of(Mono::timeout_after(within.0.millis(), self.requests.recv()).await)
        }
        fn done(&mut self, ok: bool) {
            let _ = self.done.try_send(ok);
        }
        async fn report(&mut self, e: Event) {
            let _ = self.reports.send(Report::Event(e)).await;
        }
        async fn counters(&mut self) {
            let _ = self.reports.send(Report::Counters).await;
        }
        async fn served(&mut self, ok: bool) {
            let _ = self.reports.send(Report::Link(LinkEvent::Served(ok))).await;
        }
        fn try_report(&mut self, e: Event) -> bool {
            self.reports.try_send(Report::Event(e)).is_ok()
        }
        async fn delay(&mut self, ms: Millis) {
            Mono::delay(ms.0.millis()).await;
        }
        fn now(&self) -> Millis {
            now()
        }
        fn now_sample(&self) -> u64 {
            now_sample()
        }
        fn stamp(&self) -> u32 {
            board::stamp()
        }
        fn elapsed(&self, since: u32) -> u32 {
            board::elapsed(since)
        }
        fn contact_force(&mut self, from: u64, to: u64, fs_hz: f32) -> Option<RawForce> {
            self.forces.lock(|f| f.over(from, to, fs_hz))
        }
    }

    /// The monotonic's time in ms (`Mono` ticks at 1 kHz).
    fn now() -> Millis {
        use rtic_monotonics::rtic_time::monotonic::TimerQueueBasedInstant;
        Millis(Mono::now().ticks())
    }

    /// The watchdog's guard: every [`FEED`] period it feeds the independent watchdog as long
    /// as the measurement task keeps its liveness promise ([`watchdog::guard`]). Above the
    /// measurement task's priority, so it runs through a long `calibrate fit`; a measurement
    /// task that hangs breaks its promise, the feeding stops and the watchdog resets the core.
    #[task(priority = 2, local = [watchdog])]
    async fn guard(cx: guard::Context) {
        loop {
            watchdog::guard(&LIVENESS, now(), cx.local.watchdog);
            Mono::delay(FEED.0.millis()).await;
        }
    }

    /// The measurement task: the session served one request at a time
    /// ([`FwIo::serve`]), keeping the watchdog's liveness promise (`guard`) while alive.
    #[task(priority = 1, shared = [forces], local = [store, scale])]
    async fn measure(
        cx: measure::Context,
        requests: Receiver<'static, Command, REQUEST_CAP>,
        plans: Sender<'static, EngineCmd, PLAN_CAP>,
        points: Receiver<'static, PointRaw, POINT_CAP>,
        reports: Sender<'static, Report, REPORT_CAP>,
        done: Sender<'static, bool, DONE_CAP>,
    ) {
        let links = Links {
            requests,
            plans,
            points,
            reports,
            done,
            forces: cx.shared.forces,
        };
        let (store, scale) = (cx.local.store, *cx.local.scale);
        FwIo::new(links, store, scale, &LIVENESS, board::boot_error())
            .serve()
            .await
    }

    /// The command task: host bytes → lines → requests, one request at a time.
    ///
    /// The STM32 serves the host link from power-on ([`serve_link`]). On QEMU the task first
    /// runs the boot command line's script (or the board's built-in one), waiting for each
    /// request to finish; at its end it ends the run with success iff every request succeeded
    /// and no overrun happened, or, at a `serve` line, serves the host link.
    #[task(priority = 1)]
    async fn command(
        _cx: command::Context,
        requests: Sender<'static, Command, REQUEST_CAP>,
        reports: Sender<'static, Report, REPORT_CAP>,
        done: Receiver<'static, bool, DONE_CAP>,
        rx: Receiver<'static, u8, RX_CAP>,
    ) {
        let scale = board::scale();
        #[cfg(feature = "qemu")]
        {
            use pzt_probe::board::sim_script::{lines, Action, Runner, SCENE_SETTLE_MS};
            let (mut requests, mut reports, mut done) = (requests, reports, done);
            // The boot command line's script, else the built-in one.
            let mut cmdline = [0u8; board::CMDLINE_MAX];
            let script = board::boot_script(&mut cmdline).unwrap_or(board::SCRIPT);
            let mut run = Runner::new(lines(script), board::sim_state(), scale);
            // After the power-on self-test (on the script's leading `sim` lines' scene).
            run.done(done.recv().await.unwrap_or(false));
            while let Some(action) = run.next() {
                match action {
                    Action::Sim => {
                        board::set_scene(run.sim().scene(), run.sim().seed);
                        Mono::delay(SCENE_SETTLE_MS.millis()).await;
                    }
                    Action::Send(c) => {
                        let sent = requests.send(c).await.is_ok();
                        run.done(sent && done.recv().await.unwrap_or(false));
                    }
                    Action::Reject(message) => {
                        let _ = reports.send(Report::Rejected(message)).await;
                    }
                    Action::Serve => {
                        let sim = *run.sim();
                        serve_link(rx, requests, reports, done, scale, sim).await;
                        return;
                    }
                }
            }
            let ok = run.ok() && !Overruns::now().any();
            let _ = reports.send(Report::Exit(ok)).await;
            drop(rx);
        }
        // The host link from power-on (the QEMU image: after its script's `serve`).
        #[cfg(not(feature = "qemu"))]
        serve_link(rx, requests, reports, done, scale).await;
    }

    /// The host link's receive side (QEMU: after the script's `serve`): bytes → frames →
    /// commands for the measurement task, each answered (`docs/protocol.md`). A command that
    /// finds the request queue full is rejected (`busy`), so the byte path never waits on a
    /// command in service; a frame that is no message is answered with its error. QEMU: `sim`
    /// lines (`src/board/sim_script.rs`) move the simulated probe from the scene `sim` once every
    /// command before them has been served, then wait `SCENE_SETTLE_MS` as the script does.
    async fn serve_link(
        mut rx: Receiver<'static, u8, RX_CAP>,
        mut requests: Sender<'static, Command, REQUEST_CAP>,
        mut reports: Sender<'static, Report, REPORT_CAP>,
        mut done: Receiver<'static, bool, DONE_CAP>,
        scale: pzt_probe::hal::FrontEndScale,
        #[cfg(feature = "qemu")] mut sim: pzt_probe::board::sim_script::SimState,
    ) {
        #[cfg(feature = "qemu")]
        use pzt_probe::board::sim_script::{apply, SCENE_SETTLE_MS};
        use pzt_probe::instrument::link::{HostLink, Incoming};
        let mut link = HostLink::new();
        // Requests queued and not yet served.
        let mut outstanding = 0u32;
        while let Ok(b) = rx.recv().await {
            rx_taken();
            while done.try_recv().is_ok() {
                outstanding = outstanding.saturating_sub(1);
            }
            let report = match link.push(b, &scale) {
                None => continue,
                Some(Incoming::Hello) => LinkEvent::Hello,
                Some(Incoming::Error(e)) => LinkEvent::FrameError(e),
                #[cfg(feature = "qemu")]
                Some(Incoming::Command { id, line, .. }) if line.starts_with("sim ") => {
                    while outstanding > 0 && done.recv().await.is_ok() {
                        outstanding -= 1;
                    }
                    let error = match apply(&line, &mut sim) {
                        Ok(_) => {
                            board::set_scene(sim.scene(), sim.seed);
                            Mono::delay(SCENE_SETTLE_MS.millis()).await;
                            None
                        }
                        Err(e) => Some(e.message()),
                    };
                    LinkEvent::BoardLine { id, error }
                }
                Some(Incoming::Command {
                    id,
                    parsed: Err(error),
                    ..
                }) => LinkEvent::Rejected { id, error },
                Some(Incoming::Command {
                    id, parsed: Ok(c), ..
                }) if !requests.is_full() => {
                    // Queued before it is handed on: the reply's id waits in the report task
                    // before any event of the command reaches it. This task alone sends
                    // requests, so the room seen stays.
                    let _ = reports.send(Report::Link(LinkEvent::Queued(id))).await;
                    outstanding += requests.try_send(c).is_ok() as u32;
                    continue;
                }
                Some(Incoming::Command { id, .. }) => LinkEvent::Busy(id),
            };
            let _ = reports.send(Report::Link(report)).await;
        }
    }

    /// The host link's transmitter where a task drives it (STM32: LPUART1 by DMA, chunks of the
    /// transmit queue as they come, looked for every millisecond while it is empty; QEMU: the
    /// UART's transmit interrupt does it and the task ends at once).
    #[task(priority = 1, local = [link_tx])]
    async fn link_tx(cx: link_tx::Context) {
        if !board::LinkTx::BY_TASK {
            return;
        }
        let mut chunk = [0u8; 128];
        loop {
            match board::LinkTx::take(&mut chunk) {
                0 => Mono::delay(1.millis()).await,
                n => cx.local.link_tx.write(&chunk[..n]).await,
            }
        }
    }

    /// The report task: the only task that logs, and the host link's transmit side:
    /// each report also as frames into the transmit queue ([`pzt_probe::instrument::link`]).
    /// Formats are listed in the crate docs.
    #[task(priority = 1)]
    async fn report(_cx: report::Context, mut rx: Receiver<'static, Report, REPORT_CAP>) {
        let mut seen = Overruns::default();
        let (mut out, mut frame) = (
            pzt_probe::instrument::link::Outgoing::new(
                board::NAME,
                board::ELAPSED_UNIT,
                board::boot_error(),
            ),
            [0u8; probe_proto::MAX_DEVICE_FRAME + 1],
        );
        while let Ok(r) = rx.recv().await {
            out.report(&r, &mut frame, board::link_send);
            #[allow(unused_variables)] // the exit status ends only the QEMU image
            if let Some(ok) = pzt_probe::instrument::log::report(r, board::ELAPSED_UNIT, &mut seen)
            {
                #[cfg(feature = "qemu")]
                board::exit(ok);
            }
        }
    }
}
