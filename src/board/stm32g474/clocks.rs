//! The STM32 board's clocks: the 24 MHz HSE crystal (X3) under the clock security system,
//! started and probed with a bounded wait, else HSI16; the PLL at 170 MHz through
//! `embassy_stm32::init`; the flash prefetch.

use core::sync::atomic::{AtomicU8, Ordering};
use embassy_stm32::interrupt::Priority;
use embassy_stm32::pac;
use embassy_stm32::time::Hertz;

use super::reset::{during, record, Step};
use super::{device, spin_until, BootError};

/// HSE crystal start-up, at HSI16: 100 ms (ST's HSE_STARTUP_TIMEOUT; typical start-up 2 ms).
const HSE_TIMEOUT: u32 = 16_000_000 / 10;
/// HSE frequency of the NUCLEO-G474RE's crystal X3.
const HSE_HZ: u32 = 24_000_000;

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

/// The oscillator the core runs from (set by [`init`](super::init)).
pub fn clock_source() -> ClockSource {
    match CLOCK.load(Ordering::Relaxed) {
        1 => ClockSource::Hse24,
        2 => ClockSource::Hsi16Pll,
        _ => ClockSource::Hsi16,
    }
}

/// The oscillator for this boot: HSI16 alone after a boot that hung in the clock setup
/// (`safe`, [`BootError::ClockHang`]), HSI16 through the PLL after the HSE failed on the run
/// before (`hse_failed`) or does not start now (both [`BootError::HseFailure`]), else the HSE.
/// Records the boot error and the choice ([`clock_source`]).
pub(super) fn choose(safe: bool, hse_failed: bool) -> ClockSource {
    let clock = if safe {
        record(BootError::ClockHang);
        ClockSource::Hsi16
    } else if hse_failed {
        record(BootError::HseFailure);
        ClockSource::Hsi16Pll
    } else if hse_starts() {
        ClockSource::Hse24
    } else {
        // The crystal did not start within its bound: the same fallback as after a failure
        // while running, and the user is told the same way.
        record(BootError::HseFailure);
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
    clock
}

/// `embassy_stm32::init` on `clock` (a boot step: [`Step::Clock`]), then the flash prefetch;
/// the peripherals.
pub(super) fn start(clock: ClockSource) -> embassy_stm32::Peripherals {
    let p = during(Step::Clock, || embassy_stm32::init(embassy_config(clock)));

    // Gap: embassy 0.6 never sets FLASH_ACR.PRFTEN. RAW 5/13: prefetch on (RM0440 3.3.4
    // ART accelerator / prefetch; FLASH_ACR), after embassy set the wait states.
    pac::FLASH.acr().modify(|w| w.set_prften(true));
    p
}

/// Start the HSE crystal with its clock security system and wait for it, bounded. embassy's
/// `rcc::init` (g4.rs) sets HSEON and then spins on HSERDY without a bound: it is given the HSE
/// only once it runs. embassy 0.6 has no CSS for the G4.
fn hse_starts() -> bool {
    // RAW 3/13: RCC_CR.HSEON and CSSON in one read-modify-write (RM0440 7.4.1 RCC_CR; 7.2
    // "HSE clock", "Clock security system (CSS)"). HSEBYP stays 0 (crystal). The clock detector
    // turns itself on once the HSE is ready and off when it is stopped: if the crystal does not
    // start, embassy's init (`hse: None`) clears HSEON again and the CSS never arms. A failure
    // later is the NMI (`NonMaskableInt`). embassy's own RCC_CR writes are read-modify-writes
    // of other fields: CSSON stays set.
    pac::RCC.cr().modify(|w| {
        w.set_hseon(true);
        w.set_csson(true);
    });
    // RAW 4/13: RCC_CR.HSERDY, polled with a bound (RM0440 7.4.1 RCC_CR).
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
    Priority::from(crate::board::nvic_priority(logical, device::NVIC_PRIO_BITS))
}
