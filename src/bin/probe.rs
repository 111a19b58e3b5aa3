//! The probe's firmware: the RTIC 2 application.
//!
//! One image, two boards: `--features stm32` for the STM32G474RE (NUCLEO-G474RE) and
//! `--features qemu` for QEMU's mps2-an386 with the simulated probe; both built for
//! `thumbv7em-none-eabihf` with `--no-default-features` (see `docs/firmware.md`). On the host
//! this file compiles to an empty `main` so workspace builds and tests stay simple.
//!
//! # Tasks
//!
//! Each task body calls one function of [`pzt_probe::board::tasks`] (the channels, the
//! monotonic, the board), whose decisions are the portable, host-tested
//! [`pzt_probe::instrument::tasks`], [`pzt_probe::instrument::measure`] and
//! [`pzt_probe::instrument::watchdog`]: this file is wiring.
//!
//! | task | priority | what |
//! |---|---|---|
//! | `sample` (hardware) | 3 | per batch: demodulate the ADC half, refill the DAC half ([`pzt_probe::engine::SampleEngine`]) |
//! | `uart_rx` (hardware) | 2 | host bytes from LPUART1's DMA ring (ST-LINK virtual COM port) into a channel |
//! | `measure` | 1 | the session ([`pzt_probe::instrument::session`]): profile, settings, the flash store; readings through [`pzt_probe::reading::driver`]; the task's board and loop are [`pzt_probe::instrument::measure`], over the links of [`pzt_probe::board::tasks::MeasureLinks`] |
//! | `command` | 1 | the host link's receive side: bytes → frames → [`pzt_probe::instrument::command::parse`] → requests to `measure`, each answered ([`pzt_probe::instrument::tasks::serve_link`], [`pzt_probe::instrument::link`], `docs/protocol.md`); QEMU: first the boot command line's script or the built-in one, run by [`pzt_probe::board::sim_script::run_script`], the link after its `serve` |
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
// (`pzt_probe::board::qemu`, `pzt_probe::board::stm32g474`); the tasks' work, the channels'
// types and the monotonic in `pzt_probe::board::tasks`.

#[cfg(target_os = "none")]
#[rtic::app(device = crate::board::device, peripherals = false, dispatchers = [SPI3, SPI2])]
mod app {
    use crate::board;
    use pzt_probe::board::tasks::{self as work, MeasureLinks};
    use pzt_probe::board::tasks::{ByteRx, ByteTx, DoneRx, DoneTx, PlanRx, PlanTx, PointRx};
    use pzt_probe::board::tasks::{PointTx, ReportRx, ReportTx, RequestRx, RequestTx};
    use pzt_probe::counters::BatchStats;
    use pzt_probe::engine::{PointRaw, SampleEngine, BATCH};
    use pzt_probe::hal::FrontEndScale;
    use pzt_probe::instrument::command::Command;
    use pzt_probe::instrument::link::Report;
    use pzt_probe::instrument::tasks::{EngineCmd, DONE_CAP, PLAN_CAP, POINT_CAP};
    use pzt_probe::instrument::tasks::{REPORT_CAP, REQUEST_CAP, RX_CAP};
    use pzt_probe::loadcell::ForceLog;
    use pzt_probe::unit::store::Store;
    use rtic_sync::make_channel;

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
        plan_rx: PlanRx,
        point_tx: PointTx,
        isr: BatchStats,
        watchdog: board::Watchdog,
        store: Store<board::StoreFlash>,
        scale: FrontEndScale,
        uart: board::Uart,
        rx_tx: ByteTx,
        link_tx: board::LinkTx,
        load_cell: Option<board::LoadCell>,
    }

    // The force log lives in init's static (1.5 KiB), not on its stack: the shared resource is
    // a reference to it.
    #[init(local = [forces: ForceLog = ForceLog::new()])]
    fn init(mut cx: init::Context) -> (Shared, Local) {
        let parts = board::init(&mut cx.core);
        work::start_monotonic(cx.core.SYST, &mut cx.core.SCB);

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

    /// The sample interrupt: one batch ([`BATCH`] samples, 2.5 ms at 10 kHz) per call
    /// ([`work::sample`]).
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
        let l = cx.local;
        work::sample(l.stream, l.engine, l.plan_rx, l.point_tx, l.isr);
    }

    /// Host bytes from the UART into the command task's channel while it has room; then the
    /// board holds the rest (`Uart::hold`: QEMU keeps the host's stream back in its receive
    /// register; the STM32 drops what its DMA ring holds, the line then fails to parse and is
    /// reported), and the command task pends this interrupt after each byte it takes
    /// ([`work::uart_rx`]).
    #[task(binds = LPUART1, priority = 2, local = [uart, rx_tx])]
    fn uart_rx(cx: uart_rx::Context) {
        work::uart_rx(cx.local.uart, cx.local.rx_tx);
    }

    /// The load-cell task: a conversion of the HX711, when one is ready, into the force log,
    /// with interrupts masked during the read; driver errors are counted, never logged from
    /// here ([`work::load_cell`]).
    #[task(priority = 1, shared = [forces], local = [load_cell])]
    async fn load_cell(cx: load_cell::Context) {
        work::load_cell(cx.local.load_cell, cx.shared.forces).await
    }

    /// The watchdog's guard: every feed period it feeds the independent watchdog as long as
    /// the measurement task keeps its liveness promise ([`work::guard`]). Above the
    /// measurement task's priority, so it runs through a long `calibrate fit`; a measurement
    /// task that hangs breaks its promise, the feeding stops and the watchdog resets the core.
    #[task(priority = 2, local = [watchdog])]
    async fn guard(cx: guard::Context) {
        work::guard(cx.local.watchdog).await
    }

    /// The measurement task: the session served one request at a time, keeping the
    /// watchdog's liveness promise (`guard`) while alive ([`work::measure`]).
    #[task(priority = 1, shared = [forces], local = [store, scale])]
    async fn measure(
        cx: measure::Context,
        requests: RequestRx,
        plans: PlanTx,
        points: PointRx,
        reports: ReportTx,
        done: DoneTx,
    ) {
        let forces = cx.shared.forces;
        let links = MeasureLinks {
            requests,
            plans,
            points,
            reports,
            done,
            forces,
        };
        work::measure(links, cx.local.store, *cx.local.scale).await
    }

    /// The command task: host bytes → frames → requests, one request at a time; on QEMU
    /// first the boot command line's script ([`work::command`]).
    #[task(priority = 1)]
    async fn command(
        _cx: command::Context,
        requests: RequestTx,
        reports: ReportTx,
        done: DoneRx,
        rx: ByteRx,
    ) {
        work::command(requests, reports, done, rx).await
    }

    /// The host link's transmitter where a task drives it: STM32 LPUART1 by DMA; QEMU's
    /// transmit interrupt does it and the task ends ([`work::link_tx`]).
    #[task(priority = 1, local = [link_tx])]
    async fn link_tx(cx: link_tx::Context) {
        work::link_tx(cx.local.link_tx).await
    }

    /// The report task: the only task that logs, and the host link's transmit side
    /// ([`work::report`]). Formats are listed in the crate docs.
    #[task(priority = 1)]
    async fn report(_cx: report::Context, rx: ReportRx) {
        work::report(rx).await
    }
}
