//! The QEMU board: the firmware image on QEMU's `mps2-an386` machine (ARM AN386: Cortex-M4 with
//! FPU, CMSDK peripherals, 25 MHz system clock), with the simulated probe (`hal-sim`, compiled
//! `no_std`) behind the same stream interface as the STM32's DAC/ADC DMA driver.
//!
//! * **Sample cadence.** CMSDK APB timer 0 (IRQ 8) fires once per batch period
//!   ([`BATCH`] samples at the simulated front end's sample rate: 2.5 ms at 10 kHz), standing in for
//!   the STM32's ADC DMA half/full-transfer interrupt (and bound under its name, `DMA1_CHANNEL1`, as embassy-stm32's device crate calls it). [`Stream::capture`] then does what the two
//!   DMA channels did during that period — play the DAC half-buffer through [`SimProbe`] and fill
//!   the ADC half-buffer — and hands both halves to the interrupt, exactly as the STM32 driver
//!   does: the ADC half just captured and the DAC half just played (to be refilled; it plays two
//!   batches later).
//! * **Instruction clock.** CMSDK timer 1 runs free at 25 MHz. Under `-icount shift=0` QEMU
//!   executes exactly one instruction per nanosecond of virtual time, so one timer tick is
//!   [`INSTRUCTIONS_PER_TICK`] instructions: [`stamp`]/[`elapsed`] count instructions with a
//!   resolution of 40.
//! * **Output and exit.** defmt frames go out over semihosting (`defmt-semihosting`); [`exit`]
//!   ends QEMU through semihosting with success or failure.
//! * **Flash.** A [`SimFlash`] in RAM (two 2 KiB sectors) stands in for the STM32's last two
//!   flash pages, so the calibration store runs the same code; it starts erased at every boot.
//!
//! Run with `-machine mps2-an386 -cpu cortex-m4 -icount shift=0,sleep=off
//! -semihosting-config enable=on,target=native` (see `scripts/qemu-run`).

use crate::board::tx_queue;
use crate::engine::SampleEngine;
use crate::engine::BATCH;
use crate::hal::{AdcFrame, FrontEndScale};
use crate::loadcell::Hx711;
use crate::units::{AdcCode, DacCode};
use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};
use hal_sim::flash::SimFlash;
use hal_sim::loadcell::{ChipHandle, Delay, Dout, Hx711Sim, Sck};
use hal_sim::{AdcPair, SimProbe};

// The image's defmt global logger: semihosting.
use defmt_semihosting as _;

/// The image's panic handler: log the panic's location and message, then end the run with
/// failure.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic {}", defmt::Display2Format(info));
    exit(false)
}

/// `defmt::panic!` and its kin have logged their message already: end the run with failure
/// without a second line.
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    exit(false)
}

/// A fault ends the run with failure.
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    exit(false)
}

/// What RTIC needs of a device crate, for the interrupt lines this image uses.
///
/// AN386 has 32 external interrupt lines (UARTs 0–5, 12; GPIO 6–7, 16–31; timers 8–10; SPI 11;
/// ...). The image binds five of them, and names four after the STM32G474 vectors they stand in
/// for, so one RTIC application (same `binds`, same dispatcher) serves both boards:
///
/// * line 8, CMSDK timer 0, is `DMA1_CHANNEL1`: the batch cadence, in place of the STM32's ADC DMA
///   half/full-transfer interrupt;
/// * line 0, CMSDK UART0 receive, is `LPUART1` (the STM32 LPUART1 vector): host bytes, like the STM32's ST-LINK virtual COM
///   port (QEMU's first serial port);
/// * line 1, CMSDK UART0 transmit, is `UART0TX`: the host link's transmit queue drained byte by
///   byte, by this board's own handler ([`link_send`]), not an RTIC task;
/// * line 11 (the AN386 SPI controller, unused here) is `SPI3` and line 15 (the touch screen,
///   not modelled) is `SPI2`: the software-task dispatchers (priorities 1 and 2), the same
///   unused vectors the STM32 image dispatches on.
pub mod device {
    /// Priority bits RTIC assumes (QEMU implements all eight; the upper three are used, as on
    /// the STM32G4's four-bit NVIC with one bit to spare).
    pub const NVIC_PRIO_BITS: u8 = 3;

