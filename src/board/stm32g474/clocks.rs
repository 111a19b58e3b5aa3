//! The STM32 board's clocks: the 24 MHz HSE crystal (X3) under the clock security system,
//! started and probed with a bounded wait, else HSI16; the PLL through `embassy_stm32::init`
//! with the AHB at /2 (85 MHz); then the board's last step of RM0440's range 1 boost sequence
//! (HCLK to 170 MHz 1 µs after the switch) and the flash prefetch.
//!
//! embassy 0.6's `rcc::init` switches SYSCLK to the PLL and writes its `ahb_pre` in the same
//! RCC_CFGR write, so asked for /1 it never holds the AHB at /2 with the PLL applied, which
//! RM0440 6.1.5 (PWR "Dynamic voltage scaling management", range 1 boost, steps 1–5) asks for
//! 1 µs. Asked for /2 it switches at HCLK 85 MHz and leaves HPRE alone; [`full_speed`] then
//! raises the wait states, waits and sets /1. embassy records the clocks of its own
//! configuration: HCLK, PCLK1/2 and the APB timer clocks at half their value (SYSCLK and the
//! PLL's outputs are right). Nothing the board uses reads a halved record: LPUART1 and ADC12
//! take SYSCLK as their kernel clock ([`embassy_config`]), TIM6 is programmed from
//! [`TIM6_CLOCK_HZ`], DAC1's high-frequency interface mode is set from [`HCLK_HZ`], the IWDG
//! runs from LSI, SysTick and the cycle counter from [`SYSCLK_HZ`](super::SYSCLK_HZ).

use core::sync::atomic::{AtomicU8, Ordering};
use embassy_stm32::interrupt::Priority;
use embassy_stm32::pac;
use embassy_stm32::time::Hertz;

use super::reset::{during, record, Step};
use super::{device, spin_until, BootError, SYSCLK_HZ};

/// HSE crystal start-up, at HSI16: 100 ms (ST's HSE_STARTUP_TIMEOUT; typical start-up 2 ms).
const HSE_TIMEOUT: u32 = 16_000_000 / 10;
/// HSE frequency of the NUCLEO-G474RE's crystal X3.
const HSE_HZ: u32 = 24_000_000;
/// HCLK once [`full_speed`] ran: SYSCLK with the AHB prescaler at /1.
pub(super) const HCLK_HZ: u32 = SYSCLK_HZ;
/// TIM6's kernel clock: TIMPCLK1 = PCLK1 with the APB1 prescaler at /1 (RM0440 7.2 "Timer
/// clock"), PCLK1 = [`HCLK_HZ`] with APB1 at /1. embassy's record of it is halved: TIM6 is
/// programmed from this.
pub(super) const TIM6_CLOCK_HZ: u32 = HCLK_HZ;
/// How long the AHB stays at /2 after the switch to the PLL: 2 µs in cycles of the 85 MHz HCLK
/// it runs at then (RM0440 6.1.5 asks for at least 1 µs).
const BOOST_HOLD_CYCLES: u32 = 2 * (SYSCLK_HZ / 2 / 1_000_000);
/// Flash wait states at HCLK 170 MHz in range 1 boost (RM0440 3.3.3, Table 9: 4 WS above
/// 136 MHz).
const WAIT_STATES_170_MHZ: pac::flash::vals::Latency = pac::flash::vals::Latency::WS4;

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

/// `embassy_stm32::init` on `clock` and, with the PLL, [`full_speed`] (a boot step:
/// [`Step::Clock`]); the peripherals.
pub(super) fn start(clock: ClockSource) -> embassy_stm32::Peripherals {
    during(Step::Clock, || {
        let p = embassy_stm32::init(embassy_config(clock));
        if clock != ClockSource::Hsi16 {
            full_speed();
        }
        p
    })
}

