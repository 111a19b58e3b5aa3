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
//! | `sample` (hardware) | 3 | per batch: demodulate the ADC half, refill the DAC half ([`SampleEngine`]) |
//! | `uart_rx` (hardware, STM32) | 2 | host bytes from LPUART1 (ST-LINK virtual COM port) into a channel |
//! | `measure` | 1 | owns settings, calibration and the flash store; runs readings plan by plan ([`pzt_probe::measure::Procedure`]) |
//! | `command` | 1 | bytes → lines → [`pzt_probe::command::parse`] → requests to `measure` (QEMU: `command_script`, a fixed script through the same parser) |
//! | `report` | 1 | the only place that logs: one defmt line per event, formats below |
//!
//! Data flow: `command` → (request channel) → `measure` → (plan channel, capacity 2: the double
//! buffer of the interrupt's settings) → `sample` → (point channel) → `measure` → (report channel)
//! → `report`. Settings are validated before anything reaches the interrupt: by the command
//! parser against the board's converter scale, by the method's own validation when they are
//! applied, and again by [`pzt_probe::measure::Procedure::new`] when a reading starts; the
//! interrupt only ever sees [`PointPlan`]s of validated settings. The running reading keeps the
//! settings it started with; a new `method`, `sweep`, `staged` or `ringdown` applies from the
//! next reading.
//!
//! The default method is `auto` ([`pzt_probe::Method::Auto`]): hold, falling back to fit, then
//! to sweep-G while the resonance is not found or not resolved; its `reading` line names the
//! method that produced it (`hold`, `fit` or `sweep-g`).
//!
//! # Log lines (parsed by `probe-bench log` and `tests/qemu.rs`; keep them stable)
//!
//! Every line is one defmt message; floats are `{=f32}` (missing values are `NaN`), names
//! `{=str}`:
//!
//! ```text
//! boot board=<qemu|stm32> fs_hz=<f32> batch=<u32>
//! store loaded slot=<u8> seq=<u32> other=<str>            (info)
//! store fallback slot0=<str> slot1=<str> calibration=paper-experiment   (warn)
//! store saved slot=<u8> seq=<u32>                          (info)
//! store error=<str>                                        (error)
//! settings method=<str> start_hz=<f32> stop_hz=<f32> step_hz=<f32> settle_s=<f32> integrate_s=<f32> drive_v=<f32>
//! point tag=<u16> f_hz=<f32> g_s=<f32> b_s=<f32> sigma_s=<f32>
//! reading status=<str> f_hz=<f32> f_sigma_hz=<f32> e_kpa=<f32> e_sigma_kpa=<f32> e_repeat_kpa=<f32> q=<f32> probe_time_s=<f32> points=<u16> method=<str>
//! air f_hz=<f32> q=<f32>
//! reference e_kpa=<f32> f_hz=<f32> f_sigma_hz=<f32> n=<u16>
//! calibration source=<str> a=<f32> b=<f32> c=<f32> min_kpa=<f32> max_kpa=<f32>
//! hint code=<str> message=<str>                           (warn; after a failed reading: what to do)
//! rejected error=<str>                                     (warn)
//! stalled tag=<u16>                                        (error)
//! overrun late=<u32> ring=<u32> dropped=<u32>              (error; whenever a counter grew)
//! counters batches=<u32> late=<u32> ring=<u32> dropped=<u32> isr_mean=<u32> isr_max=<u32> unit=<str>
//! status method=<str> calibration=<str> fallback=<bool> air=<bool> q_model=<bool> references=<u16>
//! help commands=<str> methods=<str> default=<str>
//! exit ok=<bool>                                           (QEMU script end)
//! ```
//!
//! `settings` carries a stepped sweep's own fields; for the two-stage methods (auto, fit,
//! adaptive, track) `start_hz`/`stop_hz` are the band, `step_hz` is `NaN`, `settle_s` the
//! coarse settling and `integrate_s` the integration; for ring-down the band, `NaN`, the burst
//! and the ring. `status` of a reading is `ok` or a failure code of
//! [`pzt_probe::Failure::code`]. `isr_mean`
//! and `isr_max` are the sample interrupt's work per batch (plan intake, demodulation, DAC
//! refill, point hand-off) in `unit`: instructions under QEMU, core cycles on the STM32.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(all(target_os = "none", not(any(feature = "stm32", feature = "qemu"))))]
compile_error!("the firmware image needs feature `stm32` or `qemu` (with --no-default-features)");

#[cfg(all(target_os = "none", feature = "qemu"))]
use pzt_probe::board::qemu as board;
#[cfg(all(target_os = "none", feature = "stm32"))]
use pzt_probe::board::stm32g474 as board;

