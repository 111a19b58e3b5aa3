//! The STM32G474RE board (NUCLEO-G474RE): clocks from `stm32g4xx-hal`, and a small
//! register-level driver for what the HAL lacks — the timer-triggered DAC/ADC sample stream
//! with circular DMA — plus the internal-flash driver of the calibration store, the
//! independent watchdog and the LPUART1 receive path.
//!
//! # Bring-up (RM0440 references; audit table in `docs/firmware.md`)
//!
//! [`init`] runs, in order: the cycle counter (it times every bounded wait), DBGMCU freezes the
//! IWDG while the core is halted, PWR's bus clock (the HAL's `Rcc::freeze` reads PWR_CR1 but
//! never clocks PWR), flash prefetch and 4 wait states read back before the clock goes up, the
//! 24 MHz HSE crystal (X3) with a bounded start-up wait and HSI16 as the fallback, a bounded
//! PLL lock probe, then the HAL's `Rcc::freeze` (range 1 boost, PLL 170 MHz), the option-byte
//! check of dual-bank mode and the watchdog. [`Stream::start`] calibrates and enables ADC1 with
//! bounded waits. Nothing on this path panics or spins without a bound: a wait that times out
//! records a [`BootError`] (the first one is kept, see [`boot_error`]) and the board carries on
//! degraded — without the PLL at 16 MHz, without the sample stream, or without flash writes.
//! [`clock_source`] says which oscillator the PLL runs from. Waits that remain inside the HAL
//! (`enable_hse`, `enable_hsi`, `config_pll`, the SYSCLK switch) are entered only once the
//! condition they wait for is known to hold (HSE ready, HSI16 on at reset, PLL locked once).
//!
//! # Analog stream (RM0440 references)
//!
//! ```text
//! TIM6 update @ 10 kHz ──TRGO──┬─> DAC1 CH1 (PA4) ← DMA1 CH2 ← DAC_BUF [2 × 50] (circular)
//!                              └─> ADC1 seq: IN1 (PA0, sense current), IN2 (PA1, drive monitor)
//!                                   → DMA1 CH1 → ADC_BUF [2 × 50 × 2] (circular, HT + TC irq)
//! ```
//!
//! * TIM6: PSC 0, ARR = 170 MHz / 10 kHz − 1, CR2.MMS = update → TRGO.
//! * DAC1 CH1: TEN1, TSEL1 = 7 (`dac_ch1_trg7` = TIM6_TRGO), DMAEN1; MCR.HFSEL for AHB > 160 MHz.
//! * ADC1: synchronous clock HCLK/4 (42.5 MHz); regular sequence of 2 (IN1, IN2), 47.5-cycle
//!   sampling; EXTSEL = 13 (TIM6_TRGO), rising edge; circular DMA (DMACFG), overrun overwrites.
//! * DMAMUX1: channel 0 (→ DMA1 CH1) request 5 = ADC1; channel 1 (→ DMA1 CH2) request 6 =
//!   DAC1_CH1.
//! * DMA1 CH1 half-transfer and transfer-complete interrupts (vector `DMA1_CH1`) mark a captured
//!   ADC half; the DAC half with the same index has been played (the DAC's DMA runs off the same
//!   trigger) and is refilled by the interrupt; it plays again two halves later.
//!
//! Both DMA streams start together from one trigger source, so DAC half `h` and ADC half `h`
//! cover the same 50 sample periods (the DAC's one-sample output register delay shifts drive and
//! monitor alike and cancels in the admittance).
//!
//! DMA transfer errors (TEIF1, TEIF2; the hardware then disables the channel: RM0440 DMA chapter,
//! "DMA error management") and DAC DMA underruns (DMAUDR1; the DAC then stops requesting: RM0440
//! DAC chapter, "DMA underrun") are checked at every batch: they make [`Stream::late`] true
//! for that batch (the `LATE` counter of the application), are counted in [`stream_faults`]
//! and stop TIM6, so readings stall rather than run on without drive or samples.
//!
//! Pins: PA0 sense current (TIA output), PA1 drive monitor, PA4 DAC out to the drive amplifier,
//! PA2/PA3 LPUART1 TX/RX (AF12) to the ST-LINK virtual COM port.

use crate::engine::SampleEngine;
use crate::hal::{AdcFrame, FrontEndScale};
use crate::runner::BATCH;
use crate::units::{AdcCode, DacCode, Hz};
use core::ptr::{addr_of_mut, read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};
use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};
use stm32g4xx_hal::pwr::{PwrExt, VoltageScale};
use stm32g4xx_hal::rcc::{
    Config, PllConfig, PllMDiv, PllNMul, PllRDiv, PllSrc, RccExt, SysClockSrc,
};
use stm32g4xx_hal::time::RateExtU32;

/// The device crate (PAC) RTIC binds to.
pub use stm32g4xx_hal::stm32 as device;

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

/// A bring-up step that did not complete within its bound. The board carries on degraded;
/// [`boot_error`] holds the first one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum BootError {
    /// PWR_CR1.VOS did not read range 1 after PWR was clocked (or SYSCLK already ran from the
    /// PLL): the clock configuration was skipped, the core runs from HSI16 at 16 MHz.
    PowerRange = 1,
    /// FLASH_ACR did not take the wait states within its bound: clock configuration skipped.
    FlashLatency,
    /// The PLL did not lock within its bound: clock configuration skipped (HSI16, 16 MHz).
    PllLock,
    /// The independent watchdog did not acknowledge its prescaler and reload (IWDG_SR): it runs
    /// with its reset configuration (about 512 ms).
    Watchdog,
    /// The flash controller stayed busy at boot.
    FlashBusy,
    /// FLASH_OPTR.DBANK is 0 (single-bank mode, 4 KiB pages): the store's erase and program
    /// are refused (they would address the wrong pages).
    FlashSingleBank,
    /// ADC1 calibration (ADCAL) did not finish: the sample stream is not started.
    AdcCalibration,
    /// ADC1 did not become ready (ADRDY) after ADEN: the sample stream is not started.
    AdcReady,
}

