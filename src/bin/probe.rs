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
//! The default method is `auto` ([`pzt_probe::Method::Auto`]): fit, falling back to sweep-G
//! when fit finds no trustworthy resonance; its `reading` line names the method that produced
//! it (`fit` or `sweep-g`).
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
//! reading status=<str> f_hz=<f32> f_sigma_hz=<f32> e_kpa=<f32> e_sigma_kpa=<f32> q=<f32> probe_time_s=<f32> points=<u16> method=<str>
//! air f_hz=<f32> q=<f32>
//! reference e_kpa=<f32> f_hz=<f32> f_sigma_hz=<f32> n=<u16>
//! calibration source=<str> a=<f32> b=<f32> c=<f32> min_kpa=<f32> max_kpa=<f32>
//! hint code=<str> message=<str>                           (warn; after a failed reading: what to do)
//! rejected error=<str>                                     (warn)
//! stalled tag=<u16>                                        (error)
//! overrun late=<u32> ring=<u32> dropped=<u32>              (error; whenever a counter grew)
//! counters batches=<u32> late=<u32> ring=<u32> dropped=<u32> isr_mean=<u32> isr_max=<u32> unit=<str>
//! status method=<str> calibration=<str> fallback=<bool> air=<bool> references=<u16>
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
    use pzt_probe::measure::Settings;
    use pzt_probe::store::{Loaded, SlotState, StoreError};
    use pzt_probe::sweep::SweepPoint;
    use pzt_probe::{Method, PowerLaw, Reading};

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

    /// Everything the report task logs.
    #[derive(Clone, Copy)]
    pub enum Report {
        Loaded(Loaded),
        Saved {
            slot: u8,
            seq: u32,
        },
        StoreFailed(StoreError),
        Settings(Method, Settings),
        Point {
            tag: u16,
            point: SweepPoint,
        },
        Reading(Reading),
        Air {
            f_hz: f32,
            q: f32,
        },
        AirRefused(pzt_probe::Failure),
        Reference {
            e_kpa: f32,
            f_hz: f32,
            f_sigma_hz: f32,
            n: u16,
        },
        Calibration(PowerLaw),
        Rejected(CommandError),
        /// What the user can do about a failed reading.
        Hint(pzt_probe::Failure),
        Refused(&'static str),
        Stalled {
            tag: u16,
        },
        Counters,
        Status {
            method: Method,
            cal: PowerLaw,
            fallback: bool,
            air: bool,
            references: u16,
        },
        #[cfg_attr(not(feature = "qemu"), allow(dead_code))]
        Exit(bool),
    }

    pub fn slot_name(s: SlotState) -> &'static str {
        match s {
            SlotState::Valid(_) => "valid",
            SlotState::Empty => "empty",
            SlotState::Corrupt => "corrupt",
            SlotState::Unreadable => "unreadable",
        }
    }

    pub fn store_error_name(e: StoreError) -> &'static str {
        match e {
            StoreError::Geometry => "geometry",
            StoreError::InvalidRecord => "invalid_record",
            StoreError::Erase => "erase",
            StoreError::Program => "program",
            StoreError::Verify => "verify",
        }
    }
}

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::device, peripherals = false, dispatchers = [SPI3])]
mod app {
    use crate::board;
    use crate::shared::*;
    use core::sync::atomic::Ordering;
    use pzt_probe::command::{parse, Command, CommandError, LineBuffer};
    use pzt_probe::engine::{PointRaw, SampleEngine};
    use pzt_probe::hal::FrontEndScale;
    use pzt_probe::measure::DEFAULT_METHOD;
    use pzt_probe::measure::{Measurement, Procedure, Settings};
    use pzt_probe::profile::{self, Reference, UnitProfile, AIR_SWEEP};
    use pzt_probe::runner::window_budget_samples;
    use pzt_probe::runner::BATCH;
    use pzt_probe::store::{LoadSource, Store};
    use pzt_probe::{Failure, Method, PowerLaw, Reading, Seconds};
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
    /// Reference readings kept for a calibration fit.
    const MAX_REFERENCES: usize = 32;
    /// Points of an air-reference sweep ([`AIR_SWEEP`]: 61).
    const AIR_POINTS: usize = 64;
    /// The measurement task feeds the watchdog at least this often while it is alive (ms).
    const FEED_MS: u32 = 100;