#[cfg(all(target_os = "none", feature = "stm32"))]
use defmt_rtt as _;

#[cfg(all(target_os = "none", feature = "qemu"))]
use defmt_semihosting as _;

/// Stop for good: QEMU exits with failure; the STM32 takes a permanent fault (`udf`, as
/// `panic-probe` does: probe-rs shows the backtrace, and without a debugger the watchdog resets
/// the core).
#[cfg(target_os = "none")]
fn fail() -> ! {
    #[cfg(feature = "qemu")]
    board::exit(false);
    #[cfg(not(feature = "qemu"))]
    cortex_m::asm::udf()
}

/// Log that the image panicked, then [`fail`]. Neither the message nor the location is
/// logged: touching the `PanicInfo` at all keeps core's formatting machinery in the image (with
/// float formatting for the messages of `f64::clamp` and the like: about 16 KiB of flash), and
/// the STM32 image must fit 64 KiB. On the board probe-rs shows the backtrace of the fault that
/// follows.
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    defmt::error!(
        "panic {}",
        "(message and location not kept: see src/bin/probe.rs)"
    );
    fail()
}

#[cfg(target_os = "none")]
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    fail()
}

#[cfg(all(target_os = "none", feature = "qemu"))]
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    board::exit(false)
}

#[cfg(target_os = "none")]
mod shared {
    //! Types and counters shared by the tasks.

    use core::sync::atomic::{AtomicU32, Ordering};
    use pzt_probe::command::CommandError;
    use pzt_probe::engine::PointPlan;
    use pzt_probe::session::Event;

    /// Batches serviced by the sample interrupt.
    pub static BATCHES: AtomicU32 = AtomicU32::new(0);
    /// Batches whose interrupt overran its period (the next one was already pending).
    pub static LATE: AtomicU32 = AtomicU32::new(0);
    /// Engine ring overruns (a DAC batch forgotten before it was demodulated).
    pub static RING: AtomicU32 = AtomicU32::new(0);
    /// Finished points the interrupt could not hand on (channel full).
    pub static DROPPED: AtomicU32 = AtomicU32::new(0);
    /// Mean and largest interrupt work per batch (board unit).
    pub static ISR_MEAN: AtomicU32 = AtomicU32::new(0);
    /// See [`ISR_MEAN`].
    pub static ISR_MAX: AtomicU32 = AtomicU32::new(0);

    /// A snapshot of the overrun counters.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Overruns {
        pub late: u32,
        pub ring: u32,
        pub dropped: u32,
    }

    impl Overruns {
        pub fn now() -> Self {
            Self {
                late: LATE.load(Ordering::Relaxed),
                ring: RING.load(Ordering::Relaxed),
                dropped: DROPPED.load(Ordering::Relaxed),
            }
        }
        #[cfg_attr(not(feature = "qemu"), allow(dead_code))]
        pub fn any(&self) -> bool {
            self.late + self.ring + self.dropped > 0
        }
    }

    /// What the measurement task asks of the interrupt.
    #[derive(Clone, Copy)]
    pub enum EngineCmd {
        Load(PointPlan),
        Stop,
    }

    /// Everything the report task logs: the session's events and the board's own.
    #[derive(Clone, Copy)]
    pub enum Report {
        Event(Event),
        Rejected(CommandError),
        #[cfg(feature = "qemu")]
        SimRejected(pzt_probe::board::sim_script::SimError),
        Counters,
        #[cfg_attr(not(feature = "qemu"), allow(dead_code))]
        Exit(bool),
    }
}

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::device, peripherals = false, dispatchers = [SPI3])]
mod app {
    use crate::board;
    use crate::shared::*;
    use core::sync::atomic::Ordering;
    use pzt_probe::command::{parse, Command, LineBuffer};
    use pzt_probe::engine::PointPlan;
    use pzt_probe::engine::{PointRaw, SampleEngine};
    use pzt_probe::hal::FrontEndScale;
    use pzt_probe::reading::{PointSource, BATCH};
    use pzt_probe::session::{Event, Io, Session};
    use pzt_probe::store::{Loaded, Saved, Store, StoreError};
    use pzt_probe::UnitProfile;
    use rtic_monotonics::systick::prelude::*;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    systick_monotonic!(Mono, 1_000);

    const PLAN_CAP: usize = 2;
    const POINT_CAP: usize = 4;
    const REQUEST_CAP: usize = 4;
    const REPORT_CAP: usize = 16;
    const DONE_CAP: usize = 1;
    /// Received bytes buffered between the UART interrupt and the command task (STM32).
    const RX_CAP: usize = 64;
    /// The measurement task feeds the watchdog at least this often while it is alive (ms).
    const FEED_MS: u32 = 100;