impl BootError {
    const ALL: [BootError; 8] = [
        BootError::PowerRange,
        BootError::FlashLatency,
        BootError::PllLock,
        BootError::Watchdog,
        BootError::FlashBusy,
        BootError::FlashSingleBank,
        BootError::AdcCalibration,
        BootError::AdcReady,
    ];

    /// Short name for the log.
    pub fn name(self) -> &'static str {
        match self {
            BootError::PowerRange => "power_range",
            BootError::FlashLatency => "flash_latency",
            BootError::PllLock => "pll_lock",
            BootError::Watchdog => "watchdog",
            BootError::FlashBusy => "flash_busy",
            BootError::FlashSingleBank => "flash_single_bank",
            BootError::AdcCalibration => "adc_calibration",
            BootError::AdcReady => "adc_ready",
        }
    }
}

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

/// The oscillator the core clock comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// The NUCLEO-G474RE's 24 MHz crystal (X3) through the PLL: 170 MHz.
    Hse24,
    /// HSI16 through the PLL (the HSE did not start): 170 MHz, RC accuracy.
    Hsi16Pll,
    /// HSI16 directly, 16 MHz: clock configuration skipped (see [`boot_error`]).
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

/// 0: HSI16 (reset state), 1: HSE through the PLL, 2: HSI16 through the PLL.
static CLOCK: AtomicU8 = AtomicU8::new(0);

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
    /// DMA1 transfer errors (TEIF) on channel 1 (ADC) or 2 (DAC).
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

// Bounds of the waits, in core cycles at the clock the wait runs under.
/// HSE crystal start-up, at HSI16: 100 ms (ST's HSE_STARTUP_TIMEOUT; typical start-up 2 ms).
const HSE_TIMEOUT: u32 = 16_000_000 / 10;
/// PLL lock, at HSI16: 10 ms (typical lock time tens of µs).
const PLL_TIMEOUT: u32 = 16_000_000 / 100;
/// FLASH_ACR write taking effect: a few bus cycles.
const ACR_TIMEOUT: u32 = 1_000;
/// IWDG register updates (PVU, RVU: up to a few LSI periods), at 170 MHz: 10 ms.
const IWDG_TIMEOUT: u32 = SYSCLK_HZ / 100;
/// ADC calibration (about 116 ADC clocks) and ADRDY, at 170 MHz: 1 ms.
const ADC_TIMEOUT: u32 = SYSCLK_HZ / 1_000;
/// Flash page erase (about 22 ms) or double-word program (about 82 µs), at 170 MHz: 50 ms.
const FLASH_TIMEOUT: u32 = SYSCLK_HZ / 20;

// ---- register map (RM0440) --------------------------------------------------------------

const RCC_AHB1ENR_DMA1EN: u32 = 1 << 0;
const RCC_AHB1ENR_DMAMUX1EN: u32 = 1 << 2;
const RCC_AHB2ENR_GPIOAEN: u32 = 1 << 0;
const RCC_AHB2ENR_ADC12EN: u32 = 1 << 13;
const RCC_AHB2ENR_DAC1EN: u32 = 1 << 16;
const RCC_APB1ENR1_TIM6EN: u32 = 1 << 4;
const RCC_APB1ENR1_PWREN: u32 = 1 << 28;
const RCC_APB1ENR2_LPUART1EN: u32 = 1 << 0;
const RCC_CR_HSEON: u32 = 1 << 16;
const RCC_CR_HSERDY: u32 = 1 << 17;
const RCC_CR_HSEBYP: u32 = 1 << 18;
const RCC_CR_PLLON: u32 = 1 << 24;
const RCC_CR_PLLRDY: u32 = 1 << 25;
const RCC_CFGR_SWS_MASK: u32 = 0b11 << 2;
const RCC_CFGR_SWS_PLL: u32 = 0b11 << 2;
const RCC_PLLCFGR_SRC_HSI16: u32 = 0b10;
const RCC_PLLCFGR_SRC_HSE: u32 = 0b11;
const RCC_PLLCFGR_N85: u32 = 85 << 8;
/// PLLR = /2 (field 00), output enabled.
const RCC_PLLCFGR_REN_R2: u32 = 1 << 24;
/// HSE frequency of the NUCLEO-G474RE's crystal X3.
const HSE_HZ: u32 = 24_000_000;

const PWR_CR1_VOS_MASK: u32 = 0b11 << 9;
const PWR_CR1_VOS_RANGE1: u32 = 0b01 << 9;

const FLASH_ACR_LATENCY_MASK: u32 = 0xF;
/// 4 wait states: range 1 boost, 136–170 MHz.
const FLASH_ACR_LATENCY_4WS: u32 = 4;
const FLASH_ACR_PRFTEN: u32 = 1 << 8;
const FLASH_ACR_DCEN: u32 = 1 << 10;
const FLASH_ACR_DCRST: u32 = 1 << 12;
const FLASH_OPTR_DBANK: u32 = 1 << 22;

const DBGMCU_APB1FZR1_DBG_IWDG_STOP: u32 = 1 << 12;

const IWDG_KEY_START: u16 = 0xCCCC;
const IWDG_KEY_UNLOCK: u16 = 0x5555;
const IWDG_KEY_FEED: u16 = 0xAAAA;
/// Prescaler /4: LSI 32 kHz → 8 kHz.
const IWDG_PR_DIV4: u16 = 0;
/// 500 ms at 8 kHz.
const IWDG_RLR_500MS: u16 = 500 * 8 - 1;

const TIM_CR1_CEN: u32 = 1 << 0;
const TIM_CR2_MMS_UPDATE: u32 = 0b010 << 4;
const TIM_EGR_UG: u32 = 1 << 0;

const DAC_CR_EN1: u32 = 1 << 0;
const DAC_CR_TEN1: u32 = 1 << 1;
const DAC_CR_TSEL1_TIM6: u32 = 7 << 2;
const DAC_CR_DMAEN1: u32 = 1 << 12;
const DAC_MCR_HFSEL_160: u32 = 0b10 << 14;
const DAC_SR_DMAUDR1: u32 = 1 << 13;