    /// Interrupt lines of the image.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    #[allow(non_camel_case_types, clippy::upper_case_acronyms)]
    #[repr(u16)]
    pub enum Interrupt {
        /// CMSDK UART0 receive.
        LPUART1 = 0,
        /// CMSDK UART0 transmit.
        UART0TX = 1,
        /// CMSDK timer 0: the sample cadence (one batch per period).
        DMA1_CHANNEL1 = 8,
        /// Line 11: the software-task dispatcher (priority 1).
        SPI3 = 11,
        /// Line 15 (the touch screen's, not modelled by QEMU): the software-task dispatcher
        /// (priority 2, the watchdog's guard).
        SPI2 = 15,
    }

    pub use self::Interrupt as interrupt;

    // SAFETY: the numbers are valid external interrupt lines of the AN386 NVIC (0..32).
    unsafe impl cortex_m::interrupt::InterruptNumber for Interrupt {
        fn number(self) -> u16 {
            self as u16
        }
    }

    /// One entry of the external interrupt vector table.
    #[derive(Clone, Copy)]
    #[repr(transparent)]
    pub struct Vector(unsafe extern "C" fn());

    extern "C" {
        fn LPUART1();
        fn UART0TX();
        fn DMA1_CHANNEL1();
        fn SPI3();
        fn SPI2();
        fn DefaultHandler();
    }

    /// The external interrupt vectors (placed after the core exceptions by cortex-m-rt);
    /// unused lines go to cortex-m-rt's default handler.
    #[link_section = ".vector_table.interrupts"]
    #[no_mangle]
    pub static __INTERRUPTS: [Vector; 32] = {
        let mut v = [Vector(DefaultHandler); 32];
        v[0] = Vector(LPUART1);
        v[1] = Vector(UART0TX);
        v[8] = Vector(DMA1_CHANNEL1);
        v[11] = Vector(SPI3);
        v[15] = Vector(SPI2);
        v
    };
}

/// Board name in the boot log line.
pub const NAME: &str = "qemu";

/// The clock in the boot fault line: the machine has one.
pub fn clock_name() -> &'static str {
    NAME
}

/// The script the image runs when its boot command line holds none ([`boot_script`]), through
/// the same line parser as a host's lines: a reading with the default method (auto), one with
/// sweep-G over a sweep of its own, back to auto with two-stage settings of its own, store,
/// status.
pub const SCRIPT: &str = "status;measure;method sweep-g;sweep 200 260 2 0.02 0.03 5;measure;method auto;staged 180 280 6 0.02 0.03 5 0.8 5 4;store;status";

/// The probe at power-on: on phantom B of paper 003 (279 kPa) at 30 mN and the bench noise
/// level, noise seed 1. The command script moves it (`sim ...` lines,
/// [`super::sim_script`]).
pub fn sim_state() -> super::sim_script::SimState {
    super::sim_script::SimState {
        base: hal_sim::Scene::on_phantom(&hal_sim::phantoms::B),
        preload_n: 0.03,
        noise: hal_sim::NoiseScene::Bench,
        seed: 1,
        fault: None,
        boot_fault: None,
        events: Default::default(),
    }
}

/// The scene at power-on ([`sim_state`]).
pub fn scene() -> hal_sim::Scene {
    sim_state().scene()
}

/// The probe at power-on as the boot script has it: [`sim_state`] with the script's leading
/// `sim` lines (those before its first probe command) applied, so that the power-on self-test
/// already sees the scene, or the fault, the script starts on. The command task applies them
/// again in order (a fresh probe on the same scene).
pub fn boot_state() -> super::sim_script::SimState {
    let mut state = sim_state();
    let mut cmdline = [0u8; CMDLINE_MAX];
    if let Some(script) = boot_script(&mut cmdline) {
        for line in super::sim_script::lines(script) {
            if super::sim_script::apply(line, &mut state) != Ok(true) {
                break;
            }
        }
    }
    state
}

