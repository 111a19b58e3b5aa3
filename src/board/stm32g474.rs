//! The STM32G474RE board (NUCLEO-G474RE) on `embassy-stm32` 0.6: clocks, TIM6, DAC1, ADC1/ADC2
//! on DMA ring buffers, the bank-2 flash of the calibration store, LPUART1 and the independent
//! watchdog are embassy drivers, used from RTIC 2 tasks without an embassy executor. Raw
//! register code remains only where embassy 0.6 lacks the feature: twelve accesses, each
//! marked `RAW n/12` with the gap and the RM0440 section, listed in `docs/firmware.md`. The
//! HSE runs under the clock security system (CSSON with HSEON in one access); its NMI resets
//! the core into a boot on HSI16 through the PLL ([`BootError::HseFailure`]).
//!
//! # Bring-up ([`init`])
//!
//! The cycle counter first (it times the bounded waits); the IWDG, frozen under the debugger,
//! started before any of embassy's own waits (several have no bound: `docs/firmware.md`), with
//! the step in progress kept in RAM a reset does not clear ([`Step`]): a step that hangs ends in
//! a watchdog reset, and the next boot goes around it with a typed [`BootError`]
//! (`clock_hang`: HSI16 at 16 MHz, no stream; `converter_hang`: no stream; `flash_hang`: no
//! store) instead of hanging again. Then the 24 MHz HSE crystal (X3), started and probed here
//! with a bounded wait (embassy's `rcc::init` waits for HSERDY without a bound, so it is handed
//! the HSE only once it is known to run; otherwise the PLL runs from HSI16 and
//! [`clock_source`] says so); `embassy_stm32::init` (PWR and FLASH clocked and reset, range 1
//! boost, 4 wait states, PLL 170 MHz, ADC12 kernel clock = SYSCLK, DMA interrupt priority);
//! flash prefetch; the option bytes' bank mode (embassy's `Flash::new_blocking` panics on a
//! mismatch: checked first, [`BootError::FlashSingleBank`]); the converters; LPUART1 receive
//! on a DMA ring. A failed step records a [`BootError`] (the first is kept, [`boot_error`]) and
//! the board carries on degraded. Unverified on hardware.
//!
//! # Analog stream ([`Stream`])
//!
//! ```text
//! TIM6 update @ 10 kHz ──TRGO──┬─> DAC1 CH1 (PA4) ← DMA1 CH3 ← DAC_BUF [2 × 50] (circular)
//!                              ├─> ADC1 IN1 (PA0, sense current)  → DMA1 CH1 → ring [2 × 50]
//!                              └─> ADC2 IN2 (PA1, drive monitor)  → DMA1 CH2 → ring [2 × 50]
//! ```
//!
//! ADC1 and ADC2 convert on the same TIM6_TRGO rising edge, with the same kernel clock, sample
//! time and resolution, so the current and the drive monitor are sampled at the same instant
//! (before: one ADC's sequence, 1.4 µs apart). They run as two independent ADCs rather than in
//! the dual regular-simultaneous mode: embassy 0.6 writes ADC_CCR.DUAL after enabling ADC1,
//! where RM0440 allows the field to be written only with both ADCs disabled (docs/firmware.md).
//! The DMA1 CH1 half/full-transfer interrupt (ADC1's ring) is the RTIC `sample` task; it runs
//! embassy's DMA handler for that channel itself ([`Stream::capture`]).
//!
//! DMA transfer errors (TEIF on any of the four channels) are counted and cleared before
//! embassy's DMA handler runs (embassy 0.6 panics on TEIF); DAC DMA underruns (DMAUDR1; embassy
//! has no check) are read every batch. Either makes [`Stream::late`] true, is counted in
//! [`stream_faults`] and stops TIM6, so readings stall rather than run on without drive.
//!
//! Pins: PA0 sense current (TIA output), PA1 drive monitor, PA4 DAC out to the drive amplifier,
//! PA3 LPUART1 RX (AF12) from the ST-LINK virtual COM port, PB4 (Arduino D5) the load cell's
//! HX711 `DOUT` (input, pull-up), PB5 (D4) its `PD_SCK` (push-pull output).

use crate::engine::SampleEngine;
use crate::engine::BATCH;
use crate::hal::{AdcFrame, FrontEndScale};
use crate::units::{AdcCode, DacCode, Hz};
use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::dac::{DacChannel, Mode};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::interrupt::typelevel::{Binding, Handler};
use embassy_stm32::interrupt::Priority;
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{ADC1, ADC2, DMA1_CH1, TIM6};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{RoundTo, Timer};
use embassy_stm32::usart::{RingBufferedUartRx, UartRx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, interrupt, pac, peripherals, usart, Peri};
use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

// The image's defmt global logger (RTT) and panic handler: panic-probe logs the panic's
// message and location over defmt (feature `print-defmt`), then takes a HardFault (`udf`):
// probe-rs shows the backtrace and, without a debugger, the watchdog resets the core.
use defmt_rtt as _;
use panic_probe as _;

/// `defmt::panic!` and its kin have logged their message already: stop for good without a
/// second line, with panic-probe's permanent fault (`udf` with UsageFault disabled, so that it
/// escalates to HardFault).
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    panic_probe::hard_fault()
}

/// The device crate RTIC binds to (`device = embassy_stm32`, `peripherals = false`).
pub use embassy_stm32 as device;

/// Board name in the boot log line.
pub const NAME: &str = "stm32";
/// Core clock, Hz.
pub const SYSCLK_HZ: u32 = 170_000_000;
/// Sample rate of the DAC and ADC, Hz.
pub const SAMPLE_RATE_HZ: u32 = 10_000;

/// Converter scale of the probe's front end on this board: 12-bit DAC and ADC on a 3.3 V
/// reference, drive amplifier gain 5, transimpedance 300 kΩ, drive monitor divider 0.15 — the
/// same front end `hal_sim::FrontEnd::default()` simulates.
pub const SCALE: FrontEndScale = FrontEndScale {
    sample_rate: Hz(SAMPLE_RATE_HZ as f32),
    drive_volts_per_code: 5.0 * 3.3 / 4096.0,
    amps_per_code: 3.3 / 4096.0 / 300e3,
    monitor_volts_per_code: 3.3 / 4096.0 / 0.15,
};

