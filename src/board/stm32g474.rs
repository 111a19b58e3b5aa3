//! The STM32G474RE board (NUCLEO-G474RE): clocks from `stm32g4xx-hal`, and a small
//! register-level driver for what the HAL lacks — the timer-triggered DAC/ADC sample stream
//! with circular DMA — plus the internal-flash driver of the calibration store and the
//! LPUART1 receive path.
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
//! Pins: PA0 sense current (TIA output), PA1 drive monitor, PA4 DAC out to the drive amplifier,
//! PA2/PA3 LPUART1 TX/RX (AF12) to the ST-LINK virtual COM port.

use crate::engine::SampleEngine;
use crate::hal::{AdcFrame, FrontEndScale};
use crate::runner::BATCH;
use crate::units::{AdcCode, DacCode, Hz};
use core::ptr::{addr_of_mut, read_volatile, write_volatile};
use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};
use stm32g4xx_hal::independent_watchdog::IndependentWatchdog;
use stm32g4xx_hal::pwr::{PwrExt, VoltageScale};
use stm32g4xx_hal::rcc::{
    Config, PllConfig, PllMDiv, PllNMul, PllRDiv, PllSrc, RccExt, SysClockSrc,
};
use stm32g4xx_hal::time::ExtU32;

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
/// the linker's FLASH region (`memory/stm32g474re.x`), so a firmware update keeps it.
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

// ---- register map (RM0440) --------------------------------------------------------------

const RCC_AHB1ENR_DMA1EN: u32 = 1 << 0;
const RCC_AHB1ENR_DMAMUX1EN: u32 = 1 << 2;
const RCC_AHB2ENR_GPIOAEN: u32 = 1 << 0;
const RCC_AHB2ENR_ADC12EN: u32 = 1 << 13;
const RCC_AHB2ENR_DAC1EN: u32 = 1 << 16;
const RCC_APB1ENR1_TIM6EN: u32 = 1 << 4;
const RCC_APB1ENR2_LPUART1EN: u32 = 1 << 0;

const TIM_CR1_CEN: u32 = 1 << 0;
const TIM_CR2_MMS_UPDATE: u32 = 0b010 << 4;
const TIM_EGR_UG: u32 = 1 << 0;

const DAC_CR_EN1: u32 = 1 << 0;
const DAC_CR_TEN1: u32 = 1 << 1;
const DAC_CR_TSEL1_TIM6: u32 = 7 << 2;
const DAC_CR_DMAEN1: u32 = 1 << 12;
const DAC_MCR_HFSEL_160: u32 = 0b10 << 14;

const ADC_CR_ADEN: u32 = 1 << 0;
const ADC_CR_ADSTART: u32 = 1 << 2;
const ADC_CR_ADVREGEN: u32 = 1 << 28;
const ADC_CR_DEEPPWD: u32 = 1 << 29;
const ADC_CR_ADCAL: u32 = 1 << 31;
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
const DMA_IFCR_CGIF1: u32 = 1 << 0;

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
        }
    }

    /// Prefill both DAC halves from `engine`, configure the converters and DMA and start the
    /// trigger timer. Called once from `init` with interrupts disabled.
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
            adc.cr().write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADCAL));
            while adc.cr().read().bits() & ADC_CR_ADCAL != 0 {}
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
            adc.cr().write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADEN));
            while adc.isr().read().bits() & ADC_ISR_ADRDY == 0 {}
            adc.cr()
                .write(|w| w.bits(ADC_CR_ADVREGEN | ADC_CR_ADEN | ADC_CR_ADSTART));
            debug_assert_eq!(adc.cr().read().bits() & ADC_CR_DEEPPWD, 0);

            // Go: every TIM6 update now plays one DAC code and converts one frame.
            tim.cr1().write(|w| w.bits(TIM_CR1_CEN));
        }
    }

    /// Acknowledge the DMA half/full-transfer interrupt; returns the ADC half just captured
    /// (de-interleaved into frames) and the DAC half just played (to refill).
    pub fn capture(&mut self) -> (&[AdcFrame], &mut [DacCode]) {
        let dp = pac();
        let flags = dp.DMA1.isr().read().bits();
        // SAFETY: write-one-to-clear of channel 1's flags.
        unsafe { dp.DMA1.ifcr().write(|w| w.bits(DMA_IFCR_CGIF1)) };
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
    /// before the handler finished.
    pub fn late(&self) -> bool {
        let flags = pac().DMA1.isr().read().bits();
        self.late_seen || flags & (DMA_ISR_HTIF1 | DMA_ISR_TCIF1) != 0
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

/// The independent watchdog (LSI): 500 ms timeout, fed by the measurement task while alive.
pub struct Watchdog(IndependentWatchdog);

impl Watchdog {
    /// Feed the watchdog.
    pub fn feed(&mut self) {
        self.0.feed();
    }
}

/// Errors of the internal flash driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Bad alignment or range.
    Args(NorFlashErrorKind),
    /// The controller reported an error (FLASH_SR bits).
    Controller(u32),
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Args(k) => *k,
            FlashError::Controller(_) => NorFlashErrorKind::Other,
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

/// The internal flash as a NOR flash (dual-bank mode, the reset default of the STM32G474RE:
/// 2 KiB pages, 8-byte double-word programming). Offsets count from 0x0800_0000. The store
/// lives in bank 2 while the code runs from bank 1, so erasing and programming do not stall
/// the sample interrupt (read-while-write across banks).
pub struct InternalFlash(());

impl InternalFlash {
    fn wait() -> Result<(), FlashError> {
        let dp = pac();
        while dp.FLASH.sr().read().bits() & FLASH_SR_BSY != 0 {}
        let sr = dp.FLASH.sr().read().bits();
        // SAFETY: write-one-to-clear of the status flags.
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

    fn unlocked<T>(f: impl FnOnce() -> Result<T, FlashError>) -> Result<T, FlashError> {
        let dp = pac();
        // SAFETY: the documented unlock sequence, then CR is restored to locked.
        unsafe {
            if dp.FLASH.cr().read().bits() & FLASH_CR_LOCK != 0 {
                dp.FLASH.keyr().write(|w| w.bits(FLASH_KEY1));
                dp.FLASH.keyr().write(|w| w.bits(FLASH_KEY2));
            }
        }
        let r = Self::wait().and_then(|_| f());
        // SAFETY: lock again.
        unsafe { dp.FLASH.cr().write(|w| w.bits(FLASH_CR_LOCK)) };
        r
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
            Self::unlocked(|| {
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
                Self::wait()
            })?;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_write(self, offset, bytes.len())?;
        Self::unlocked(|| {
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
                Self::wait()?;
            }
            Ok(())
        })
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

/// Set the board up: 170 MHz from HSI16 through the PLL (range 1 boost), cycle counter, UART,
/// watchdog. Call once, from `init`.
pub fn init(core: &mut cortex_m::Peripherals) -> Parts {
    let dp = pac();
    let pll = PllConfig {
        mux: PllSrc::HSI,
        m: PllMDiv::DIV_4,
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
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();
    let mut iwdg = IndependentWatchdog::new(dp.IWDG);
    iwdg.start(500.millis());
    Parts {
        stream: Stream::new(),
        watchdog: Watchdog(iwdg),
        flash: InternalFlash(()),
        uart: Uart::new(),
    }
}