const ADC_CR_ADEN: u32 = 1 << 0;
const ADC_CR_ADSTART: u32 = 1 << 2;
const ADC_CR_ADVREGEN: u32 = 1 << 28;
const ADC_CR_ADCAL: u32 = 1 << 31;
/// Core cycles from the end of ADCAL to ADEN: at least 4 ADC clocks (HCLK/4), 16 core cycles;
/// 64 leaves a margin.
const ADC_CAL_TO_ADEN_CYCLES: u32 = 64;
const ADC_ISR_ADRDY: u32 = 1 << 0;
const ADC_CFGR_DMAEN: u32 = 1 << 0;
const ADC_CFGR_DMACFG: u32 = 1 << 1;
const ADC_CFGR_EXTSEL_TIM6: u32 = 13 << 5;
const ADC_CFGR_EXTEN_RISING: u32 = 0b01 << 10;
const ADC_CFGR_OVRMOD: u32 = 1 << 12;
const ADC_CCR_CKMODE_HCLK_4: u32 = 0b11 << 16;
/// 47.5 ADC clock cycles sampling for IN1 and IN2.
const ADC_SMPR1_IN1_IN2: u32 = (0b100 << 3) | (0b100 << 6);
/// Two conversions: IN1 then IN2.
const ADC_SQR1_SEQ: u32 = 1 | (1 << 6) | (2 << 12);

const DMAMUX_REQ_ADC1: u32 = 5;
const DMAMUX_REQ_DAC1_CH1: u32 = 6;
const DMA_CCR_EN: u32 = 1 << 0;
const DMA_CCR_TCIE: u32 = 1 << 1;
const DMA_CCR_HTIE: u32 = 1 << 2;
const DMA_CCR_TEIE: u32 = 1 << 3;
const DMA_CCR_DIR_FROM_MEM: u32 = 1 << 4;
const DMA_CCR_CIRC: u32 = 1 << 5;
const DMA_CCR_MINC: u32 = 1 << 7;
const DMA_CCR_PSIZE_16: u32 = 0b01 << 8;
const DMA_CCR_PSIZE_32: u32 = 0b10 << 8;
const DMA_CCR_MSIZE_16: u32 = 0b01 << 10;
const DMA_CCR_PL_VERY_HIGH: u32 = 0b11 << 12;
const DMA_ISR_TCIF1: u32 = 1 << 1;
const DMA_ISR_HTIF1: u32 = 1 << 2;
const DMA_ISR_TEIF1: u32 = 1 << 3;
const DMA_ISR_TEIF2: u32 = 1 << 7;
const DMA_IFCR_CGIF1: u32 = 1 << 0;
const DMA_IFCR_CGIF2: u32 = 1 << 4;
const DMA_IFCR_CTEIF2: u32 = 1 << 7;

const GPIOA_MODER_PA2_PA3_AF: u32 = (0b10 << 4) | (0b10 << 6);
const GPIOA_MODER_PA2_PA3_MASK: u32 = (0b11 << 4) | (0b11 << 6);
const GPIOA_AFRL_PA2_PA3_AF12: u32 = (12 << 8) | (12 << 12);
const GPIOA_AFRL_PA2_PA3_MASK: u32 = (0xF << 8) | (0xF << 12);

const LPUART_CR1_UE: u32 = 1 << 0;
const LPUART_CR1_RE: u32 = 1 << 2;
const LPUART_CR1_TE: u32 = 1 << 3;
const LPUART_CR1_RXNEIE: u32 = 1 << 5;
const LPUART_ISR_RXNE: u32 = 1 << 5;
const LPUART_ISR_ORE: u32 = 1 << 3;
const LPUART_ICR_ORECF: u32 = 1 << 3;
const LPUART_BAUD: u32 = 115_200;

/// DMA buffers: the DMA owns them once started; the interrupt touches only the half the DMA
/// has just left.
static mut DAC_BUF: [[DacCode; BATCH]; 2] = [[DacCode::MID; BATCH]; 2];
static mut ADC_BUF: [[[u16; 2]; BATCH]; 2] = [[[0; 2]; BATCH]; 2];

fn pac() -> device::Peripherals {
    // SAFETY: the board driver is the only user of these peripherals; every register it
    // touches belongs to a peripheral this module configures and owns exclusively, and the
    // RTIC application does not take the PAC's peripherals itself (`peripherals = false`).
    unsafe { device::Peripherals::steal() }
}

/// The DAC/ADC sample stream over TIM6, DAC1, ADC1 and two DMA1 channels.
pub struct Stream {
    frames: [AdcFrame; BATCH],
    late_seen: bool,
    fault_seen: bool,
}

impl Stream {
    /// Converter scale of this board.
    pub fn scale(&self) -> FrontEndScale {
        SCALE
    }

    fn new() -> Self {
        Self {
            frames: [AdcFrame::default(); BATCH],
            late_seen: false,
            fault_seen: false,
        }
    }