/// The board's converter scale.
pub fn scale() -> FrontEndScale {
    SCALE
}

/// Start of the calibration store: the last two 2 KiB pages of bank 2 (0x0807_F000), outside
/// the linker's FLASH region (bank 1 in the root `memory.x`, which names the store's pages
/// `_pzt_store_start`/`_pzt_store_end`; `tests/memory_map.rs` checks they agree), so a firmware
/// update keeps it.
pub const STORE_BASE: u32 = 0x7_F000;
/// The store's flash.
pub type StoreFlash = InternalFlash;

/// Unit of [`elapsed`].
pub const ELAPSED_UNIT: &str = "cycles";

/// A reading of the cycle counter (DWT CYCCNT, enabled in [`init`]).
#[inline(always)]
pub fn stamp() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

/// Core cycles since `start` (a [`stamp`]).
#[inline(always)]
pub fn elapsed(start: u32) -> u32 {
    stamp().wrapping_sub(start)
}

// ---- boot errors, clock source, stream faults ---------------------------------------------

/// A bring-up step that failed (portable, so the session's handling of it is tested on the
/// host). The board carries on degraded; [`boot_error`] holds the first.
pub use crate::boot::BootError;

/// First boot error (0: none).
static BOOT_ERROR: AtomicU8 = AtomicU8::new(0);

fn record(e: BootError) {
    let _ = BOOT_ERROR.compare_exchange(0, e as u8, Ordering::Relaxed, Ordering::Relaxed);
}

/// The first bring-up step that failed, if any — complete once [`init`] and [`Stream::start`]
/// have run.
pub fn boot_error() -> Option<BootError> {
    let v = BOOT_ERROR.load(Ordering::Relaxed);
    BootError::ALL.into_iter().find(|e| *e as u8 == v)
}

// ---- the boot-step marker ----------------------------------------------------------------

/// A step whose waits are embassy's own and unbounded. The watchdog runs from the start of
/// [`init`]; the step in progress is kept in RAM that a reset does not clear, so the boot after
/// a watchdog reset ([`reset_cause`]) knows which step hung and goes around it with a typed
/// [`BootError`] instead of hanging again (no reset loop).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
enum Step {
    /// `embassy_stm32::init` (RCC, flash latency).
    Clock = 1,
    /// TIM6, DAC1 (with its calibration), ADC1 and ADC2.
    Converters = 2,
    /// A flash erase or program of the store.
    Flash = 3,
    /// Not a step: the clock security system saw the HSE fail while the image ran; its NMI
    /// (`NonMaskableInt`) wrote this and reset the core, and the boot after a software reset
    /// that finds it runs from HSI16 through the PLL ([`BootError::HseFailure`]).
    HseFailed = 4,
}

/// Tag of a valid marker (upper half-word); the second word is the first's complement, so the
/// random contents of SRAM at power-on are not taken for a step.
const STEP_MAGIC: u32 = 0x5EB0_0000;

/// The step in progress: not zeroed by the start-up code (`.uninit`), so it survives a reset
/// (not a power cycle).
#[link_section = ".uninit.pzt_boot_step"]
static mut STEP: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

fn set_step(step: Option<Step>) {
    let v = step.map_or(0, |s| STEP_MAGIC | s as u32);
    // SAFETY: two aligned words of our own static; volatile so the marker is in RAM before the
    // step's first wait.
    unsafe {
        let p = addr_of_mut!(STEP) as *mut u32;
        p.write_volatile(v);
        p.add(1).write_volatile(!v);
    }
}

/// What caused the last reset, as far as the boot-step marker cares.
#[derive(Clone, Copy)]
struct ResetCause {
    /// The independent watchdog (IWDGRSTF).
    watchdog: bool,
    /// A software reset (SFTRSTF): the clock security system's NMI resets this way.
    software: bool,
}

/// What caused the last reset; the reset flags are cleared, so the next boot reads its own
/// cause (they are sticky until RMVF).
///
/// Gap: embassy-stm32 0.6 has no reset-cause API. RAW 12/12: RCC_CSR read-modify-write,
/// IWDGRSTF and SFTRSTF read and RMVF set in one access (RM0440 7.4.28 RCC_CSR, numbered by
/// the register order: see docs/firmware.md).
fn reset_cause() -> ResetCause {
    pac::RCC.csr().modify(|w| {
        let cause = ResetCause {
            watchdog: w.iwdgrstf(),
            software: w.sftrstf(),
        };
        w.set_rmvf(true);
        cause
    })
}

/// The clock security system's NMI (RM0440 7.2, RCC clocks: "Clock security system (CSS)"): the HSE failed
/// while it clocked the PLL; the hardware has switched SYSCLK to HSI16 (16 MHz, PLL off), under
/// TIM6, LPUART1 and the monotonic set up for 170 MHz. Rather than run on mis-timed, the core
/// is reset; the boot after it finds the marker and runs from HSI16 through the PLL at 170 MHz
/// with [`BootError::HseFailure`] (no reset loop: that boot does not start the HSE again).
/// The reset also clears the CSS flag (CSSF), which would otherwise re-enter this handler for
/// ever (RCC_CICR.CSSC is not written: no raw access spent on it).
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    set_step(Some(Step::HseFailed));
    cortex_m::peripheral::SCB::sys_reset()
}

/// The step the run before this boot was in when the watchdog reset it.
fn interrupted_step() -> Option<Step> {
    // SAFETY: two aligned words of our own static; after a power-on they hold whatever SRAM
    // came up with, which the complement check and the tag reject (read as plain words).
    let (a, b) = unsafe {
        let p = addr_of!(STEP) as *const u32;
        (p.read_volatile(), p.add(1).read_volatile())
    };
    if a != !b || a & 0xFFFF_0000 != STEP_MAGIC {
        return None;
    }
    [Step::Clock, Step::Converters, Step::Flash, Step::HseFailed]
        .into_iter()
        .find(|s| *s as u32 == a & 0xFFFF)
}

/// The oscillator the core clock comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// The NUCLEO-G474RE's 24 MHz crystal (X3) through the PLL: 170 MHz.
    Hse24,
    /// HSI16 through the PLL (the HSE did not start, or failed on the run before:
    /// [`BootError::HseFailure`]): 170 MHz, RC accuracy.
    Hsi16Pll,
    /// HSI16 directly, 16 MHz, no PLL: the boot before hung in the clock setup
    /// ([`BootError::ClockHang`]); the sample stream is not started.
    Hsi16,
}

