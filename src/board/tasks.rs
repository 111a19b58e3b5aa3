//! The RTIC side of the firmware's tasks: the channels between them, the monotonic, and each
//! task's work over them and the board, so that the application (`src/bin/probe.rs`) is wiring
//! (each task body calls one function here). What the tasks decide is portable and tested on
//! the host: the measurement task in [`crate::instrument::measure`], the watchdog's guard in
//! [`crate::instrument::watchdog`], the sample interrupt's batch, the UART receive, the host
//! link's receive side and the load cell's read in [`crate::instrument::tasks`], the QEMU
//! image's script in [`super::sim_script`]. Here is only what needs RTIC or the board: the
//! channels' ends, the monotonic's waits, the board's peripherals.

#[cfg(feature = "qemu")]
use super::qemu as board;
#[cfg(all(feature = "stm32", not(feature = "qemu")))]
use super::stm32g474 as board;

use crate::counters::{BatchStats, Overruns, BATCHES};
use crate::engine::{PointRaw, SampleEngine, BATCH};
use crate::hal::FrontEndScale;
use crate::instrument::command::Command;
use crate::instrument::link::{LinkEvent, Outgoing, Report};
use crate::instrument::measure::{FwIo, Link, Recv};
use crate::instrument::session::Event;
use crate::instrument::tasks::{self as portable, ByteSink, CommandLink, RxPort};
use crate::instrument::tasks::{
    EngineCmd, DONE_CAP, LOAD_CELL_POLL_MS, PLAN_CAP, POINT_CAP, REPORT_CAP, REQUEST_CAP, RX_CAP,
};
use crate::instrument::watchdog::{self, Liveness, Millis, BOOT, FEED};
use crate::loadcell::{ForceLog, RawForce};
use crate::unit::store::Store;
use core::sync::atomic::Ordering;
use rtic_monotonics::systick::prelude::*;
use rtic_sync::channel::{Receiver, Sender};

systick_monotonic!(Mono, 1_000);

/// The measurement task's liveness promise, kept by `measure`, read by `guard`.
pub static LIVENESS: Liveness = Liveness::new(BOOT);