    /// Prefill both DAC halves from `engine`, configure the converters and DMA and start the
    /// trigger timer. Called once from `init` with interrupts disabled. If ADC1 does not
    /// calibrate or become ready within its bound, records [`BootError::AdcCalibration`] or
    /// [`BootError::AdcReady`] and leaves the timer stopped (no batches, readings stall).
    pub fn start(&mut self, engine: &mut SampleEngine) {
        let dp = pac();
        // SAFETY: init context, the DMA is not running yet; the buffers are only reached
        // through these raw pointers.
        let (dac_buf, adc_buf) =
            unsafe { (&mut *addr_of_mut!(DAC_BUF), &mut *addr_of_mut!(ADC_BUF)) };
        for half in dac_buf.iter_mut() {
            engine.generate(half);
        }
        // SAFETY (all `bits` writes below): values follow RM0440's register descriptions; the
        // peripherals are owned by this driver.
        unsafe {
            dp.RCC
                .ahb1enr()
                .modify(|r, w| w.bits(r.bits() | RCC_AHB1ENR_DMA1EN | RCC_AHB1ENR_DMAMUX1EN));
            dp.RCC.ahb2enr().modify(|r, w| {
                w.bits(r.bits() | RCC_AHB2ENR_GPIOAEN | RCC_AHB2ENR_ADC12EN | RCC_AHB2ENR_DAC1EN)
            });
            dp.RCC
                .apb1enr1()
                .modify(|r, w| w.bits(r.bits() | RCC_APB1ENR1_TIM6EN));
            // PA0, PA1, PA4 stay in their reset mode: analog.

            // TIM6: 10 kHz update as TRGO, not yet running.
            let tim = &dp.TIM6;
            tim.psc().write(|w| w.bits(0));
            tim.arr().write(|w| w.bits(SYSCLK_HZ / SAMPLE_RATE_HZ - 1));
            tim.cr2().write(|w| w.bits(TIM_CR2_MMS_UPDATE));
            tim.egr().write(|w| w.bits(TIM_EGR_UG));

            // Stale fault flags would be counted as faults of this stream: clear channel 1's and
            // 2's DMA flags and the DAC underrun (RM0440 DMA_IFCR, DAC_SR; no HAL driver).
            dp.DMA1
                .ifcr()
                .write(|w| w.bits(DMA_IFCR_CGIF1 | DMA_IFCR_CGIF2));
            dp.DAC1.sr().write(|w| w.bits(DAC_SR_DMAUDR1));

            // DMAMUX: request lines of the two DMA1 channels.
            dp.DMAMUX.ccr(0).write(|w| w.bits(DMAMUX_REQ_ADC1));
            dp.DMAMUX.ccr(1).write(|w| w.bits(DMAMUX_REQ_DAC1_CH1));

            // DMA1 CH2: DAC buffer → DHR12R1, 32-bit peripheral writes of 16-bit codes.
            let ch2 = dp.DMA1.ch2();
            ch2.par()
                .write(|w| w.bits(dp.DAC1.dhr12r1().as_ptr() as u32));
            ch2.mar().write(|w| w.bits(dac_buf.as_ptr() as u32));
            ch2.ndtr().write(|w| w.bits((2 * BATCH) as u32));
            ch2.cr().write(|w| {
                w.bits(
                    DMA_CCR_DIR_FROM_MEM
                        | DMA_CCR_CIRC
                        | DMA_CCR_MINC
                        | DMA_CCR_PSIZE_32
                        | DMA_CCR_MSIZE_16
                        | DMA_CCR_PL_VERY_HIGH,
                )
            });
            ch2.cr().modify(|r, w| w.bits(r.bits() | DMA_CCR_EN));

            // DMA1 CH1: ADC1 DR → ADC buffer, interleaved (IN1, IN2) pairs, HT + TC interrupts.
            let ch1 = dp.DMA1.ch1();
            ch1.par().write(|w| w.bits(dp.ADC1.dr().as_ptr() as u32));
            ch1.mar().write(|w| w.bits(adc_buf.as_ptr() as u32));
            ch1.ndtr().write(|w| w.bits((2 * BATCH * 2) as u32));
            ch1.cr().write(|w| {
                w.bits(
                    DMA_CCR_CIRC
                        | DMA_CCR_MINC
                        | DMA_CCR_PSIZE_16
                        | DMA_CCR_MSIZE_16
                        | DMA_CCR_PL_VERY_HIGH
                        | DMA_CCR_HTIE
                        | DMA_CCR_TCIE
                        | DMA_CCR_TEIE,
                )
            });
            ch1.cr().modify(|r, w| w.bits(r.bits() | DMA_CCR_EN));

            // DAC1 CH1: triggered by TIM6, fed by DMA; first code mid-scale.
            dp.DAC1
                .mcr()
                .modify(|r, w| w.bits(r.bits() | DAC_MCR_HFSEL_160));
            dp.DAC1.dhr12r1().write(|w| w.bits(DacCode::MID.0 as u32));
            dp.DAC1
                .cr()
                .write(|w| w.bits(DAC_CR_TEN1 | DAC_CR_TSEL1_TIM6 | DAC_CR_DMAEN1));
            dp.DAC1.cr().modify(|r, w| w.bits(r.bits() | DAC_CR_EN1));

            // ADC1: power up, calibrate, configure, enable, arm.
            dp.ADC12_COMMON
                .ccr()
                .modify(|r, w| w.bits(r.bits() | ADC_CCR_CKMODE_HCLK_4));
            let adc = &dp.ADC1;
            adc.cr().write(|w| w.bits(0)); // leave deep power-down
            adc.cr().write(|w| w.bits(ADC_CR_ADVREGEN));
            cortex_m::asm::delay(SYSCLK_HZ / 50_000); // t_ADCVREG_STUP = 20 µs

            // Calibration, bounded (RM0440 21.4.8; the HAL's ADC driver is not used).
            adc.cr().write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADCAL));
            if !spin_until(ADC_TIMEOUT, || adc.cr().read().bits() & ADC_CR_ADCAL == 0) {
                record(BootError::AdcCalibration);
                return;
            }
            // ADEN must not be set within 4 ADC clock cycles of ADCAL's end (RM0440 21.4.8,
            // 21.4.9); the register writes below take fewer, hence the explicit delay.
            cortex_m::asm::delay(ADC_CAL_TO_ADEN_CYCLES);
            adc.cfgr().write(|w| {
                w.bits(
                    ADC_CFGR_DMAEN
                        | ADC_CFGR_DMACFG
                        | ADC_CFGR_EXTSEL_TIM6
                        | ADC_CFGR_EXTEN_RISING
                        | ADC_CFGR_OVRMOD,
                )
            });
            adc.smpr1().write(|w| w.bits(ADC_SMPR1_IN1_IN2));
            adc.sqr1().write(|w| w.bits(ADC_SQR1_SEQ));
            adc.isr().write(|w| w.bits(ADC_ISR_ADRDY));
            // Enable, bounded wait for ADRDY (RM0440 21.4.9).
            adc.cr().write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADEN));
            if !spin_until(ADC_TIMEOUT, || adc.isr().read().bits() & ADC_ISR_ADRDY != 0) {
                record(BootError::AdcReady);
                return;
            }
            adc.cr()
                .write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADEN | ADC_CR_ADSTART));

            // Go: every TIM6 update now plays one DAC code and converts one frame.
            tim.cr1().write(|w| w.bits(TIM_CR1_CEN));
        }
    }

    /// Acknowledge the DMA half/full-transfer interrupt; returns the ADC half just captured
    /// (de-interleaved into frames) and the DAC half just played (to refill). Counts DMA
    /// transfer errors and DAC underruns ([`stream_faults`]); a batch that saw one is late.
    pub fn capture(&mut self) -> (&[AdcFrame], &mut [DacCode]) {
        let dp = pac();
        let flags = dp.DMA1.isr().read().bits();
        // Faults the register-level stream must watch itself (no HAL driver; RM0440 DMA_ISR
        // TEIFx, DAC_SR DMAUDR1): on a transfer error the DMA disables the channel, on an
        // underrun the DAC stops its DMA requests.
        let dac_sr = dp.DAC1.sr().read().bits();
        let te2 = flags & DMA_ISR_TEIF2 != 0;
        // SAFETY: write-one-to-clear of channel 1's flags, of channel 2's transfer error flag
        // and of the DAC's underrun flag.
        unsafe {
            dp.DMA1
                .ifcr()
                .write(|w| w.bits(DMA_IFCR_CGIF1 | if te2 { DMA_IFCR_CTEIF2 } else { 0 }));
        }
        let transfer_errors = (flags & DMA_ISR_TEIF1 != 0) as u32 + te2 as u32;
        let underrun = dac_sr & DAC_SR_DMAUDR1 != 0;
        if underrun {
            // SAFETY: as above.
            unsafe { dp.DAC1.sr().write(|w| w.bits(DAC_SR_DMAUDR1)) };
            DAC_UNDERRUNS.fetch_add(1, Ordering::Relaxed);
        }
        if transfer_errors != 0 {
            DMA_TRANSFER_ERRORS.fetch_add(transfer_errors, Ordering::Relaxed);
        }
        self.fault_seen = underrun || transfer_errors != 0;
        if self.fault_seen {
            // Either fault ends the stream as a whole (a disabled DMA channel, a DAC that no
            // longer requests data): stop the trigger, so the measurement task's readings end
            // as `stalled` rather than run on with a dead drive or stale samples.
            // SAFETY: TIM6 belongs to this driver.
            unsafe { dp.TIM6.cr1().write(|w| w.bits(0)) };
        }
        let both = DMA_ISR_HTIF1 | DMA_ISR_TCIF1;
        // Both flags at once: a whole half went by unserviced.
        self.late_seen = flags & both == both;
        let h = if flags & DMA_ISR_TCIF1 != 0 { 1 } else { 0 };
        // SAFETY: the DMA has left half `h` of both buffers (it is now in the other half) and
        // comes back to it only after the other half completes.
        let (adc, dac) = unsafe {
            (
                &(*addr_of_mut!(ADC_BUF))[h],
                &mut (*addr_of_mut!(DAC_BUF))[h],
            )
        };
        for (f, pair) in self.frames.iter_mut().zip(adc.iter()) {
            *f = AdcFrame {
                current: AdcCode(pair[0]),
                monitor: AdcCode(pair[1]),
            };
        }
        (&self.frames, dac)
    }

    /// True when the handler was late: a half went by unserviced, or the next half completed
    /// before the handler finished — or the batch saw a DMA transfer error or DAC underrun
    /// (its data are stale; [`stream_faults`] tells the two apart).
    pub fn late(&self) -> bool {
        let flags = pac().DMA1.isr().read().bits();
        self.late_seen || self.fault_seen || flags & (DMA_ISR_HTIF1 | DMA_ISR_TCIF1) != 0
    }
}