impl ClockSource {
    /// Short name for the log.
    pub fn name(self) -> &'static str {
        match self {
            ClockSource::Hse24 => "hse24",
            ClockSource::Hsi16Pll => "hsi16-pll",
            ClockSource::Hsi16 => "hsi16",
        }
    }
}

/// 1: HSE through the PLL, 2: HSI16 through the PLL, otherwise HSI16 directly.
static CLOCK: AtomicU8 = AtomicU8::new(0);

/// The clock in the boot fault line: [`clock_source`]'s name.
pub fn clock_name() -> &'static str {
    clock_source().name()
}

/// The oscillator the core runs from (set by [`init`]).
pub fn clock_source() -> ClockSource {
    match CLOCK.load(Ordering::Relaxed) {
        1 => ClockSource::Hse24,
        2 => ClockSource::Hsi16Pll,
        _ => ClockSource::Hsi16,
    }
}

static DMA_TRANSFER_ERRORS: AtomicU32 = AtomicU32::new(0);
static DAC_UNDERRUNS: AtomicU32 = AtomicU32::new(0);

/// Hardware faults of the sample stream since boot. Either ends the stream (the DMA disables
/// the channel, the DAC stops its requests), and the driver then stops TIM6: after a non-zero
/// count the readings stall until reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamFaults {
    /// DMA1 transfer errors (TEIF) on channels 1–4 (ADC1, ADC2, DAC1, LPUART1 RX).
    pub dma_transfer_errors: u32,
    /// DAC1 channel 1 DMA underruns (DMAUDR1).
    pub dac_underruns: u32,
}

/// The stream's hardware fault counts (readable from any task).
pub fn stream_faults() -> StreamFaults {
    StreamFaults {
        dma_transfer_errors: DMA_TRANSFER_ERRORS.load(Ordering::Relaxed),
        dac_underruns: DAC_UNDERRUNS.load(Ordering::Relaxed),
    }
}

/// Poll `done` until it holds or `cycles` core cycles have passed (DWT cycle counter, enabled
/// first thing in [`init`]); true if it holds. Should the cycle counter be stopped (a debugger
/// can clear DEMCR.TRCENA), the poll count ends the wait: every poll takes at least one cycle.
fn spin_until(cycles: u32, mut done: impl FnMut() -> bool) -> bool {
    let t0 = stamp();
    let mut polls = cycles;
    while polls > 0 && elapsed(t0) < cycles {
        if done() {
            return true;
        }
        polls -= 1;
    }
    done()
}

/// HSE crystal start-up, at HSI16: 100 ms (ST's HSE_STARTUP_TIMEOUT; typical start-up 2 ms).
const HSE_TIMEOUT: u32 = 16_000_000 / 10;
/// The second ADC's last sample of a batch, after the first ADC's DMA interrupt: both convert
/// on the same trigger, so it is there within a few bus cycles; 2 000 cycles (12 µs) of margin.
const ADC_PAIR_TIMEOUT: u32 = 2_000;
/// One batch period in core cycles (2.5 ms).
const BATCH_CYCLES: u32 = SYSCLK_HZ / SAMPLE_RATE_HZ * BATCH as u32;
/// HSE frequency of the NUCLEO-G474RE's crystal X3.
const HSE_HZ: u32 = 24_000_000;
/// LPUART1 baud rate (ST-LINK virtual COM port).
const LPUART_BAUD: u32 = 115_200;
/// Received bytes buffered by LPUART1's DMA ring.
const UART_RING: usize = 64;
/// Watchdog timeout, µs.
const WATCHDOG_US: u32 = 500_000;

// ---- interrupts ------------------------------------------------------------------------

bind_interrupts!(struct Irqs {
    DMA1_CHANNEL2 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH2>;
    DMA1_CHANNEL3 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH3>;
    DMA1_CHANNEL4 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH4>;
    DMA1_CHANNEL5 => DmaFaults, dma::InterruptHandler<peripherals::DMA1_CH5>;
});

// DMA1 CH1's vector (`DMA1_CHANNEL1`) is the RTIC task `sample` (src/bin/probe.rs), which calls
// embassy's handler for the channel itself (after [`DmaFaults`]) in [`Stream::capture`];
// `bind_interrupts!` would define the same vector symbol a second time.
// SAFETY: the handler runs on every DMA1_CH1 interrupt, from `Stream::capture`.
unsafe impl Binding<interrupt::typelevel::DMA1_CHANNEL1, dma::InterruptHandler<DMA1_CH1>> for Irqs {}
// The LPUART1 vector is the RTIC task `uart_rx`, which reads the ring through embassy's
// non-blocking read ([`Uart::read_byte`]); that read clears the idle and error flags the
// interrupt is enabled for, and embassy's handler (which only masks them and wakes an async
// reader) is not needed.
// SAFETY: every `uart_rx` run reads until the ring is empty, clearing the flags.
unsafe impl Binding<interrupt::typelevel::LPUART1, usart::InterruptHandler<peripherals::LPUART1>>
    for Irqs
{
}

/// Counts and clears DMA1 transfer errors before embassy's DMA handler sees them.
///
/// Gap: embassy-stm32 0.6's DMA interrupt handler (`dma_bdma.rs`, `on_irq`) panics on TEIF; the
/// stream must count a transfer error and stop instead (the hardware has already disabled the
/// channel: RM0440 12, DMA: "DMA error management").
struct DmaFaults;

impl<I: interrupt::typelevel::Interrupt> Handler<I> for DmaFaults {
    unsafe fn on_interrupt() {
        // RAW 1/12: DMA1_ISR TEIF1..4 (RM0440 12, DMA: DMA_ISR).
        let isr = pac::DMA1.isr().read();
        // RAW 2/12: DMA1_IFCR CTEIF1..4, write-one-to-clear (RM0440 12, DMA: DMA_IFCR).
        let n = pac::DMA1.ifcr().write(|w| {
            let mut n = 0;
            for ch in 0..4 {
                if isr.teif(ch) {
                    w.set_teif(ch, true);
                    n += 1;
                }
            }
            n
        });
        if n != 0 {
            DMA_TRANSFER_ERRORS.fetch_add(n, Ordering::Relaxed);
        }
    }
}