    /// The QEMU image has no host link: it runs this script through the same line parser — a
    /// reading with the default method (auto), one with sweep-G over a sweep of its own, back to
    /// auto with two-stage settings of its own, store, status.
    #[cfg(feature = "qemu")]
    const SCRIPT: &str = "status;measure;method sweep-g;sweep 200 260 2 0.02 0.03 5;measure;method auto;staged 180 280 6 0.02 0.03 5 0.8 5 4;store;status";

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        stream: board::Stream,
        engine: SampleEngine,
        plan_rx: Receiver<'static, EngineCmd, PLAN_CAP>,
        point_tx: Sender<'static, PointRaw, POINT_CAP>,
        isr_sum: u64,
        isr_n: u32,
        watchdog: board::Watchdog,
        store: Store<board::StoreFlash>,
        scale: FrontEndScale,
        uart: board::Uart,
        rx_tx: Sender<'static, u8, RX_CAP>,
    }

    #[init]
    fn init(mut cx: init::Context) -> (Shared, Local) {
        let parts = board::init(&mut cx.core);
        Mono::start(cx.core.SYST, board::SYSCLK_HZ);
        // SysTick below the sample interrupt so the timer queue never delays a batch.
        // SAFETY: priorities are set before any task runs.
        unsafe {
            cx.core.SCB.set_priority(
                cortex_m::peripheral::scb::SystemHandler::SysTick,
                logical_to_hw(2),
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

        let store = match Store::new(parts.flash, board::STORE_BASE) {
            Ok(s) => s,
            Err(_) => defmt::panic!("store geometry"),
        };

        measure::spawn(request_rx, plan_tx, point_rx, report_tx.clone(), done_tx).ok();
        report::spawn(report_rx).ok();

        let (rx_tx, rx_rx) = make_channel!(u8, RX_CAP);
        command::spawn(request_tx, report_tx, done_rx, rx_rx).ok();

        (
            Shared {},
            Local {
                stream,
                engine,
                plan_rx,
                point_tx,
                isr_sum: 0,
                isr_n: 0,
                watchdog: parts.watchdog,
                store,
                scale,
                uart: parts.uart,
                rx_tx,
            },
        )
    }

    /// Hardware priority value of RTIC logical priority `p`.
    fn logical_to_hw(p: u8) -> u8 {
        let bits = crate::board::device::NVIC_PRIO_BITS;
        ((1u8 << bits) - p) << (8 - bits)
    }

    /// Runs when no task has work: sleep until the next interrupt.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// The sample interrupt: one batch ([`BATCH`] samples, 5 ms at 10 kHz) per call.
    ///
    /// Bound to the ADC DMA half/full-transfer interrupt `DMA1_CH1` on the STM32; on QEMU the
    /// same vector is the batch timer, whose driver first emulates the DMA of the period. It
    /// takes any queued plan (`Load`/`Stop`) from the plan channel, demodulates the ADC
    /// half-buffer just captured ([`SampleEngine::demodulate`]), refills the DAC half-buffer
    /// just played ([`SampleEngine::generate`], which applies the plan phase-continuously) and
    /// hands a finished point to the measurement task with a non-blocking send. It never logs,
    /// allocates or waits.
    ///
    /// **Budget.** 2 % of the core per batch: 17 000 cycles at 170 MHz for 50 samples
    /// (340 per sample); measured figures are in `docs/firmware.md` and in the `counters`
    /// log line (`isr_mean`, `isr_max`). The hard limit is the batch period itself: the
    /// refilled DAC half plays one batch after the one now playing.
    ///
    /// **Overrun.** Detected, counted and reported by the report task, never silent: if the
    /// next batch interrupt is already pending when this one ends, the batch was late (`LATE`;
    /// on the STM32 the DMA may then have played a stale half); if the engine's ring forgot a
    /// batch (`RING`); if the point channel was full (`DROPPED`). The measurement task also
    /// times every point out, so a lost point ends the reading as `stalled` rather than hanging.
    #[task(binds = DMA1_CH1, priority = 3, local = [stream, engine, plan_rx, point_tx, isr_sum, isr_n])]
    fn sample(cx: sample::Context) {
        let stream = cx.local.stream;
        let engine = cx.local.engine;
        let (adc, dac) = stream.capture();
        let t0 = board::stamp();
        while let Ok(cmd) = cx.local.plan_rx.try_recv() {
            match cmd {
                EngineCmd::Load(plan) => engine.load(plan),
                EngineCmd::Stop => engine.stop(),
            }
        }
        let point = engine.demodulate(adc);
        engine.generate(dac);
        if let Some(p) = point {
            if cx.local.point_tx.try_send(p).is_err() {
                DROPPED.fetch_add(1, Ordering::Relaxed);
            }
        }
        let work = board::elapsed(t0);
        *cx.local.isr_sum += work as u64;
        *cx.local.isr_n += 1;
        // In f32 (24-bit mantissa: exact enough for a mean) rather than a u64 division, whose
        // library routine costs a kilobyte of flash.
        let mean = *cx.local.isr_sum as f32 / *cx.local.isr_n as f32;
        ISR_MEAN.store(mean as u32, Ordering::Relaxed);
        ISR_MAX.fetch_max(work, Ordering::Relaxed);
        RING.store(engine.overruns(), Ordering::Relaxed);
        BATCHES.fetch_add(1, Ordering::Relaxed);
        if stream.late() {
            LATE.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Host bytes from the UART into the command task's channel.
    #[task(binds = LPUART, priority = 2, local = [uart, rx_tx])]
    fn uart_rx(cx: uart_rx::Context) {
        while let Some(b) = cx.local.uart.read_byte() {
            // A full channel drops the byte; the line then fails to parse and is reported.
            let _ = cx.local.rx_tx.try_send(b);
        }
    }

    /// The measurement task's board: the interrupt's channels as the session's point source,
    /// the flash store, the report channel as its event sink.
    struct FwIo<'a> {
        plans: &'a mut Sender<'static, EngineCmd, PLAN_CAP>,
        points: &'a mut Receiver<'static, PointRaw, POINT_CAP>,
        reports: &'a mut Sender<'static, Report, REPORT_CAP>,
        watchdog: &'a mut board::Watchdog,
        store: &'a mut Store<board::StoreFlash>,
        scale: FrontEndScale,
    }

    impl PointSource for FwIo<'_> {
        fn scale(&self) -> FrontEndScale {
            self.scale
        }
        /// The interrupt's double buffer: a plan applies from the batch after the one playing.
        fn latency_batches(&self) -> usize {
            2
        }
        fn now_sample(&self) -> u64 {
            BATCHES.load(Ordering::Relaxed) as u64 * BATCH as u64
        }
        async fn load(&mut self, plan: PointPlan) -> bool {
            self.plans.send(EngineCmd::Load(plan)).await.is_ok()
        }
        async fn next(&mut self, plan: &PointPlan, budget: u64) -> Option<PointRaw> {
            // The budget in ms, with a watchdog period of margin for this task's own delay.
            let ms = (budget as f32 / self.scale.sample_rate.0 * 1000.0) as u32 + FEED_MS;
            let got = loop {
                match Mono::timeout_after(ms.millis(), self.points.recv()).await {
                    Ok(Ok(raw)) if raw.plan == *plan => break Some(raw),
                    Ok(Ok(_stale)) => continue,
                    _ => break None,
                }
            };
            self.watchdog.feed();
            got
        }
        async fn stop(&mut self) {
            let _ = self.plans.send(EngineCmd::Stop).await;
        }
    }

    impl Io for FwIo<'_> {
        async fn emit(&mut self, e: Event) {
            // The report task only ends with the image; a closed channel is not an error here.
            let _ = self.reports.send(Report::Event(e)).await;
            if matches!(e, Event::Reading(_) | Event::Status { .. }) {
                let _ = self.reports.send(Report::Counters).await;
            }
        }
        fn save(&mut self, p: &UnitProfile) -> Result<Saved, StoreError> {
            self.store.save(p)
        }
        fn load_profile(&mut self) -> Loaded {
            self.store.load()
        }
    }

    /// The measurement task: the session (src/session.rs) served one request at a time; it
    /// feeds the watchdog while alive.
    #[task(priority = 1, local = [watchdog, store, scale])]
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
            watchdog: cx.local.watchdog,
            store: cx.local.store,
            scale: *cx.local.scale,
        };
        let mut session = Session::boot(&mut io).await;
        loop {
            let req = match Mono::timeout_after(FEED_MS.millis(), requests.recv()).await {
                Ok(Ok(r)) => r,
                Ok(Err(_)) => {
                    // No command source any more: stay alive for the watchdog, serve nothing.
                    loop {
                        io.watchdog.feed();
                        Mono::delay(FEED_MS.millis()).await;
                    }
                }
                Err(_) => {
                    io.watchdog.feed();
                    continue;
                }
            };
            io.watchdog.feed();
            let ok = session.handle(req, &mut io).await;
            // Only the QEMU script waits for this; elsewhere the slot just stays full.
            let _ = done.try_send(ok);
        }
    }

    /// Turn lines into requests. Parse errors are reported and the line is dropped.
    #[cfg_attr(feature = "qemu", allow(dead_code))]
    async fn serve_line(
        line: &[u8],
        scale: &FrontEndScale,
        requests: &mut Sender<'static, Command, REQUEST_CAP>,
        reports: &mut Sender<'static, Report, REPORT_CAP>,
    ) -> bool {
        match parse(line, scale) {
            Ok(c) => requests.send(c).await.is_ok(),
            Err(e) => {
                let _ = reports.send(Report::Rejected(e)).await;
                false
            }
        }
    }

    /// The command task: host bytes → lines → requests, one request at a time.
    ///
    /// On QEMU there is no host on the line: the task feeds the fixed [`SCRIPT`] through the
    /// same line buffer and parser, waits for each request to finish, then ends the run with
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
        let mut lines = LineBuffer::new();
        #[cfg(feature = "qemu")]
        {
            // The boot command line's script if there is one, else the built-in one; `sim`
            // lines move the simulated probe (src/board/sim_script.rs), the others go through
            // the same line buffer and parser as host bytes.
            let mut cmdline = [0u8; board::CMDLINE_MAX];
            let script = board::boot_script(&mut cmdline).unwrap_or(SCRIPT);
            let mut sim = board::sim_state();
            let mut ok = true;
            for line in script
                .split([';', '\n'])
                .map(str::trim)
                .filter(|l| !l.is_empty())
            {
                match pzt_probe::board::sim_script::apply(line, &mut sim) {
                    Ok(true) => {
                        board::set_scene(sim.scene(), sim.seed);
                        continue;
                    }
                    Ok(false) => {}
                    Err(e) => {
                        let _ = reports.send(Report::SimRejected(e)).await;
                        ok = false;
                        continue;
                    }
                }
                let mut parsed = None;
                for &b in line.as_bytes().iter().chain(b"\n") {
                    if let Some(r) = lines.push(b) {
                        parsed = Some(r.map(|l| parse(l, &scale)));
                    }
                }
                match parsed {
                    Some(Ok(Ok(c))) if requests.send(c).await.is_ok() => {
                        ok &= done.recv().await.unwrap_or(false);
                    }
                    Some(Ok(Err(e)) | Err(e)) => {
                        let _ = reports.send(Report::Rejected(e)).await;
                        ok = false;
                    }
                    _ => ok = false,
                }
            }
            ok &= !Overruns::now().any();
            let _ = reports.send(Report::Exit(ok)).await;
            drop(rx);
        }
        #[cfg(not(feature = "qemu"))]
        let mut rx = rx;
        #[cfg(not(feature = "qemu"))]
        while let Ok(b) = rx.recv().await {
            // A stale completion from an earlier request is of no interest here.
            let _ = done.try_recv();
            match lines.push(b) {
                Some(Ok(l)) => {
                    serve_line(l, &scale, &mut requests, &mut reports).await;
                }
                Some(Err(e)) => {
                    let _ = reports.send(Report::Rejected(e)).await;
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
            match r {
                Report::Event(e) => pzt_probe::log::event(e),
                Report::Rejected(e) => defmt::warn!("rejected error={=str}", e.message()),
                #[cfg(feature = "qemu")]
                Report::SimRejected(e) => defmt::warn!("rejected error={=str}", e.message()),
                Report::Counters => defmt::info!(
                    "counters batches={=u32} late={=u32} ring={=u32} dropped={=u32} isr_mean={=u32} isr_max={=u32} unit={=str}",
                    BATCHES.load(Ordering::Relaxed),
                    LATE.load(Ordering::Relaxed),
                    RING.load(Ordering::Relaxed),
                    DROPPED.load(Ordering::Relaxed),
                    ISR_MEAN.load(Ordering::Relaxed),
                    ISR_MAX.load(Ordering::Relaxed),
                    board::ELAPSED_UNIT
                ),
                Report::Exit(ok) => {
                    report_overruns(&mut seen);
                    defmt::info!("exit ok={=bool}", ok);
                    #[cfg(feature = "qemu")]
                    board::exit(ok);
                }
            }
            report_overruns(&mut seen);
        }
    }

    /// Log the overrun counters whenever one of them grew since the last call.
    fn report_overruns(seen: &mut Overruns) {
        let now = Overruns::now();
        if now != *seen {
            defmt::error!(
                "overrun late={=u32} ring={=u32} dropped={=u32}",
                now.late,
                now.ring,
                now.dropped
            );
            *seen = now;
        }
    }
}