/// A new scene and noise stream for the probe, taken by the sample interrupt at its next batch.
static SCENE_REQUEST: cortex_m::interrupt::Mutex<core::cell::Cell<Option<(hal_sim::Scene, u64)>>> =
    cortex_m::interrupt::Mutex::new(core::cell::Cell::new(None));

/// Put the probe on `scene` with noise stream `seed` from the next batch on (a fresh simulated
/// probe: the state of the old scene does not carry over, as after a lift and a new press).
pub fn set_scene(scene: hal_sim::Scene, seed: u64) {
    cortex_m::interrupt::free(|cs| SCENE_REQUEST.borrow(cs).set(Some((scene, seed))));
}

/// Bytes of the boot command line the image reads.
pub const CMDLINE_MAX: usize = 1024;

/// The command script of the boot command line (semihosting `SYS_GET_CMDLINE`: QEMU's
/// `-semihosting-config arg=...`, which `scripts/qemu-run` sets from `QEMU_SCRIPT`): the text
/// after its `script:` prefix, lines separated by `;`, or `None` when the command line holds
/// no script (the image then runs its built-in one).
pub fn boot_script(buf: &mut [u8; CMDLINE_MAX]) -> Option<&str> {
    let mut block = [buf.as_mut_ptr() as usize, CMDLINE_MAX];
    // SAFETY: semihosting call with a block of (buffer, length) that outlives it; the host
    // writes at most `CMDLINE_MAX` bytes and the length back.
    let r = unsafe {
        cortex_m_semihosting::syscall1(
            cortex_m_semihosting::nr::GET_CMDLINE,
            block.as_mut_ptr() as usize,
        )
    };
    let n = block[1].min(CMDLINE_MAX);
    if r != 0 || n == 0 {
        return None;
    }
    // The host writes a NUL-terminated string.
    let text = buf.get(..n)?;
    let end = text.iter().position(|&b| b == 0).unwrap_or(text.len());
    let s = core::str::from_utf8(text.get(..end)?).ok()?;
    let i = s.find("script:")?;
    s.get(i + "script:".len()..).map(str::trim)
}

/// Converter scale of the simulated front end (`hal_sim::FrontEnd::default()`).
pub fn scale() -> FrontEndScale {
    crate::board::sim::scale_of(&scene().front_end)
}

/// The board's parts, as the application takes them over (the watchdog a stand-in).
pub type Parts = super::Parts<Stream, Watchdog, StoreFlash, Uart, LinkTx, LoadCell>;

/// Set the board up: the simulated probe on [`boot_state`]'s scene, and its flash as the
/// factory left it —
/// the unit's profile ([`super::sim_factory::RECORD`]) programmed into the store's first slot.
/// Call once, from `init`.
pub fn init(core: &mut cortex_m::Peripherals) -> Parts {
    // The host link's transmit interrupt, outside RTIC: the lowest task priority.
    // SAFETY: before any task runs; the handler shares nothing with RTIC's resources.
    unsafe {
        core.NVIC.set_priority(
            device::Interrupt::UART0TX,
            super::nvic_priority(1, device::NVIC_PRIO_BITS),
        );
        cortex_m::peripheral::NVIC::unmask(device::Interrupt::UART0TX);
    }
    let mut flash = StoreFlash::new();
    // The simulated flash is erased at boot and the record fits its first sector: the factory
    // programming cannot fail; if it did, the store would load its fallback and say so.
    let _ = embedded_storage::nor_flash::NorFlash::write(
        &mut flash,
        STORE_BASE,
        &super::sim_factory::RECORD,
    );
    let boot = boot_state();
    if let Some(e) = boot.boot_fault {
        BOOT_FAULT.store(e as u8, core::sync::atomic::Ordering::Relaxed);
    }
    let mut stream = Stream::new(SimProbe::new(boot.scene(), boot.seed));
    // As on the STM32: a failed step that leaves it without converters starts no stream.
    stream.dead = boot.boot_fault.is_some_and(|e| e.blocks_readings());
    Parts {
        stream,
        watchdog: Watchdog { last: None },
        flash,
        uart: Uart::new(),
        link_tx: LinkTx,
        load_cell: load_cell(),
    }
}