/// Each channel's two ends, `Tx` sending up to the capacity's items to `Rx`, with the doc that
/// names what goes through it and from whom to whom.
macro_rules! channels {
    ($($(#[$doc:meta])* $tx:ident, $rx:ident: $item:ty, $cap:ident;)*) => {$(
        $(#[$doc])*
        pub type $tx = Sender<'static, $item, $cap>;
        $(#[$doc])*
        pub type $rx = Receiver<'static, $item, $cap>;
    )*};
}

channels! {
    /// Plans, from the measurement task to the sample interrupt.
    PlanTx, PlanRx: EngineCmd, PLAN_CAP;
    /// Points, from the sample interrupt to the measurement task.
    PointTx, PointRx: PointRaw, POINT_CAP;
    /// Requests, from the command task to the measurement task.
    RequestTx, RequestRx: Command, REQUEST_CAP;
    /// Reports, from the measurement and command tasks to the report task.
    ReportTx, ReportRx: Report, REPORT_CAP;
    /// Completions, from the measurement task to the command task.
    DoneTx, DoneRx: bool, DONE_CAP;
    /// Host bytes, from the UART's receive interrupt to the command task.
    ByteTx, ByteRx: u8, RX_CAP;
}

/// Start the monotonic (SysTick at 1 kHz) below the sample interrupt, so that the timer queue
/// never delays a batch. Call once, from `init`, before any task runs.
pub fn start_monotonic(syst: cortex_m::peripheral::SYST, scb: &mut cortex_m::peripheral::SCB) {
    Mono::start(syst, board::SYSCLK_HZ);
    // SAFETY: priorities are set before any task runs.
    unsafe {
        scb.set_priority(
            cortex_m::peripheral::scb::SystemHandler::SysTick,
            super::nvic_priority(2, board::device::NVIC_PRIO_BITS),
        );
    }
}

/// The monotonic's time in ms (`Mono` ticks at 1 kHz).
pub fn now() -> Millis {
    use rtic_monotonics::rtic_time::monotonic::TimerQueueBasedInstant;
    Millis(Mono::now().ticks())
}

/// The engine's sample count now: the time base of readings and of the force log.
pub fn now_sample() -> u64 {
    BATCHES.load(Ordering::Relaxed) as u64 * BATCH as u64
}

/// The sample interrupt: the batch the stream just captured ([`portable::batch`]), timed and
/// counted ([`BatchStats`]). Never logs, allocates or waits.
#[inline(always)]
pub fn sample(
    stream: &mut board::Stream,
    engine: &mut SampleEngine,
    plans: &mut PlanRx,
    points: &mut PointTx,
    isr: &mut BatchStats,
) {
    let (adc, dac) = stream.capture();
    let t0 = board::stamp();
    portable::batch(
        engine,
        adc,
        dac,
        || plans.try_recv().ok(),
        |p| points.try_send(p).is_ok(),
    );
    isr.batch(board::elapsed(t0), engine.overruns(), stream.late());
}

impl RxPort for board::Uart {
    fn hold(&mut self) {
        board::Uart::hold(self)
    }
    fn read_byte(&mut self) -> Option<u8> {
        board::Uart::read_byte(self)
    }
}

impl ByteSink for ByteTx {
    fn is_full(&self) -> bool {
        Sender::is_full(self)
    }
    fn put(&mut self, byte: u8) {
        let _ = self.try_send(byte);
    }
}

/// The UART's receive interrupt ([`portable::receive`]).
pub fn uart_rx(uart: &mut board::Uart, bytes: &mut ByteTx) {
    portable::receive(uart, bytes)
}

/// The load-cell task: every [`LOAD_CELL_POLL_MS`] the HX711's conversion, if one is ready,
/// into the force log, stamped with the sample count. The read (25 clock pulses)
/// runs with interrupts masked: a pulse stretched past 60 µs by the sample interrupt would
/// power the chip down and lose the conversion (`src/loadcell.rs`). Without a load cell the
/// task ends.
pub async fn load_cell(
    hx: &mut Option<board::LoadCell>,
    mut forces: impl rtic::Mutex<T = &'static mut ForceLog>,
) {
    let Some(hx) = hx.as_mut() else {
        return;
    };
    loop {
        Mono::delay(LOAD_CELL_POLL_MS.millis()).await;
        if let Some(c) = portable::conversion(cortex_m::interrupt::free(|_| hx.read())) {
            let at = now_sample();
            forces.lock(|f| f.push(at, c));
        }
    }
}

/// The measurement task's links ([`Link`]): the channels it was spawned with, the monotonic,
/// the force log.
pub struct MeasureLinks<F> {
    /// From the command task.
    pub requests: RequestRx,
    /// To the sample interrupt.
    pub plans: PlanTx,
    /// From the sample interrupt.
    pub points: PointRx,
    /// To the report task.
    pub reports: ReportTx,
    /// To the command task.
    pub done: DoneTx,
    /// The load cell's force log.
    pub forces: F,
}

impl<F: rtic::Mutex<T = &'static mut ForceLog>> Link for MeasureLinks<F> {
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
    fn dma_errors(&self) -> u32 {
        crate::counters::DMA_ERRORS.load(Ordering::Relaxed)
    }
}

/// The measurement task: the session served one request at a time ([`FwIo::serve`]), keeping
/// the watchdog's liveness promise ([`LIVENESS`]) while alive.
pub async fn measure<F: rtic::Mutex<T = &'static mut ForceLog>>(
    links: MeasureLinks<F>,
    store: &mut Store<board::StoreFlash>,
    scale: FrontEndScale,
) -> ! {
    FwIo::new(links, store, scale, &LIVENESS, board::boot_error())
        .serve()
        .await
}

/// The watchdog's guard: every [`FEED`] period it feeds the independent watchdog as long as
/// the measurement task keeps its liveness promise ([`watchdog::guard`]).
pub async fn guard(dog: &mut board::Watchdog) -> ! {
    loop {
        watchdog::guard(&LIVENESS, now(), dog);
        Mono::delay(FEED.0.millis()).await;
    }
}

/// The command task's links ([`CommandLink`]): the channels it was spawned with and, on QEMU,
/// the simulated probe as the `sim` lines so far have it.
struct CommandLinks {
    requests: RequestTx,
    reports: ReportTx,
    done: DoneRx,
    rx: ByteRx,
    #[cfg(feature = "qemu")]
    sim: super::sim_script::SimState,
}

impl CommandLink for CommandLinks {
    /// The next byte; then the UART's receive interrupt may move the next ones in.
    async fn byte(&mut self) -> Option<u8> {
        let b = self.rx.recv().await.ok()?;
        rtic::pend(board::device::interrupt::LPUART1);
        Some(b)
    }
    async fn request(&mut self, c: Command) -> bool {
        self.requests.send(c).await.is_ok()
    }
    fn has_room(&self) -> bool {
        !self.requests.is_full()
    }
    fn try_request(&mut self, c: Command) -> bool {
        self.requests.try_send(c).is_ok()
    }
    async fn done(&mut self) -> Option<bool> {
        self.done.recv().await.ok()
    }
    fn try_done(&mut self) -> Option<bool> {
        self.done.try_recv().ok()
    }
    async fn report(&mut self, r: Report) {
        let _ = self.reports.send(r).await;
    }
    #[cfg(feature = "qemu")]
    fn is_board_line(&self, line: &str) -> bool {
        super::sim_script::is_sim_line(line)
    }
    #[cfg(feature = "qemu")]
    async fn board_line(&mut self, line: &str) -> Option<&'static str> {
        let mut sim = self.sim;
        let error = super::sim_script::sim_line(self, line, &mut sim).await;
        self.sim = sim;
        error
    }
}

