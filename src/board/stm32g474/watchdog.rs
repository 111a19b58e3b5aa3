//! The STM32 board's independent watchdog (IWDG), fed by the guard task.

use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{pac, peripherals};

/// Watchdog timeout, µs.
const WATCHDOG_US: u32 = 500_000;

/// The independent watchdog (LSI): 500 ms timeout, fed by the guard task while the measurement
/// task keeps its liveness promise; frozen while a debugger halts the core.
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

/// Freeze the IWDG under the debugger, then start it: 500 ms, or eleven times that when the
/// core runs on HSI16 without the PLL (`safe_clock`).
pub(super) fn start(safe_clock: bool) -> Watchdog {
    // Gap: embassy 0.6 has no DBGMCU API. RAW 8/17: DBGMCU_APB1FZR1.DBG_IWDG_STOP (RM0440
    // "Debug support (DBG)" chapter, DBGMCU_APB1FZR1; its number unverified:
    // docs/bringup.md), before the IWDG starts.
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
    Watchdog(wdg)
}