/// The end of RM0440 6.1.5's range 1 boost sequence, after embassy switched SYSCLK to the PLL
/// with the AHB at /2 (HCLK 85 MHz, 2 wait states): the wait states for 170 MHz (3.3.3: raised,
/// and read back, before HCLK rises) with the prefetch, the AHB held at /2 for
/// [`BOOST_HOLD_CYCLES`] after the switch (step 5: at least 1 µs), then /1: HCLK 170 MHz.
///
/// The read-back of the wait states waits as embassy's own (`rcc/g4.rs`) does, without a
/// bound: inside [`Step::Clock`], a latency that never takes effect is a clock setup that hangs
/// (the watchdog resets, the next boot runs on HSI16 and says `clock_hang`).
fn full_speed() {
    // Gap: embassy 0.6 sets the wait states for the HCLK of its configuration only, and never
    // sets FLASH_ACR.PRFTEN. RAW 5/17: FLASH_ACR.LATENCY = 4 WS and PRFTEN (RM0440 3.3.3
    // Table 9, 3.3.4 prefetch; FLASH_ACR) in one read-modify-write.
    pac::FLASH.acr().modify(|w| {
        w.set_latency(WAIT_STATES_170_MHZ);
        w.set_prften(true);
    });
    // RAW 14/17: FLASH_ACR.LATENCY read back until it holds (RM0440 3.3.3).
    while pac::FLASH.acr().read().latency() != WAIT_STATES_170_MHZ {}
    // The hold, counted on the cycle counter from here: after the switch (embassy waited for
    // SWS = PLL before it returned).
    spin_until(BOOST_HOLD_CYCLES, || false);
    // Gap: embassy 0.6 writes SW and HPRE together. RAW 15/17: RCC_CFGR.HPRE = /1 (RM0440
    // 6.1.5 step 5; 7.4.3 RCC_CFGR).
    pac::RCC
        .cfgr()
        .modify(|w| w.set_hpre(pac::rcc::vals::Hpre::DIV1));
}

/// Start the HSE crystal with its clock security system and wait for it, bounded. embassy's
/// `rcc::init` (g4.rs) sets HSEON and then spins on HSERDY without a bound: it is given the HSE
/// only once it runs. embassy 0.6 has no CSS for the G4.
fn hse_starts() -> bool {
    // RAW 3/17: RCC_CR.HSEON and CSSON in one read-modify-write (RM0440 7.4.1 RCC_CR; 7.2
    // "HSE clock", "Clock security system (CSS)"). HSEBYP stays 0 (crystal). The clock detector
    // turns itself on once the HSE is ready and off when it is stopped: if the crystal does not
    // start, embassy's init (`hse: None`) clears HSEON again and the CSS never arms. A failure
    // later is the NMI (`NonMaskableInt`). embassy's own RCC_CR writes are read-modify-writes
    // of other fields: CSSON stays set.
    pac::RCC.cr().modify(|w| {
        w.set_hseon(true);
        w.set_csson(true);
    });
    // RAW 4/17: RCC_CR.HSERDY, polled with a bound (RM0440 7.4.1 RCC_CR).
    spin_until(HSE_TIMEOUT, || pac::RCC.cr().read().hserdy())
}

/// embassy's clock configuration: the PLL at 170 MHz (24 MHz / 6 or 16 MHz / 4 = 4 MHz × 85 / 2)
/// as SYSCLK with range 1 boost and the AHB at /2 ([`full_speed`] sets /1) — or HSI16 at
/// 16 MHz without the PLL, AHB /1 ([`ClockSource::Hsi16`], after a boot that hung in the clock
/// setup) —; SYSCLK as the kernel clock of ADC12 (embassy's default is none) and of LPUART1
/// (not PCLK1, whose record is halved).
fn embassy_config(clock: ClockSource) -> embassy_stm32::Config {
    use embassy_stm32::rcc::{
        mux, AHBPrescaler, Hse, HseMode, LsConfig, Pll, PllMul, PllPreDiv, PllRDiv, PllSource,
        Sysclk,
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
        rcc.ahb_pre = AHBPrescaler::DIV2;
    }
    // Nothing uses HSI48 (USB, RNG) or the RTC: no HSI48RDY or LSIRDY waits, no backup domain.
    rcc.hsi48 = None;
    rcc.ls = LsConfig::off();
    rcc.mux.adc12sel = mux::Adcsel::SYS;
    rcc.mux.lpuart1sel = mux::Uartsel::SYS;
    // embassy enables every DMA channel interrupt at this priority: the sample task's (RTIC
    // logical 3), so none preempts the sample interrupt.
    config.bdma_interrupt_priority = prio(3);
    config
}

/// The NVIC priority of RTIC logical priority `logical`.
fn prio(logical: u8) -> Priority {
    Priority::from(crate::board::nvic_priority(logical, device::NVIC_PRIO_BITS))
}