// ---- clocks ----------------------------------------------------------------------------

/// Start the HSE crystal with its clock security system and wait for it, bounded. embassy's
/// `rcc::init` (g4.rs) sets HSEON and then spins on HSERDY without a bound: it is given the HSE
/// only once it runs. embassy 0.6 has no CSS for the G4.
fn hse_starts() -> bool {
    // RAW 3/12: RCC_CR.HSEON and CSSON in one read-modify-write (RM0440 7.4.1 RCC_CR; 7.2
    // "HSE clock", "Clock security system (CSS)"). HSEBYP stays 0 (crystal). The clock detector
    // turns itself on once the HSE is ready and off when it is stopped: if the crystal does not
    // start, embassy's init (`hse: None`) clears HSEON again and the CSS never arms. A failure
    // later is the NMI (`NonMaskableInt`). embassy's own RCC_CR writes are read-modify-writes
    // of other fields: CSSON stays set.
    pac::RCC.cr().modify(|w| {
        w.set_hseon(true);
        w.set_csson(true);
    });
    // RAW 4/12: RCC_CR.HSERDY, polled with a bound (RM0440 7.4.1 RCC_CR).
    spin_until(HSE_TIMEOUT, || pac::RCC.cr().read().hserdy())
}

/// embassy's clock configuration: 170 MHz from the PLL (24 MHz / 6 or 16 MHz / 4 = 4 MHz × 85
/// / 2), range 1 boost — or HSI16 at 16 MHz without the PLL ([`ClockSource::Hsi16`], after a
/// boot that hung in the clock setup) —, the ADC12 kernel clock from SYSCLK (embassy's default
/// is none).
fn embassy_config(clock: ClockSource) -> embassy_stm32::Config {
    use embassy_stm32::rcc::{
        mux, Hse, HseMode, LsConfig, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk,
    };
    let mut config = embassy_stm32::Config::default();
    let rcc = &mut config.rcc;
    let hse = clock == ClockSource::Hse24;
    rcc.hse = hse.then_some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    if clock != ClockSource::Hsi16 {
        rcc.pll = Some(Pll {
            source: if hse { PllSource::HSE } else { PllSource::HSI },
            prediv: if hse {
                PllPreDiv::DIV6
            } else {
                PllPreDiv::DIV4
            },
            mul: PllMul::MUL85,
            divp: None,
            divq: None,
            divr: Some(PllRDiv::DIV2),
        });
        rcc.sys = Sysclk::PLL1_R;
        rcc.boost = true;
    }
    // Nothing uses HSI48 (USB, RNG) or the RTC: no HSI48RDY or LSIRDY waits, no backup domain.
    rcc.hsi48 = None;
    rcc.ls = LsConfig::off();
    rcc.mux.adc12sel = mux::Adcsel::SYS;
    // embassy enables every DMA channel interrupt at this priority: the sample task's (RTIC
    // logical 3), so none preempts the sample interrupt.
    config.bdma_interrupt_priority = prio(3);
    config
}

/// The NVIC priority of RTIC logical priority `logical`.
fn prio(logical: u8) -> Priority {
    Priority::from(super::nvic_priority(logical, device::NVIC_PRIO_BITS))
}

// ---- the sample stream -----------------------------------------------------------------

// Two DMA half-buffers: the pipeline of `reading::PIPELINE_BATCHES` that the host's simulated
// board models too.
const _: () = assert!(crate::engine::PIPELINE_BATCHES == 2);

/// DMA buffers: the DMA owns them once started; the interrupt touches only the DAC half the DMA
/// has just left, and reads the ADC rings through embassy.
static mut DAC_BUF: [DacCode; 2 * BATCH] = [DacCode::MID; 2 * BATCH];
static mut ADC1_RING: [u16; 2 * BATCH] = [0; 2 * BATCH];
static mut ADC2_RING: [u16; 2 * BATCH] = [0; 2 * BATCH];

/// DMA1 CH3, the DAC's channel, borrowed by its circular transfer for the life of the image.
static mut DAC_DMA: Option<dma::Channel<'static>> = None;

/// The converters of the stream (absent when a boot error kept them from being set up).
struct Converters {
    adc1: RingBufferedAdc<'static, ADC1>,
    adc2: RingBufferedAdc<'static, ADC2>,
    tim: Timer<'static, TIM6>,
    /// Kept for its `Drop` (which would disable the channel); its DMA is [`DAC_DMA`].
    _dac: DacChannel<'static, Async>,
    /// DMAMUX request of DAC1 channel 1.
    dac_request: dma::Request,
    /// The DAC's circular transfer, once started.
    dac_transfer: Option<dma::Transfer<'static>>,
}

/// The DAC/ADC sample stream over TIM6, DAC1, ADC1, ADC2 and three DMA1 channels.
pub struct Stream {
    hw: Option<Converters>,
    frames: [AdcFrame; BATCH],
    current: [u16; BATCH],
    monitor: [u16; BATCH],
    /// [`stamp`] of the last batch (`None` before the first).
    last: Option<u32>,
    started: u32,
    late_seen: bool,
    fault_seen: bool,
    faults: StreamFaults,
    dac_underrun: bool,
}

impl Stream {
    /// Converter scale of this board.
    pub fn scale(&self) -> FrontEndScale {
        SCALE
    }