/// Core clock of the machine (SysTick and the CMSDK timers), Hz.
pub const SYSCLK_HZ: u32 = 25_000_000;
/// Instructions per tick of the 25 MHz timers under `-icount shift=0` (1 instruction per ns).
pub const INSTRUCTIONS_PER_TICK: u32 = 1_000_000_000 / SYSCLK_HZ;

/// A CMSDK APB timer's registers (ARM DDI 0479, "APB timer"; QEMU `cmsdk-apb-timer`).
#[repr(C)]
struct CmsdkTimer {
    ctrl: u32,
    value: u32,
    reload: u32,
    intclear: u32,
}

impl CmsdkTimer {
    /// CTRL.EN.
    const ENABLE: u32 = 1 << 0;
    /// CTRL.INTEN.
    const IRQ_ENABLE: u32 = 1 << 3;
}

/// mps2-an386's timer 0 (the sample clock) and timer 1 (the instruction clock).
const TIMER0: *mut CmsdkTimer = 0x4000_0000 as *mut CmsdkTimer;
const TIMER1: *mut CmsdkTimer = 0x4000_1000 as *mut CmsdkTimer;

/// Start the free-running instruction clock (timer 1, no interrupt) read by [`stamp`]; the
/// stream's [`Stream::start`] does this, a program without the stream calls it itself.
pub fn start_stamp_clock() {
    // SAFETY: CMSDK timer 1 registers of mps2-an386; the image owns the timer.
    unsafe {
        write_volatile(addr_of_mut!((*TIMER1).ctrl), 0);
        write_volatile(addr_of_mut!((*TIMER1).reload), u32::MAX);
        write_volatile(addr_of_mut!((*TIMER1).value), u32::MAX);
        write_volatile(addr_of_mut!((*TIMER1).ctrl), CmsdkTimer::ENABLE);
    }
}

/// A reading of the instruction clock.
#[inline(always)]
pub fn stamp() -> u32 {
    // SAFETY: read-only access to CMSDK timer 1's counter.
    unsafe { read_volatile(addr_of!((*TIMER1).value)) }
}

/// Instructions executed since `start` (a [`stamp`]); valid for spans under 171 s.
#[inline(always)]
pub fn elapsed(start: u32) -> u32 {
    // The timer counts down.
    start
        .wrapping_sub(stamp())
        .saturating_mul(INSTRUCTIONS_PER_TICK)
}

/// Instructions executed since `start` (a [`stamp`]), for spans too long for [`elapsed`]'s
/// `u32` (over 4.29 G instructions); valid for spans under 171 s.
pub fn elapsed_long(start: u32) -> u64 {
    start.wrapping_sub(stamp()) as u64 * INSTRUCTIONS_PER_TICK as u64
}

/// Unit of [`elapsed`].
pub const ELAPSED_UNIT: &str = "instructions";

// Two DAC halves: the pipeline of `reading::PIPELINE_BATCHES` that the host's simulated board
// models too.
const _: () = assert!(crate::engine::PIPELINE_BATCHES == 2);

/// The simulated sample stream: a double-buffered DAC/ADC exchange with the simulated probe.
pub struct Stream {
    probe: SimProbe,
    dac: [[DacCode; BATCH]; 2],
    adc: [[AdcFrame; BATCH]; 2],
    half: usize,
    scale: FrontEndScale,
    /// No converters (an emulated boot fault, [`boot_error`]): [`start`](Self::start) starts
    /// the instruction clock but not the batch timer.
    dead: bool,
}

impl Stream {
    /// A stream over `probe`, idle until [`start`](Self::start); the probe's load cell, if its
    /// scene has one, becomes the board's ([`LoadCell`]).
    pub fn new(probe: SimProbe) -> Self {
        attach_load_cell(&probe);
        let scale = crate::board::sim::scale_of(probe.front_end());
        Self {
            probe,
            dac: [[DacCode::MID; BATCH]; 2],
            adc: [[AdcFrame::default(); BATCH]; 2],
            half: 0,
            scale,
            dead: false,
        }
    }