/// LPUART1 receiver (115 200 Bd, 8N1) on the ST-LINK virtual COM port.
pub struct Uart(());

impl Uart {
    fn new() -> Self {
        let dp = pac();
        // SAFETY: LPUART1 and GPIOA (PA2/PA3 only) belong to this driver; values per RM0440.
        unsafe {
            dp.RCC
                .apb1enr2()
                .modify(|r, w| w.bits(r.bits() | RCC_APB1ENR2_LPUART1EN));
            dp.RCC
                .ahb2enr()
                .modify(|r, w| w.bits(r.bits() | RCC_AHB2ENR_GPIOAEN));
            dp.GPIOA.afrl().modify(|r, w| {
                w.bits((r.bits() & !GPIOA_AFRL_PA2_PA3_MASK) | GPIOA_AFRL_PA2_PA3_AF12)
            });
            dp.GPIOA.moder().modify(|r, w| {
                w.bits((r.bits() & !GPIOA_MODER_PA2_PA3_MASK) | GPIOA_MODER_PA2_PA3_AF)
            });
            // LPUART clock = PCLK1 (170 MHz, CCIPR reset value); BRR = 256 f / baud.
            let brr = ((256u64 * SYSCLK_HZ as u64) / LPUART_BAUD as u64) as u32;
            dp.LPUART1.brr().write(|w| w.bits(brr));
            dp.LPUART1.cr1().write(|w| {
                w.bits(LPUART_CR1_UE | LPUART_CR1_RE | LPUART_CR1_TE | LPUART_CR1_RXNEIE)
            });
        }
        Self(())
    }

    /// The next received byte, if any (reading it clears the receive interrupt).
    pub fn read_byte(&mut self) -> Option<u8> {
        let dp = pac();
        let isr = dp.LPUART1.isr().read().bits();
        if isr & LPUART_ISR_ORE != 0 {
            // SAFETY: write-one-to-clear of the overrun flag; the lost byte shows up as a
            // malformed line, which the parser reports.
            unsafe { dp.LPUART1.icr().write(|w| w.bits(LPUART_ICR_ORECF)) };
        }
        (isr & LPUART_ISR_RXNE != 0).then(|| dp.LPUART1.rdr().read().bits() as u8)
    }
}