    /// Prefill both DAC halves from `engine`, start the DAC's circular DMA and the ADC rings,
    /// then the trigger timer. Called once from `init` with interrupts disabled. If the DAC's
    /// transfer does not start, records [`BootError::DacStart`] and leaves the timer stopped
    /// (no batches, readings stall).
    pub fn start(&mut self, engine: &mut SampleEngine) {
        // SAFETY: init context, no DMA runs yet; the buffer is reached only through this
        // pointer now and, once the DMA runs, only the half it has left (`capture`).
        let dac_buf = unsafe { &mut *addr_of_mut!(DAC_BUF) };
        for half in dac_buf.chunks_exact_mut(BATCH) {
            engine.generate(half);
        }
        let Some(hw) = self.hw.as_mut() else {
            return;
        };
        // The DAC's circular DMA, DAC_BUF → DHR12R1, half-words read and written as words
        // (zero-extended by the DMA): embassy's `DacChannel::write` programs 16-bit peripheral
        // writes, which the G4's DAC answers with a bus error (RM0440 22, DAC: its registers take word
        // accesses only; embassy issue #2783, fixed after 0.6).
        // SAFETY: `DAC_DMA` was filled by `converters` and is used only here; the buffer is
        // static; the DMA reads it for ever while `capture` writes the half the DMA has left.
        let mut options = dma::TransferOptions::default();
        options.circular = true;
        options.half_transfer_ir = false;
        options.complete_transfer_ir = false;
        let transfer = unsafe {
            (*addr_of_mut!(DAC_DMA)).as_mut().map(|ch| {
                ch.write_raw::<u16, u32>(
                    hw.dac_request,
                    core::ptr::slice_from_raw_parts(addr_of!(DAC_BUF) as *const u16, 2 * BATCH),
                    pac::DAC1.dhr12r(0).as_ptr() as *mut u32,
                    options,
                )
            })
        };
        let Some(transfer) = transfer else {
            record(BootError::DacStart);
            return;
        };
        hw.dac_transfer = Some(transfer);
        // The rings (DMA and ADSTART) before the trigger: every TIM6 update from the first on
        // plays one DAC code and converts one sample on each ADC.
        hw.adc1.start();
        hw.adc2.start();
        hw.tim.start();
    }

    /// Acknowledge the DMA half/full-transfer interrupt of ADC1's ring; returns the ADC frames
    /// of the batch just captured and the DAC half just played (to refill). Counts DMA
    /// transfer errors and DAC underruns ([`stream_faults`]); a batch that saw one is late.
    pub fn capture(&mut self) -> (&[AdcFrame], &mut [DacCode]) {
        let now = stamp();
        // SAFETY: the DMA1_CH1 vector is this task's; embassy's handler for the channel (half
        // and full transfer of ADC1's ring, waker) runs here, after the transfer-error check.
        unsafe {
            <DmaFaults as Handler<interrupt::typelevel::DMA1_CHANNEL1>>::on_interrupt();
            <dma::InterruptHandler<DMA1_CH1> as Handler<interrupt::typelevel::DMA1_CHANNEL1>>::on_interrupt();
        }
        // A half that went by unserviced shows in the time since the last batch.
        self.late_seen = self
            .last
            .is_some_and(|t| now.wrapping_sub(t) > BATCH_CYCLES + BATCH_CYCLES / 2);
        self.last = Some(now);
        self.started = now;
        // The DAC half just played is the one its DMA is not in (from the channel's remaining
        // count: 2 × BATCH .. BATCH + 1 in half 0, BATCH .. 1 in half 1). Both DMA streams run
        // off the same trigger, so it is the half of the ADC batch just captured; the DAC's
        // output register holds the last sample of that half already (it is fetched one trigger
        // ahead), so the whole half can be refilled.
        let h = match self.hw.as_ref().and_then(|hw| hw.dac_transfer.as_ref()) {
            Some(t) if t.get_remaining_transfers() as usize > BATCH => 1,
            _ => 0,
        };

        // Gap: embassy 0.6's DAC driver has no underrun check: DAC_SR.DMAUDR1 (RM0440 22, DAC:
        // "DMA underrun"), read through [`dac_sr`]. Not cleared: the stream stops on
        // the first underrun, which is counted once.
        if !self.dac_underrun && self.hw.is_some() && dac_sr().dmaudr(0) {
            self.dac_underrun = true;
            DAC_UNDERRUNS.fetch_add(1, Ordering::Relaxed);
        }
        let faults = stream_faults();
        self.fault_seen = faults != self.faults;
        self.faults = faults;
        match self.hw.as_mut() {
            // Either fault ends the stream as a whole (a disabled DMA channel, a DAC that no
            // longer requests data): stop the trigger, so the measurement task's readings end
            // as `stalled` rather than run on with a dead drive or stale samples.
            Some(hw) if self.fault_seen => hw.tim.stop(),
            Some(hw) => {
                if !(fill(&mut hw.adc1, &mut self.current) && fill(&mut hw.adc2, &mut self.monitor))
                {
                    self.late_seen = true;
                }
            }
            None => self.late_seen = true,
        }
        for ((f, &i), &v) in self.frames.iter_mut().zip(&self.current).zip(&self.monitor) {
            *f = AdcFrame {
                current: AdcCode(i),
                monitor: AdcCode(v),
            };
        }
        // SAFETY: the DAC's DMA has left half `h` (it is in the other half) and comes back to it
        // only after the other half completes.
        let dac = unsafe {
            core::slice::from_raw_parts_mut(
                (addr_of_mut!(DAC_BUF) as *mut DacCode).add(h * BATCH),
                BATCH,
            )
        };
        (&self.frames, dac)
    }

    /// True when the handler was late: a half went by unserviced, or the handler ran longer
    /// than a batch (the next half completed before it finished) — or the batch saw a DMA
    /// transfer error or DAC underrun (its data are stale; [`stream_faults`] tells them apart).
    pub fn late(&self) -> bool {
        self.late_seen || self.fault_seen || elapsed(self.started) >= BATCH_CYCLES
    }
}

/// Read the newest [`BATCH`] samples of `adc`'s ring into `out`, waiting a bounded time for the
/// last ones (the second ADC's DMA may trail the first's interrupt by a few bus cycles).
fn fill<T: embassy_stm32::adc::Instance>(
    adc: &mut RingBufferedAdc<'static, T>,
    out: &mut [u16; BATCH],
) -> bool {
    let mut got = 0;
    spin_until(ADC_PAIR_TIMEOUT, || {
        got += adc.read_latest(&mut out[got..]);
        got == BATCH
    })
}

// ---- host link, watchdog ---------------------------------------------------------------