    /// Converter scale of the simulated front end.
    pub fn scale(&self) -> FrontEndScale {
        self.scale
    }

    /// Prefill both DAC halves from `engine`, as the STM32 driver does before starting its DMA
    /// (and a program calling [`capture`](Self::capture) itself, without the batch timer,
    /// before its first batch).
    pub fn prefill(&mut self, engine: &mut SampleEngine) {
        for half in self.dac.iter_mut() {
            engine.generate(half);
        }
    }

    /// [`prefill`](Self::prefill), then start the instruction clock and the batch timer.
    pub fn start(&mut self, engine: &mut SampleEngine) {
        self.prefill(engine);
        start_stamp_clock();
        if self.dead {
            return;
        }
        let period = (SYSCLK_HZ as f32 * BATCH as f32 / self.scale.sample_rate.0) as u32;
        // SAFETY: CMSDK timer 0 registers; the image owns the timer.
        unsafe {
            write_volatile(addr_of_mut!((*TIMER0).ctrl), 0);
            write_volatile(addr_of_mut!((*TIMER0).reload), period.saturating_sub(1));
            write_volatile(addr_of_mut!((*TIMER0).value), period.saturating_sub(1));
            write_volatile(addr_of_mut!((*TIMER0).intclear), 1);
            write_volatile(
                addr_of_mut!((*TIMER0).ctrl),
                CmsdkTimer::ENABLE | CmsdkTimer::IRQ_ENABLE,
            );
        }
    }

    /// Acknowledge the batch interrupt and emulate the DMA of the period that just ended: the
    /// DAC half of this period plays through the probe, the ADC half fills. Returns the ADC half
    /// just captured and the DAC half just played (to refill).
    pub fn capture(&mut self) -> (&[AdcFrame], &mut [DacCode]) {
        // SAFETY: write-one-to-clear of timer 0's interrupt.
        unsafe { write_volatile(addr_of_mut!((*TIMER0).intclear), 1) };
        if let Some((scene, seed)) = cortex_m::interrupt::free(|cs| SCENE_REQUEST.borrow(cs).take())
        {
            self.probe = SimProbe::new(scene, seed);
            attach_load_cell(&self.probe);
        }
        let h = self.half & 1;
        self.half ^= 1;
        let mut codes = [0u16; BATCH];
        for (c, d) in codes.iter_mut().zip(self.dac[h].iter()) {
            *c = d.0;
        }
        let mut pairs = [AdcPair::default(); BATCH];
        self.probe.exchange(&codes, &mut pairs);
        cortex_m::interrupt::free(|cs| {
            if let Some(c) = LOAD_CELL_CHIP.borrow(cs).borrow_mut().as_mut() {
                c.follow(&self.probe);
            }
        });
        for (a, p) in self.adc[h].iter_mut().zip(pairs.iter()) {
            *a = AdcFrame {
                current: AdcCode(p.current),
                monitor: AdcCode(p.monitor),
            };
        }
        (&self.adc[h], &mut self.dac[h])
    }

    /// True when the next batch interrupt is already pending: the handler overran its period.
    pub fn late(&self) -> bool {
        cortex_m::peripheral::NVIC::is_pending(device::Interrupt::DMA1_CHANNEL1)
    }
}

/// A CMSDK APB UART's registers (ARM DDI 0479, "APB UART"; QEMU `cmsdk-apb-uart`).
#[repr(C)]
struct CmsdkUart {
    data: u32,
    state: u32,
    ctrl: u32,
    intclear: u32,
    bauddiv: u32,
}

impl CmsdkUart {
    /// STATE.TXFULL.
    const TX_FULL: u32 = 1 << 0;
    /// STATE.RXFULL.
    const RX_FULL: u32 = 1 << 1;
    /// CTRL.TXEN, CTRL.RXEN, CTRL.TXINTEN, CTRL.RXINTEN.
    const TX_RX_IRQS: u32 = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 3);
    /// INTCLEAR.TXINT.
    const INT_TX: u32 = 1 << 0;
    /// INTCLEAR.RXINT.
    const INT_RX: u32 = 1 << 1;
}