#[cfg(feature = "qemu")]
impl super::sim_script::SimLink for CommandLinks {
    async fn scene(&mut self, sim: &super::sim_script::SimState) {
        board::set_scene(sim.scene(), sim.seed);
        Mono::delay(super::sim_script::SCENE_SETTLE_MS.millis()).await;
    }
}

/// The command task: host bytes → frames → requests, one request at a time.
///
/// The STM32 serves the host link from power-on ([`portable::serve_link`]). On QEMU the task
/// first runs the boot command line's script (or the board's built-in one,
/// [`super::sim_script::run_script`]); at its end it ends the run with success iff every
/// request succeeded and no overrun happened, or, at a `serve` line, serves the host link.
pub async fn command(requests: RequestTx, reports: ReportTx, done: DoneRx, rx: ByteRx) {
    let scale = board::scale();
    let mut links = CommandLinks {
        requests,
        reports,
        done,
        rx,
        #[cfg(feature = "qemu")]
        sim: board::sim_state(),
    };
    #[cfg(feature = "qemu")]
    {
        use super::sim_script::{run_script, End};
        // The boot command line's script, else the built-in one.
        let mut cmdline = [0u8; board::CMDLINE_MAX];
        let script = board::boot_script(&mut cmdline).unwrap_or(board::SCRIPT);
        let mut sim = links.sim;
        match run_script(&mut links, script, &mut sim, scale).await {
            End::Serve => links.sim = sim,
            End::Exit(ok) => {
                let ok = ok && !Overruns::now().any();
                links.report(Report::Exit(ok)).await;
                return;
            }
        }
    }
    portable::serve_link(&mut links, &scale).await
}

/// The host link's transmitter where a task drives it (STM32: LPUART1 by DMA, chunks of the
/// transmit queue as they come, looked for every millisecond while it is empty; QEMU: the
/// UART's transmit interrupt does it and the task ends at once).
pub async fn link_tx(tx: &mut board::LinkTx) {
    if !board::LinkTx::BY_TASK {
        return;
    }
    let mut chunk = [0u8; 128];
    loop {
        match board::LinkTx::take(&mut chunk) {
            0 => Mono::delay(1.millis()).await,
            n => {
                // The transfer is polled every 10 ms besides its wake: embassy 0.6 wakes the
                // writer only on half and full transfer, and a transfer a DMA error ended (the
                // channel disabled; its frames cut, which the host's decoder skips) is seen
                // ended only when polled.
                let mut write = core::pin::pin!(tx.write(&chunk[..n]));
                while Mono::timeout_after(10.millis(), write.as_mut())
                    .await
                    .is_err()
                {}
            }
        }
    }
}

/// The report task: the only task that logs ([`crate::instrument::log::report`]), and the
/// host link's transmit side: each report also as frames into the transmit queue
/// ([`Outgoing`]). The QEMU image ends at the script's exit report.
pub async fn report(mut rx: ReportRx) {
    let mut seen = Overruns::default();
    let (mut out, mut frame) = (
        Outgoing::new(board::NAME, board::ELAPSED_UNIT, board::boot_error()),
        [0u8; probe_proto::MAX_DEVICE_FRAME + 1],
    );
    while let Ok(r) = rx.recv().await {
        out.report(&r, &mut frame, board::link_send);
        #[allow(unused_variables)] // the exit status ends only the QEMU image
        if let Some(ok) = crate::instrument::log::report(r, board::ELAPSED_UNIT, &mut seen) {
            #[cfg(feature = "qemu")]
            board::exit(ok);
        }
    }
}