/// LPUART1 receiver (115 200 Bd, 8N1) on the ST-LINK virtual COM port: embassy's DMA ring
/// (DMA1 CH4, [`UART_RING`] bytes), drained by the RTIC task `uart_rx` on the LPUART1 vector.
///
/// embassy enables LPUART1's idle-line and error interrupts for its ring; the vector is RTIC's,
/// and [`Uart::read_byte`] reads through embassy's non-blocking `embedded_hal_nb` read, which
/// clears those flags (`check_idle_and_errors`) and restarts the ring after an error. Bytes that
/// arrive without a pause wait in the ring until the idle line.
pub struct Uart(Option<RingBufferedUartRx<'static>>);

impl Uart {
    /// The next received byte, if any (reading clears the receive interrupt). A receive error
    /// (overrun, noise, framing) is dropped and the read retried once: the lost byte shows up
    /// as a malformed line, which the parser reports.
    pub fn read_byte(&mut self) -> Option<u8> {
        let rx = self.0.as_mut()?;
        for _ in 0..2 {
            match embedded_hal_nb::serial::Read::read(rx) {
                Ok(b) => return Some(b),
                Err(nb::Error::WouldBlock) => return None,
                Err(nb::Error::Other(_)) => {}
            }
        }
        None
    }
}

/// The independent watchdog (LSI): 500 ms timeout, fed by the measurement task while alive;
/// frozen while a debugger halts the core.
pub struct Watchdog(IndependentWatchdog<'static, peripherals::IWDG>);

impl crate::instrument::watchdog::Watchdog for Watchdog {
    /// Feed the watchdog.
    fn feed(&mut self) {
        self.0.pet();
    }

    /// Not fed this time: nothing to do, the IWDG resets the core by itself once its timeout
    /// has passed since the last feed (the QEMU board's stand-in checks the same here).
    fn starved(&mut self) {}
}

// ---- flash -----------------------------------------------------------------------------

/// Errors of the internal flash driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Bad alignment or range.
    Args(NorFlashErrorKind),
    /// The controller reported an error (embassy's reading of FLASH_SR).
    Controller(embassy_stm32::flash::Error),
    /// The flash is in single-bank mode (FLASH_OPTR.DBANK = 0): every access refused.
    SingleBank,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Args(k) => *k,
            FlashError::Controller(_) | FlashError::SingleBank => NorFlashErrorKind::Other,
        }
    }
}

impl From<NorFlashErrorKind> for FlashError {
    fn from(k: NorFlashErrorKind) -> Self {
        FlashError::Args(k)
    }
}

const FLASH_SIZE: usize = 512 * 1024;
const FLASH_PAGE: usize = 2048;

/// The internal flash as a NOR flash: embassy's blocking driver on the whole flash (dual-bank
/// mode, 2 KiB pages, 8-byte double words); offsets count from 0x0800_0000. The store lives in
/// bank 2 while the code runs from bank 1 (read-while-write).
///
/// embassy's `Flash<Blocking>` methods (`blocking_erase`, `blocking_write`) run without a
/// critical section — unlike its region drivers' blocking methods, which keep interrupts off
/// for the whole ~20 ms page erase and would overrun the sample stream — so the sample
/// interrupt keeps running while the measurement task erases or programs. embassy clears stale
/// FLASH_SR flags before each operation and, on the G4, turns the data cache off around it and
/// resets it (DCRST) before turning it back on (`flash/g.rs`).
pub struct InternalFlash(Option<Flash<'static, Blocking>>);

impl InternalFlash {
    fn flash(&mut self) -> Result<&mut Flash<'static, Blocking>, FlashError> {
        self.0.as_mut().ok_or(FlashError::SingleBank)
    }
}

impl ErrorType for InternalFlash {
    type Error = FlashError;
}

impl ReadNorFlash for InternalFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_read(self, offset, bytes.len())?;
        self.flash()?
            .blocking_read(offset, bytes)
            .map_err(FlashError::Controller)
    }

    fn capacity(&self) -> usize {
        FLASH_SIZE
    }
}

impl NorFlash for InternalFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = FLASH_PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_erase(self, from, to)?;
        let flash = self.flash()?;
        set_step(Some(Step::Flash));
        let r = flash
            .blocking_erase(from, to)
            .map_err(FlashError::Controller);
        set_step(None);
        r
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_write(self, offset, bytes.len())?;
        let flash = self.flash()?;
        set_step(Some(Step::Flash));
        let r = flash
            .blocking_write(offset, bytes)
            .map_err(FlashError::Controller);
        set_step(None);
        r
    }
}

/// tTRIM, the settling time of one calibration step, taken as 50 µs (the datasheet's figure
/// is to be checked), at 170 MHz.
const DAC_TRIM_CYCLES: u32 = SYSCLK_HZ / 20_000;

/// DAC_SR (RM0440 22, DAC: DAC_SR): CAL_FLAG1 for the calibration, DMAUDR1 for the
/// stream. Gap: embassy-stm32 0.6's DAC driver reads neither.
fn dac_sr() -> pac::dac::regs::Sr {
    // RAW 9/12: DAC_SR read.
    pac::DAC1.sr().read()
}

/// DAC_CR (RM0440 22, DAC: DAC_CR): CEN1 (calibration mode) and DMAEN1. Gap: embassy-stm32
/// 0.6 sets DMAEN1 only inside `DacChannel::write`, whose 16-bit DMA the G4's DAC refuses, and
/// has no calibration.
fn dac_cr(f: impl FnOnce(&mut pac::dac::regs::Cr)) {
    // RAW 10/12: DAC_CR modify.
    pac::DAC1.cr().modify(f);
}

/// Calibrate DAC1 channel 1's output buffer offset (RM0440 22, DAC: "DAC channel output
/// buffer calibration"): with the channel off and in normal buffered mode, CEN1 set, OTRIM1
/// stepped up from 0, tTRIM after each step, until CAL_FLAG1 reads 1 — the first trim at or
/// above the offset. 32 steps at most (1.6 ms); false if the flag never rose.
///
/// Gap: embassy-stm32 0.6's DAC driver has no calibration.
fn calibrate_dac() -> bool {
    dac_cr(|w| w.set_cen(0, true));
    let mut found = false;
    for trim in 0..32 {
        // RAW 11/12: DAC_CCR.OTRIM1 (RM0440 22, DAC: DAC_CCR); OTRIM2 (channel 2, unused)
        // written 0.
        pac::DAC1.ccr().write(|w| w.set_otrim(0, trim));
        cortex_m::asm::delay(DAC_TRIM_CYCLES);
        if dac_sr().cal_flag(0) {
            found = true;
            break;
        }
    }
    dac_cr(|w| w.set_cen(0, false));
    found
}