/// mps2-an386's UART0.
const UART0: *mut CmsdkUart = 0x4000_4000 as *mut CmsdkUart;

/// CMSDK UART0 (QEMU's first serial port), receive side, interrupt driven.
pub struct Uart(());

impl Uart {
    fn new() -> Self {
        // SAFETY: CMSDK UART0 registers; the image owns the UART.
        unsafe {
            write_volatile(addr_of_mut!((*UART0).bauddiv), SYSCLK_HZ / 115_200);
            write_volatile(addr_of_mut!((*UART0).ctrl), CmsdkUart::TX_RX_IRQS);
        }
        Self(())
    }

    /// Leave the received byte in the receive register (STATE.RXFULL: QEMU then takes no
    /// more from the host) and acknowledge its interrupt; the next [`read_byte`](Self::read_byte)
    /// takes it.
    pub fn hold(&mut self) {
        // SAFETY: write-one-to-clear of UART0's receive interrupt.
        unsafe { write_volatile(addr_of_mut!((*UART0).intclear), CmsdkUart::INT_RX) };
    }

    /// The next received byte, if any (acknowledges the receive interrupt).
    pub fn read_byte(&mut self) -> Option<u8> {
        // SAFETY: CMSDK UART0 registers; reading DATA pops the received byte.
        unsafe {
            write_volatile(addr_of_mut!((*UART0).intclear), CmsdkUart::INT_RX);
            if read_volatile(addr_of!((*UART0).state)) & CmsdkUart::RX_FULL != 0 {
                Some(read_volatile(addr_of!((*UART0).data)) as u8)
            } else {
                None
            }
        }
    }
}

/// Queue a whole frame of the host link for UART0 ([`tx_queue::queue`]), or refuse it
/// (`false`) when the queue has no room for all of it: never waits. The transmit interrupt
/// sends it.
pub fn link_send(frame: &[u8]) -> bool {
    let queued = tx_queue::queue(frame);
    if queued {
        cortex_m::peripheral::NVIC::pend(device::Interrupt::UART0TX);
    }
    queued
}

/// The host link's transmit side as the task `link_tx` sees it: nothing to drive here (UART0's
/// transmit interrupt, [`UART0TX`], sends what [`link_send`] queued), so the task ends at once.
pub struct LinkTx;

impl LinkTx {
    /// The task `link_tx` has work on this board.
    pub const BY_TASK: bool = false;

    /// Bytes the task should send next: none (the interrupt sends them).
    pub fn take(_buf: &mut [u8]) -> usize {
        0
    }

    /// Send `bytes` (never called: [`Self::BY_TASK`] is false).
    pub async fn write(&mut self, _bytes: &[u8]) {}
}

/// CMSDK UART0's transmit interrupt (line 1; not an RTIC task, at the lowest priority, set by
/// [`init`]): queued bytes while the transmitter takes them (STATE.TXFULL clear); after a
/// byte QEMU's character device could not take at once, the interrupt comes again when it has.
#[no_mangle]
extern "C" fn UART0TX() {
    // SAFETY: CMSDK UART0's transmit registers, written only here. The interrupt is cleared
    // before the writes, so a byte taken later raises it again.
    unsafe {
        write_volatile(addr_of_mut!((*UART0).intclear), CmsdkUart::INT_TX);
        while read_volatile(addr_of!((*UART0).state)) & CmsdkUart::TX_FULL == 0 {
            match tx_queue::pop() {
                Some(b) => write_volatile(addr_of_mut!((*UART0).data), b as u32),
                None => break,
            }
        }
    }
}

/// The simulated probe's load cell (its HX711), shared by the sample interrupt (which advances
/// it with the probe's time and contact force, [`Stream::capture`]) and the load-cell task
/// (which reads it through its pins, [`LoadCell`]).
static LOAD_CELL_CHIP: cortex_m::interrupt::Mutex<core::cell::RefCell<Option<Hx711Sim>>> =
    cortex_m::interrupt::Mutex::new(core::cell::RefCell::new(None));