/// The independent watchdog (LSI): 500 ms timeout, fed by the measurement task while alive;
/// frozen while a debugger halts the core.
pub struct Watchdog(());

impl Watchdog {
    /// Freeze the IWDG under the debugger, start it, set 500 ms. Register level rather than
    /// the HAL's `IndependentWatchdog::start`, whose waits on IWDG_SR are unbounded and which
    /// carries an `expect`: here a wait that times out records [`BootError::Watchdog`] and the
    /// IWDG keeps its reset configuration (/4, reload 0xFFF: about 512 ms).
    fn start() -> Self {
        let dp = pac();
        // SAFETY: DBGMCU and IWDG belong to this driver; values per RM0440 (DBGMCU_APB1FZR1,
        // IWDG_KR/PR/RLR/SR).
        unsafe {
            // Freeze the IWDG counter while the core is halted (DBG_IWDG_STOP; the HAL has no
            // DBGMCU API; RM0440 DBGMCU chapter, DBGMCU_APB1FZR1), so a breakpoint does not
            // reset the board.
            dp.DBGMCU
                .apb1l_fz()
                .modify(|r, w| w.bits(r.bits() | DBGMCU_APB1FZR1_DBG_IWDG_STOP));
            let iwdg = &dp.IWDG;
            iwdg.kr().write(|w| w.bits(IWDG_KEY_START));
            iwdg.kr().write(|w| w.bits(IWDG_KEY_UNLOCK));
            // PR and RLR take writes only while PVU/RVU are clear, and PVU/RVU/WVU clear once
            // the LSI domain took the values (RM0440 IWDG chapter, IWDG_SR): bounded waits
            // before and after.
            let idle = || iwdg.sr().read().bits() == 0;
            if spin_until(IWDG_TIMEOUT, idle) {
                iwdg.pr().write(|w| w.bits(IWDG_PR_DIV4));
                iwdg.rlr().write(|w| w.bits(IWDG_RLR_500MS));
            }
            if !spin_until(IWDG_TIMEOUT, idle) {
                record(BootError::Watchdog);
            }
            iwdg.kr().write(|w| w.bits(IWDG_KEY_FEED));
        }
        Watchdog(())
    }

    /// Feed the watchdog.
    pub fn feed(&mut self) {
        // SAFETY: the refresh key (RM0440 IWDG_KR).
        unsafe { pac().IWDG.kr().write(|w| w.bits(IWDG_KEY_FEED)) };
    }
}

/// Errors of the internal flash driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Bad alignment or range.
    Args(NorFlashErrorKind),
    /// The controller reported an error (FLASH_SR bits).
    Controller(u32),
    /// FLASH_SR.BSY did not clear within its bound.
    Busy,
    /// The flash is in single-bank mode (FLASH_OPTR.DBANK = 0): erase and program refused.
    SingleBank,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Args(k) => *k,
            FlashError::Controller(_) | FlashError::Busy | FlashError::SingleBank => {
                NorFlashErrorKind::Other
            }
        }
    }
}

impl From<NorFlashErrorKind> for FlashError {
    fn from(k: NorFlashErrorKind) -> Self {
        FlashError::Args(k)
    }
}

const FLASH_BASE: u32 = 0x0800_0000;
const FLASH_SIZE: usize = 512 * 1024;
const FLASH_PAGE: usize = 2048;
const FLASH_BANK_PAGES: u32 = 128;
const FLASH_KEY1: u32 = 0x4567_0123;
const FLASH_KEY2: u32 = 0xCDEF_89AB;
const FLASH_CR_PG: u32 = 1 << 0;
const FLASH_CR_PER: u32 = 1 << 1;
const FLASH_CR_BKER: u32 = 1 << 11;
const FLASH_CR_STRT: u32 = 1 << 16;
const FLASH_CR_LOCK: u32 = 1 << 31;
const FLASH_SR_BSY: u32 = 1 << 16;
/// OPERR, PROGERR, WRPERR, PGAERR, SIZERR, PGSERR, MISERR, FASTERR, RDERR, OPTVERR.
const FLASH_SR_ERRORS: u32 = 0xC3FA;
const FLASH_SR_EOP: u32 = 1 << 0;

/// The internal flash as a NOR flash (dual-bank mode, the factory default of the
/// STM32G474RE: 2 KiB pages, 8-byte double-word programming; checked in FLASH_OPTR.DBANK, and
/// erase and program are refused in single-bank mode). Offsets count from 0x0800_0000. The
/// store lives in bank 2 while the code runs from bank 1, so erasing and programming do not
/// stall the sample interrupt (read-while-write across banks). Every wait on FLASH_SR.BSY is
/// bounded ([`FlashError::Busy`]). Register level: the HAL's `FlashWriter` waits on BSY
/// without a bound and knows nothing of DBANK or the data cache.
pub struct InternalFlash(());

impl InternalFlash {
    /// Dual-bank mode (RM0440 3.3.1, FLASH_OPTR.DBANK; the HAL does not check it).
    fn dual_bank() -> bool {
        pac().FLASH.optr().read().bits() & FLASH_OPTR_DBANK != 0
    }

    /// Bounded wait for BSY to clear (RM0440 3.3.7/3.3.8, step "check BSY"; the HAL's waits
    /// are unbounded).
    fn wait_idle() -> Result<(), FlashError> {
        let dp = pac();
        if spin_until(FLASH_TIMEOUT, || {
            dp.FLASH.sr().read().bits() & FLASH_SR_BSY == 0
        }) {
            Ok(())
        } else {
            Err(FlashError::Busy)
        }
    }

    /// Wait for the operation to end, then read and clear FLASH_SR: its error flags are the
    /// operation's result.
    fn finish() -> Result<(), FlashError> {
        Self::wait_idle()?;
        let dp = pac();
        let sr = dp.FLASH.sr().read().bits();
        // SAFETY: write-one-to-clear of the status flags (RM0440 FLASH_SR).
        unsafe {
            dp.FLASH
                .sr()
                .write(|w| w.bits(FLASH_SR_ERRORS | FLASH_SR_EOP))
        };
        if sr & FLASH_SR_ERRORS != 0 {
            Err(FlashError::Controller(sr))
        } else {
            Ok(())
        }
    }