/// The peripherals of the sample stream.
struct ConverterPins {
    tim6: Peri<'static, TIM6>,
    dac1: Peri<'static, peripherals::DAC1>,
    dac_dma: Peri<'static, peripherals::DMA1_CH3>,
    /// Handed to `DacChannel::new_triggered`, which wants a DMA channel; never started.
    dac_dma_unused: Peri<'static, peripherals::DMA1_CH5>,
    pa4: Peri<'static, peripherals::PA4>,
    adc1: Peri<'static, ADC1>,
    adc1_dma: Peri<'static, DMA1_CH1>,
    pa0: Peri<'static, peripherals::PA0>,
    adc2: Peri<'static, ADC2>,
    adc2_dma: Peri<'static, peripherals::DMA1_CH2>,
    pa1: Peri<'static, peripherals::PA1>,
}

/// Set up TIM6 (10 kHz TRGO, stopped), DAC1 CH1 (triggered, calibrated, into [`DAC`]) and the
/// two ADC rings; [`Stream::start`] starts them.
fn converters(p: ConverterPins) -> Converters {
    // TIM6: 10 kHz update, its update event as TRGO, not yet running.
    let tim = Timer::new(p.tim6);
    tim.set_frequency(Hertz(SAMPLE_RATE_HZ), RoundTo::Faster);
    // Gap: embassy 0.6's low-level timer has no master-mode setter. RAW 7/12: TIM6_CR2.MMS =
    // update → TRGO (RM0440 "Basic timers (TIM6/TIM7)" chapter, TIMx_CR2;
    // its number unverified: docs/firmware.md).
    tim.regs_basic()
        .cr2()
        .modify(|w| w.set_mms(pac::timer::vals::Mms::UPDATE));
    tim.generate_update_event();

    // DAC1 CH1 on PA4, normal mode with the output buffer, triggered by TIM6_TRGO, fed by DMA1
    // CH3 (our own transfer, started in `Stream::start`: embassy's `DacChannel::write` programs
    // 16-bit peripheral writes, which the G4's DAC refuses).
    let dac_request =
        embassy_stm32::dac::Dma::<peripherals::DAC1, embassy_stm32::dac::Ch1>::request(&*p.dac_dma);
    let mut dac = DacChannel::new_triggered(
        p.dac1,
        p.dac_dma_unused,
        embassy_stm32::triggers::TIM6_TRGO,
        Irqs,
        p.pa4,
    );
    // embassy's `new_triggered` selects the trigger (TSEL1) and enables the channel but never
    // sets TEN1, without which the DAC neither waits for TIM6 nor requests DMA (RM0440 22, DAC:
    // "DAC trigger selection", "DMA requests"): `set_mode` turns EN1 off (TEN1 and the
    // calibration want the channel off), TEN1 is set, the buffer calibrated, EN1 and DMAEN1
    // set. No trigger comes before TIM6 starts, so no DMA request before the transfer runs.
    dac.set_mode(Mode::NormalExternalBuffered);
    dac.set_triggering(true);
    // A DAC whose calibration never settles is not trusted with the drive: the stream is not
    // started (readings end as `stalled`).
    let calibrated = calibrate_dac();
    if calibrated {
        dac.enable();
        dac_cr(|w| w.set_dmaen(0, true));
        // SAFETY: init context; `Stream::start` is the only other user of `DAC_DMA`.
        unsafe { *addr_of_mut!(DAC_DMA) = Some(dma::Channel::new(p.dac_dma, Irqs)) };
    } else {
        record(BootError::DacCalibration);
    }

    // ADC1 (current, PA0 = IN1) and ADC2 (monitor, PA1 = IN2): calibrated (single-ended and
    // differential), 20 µs before ADEN, by `Adc::new`; kernel clock SYSCLK / 4 = 42.5 MHz.
    let adc1 = Adc::new(p.adc1, AdcConfig::default());
    let adc2 = Adc::new(p.adc2, AdcConfig::default());
    // SAFETY: init context, before any DMA runs; the rings are handed to embassy for good.
    let (ring1, ring2) = unsafe { (&mut *addr_of_mut!(ADC1_RING), &mut *addr_of_mut!(ADC2_RING)) };
    let adc1 = adc1.into_ring_buffered(
        p.adc1_dma,
        ring1,
        Irqs,
        [(p.pa0.degrade_adc(), SampleTime::CYCLES47_5)].into_iter(),
        embassy_stm32::triggers::TIM6_TRGO,
        Exten::RISING_EDGE,
    );
    let adc2 = adc2.into_ring_buffered(
        p.adc2_dma,
        ring2,
        Irqs,
        [(p.pa1.degrade_adc(), SampleTime::CYCLES47_5)].into_iter(),
        embassy_stm32::triggers::TIM6_TRGO,
        Exten::RISING_EDGE,
    );
    Converters {
        adc1,
        adc2,
        tim,
        _dac: dac,
        dac_request,
        dac_transfer: None,
    }
}

// ---- bring-up --------------------------------------------------------------------------

/// The board's parts, as the application takes them over.
pub struct Parts {
    /// The sample stream (not yet started).
    pub stream: Stream,
    /// The independent watchdog, running.
    pub watchdog: Watchdog,
    /// The store's flash.
    pub flash: StoreFlash,
    /// Host link.
    pub uart: Uart,
    /// The load cell.
    pub load_cell: Option<LoadCell>,
}

/// Microsecond delays by counting core cycles (`cortex_m::asm::delay`, at least the time asked
/// for): the HX711's clock pulses. embassy's `Delay` needs its time driver, which this RTIC
/// image does not run, and cortex-m's takes SysTick, which the monotonic owns.
pub struct CycleDelay;

impl embedded_hal::delay::DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (ns as u64 * SYSCLK_HZ as u64).div_ceil(1_000_000_000);
        cortex_m::asm::delay(cycles.min(u32::MAX as u64) as u32);
    }
}

/// The load cell: the firmware's HX711 driver on PB4 (`DOUT`) and PB5 (`PD_SCK`), embassy's
/// GPIO drivers through embedded-hal 1.0.
pub type LoadCell = crate::loadcell::Hx711<
    CycleDelay,
    embassy_stm32::gpio::Input<'static>,
    embassy_stm32::gpio::Output<'static>,