/// The load cell's chip as its pins and delay see it: every access in a critical section.
#[derive(Clone, Copy)]
pub struct Chip;

impl ChipHandle for Chip {
    fn with<R>(&self, f: impl FnOnce(&mut Hx711Sim) -> R) -> R {
        cortex_m::interrupt::free(|cs| {
            let mut chip = LOAD_CELL_CHIP.borrow(cs).borrow_mut();
            match chip.as_mut() {
                Some(c) => f(c),
                // No load cell on this scene: a chip that never converts (DOUT stays high).
                None => f(&mut Hx711Sim::new(hal_sim::loadcell::LoadCell::quiet(), 0)),
            }
        })
    }
}

/// The load cell: the firmware's HX711 driver on the simulated chip's pins.
pub type LoadCell = Hx711<Delay<Chip>, Dout<Chip>, Sck<Chip>>;

/// The load cell's driver on the simulated chip's pins (`None` when they cannot be driven).
pub fn load_cell() -> Option<LoadCell> {
    Hx711::new(Delay(Chip), Dout(Chip), Sck(Chip)).ok()
}

/// The probe's load cell for `probe` (its chip follows the probe from now on).
fn attach_load_cell(probe: &SimProbe) {
    let chip = probe.load_cell();
    cortex_m::interrupt::free(|cs| *LOAD_CELL_CHIP.borrow(cs).borrow_mut() = chip);
}

/// The independent watchdog, emulated: the STM32's IWDG resets the core 500 ms after the last
/// feed; here a feed that comes later than that after the one before — or a starved watchdog
/// found by [`Watchdog::starved`] — logs the reset the STM32 would have taken and ends the run
/// with failure. Time is the instruction clock's (one instruction per virtual nanosecond):
/// the guard task's 100 ms feeds are monotonic (SysTick) milliseconds of the same virtual time.
pub struct Watchdog {
    /// [`stamp`] of the last feed (`None` before the first).
    last: Option<u32>,
}

/// The STM32's watchdog timeout in instructions of this machine's clock (500 ms).
const WATCHDOG_INSTRUCTIONS: u32 = 500_000_000;

impl crate::instrument::watchdog::Watchdog for Watchdog {
    /// Feed; fails the run if the last feed was more than the timeout ago.
    fn feed(&mut self) {
        self.check();
        self.last = Some(stamp());
    }

    /// Not fed this time (the guard found the measurement task's promise broken): fails the
    /// run once the timeout has passed since the last feed, as the IWDG would reset the core.
    fn starved(&mut self) {
        self.check();
    }
}

impl Watchdog {
    fn check(&self) {
        if let Some(t) = self.last {
            let since = elapsed(t);
            if since > WATCHDOG_INSTRUCTIONS {
                defmt::error!(
                    "watchdog reset instructions_since_feed={=u32} timeout={=u32}",
                    since,
                    WATCHDOG_INSTRUCTIONS
                );
                exit(false);
            }
        }
    }
}

/// The flash of the calibration store: 4 KiB of simulated NOR, erased at boot.
pub type StoreFlash = SimFlash<4096, 2048, 8>;
/// Offset of the store's first slot in [`StoreFlash`].
pub const STORE_BASE: u32 = 0;

/// The bring-up step the boot script's leading `sim boot-fault` line names (0: none). The
/// board's stand-in peripherals cannot fail to come up by themselves: this emulates a failed
/// step, so the QEMU tests see its refusals.
static BOOT_FAULT: core::sync::atomic::AtomicU8 = core::sync::atomic::AtomicU8::new(0);

/// The first bring-up step that failed (emulated: `sim boot-fault`), if any.
pub fn boot_error() -> Option<crate::boot::BootError> {
    let v = BOOT_FAULT.load(core::sync::atomic::Ordering::Relaxed);
    crate::boot::BootError::ALL
        .into_iter()
        .find(|e| *e as u8 == v)
}

/// End the emulation with success or failure (semihosting `SYS_EXIT`).
pub fn exit(success: bool) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Not reached under QEMU; without a debugger the core just sleeps.
    loop {
        cortex_m::asm::wfi();
    }
}