    /// Unlock, wait for idle, clear stale error flags (a flag left by an earlier operation
    /// would block the next one: PGSERR and friends, RM0440 3.3.7/3.3.8 "check and clear all
    /// error programming flags due to a previous programming"), run `f`, lock again.
    fn unlocked<T>(f: impl FnOnce() -> Result<T, FlashError>) -> Result<T, FlashError> {
        if !Self::dual_bank() {
            return Err(FlashError::SingleBank);
        }
        let dp = pac();
        // SAFETY: the documented unlock sequence, then CR is restored to locked.
        unsafe {
            if dp.FLASH.cr().read().bits() & FLASH_CR_LOCK != 0 {
                dp.FLASH.keyr().write(|w| w.bits(FLASH_KEY1));
                dp.FLASH.keyr().write(|w| w.bits(FLASH_KEY2));
            }
        }
        let r = Self::wait_idle().and_then(|_| {
            // SAFETY: write-one-to-clear of stale flags before the operation (RM0440 FLASH_SR).
            unsafe {
                dp.FLASH
                    .sr()
                    .write(|w| w.bits(FLASH_SR_ERRORS | FLASH_SR_EOP))
            };
            f()
        });
        // SAFETY: lock again (clears PER/PG with it).
        unsafe { dp.FLASH.cr().write(|w| w.bits(FLASH_CR_LOCK)) };
        r
    }

    /// Reset the flash data cache so reads of the store see what the operation left, not
    /// lines cached before it (RM0440 3.3.4: DCRST may only be written with DCEN = 0; the HAL
    /// has no cache maintenance). Bank 2 holds no code, so the instruction cache needs none.
    fn flush_data_cache() {
        let dp = pac();
        let acr = dp.FLASH.acr().read().bits();
        if acr & FLASH_ACR_DCEN == 0 {
            return;
        }
        let off = acr & !FLASH_ACR_DCEN;
        // SAFETY: FLASH_ACR sequence DCEN off, DCRST pulse, DCEN back; nothing else writes ACR
        // after boot.
        unsafe {
            dp.FLASH.acr().write(|w| w.bits(off));
            dp.FLASH.acr().write(|w| w.bits(off | FLASH_ACR_DCRST));
            dp.FLASH.acr().write(|w| w.bits(off));
            dp.FLASH.acr().write(|w| w.bits(acr));
        }
    }
}

impl ErrorType for InternalFlash {
    type Error = FlashError;
}

impl ReadNorFlash for InternalFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_read(self, offset, bytes.len())?;
        for (i, b) in bytes.iter_mut().enumerate() {
            // SAFETY: within the checked range of the memory-mapped flash.
            *b = unsafe { read_volatile((FLASH_BASE + offset + i as u32) as *const u8) };
        }
        Ok(())
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
        for page in (from / FLASH_PAGE as u32)..(to / FLASH_PAGE as u32) {
            let bank2 = page >= FLASH_BANK_PAGES;
            let pnb = page % FLASH_BANK_PAGES;
            let r = Self::unlocked(|| {
                let dp = pac();
                let bker = if bank2 { FLASH_CR_BKER } else { 0 };
                // SAFETY: page erase per RM0440 3.3.7.
                unsafe {
                    dp.FLASH
                        .cr()
                        .write(|w| w.bits(FLASH_CR_PER | bker | (pnb << 3)));
                    dp.FLASH
                        .cr()
                        .write(|w| w.bits(FLASH_CR_PER | bker | (pnb << 3) | FLASH_CR_STRT));
                }
                Self::finish()
            });
            // Also after a failed erase: the page may be partly erased.
            Self::flush_data_cache();
            r?;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_write(self, offset, bytes.len())?;
        let r = Self::unlocked(|| {
            let dp = pac();
            // SAFETY: double-word programming per RM0440 3.3.8: PG set, two word writes.
            unsafe { dp.FLASH.cr().write(|w| w.bits(FLASH_CR_PG)) };
            for (k, dw) in bytes.chunks_exact(8).enumerate() {
                let addr = FLASH_BASE + offset + 8 * k as u32;
                let lo = u32::from_le_bytes([dw[0], dw[1], dw[2], dw[3]]);
                let hi = u32::from_le_bytes([dw[4], dw[5], dw[6], dw[7]]);
                // SAFETY: an aligned double word inside the checked range.
                unsafe {
                    write_volatile(addr as *mut u32, lo);
                    write_volatile((addr + 4) as *mut u32, hi);
                }
                Self::finish()?;
            }
            Ok(())
        });
        // A line read between the erase and this write may hold the erased bytes.
        Self::flush_data_cache();
        r
    }
}

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
}

/// Set the board up: cycle counter; 170 MHz from the 24 MHz HSE crystal through the PLL
/// (HSI16 if the crystal does not start), range 1 boost; UART; watchdog (frozen under the
/// debugger). Call once, from `init`. Never panics or waits without a bound: see
/// [`boot_error`] and [`clock_source`] for what happened.
pub fn init(core: &mut cortex_m::Peripherals) -> Parts {
    // The cycle counter first: it times the bounded waits below.
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();
    match configure_clocks() {
        Ok(source) => CLOCK.store(source, Ordering::Relaxed),
        Err(e) => record(e),
    }
    check_flash();
    Parts {
        stream: Stream::new(),
        watchdog: Watchdog::start(),
        flash: InternalFlash(()),
        uart: Uart::new(),
    }
}

/// The flash controller at boot: idle, no stale error flags, dual-bank mode.
fn check_flash() {
    if InternalFlash::wait_idle().is_err() {
        record(BootError::FlashBusy);
    } else {
        // SAFETY: write-one-to-clear of stale FLASH_SR flags (RM0440 FLASH_SR).
        unsafe {
            pac()
                .FLASH
                .sr()
                .write(|w| w.bits(FLASH_SR_ERRORS | FLASH_SR_EOP))
        };
    }
    if !InternalFlash::dual_bank() {
        record(BootError::FlashSingleBank);
    }
}