>;

/// Set the board up: cycle counter; 170 MHz from the 24 MHz HSE crystal through the PLL
/// (HSI16 if the crystal does not start), range 1 boost; the converters; UART; watchdog
/// (frozen under the debugger). Call once, from `init`. See [`boot_error`] and
/// [`clock_source`] for what happened.
pub fn init(core: &mut cortex_m::Peripherals) -> Parts {
    // The cycle counter first: it times the bounded waits.
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();
    // A step is taken for hung only after a watchdog reset (a reset button pressed during a
    // step is not a hang); the HSE's failure only after the software reset of the CSS's NMI.
    let cause = reset_cause();
    let marker = interrupted_step();
    let interrupted = marker.filter(|s| cause.watchdog && *s != Step::HseFailed);
    let hse_failed = cause.software && marker == Some(Step::HseFailed);
    let safe_clock = interrupted == Some(Step::Clock);

    // The watchdog before any wait of embassy's: a step that hangs ends in a reset, and the
    // next boot goes around it (`interrupted_step`). Frozen while a debugger halts the core.
    // Gap: embassy 0.6 has no DBGMCU API. RAW 8/12: DBGMCU_APB1FZR1.DBG_IWDG_STOP (RM0440
    // "Debug support (DBG)" chapter, DBGMCU_APB1FZR1; its number unverified: docs/firmware.md), before the IWDG starts.
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
    // On HSI16 without the PLL the monotonic (started for 170 MHz) runs 10.6 times slow, and
    // the measurement task's 100 ms feeds come every 1.06 s: the timeout grows with it.
    let timeout = if safe_clock {
        WATCHDOG_US * 11
    } else {
        WATCHDOG_US
    };
    // SAFETY: the IWDG is taken before `embassy_stm32::init` hands out the peripherals; its
    // singleton from there is dropped unused, so this is its only driver.
    let mut wdg = IndependentWatchdog::new(unsafe { peripherals::IWDG::steal() }, timeout);
    wdg.unleash();

    let clock = if safe_clock {
        record(BootError::ClockHang);
        ClockSource::Hsi16
    } else if hse_failed {
        record(BootError::HseFailure);
        ClockSource::Hsi16Pll
    } else if hse_starts() {
        ClockSource::Hse24
    } else {
        ClockSource::Hsi16Pll
    };
    CLOCK.store(
        match clock {
            ClockSource::Hse24 => 1,
            ClockSource::Hsi16Pll => 2,
            ClockSource::Hsi16 => 0,
        },
        Ordering::Relaxed,
    );
    set_step(Some(Step::Clock));
    let p = embassy_stm32::init(embassy_config(clock));
    set_step(None);

    // Gap: embassy 0.6 never sets FLASH_ACR.PRFTEN. RAW 5/12: prefetch on (RM0440 3.3.4
    // ART accelerator / prefetch; FLASH_ACR), after embassy set the wait states.
    pac::FLASH.acr().modify(|w| w.set_prften(true));

    // Gap: embassy's `Flash::new_blocking` panics when FLASH_OPTR.DBANK does not match its
    // `dual-bank` feature (flash/g.rs `check_bank_setup`). RAW 6/12: DBANK read first
    // (RM0440 3.3.1 "Flash memory organization"; FLASH_OPTR), a typed boot error instead.
    let flash = if interrupted == Some(Step::Flash) {
        record(BootError::FlashHang);
        None
    } else if pac::FLASH.optr().read().dbank() {
        Some(Flash::new_blocking(p.FLASH))
    } else {
        record(BootError::FlashSingleBank);
        None
    };

    // The converters: not on HSI16 alone (readings are refused after a clock hang), not after
    // a boot that hung setting them up.
    let hw = if safe_clock {
        None
    } else if interrupted == Some(Step::Converters) {
        record(BootError::ConverterHang);
        None
    } else {
        set_step(Some(Step::Converters));
        let hw = converters(ConverterPins {
            tim6: p.TIM6,
            dac1: p.DAC1,
            dac_dma: p.DMA1_CH3,
            dac_dma_unused: p.DMA1_CH5,
            pa4: p.PA4,
            adc1: p.ADC1,
            adc1_dma: p.DMA1_CH1,
            pa0: p.PA0,
            adc2: p.ADC2,
            adc2_dma: p.DMA1_CH2,
            pa1: p.PA1,
        });
        set_step(None);
        Some(hw)
    };

    // LPUART1 RX on PA3 (AF12), DMA1 CH4 ring.
    let mut cfg = embassy_stm32::usart::Config::default();
    cfg.baudrate = LPUART_BAUD;
    static mut UART_BUF: [u8; UART_RING] = [0; UART_RING];
    // SAFETY: init context; the ring is handed to embassy for good.
    let uart_buf = unsafe { &mut *addr_of_mut!(UART_BUF) };
    let uart = match UartRx::new(p.LPUART1, p.PA3, p.DMA1_CH4, Irqs, cfg) {
        Ok(rx) => {
            let mut rx = rx.into_ring_buffered(uart_buf);
            // The ring's DMA and the idle/error interrupts; embassy starts them only from a
            // read, and the first read here waits for the first interrupt.
            rx.start_uart();
            Some(rx)
        }
        Err(_) => {
            record(BootError::Uart);
            None
        }
    };

    // The load cell's pins: DOUT with a pull-up (the HX711 drives it; a missing chip reads
    // "not ready"), PD_SCK low (the chip converts).
    let load_cell = crate::loadcell::Hx711::new(
        CycleDelay,
        embassy_stm32::gpio::Input::new(p.PB4, embassy_stm32::gpio::Pull::Up),
        embassy_stm32::gpio::Output::new(
            p.PB5,
            embassy_stm32::gpio::Level::Low,
            embassy_stm32::gpio::Speed::Low,
        ),
    )
    .ok();

    Parts {
        load_cell,
        stream: Stream {
            hw,
            frames: [AdcFrame::default(); BATCH],
            current: [0; BATCH],
            monitor: [0; BATCH],
            last: None,
            started: 0,
            late_seen: false,
            fault_seen: false,
            faults: StreamFaults::default(),
            dac_underrun: false,
        },
        watchdog: Watchdog(wdg),
        flash: InternalFlash(flash),
        uart: Uart(uart),
    }
}
