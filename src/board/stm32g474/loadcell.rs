//! The STM32 board's load cell: the firmware's HX711 driver on two GPIO pins.

use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::{peripherals, Peri};

use super::SYSCLK_HZ;

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
pub type LoadCell = crate::loadcell::Hx711<CycleDelay, Input<'static>, Output<'static>>;

/// The load cell on PB4 and PB5 (`None` when its pins cannot be driven).
pub(super) fn open(
    pb4: Peri<'static, peripherals::PB4>,
    pb5: Peri<'static, peripherals::PB5>,
) -> Option<LoadCell> {
    // The load cell's pins: DOUT with a pull-up (the HX711 drives it; a missing chip reads
    // "not ready"), PD_SCK low (the chip converts).
    crate::loadcell::Hx711::new(
        CycleDelay,
        Input::new(pb4, Pull::Up),
        Output::new(pb5, Level::Low, Speed::Low),
    )
    .ok()
}