/// The clock tree: the HAL's `Rcc::freeze` with what it leaves out done around it. Returns
/// the [`CLOCK`] code of the PLL's source; on an error the core stays on HSI16 at 16 MHz.
fn configure_clocks() -> Result<u8, BootError> {
    let dp = pac();
    // SAFETY (all `bits` writes): RCC, PWR and FLASH_ACR belong to this function during
    // `init`; values per RM0440.
    unsafe {
        // PWR's bus clock. The HAL's `Rcc::freeze` reads PWR_CR1 (`pwr::current_vos`) and
        // writes PWR_CR5 (boost) but neither `PwrExt::constrain` nor `RccExt::constrain` /
        // `freeze` sets RCC_APB1ENR1.PWREN (only `Rcc::unlock_rtc` does); unclocked, PWR_CR1
        // reads 0 and `current_vos` hits `unreachable!()`. RM0440 7.4 (RCC_APB1ENR1), 6.4.1
        // (PWR_CR1). The read back is the delay RM0440 asks for after a clock enable.
        dp.RCC
            .apb1enr1()
            .modify(|r, w| w.bits(r.bits() | RCC_APB1ENR1_PWREN));
        let _ = dp.RCC.apb1enr1().read().bits();
    }
    // The HAL's freeze handles only range 1 (normal or boost) → range 1 boost and has `todo!`
    // for the rest, and cannot stop a PLL that already clocks the core (its wait for PLLRDY to
    // clear would never end): check both before calling it (RM0440 6.1.5, 7.4.3 SWS).
    let vos = dp.PWR.cr1().read().bits() & PWR_CR1_VOS_MASK;
    let sws = dp.RCC.cfgr().read().bits() & RCC_CFGR_SWS_MASK;
    if vos != PWR_CR1_VOS_RANGE1 || sws == RCC_CFGR_SWS_PLL {
        return Err(BootError::PowerRange);
    }
    unsafe {
        // Flash: prefetch on (the HAL never sets PRFTEN; RM0440 3.3.4), and the 4 wait states
        // of 136–170 MHz in range 1 boost (RM0440 3.3.3, Table 9) set and read back *before*
        // the clock goes up, as RM0440 3.3.3 asks (the HAL's `configure_wait_states` writes
        // the same LATENCY but does not read it back). 4 wait states are valid at 16 MHz too.
        dp.FLASH.acr().modify(|r, w| {
            w.bits((r.bits() & !FLASH_ACR_LATENCY_MASK) | FLASH_ACR_LATENCY_4WS | FLASH_ACR_PRFTEN)
        });
    }
    let want = FLASH_ACR_LATENCY_4WS | FLASH_ACR_PRFTEN;
    if !spin_until(ACR_TIMEOUT, || {
        dp.FLASH.acr().read().bits() & (FLASH_ACR_LATENCY_MASK | FLASH_ACR_PRFTEN) == want
    }) {
        return Err(BootError::FlashLatency);
    }

    // HSE: the NUCLEO-G474RE's 24 MHz crystal X3 (not a bypass clock). The HAL's `enable_hse`
    // waits for HSERDY without a bound; start it here with a bounded wait (RM0440 7.2.1, HSE
    // clock) and hand it to the HAL only once it is ready. Otherwise switch it off again and
    // run the PLL from HSI16.
    unsafe {
        dp.RCC
            .cr()
            .modify(|r, w| w.bits((r.bits() & !RCC_CR_HSEBYP) | RCC_CR_HSEON));
    }
    let hse = spin_until(HSE_TIMEOUT, || {
        dp.RCC.cr().read().bits() & RCC_CR_HSERDY != 0
    });
    let (mux, m, src_bits, code) = if hse {
        // 24 MHz / 6 = 4 MHz PLL input.
        (
            PllSrc::HSE(HSE_HZ.Hz()),
            PllMDiv::DIV_6,
            RCC_PLLCFGR_SRC_HSE | (5 << 4),
            1,
        )
    } else {
        unsafe {
            dp.RCC.cr().modify(|r, w| w.bits(r.bits() & !RCC_CR_HSEON));
        }
        // 16 MHz / 4 = 4 MHz PLL input.
        (
            PllSrc::HSI,
            PllMDiv::DIV_4,
            RCC_PLLCFGR_SRC_HSI16 | (3 << 4),
            2,
        )
    };

    // PLL lock probe: the HAL's `config_pll` waits for PLLRDY without a bound. Lock the same
    // configuration (4 MHz × 85 / 2 = 170 MHz, RM0440 7.2.4 / 7.4.4 PLLCFGR) once here with a
    // bounded wait, switch it off again and let the HAL redo it: a PLL that locked from this
    // input will lock again.
    unsafe {
        dp.RCC
            .pllcfgr()
            .write(|w| w.bits(src_bits | RCC_PLLCFGR_N85 | RCC_PLLCFGR_REN_R2));
        dp.RCC.cr().modify(|r, w| w.bits(r.bits() | RCC_CR_PLLON));
    }
    let locked = spin_until(PLL_TIMEOUT, || {
        dp.RCC.cr().read().bits() & RCC_CR_PLLRDY != 0
    });
    unsafe {
        dp.RCC.cr().modify(|r, w| w.bits(r.bits() & !RCC_CR_PLLON));
    }
    if !locked {
        return Err(BootError::PllLock);
    }

    // The HAL: range 1 boost (R1MODE via the RM0440 6.1.5 sequence: AHB /2, boost, wait
    // states, switch, 1 µs, AHB /1), 4 wait states, PLL, SYSCLK switch.
    let pll = PllConfig {
        mux,
        m,
        n: PllNMul::MUL_85,
        r: Some(PllRDiv::DIV_2),
        q: None,
        p: None,
    };
    let pwr = dp
        .PWR
        .constrain()
        .vos(VoltageScale::Range1 { enable_boost: true })
        .freeze();
    let _rcc = dp
        .RCC
        .constrain()
        .freeze(Config::new(SysClockSrc::PLL).pll_cfg(pll), pwr);
    Ok(code)
}