    /// The QEMU image has no host link: it runs this script through the same line parser — a
    /// reading with the default method (auto), one with sweep-G over a sweep of its own, back to
    /// auto with two-stage settings of its own, store, status.
    #[cfg(feature = "qemu")]
    const SCRIPT: &[u8] = b"status\nmeasure\nmethod sweep-g\nsweep 200 260 2 0.02 0.03 5\nmeasure\nmethod auto\nstaged 180 280 6 0.02 0.03 5 0.8 5 4\nstore\nstatus\n";

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

    /// The active settings: what the next reading uses.
    struct Active {
        method: Method,
        settings: Settings,
    }

    impl Active {
        /// `method` with its default settings.
        fn of(method: Method) -> Self {
            Self {
                method,
                settings: method.default_settings(),
            }
        }
    }

    /// What one reading needs from the measurement task's context.
    struct Rig<'a> {
        plans: &'a mut Sender<'static, EngineCmd, PLAN_CAP>,
        points: &'a mut Receiver<'static, PointRaw, POINT_CAP>,
        reports: &'a mut Sender<'static, Report, REPORT_CAP>,
        watchdog: &'a mut board::Watchdog,
        scale: FrontEndScale,
    }

    impl Rig<'_> {
        async fn report(&mut self, r: Report) {
            // The report task only ends with the image; a closed channel is not an error here.
            let _ = self.reports.send(r).await;
        }

        /// One reading with `method` and `settings`, plan by plan through the interrupt: every
        /// window of a plan (one for a sweep point, several for a ring-down) is waited for with
        /// the shared time-out rule ([`window_budget_samples`]) and handed to the procedure; the
        /// reading ends in the one pipeline with the unit's profile. `on_point` sees every
        /// admittance point.
        async fn reading(
            &mut self,
            method: Method,
            settings: &Settings,
            unit: &UnitProfile,
            mut on_point: impl FnMut(&pzt_probe::sweep::SweepPoint),
        ) -> Reading {
            let start = BATCHES.load(Ordering::Relaxed) as u64 * BATCH as u64;
            let mut m = match Procedure::new(method, settings, &self.scale, start, unit) {
                Ok(m) => m,
                Err(_) => return Reading::failed(method, Failure::BadSettings, Seconds(0.0), 0),
            };
            let fs = self.scale.sample_rate.0;
            let mut points: u16 = 0;
            while !m.is_complete() {
                let Some(plan) = m.next_plan() else { break };
                if self.plans.send(EngineCmd::Load(plan)).await.is_err() {
                    break;
                }
                // The shared stall rule with the interrupt's pipeline (two batches) as the
                // stream's latency, and a watchdog period of margin for the task's own delay.
                let budget_s = window_budget_samples(&plan, fs as f64, 2) as f32 / fs;
                let budget_ms = (budget_s * 1000.0) as u32 + FEED_MS;
                for _ in 0..plan.windows.max(1) {
                    let got = loop {
                        match Mono::timeout_after(budget_ms.millis(), self.points.recv()).await {
                            Ok(Ok(raw)) if raw.plan == plan => break Some(raw),
                            Ok(Ok(_stale)) => continue,
                            _ => break None,
                        }
                    };
                    self.watchdog.feed();
                    let Some(raw) = got else {
                        let _ = self.plans.send(EngineCmd::Stop).await;
                        self.report(Report::Stalled { tag: plan.tag }).await;
                        let now = BATCHES.load(Ordering::Relaxed) as u64 * BATCH as u64;
                        let t = Seconds(now.saturating_sub(start) as f32 / fs);
                        return Reading::failed(method, Failure::DriveFault, t, points);
                    };
                    if let Some(p) = m.accept(&raw) {
                        points = points.saturating_add(1);
                        on_point(&p);
                        self.report(Report::Point {
                            tag: plan.tag,
                            point: p,
                        })
                        .await;
                    }
                }
            }
            let _ = self.plans.send(EngineCmd::Stop).await;
            m.finish(unit)
        }
    }

    /// The measurement task: owns the settings, the calibration record, the reference readings
    /// and the flash store; serves one request at a time and feeds the watchdog while alive.
    #[task(priority = 1, local = [watchdog, store, scale])]
    async fn measure(
        cx: measure::Context,
        mut requests: Receiver<'static, Command, REQUEST_CAP>,
        mut plans: Sender<'static, EngineCmd, PLAN_CAP>,
        mut points: Receiver<'static, PointRaw, POINT_CAP>,
        mut reports: Sender<'static, Report, REPORT_CAP>,
        mut done: Sender<'static, bool, DONE_CAP>,
    ) {
        let store = cx.local.store;
        let loaded = store.load();
        // The unit profile: calibration, contact condition, air reference.
        let mut record = loaded.record;
        let mut fallback = loaded.is_fallback();
        let _ = reports.send(Report::Loaded(loaded)).await;
        // The default strategy (the bench's too): fit, falling back to sweep-G.
        let mut active = Active::of(DEFAULT_METHOD);
        let mut refs: heapless::Vec<Reference, MAX_REFERENCES> = heapless::Vec::new();
        let mut rig = Rig {
            plans: &mut plans,
            points: &mut points,
            reports: &mut reports,
            watchdog: cx.local.watchdog,
            scale: *cx.local.scale,
        };
        loop {
            let req = match Mono::timeout_after(FEED_MS.millis(), requests.recv()).await {
                Ok(Ok(r)) => r,
                Ok(Err(_)) => {
                    // No command source any more: stay alive for the watchdog, serve nothing.
                    loop {
                        rig.watchdog.feed();
                        Mono::delay(FEED_MS.millis()).await;
                    }
                }
                Err(_) => {
                    rig.watchdog.feed();
                    continue;
                }
            };
            rig.watchdog.feed();
            let ok = match req {
                Command::Measure => {
                    // Every check (air reference, contact, range, contact condition) is in the
                    // pipeline the reading ends in.
                    let r = rig
                        .reading(active.method, &active.settings, &record, |_| {})
                        .await;
                    rig.report(Report::Reading(r)).await;
                    if let pzt_probe::Status::Failed(f) = r.status {
                        rig.report(Report::Hint(f)).await;
                    }
                    rig.report(Report::Counters).await;
                    r.status.is_ok()
                }
                Command::Method(m) => {
                    active = Active::of(m);
                    rig.report(Report::Settings(active.method, active.settings))
                        .await;
                    true
                }
                Command::Settings(s) => {
                    // Parsed and checked against the board; that they are settings of the
                    // active method is checked here, by the method's own validation.
                    // (The procedure is dropped at once: it must not live across an await.)
                    let checked =
                        Procedure::new(active.method, &s, &rig.scale, 0, &record).map(|_| ());
                    match checked {
                        Ok(()) => {
                            active.settings = s;
                            rig.report(Report::Settings(active.method, active.settings))
                                .await;
                            true
                        }
                        Err(e) => {
                            rig.report(Report::Rejected(CommandError::Settings(e)))
                                .await;
                            false
                        }
                    }
                }
                Command::SettingsDefault => {
                    active = Active::of(active.method);
                    rig.report(Report::Settings(active.method, active.settings))
                        .await;
                    true
                }
                Command::Air => {
                    // The one air-reference procedure: a sweep of the free probe and a BVD
                    // fit of its points (profile::air_from_points), which refuses a probe that
                    // touches something.
                    let mut pts: heapless::Vec<pzt_probe::sweep::SweepPoint, AIR_POINTS> =
                        heapless::Vec::new();
                    let r = rig
                        .reading(Method::SweepG, &Settings::Sweep(AIR_SWEEP), &record, |p| {
                            let _ = pts.push(*p);
                        })
                        .await;
                    let air = match r.status {
                        pzt_probe::Status::Failed(Failure::DriveFault | Failure::BadSettings) => {
                            Err(Failure::DriveFault)
                        }
                        _ => profile::air_from_points(&pts),
                    };
                    match air {
                        Ok(air) => {
                            record.air = Some(air);
                            rig.report(Report::Air {
                                f_hz: air.free_resonance.0,
                                q: air.free_q,
                            })
                            .await;
                            true
                        }
                        Err(f) => {
                            rig.report(Report::AirRefused(f)).await;
                            false
                        }
                    }
                }
                Command::CalibrateAdd(e) => {
                    let r = rig
                        .reading(active.method, &active.settings, &record, |_| {})
                        .await;
                    rig.report(Report::Reading(r)).await;
                    match Reference::of(e, &r) {
                        Some(x) if refs.push(x).is_ok() => {
                            rig.report(Report::Reference {
                                e_kpa: e.0,
                                f_hz: x.resonance_hz as f32,
                                f_sigma_hz: x.sigma_hz as f32,
                                n: refs.len() as u16,
                            })
                            .await;
                            true
                        }
                        Some(_) => {
                            rig.report(Report::Refused("reference list full")).await;
                            false
                        }
                        None => {
                            rig.report(Report::Refused("no resonance")).await;
                            false
                        }
                    }
                }
                // The one calibration procedure: robust power-law fit and the Q(E) contact
                // condition of the same readings.
                Command::CalibrateFit => match profile::calibrate(&refs) {
                    Ok((cal, q_model)) => {
                        record.calibration = cal;
                        record.q_model = Some(q_model);
                        fallback = false;
                        rig.report(Report::Calibration(cal)).await;
                        true
                    }
                    Err(_) => {
                        rig.report(Report::Refused("calibration fit failed")).await;
                        false
                    }
                },
                Command::CalibrateClear => {
                    refs.clear();
                    true
                }
                Command::CalibratePaper => {
                    record.calibration = PowerLaw::paper_experiment();
                    rig.report(Report::Calibration(record.calibration)).await;
                    true
                }
                Command::Store => match store.save(&record) {
                    Ok(s) => {
                        fallback = false;
                        rig.report(Report::Saved {
                            slot: s.slot,
                            seq: s.seq,
                        })
                        .await;
                        true
                    }
                    Err(e) => {
                        rig.report(Report::StoreFailed(e)).await;
                        false
                    }
                },
                Command::Status => {
                    rig.report(Report::Status {
                        method: active.method,
                        cal: record.calibration,
                        fallback,
                        air: record.air.is_some(),
                        references: refs.len() as u16,
                    })
                    .await;
                    rig.report(Report::Counters).await;
                    true
                }
            };
            // Only the QEMU script waits for this; elsewhere the slot just stays full.
            let _ = done.try_send(ok);
        }
    }

    /// Turn lines into requests. Parse errors are reported and the line is dropped.
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
            let mut ok = true;
            for &b in SCRIPT {
                let line = match lines.push(b) {
                    Some(Ok(l)) => l,
                    Some(Err(e)) => {
                        let _ = reports.send(Report::Rejected(e)).await;
                        ok = false;
                        continue;
                    }
                    None => continue,
                };
                if serve_line(line, &scale, &mut requests, &mut reports).await {
                    ok &= done.recv().await.unwrap_or(false);
                } else {
                    ok = false;
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

    fn nan_or(v: Option<f32>) -> f32 {
        v.unwrap_or(f32::NAN)
    }

    /// The `settings` line's fields `[start_hz, stop_hz, step_hz, settle_s, integrate_s,
    /// drive_v]` of any method's settings: a sweep's own; for the staged methods the band, no
    /// step (`NaN`), the coarse settling, the integration and the drive; for ring-down the
    /// band, no step, the burst as settling, the ring as integration and the drive; `NaN` for
    /// settings of other kinds.
    fn settings_fields(s: &Settings) -> [f32; 6] {
        if let Settings::Sweep(s) = s {
            return [
                s.start.0,
                s.stop.0,
                s.step.0,
                s.settle.0,
                s.integrate.0,
                s.drive.0,
            ];
        }
        if let Settings::Staged(s) = s {
            return [
                s.band_start.0,
                s.band_stop.0,
                f32::NAN,
                s.coarse_settle.0,
                s.integrate.0,
                s.drive.0,
            ];
        }
        #[cfg(feature = "all-methods")]
        if let Settings::Ringdown(s) = s {
            return [
                s.band_start.0,
                s.band_stop.0,
                f32::NAN,
                s.burst.0,
                s.ring.0,
                s.drive.0,
            ];
        }
        [f32::NAN; 6]
    }

    /// The report task: the only task that logs. Formats are listed in the crate docs.
    #[task(priority = 1)]
    async fn report(_cx: report::Context, mut rx: Receiver<'static, Report, REPORT_CAP>) {
        let mut seen = Overruns::default();
        while let Ok(r) = rx.recv().await {
            match r {
                Report::Loaded(l) => match l.source {
                    LoadSource::Stored { slot, seq, other } => defmt::info!(
                        "store loaded slot={=u8} seq={=u32} other={=str}",
                        slot,
                        seq,
                        slot_name(other)
                    ),
                    LoadSource::Fallback { slots } => defmt::warn!(
                        "store fallback slot0={=str} slot1={=str} calibration=paper-experiment",
                        slot_name(slots[0]),
                        slot_name(slots[1])
                    ),
                },
                Report::Saved { slot, seq } => {
                    defmt::info!("store saved slot={=u8} seq={=u32}", slot, seq)
                }
                Report::StoreFailed(e) => defmt::error!("store error={=str}", store_error_name(e)),
                Report::Settings(m, s) => {
                    let [start, stop, step, settle, integrate, drive] = settings_fields(&s);
                    defmt::info!(
                        "settings method={=str} start_hz={=f32} stop_hz={=f32} step_hz={=f32} settle_s={=f32} integrate_s={=f32} drive_v={=f32}",
                        m.name(),
                        start,
                        stop,
                        step,
                        settle,
                        integrate,
                        drive
                    )
                }
                Report::Point { tag, point } => defmt::info!(
                    "point tag={=u16} f_hz={=f32} g_s={=f32} b_s={=f32} sigma_s={=f32}",
                    tag,
                    point.freq.0,
                    point.g_s,
                    point.b_s,
                    point.sigma_s
                ),
                Report::Reading(r) => defmt::info!(
                    "reading status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str}",
                    r.status.code(),
                    nan_or(r.resonance.map(|v| v.0)),
                    nan_or(r.resonance_sigma.map(|v| v.0)),
                    nan_or(r.modulus.map(|v| v.0)),
                    nan_or(r.modulus_sigma.map(|v| v.0)),
                    nan_or(r.q),
                    r.probe_time.0,
                    r.points,
                    r.method.name()
                ),
                Report::Air { f_hz, q } => defmt::info!("air f_hz={=f32} q={=f32}", f_hz, q),
                Report::AirRefused(f) => defmt::warn!(
                    "rejected error={=str}",
                    f.message()
                ),
                Report::Reference {
                    e_kpa,
                    f_hz,
                    f_sigma_hz,
                    n,
                } => defmt::info!(
                    "reference e_kpa={=f32} f_hz={=f32} f_sigma_hz={=f32} n={=u16}",
                    e_kpa,
                    f_hz,
                    f_sigma_hz,
                    n
                ),
                Report::Calibration(c) => defmt::info!(
                    "calibration source={=str} a={=f32} b={=f32} c={=f32} min_kpa={=f32} max_kpa={=f32}",
                    c.source.name(),
                    c.a as f32,
                    c.b as f32,
                    c.c as f32,
                    c.min_kpa as f32,
                    c.max_kpa as f32
                ),
                Report::Rejected(e) => defmt::warn!("rejected error={=str}", e.message()),
                Report::Hint(f) => defmt::warn!(
                    "hint code={=str} message={=str}",
                    f.code(),
                    f.message()
                ),
                Report::Refused(why) => defmt::warn!("rejected error={=str}", why),
                Report::Stalled { tag } => defmt::error!("stalled tag={=u16}", tag),
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
                Report::Status {
                    method,
                    cal,
                    fallback,
                    air,
                    references,
                } => defmt::info!(
                    "status method={=str} calibration={=str} fallback={=bool} air={=bool} references={=u16}",
                    method.name(),
                    cal.source.name(),
                    fallback,
                    air,
                    references
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
