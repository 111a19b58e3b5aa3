//! The STM32G474RE board (NUCLEO-G474RE) on `embassy-stm32` 0.6: clocks, TIM6, DAC1, ADC1/ADC2
//! on DMA ring buffers, the bank-2 flash of the calibration store, LPUART1 and the independent
//! watchdog are embassy drivers, used from RTIC 2 tasks without an embassy executor. Raw
//! register code remains only where embassy 0.6 lacks the feature: seventeen accesses, each
//! marked `RAW n/17` with the gap and the RM0440 section, listed in `docs/bringup.md`. The
//! HSE runs under the clock security system (CSSON with HSEON in one access); its NMI resets
//! the core into a boot on HSI16 through the PLL ([`BootError::HseFailure`]).
//!
//! # Bring-up ([`init`])
//!
//! The cycle counter first (it times the bounded waits); the IWDG, frozen under the debugger,
//! started before any of embassy's own waits (several have no bound: `docs/bringup.md`), with
//! the step in progress kept in RAM a reset does not clear (`Step`): a step that hangs ends in
//! a watchdog reset, and the next boot goes around it with a typed [`BootError`]
//! (`clock_hang`: HSI16 at 16 MHz, no stream; `converter_hang`: no stream; `flash_hang`: no
//! store) instead of hanging again. Then the 24 MHz HSE crystal (X3), started and probed here
//! with a bounded wait (embassy's `rcc::init` waits for HSERDY without a bound, so it is handed
//! the HSE only once it is known to run; otherwise the PLL runs from HSI16 and
//! [`clock_source`] says so); `embassy_stm32::init` (PWR and FLASH clocked and reset, range 1
//! boost, the PLL at 170 MHz with the AHB at /2, ADC12 and LPUART1 kernel clocks = SYSCLK, DMA
//! interrupt priority); the last step of the boost sequence (4 wait states, prefetch, 1 µs, AHB
//! /1: HCLK 170 MHz); the option bytes' bank mode (embassy's `Flash::new_blocking` panics on a
//! mismatch: checked first, [`BootError::FlashSingleBank`]); the converters; LPUART1 receive
//! on a DMA ring and transmit by DMA. A failed step records a [`BootError`] (the first is kept, [`boot_error`]) and
//! the board carries on degraded. Unverified on hardware.
//!
//! # Parts
//!
//! | module | what |
//! |---|---|
//! | `reset` | the first boot error, the boot-step marker a reset leaves, the reset cause, the CSS's NMI |
//! | `clocks` | HSE or HSI16, the PLL at 170 MHz and the boost switch, the flash prefetch ([`clock_source`]) |
//! | `interrupts` | DMA1 and LPUART1 bindings, the DMA transfer-error count |
//! | `analog` | the sample stream: TIM6, DAC1, ADC1/ADC2 on DMA1 ([`Stream`], [`stream_faults`]) |
//! | `store` | the store's bank-2 flash ([`InternalFlash`], [`STORE_BASE`]) |
//! | `uart` | LPUART1: receive ([`Uart`]), the host link's transmit queue and DMA ([`link_send`], [`LinkTx`]) |
//! | `watchdog` | the IWDG ([`Watchdog`]) |
//! | `loadcell` | the HX711 on PB4/PB5 ([`LoadCell`]) |
//!
//! Pins: PA0 sense current (TIA output), PA1 drive monitor, PA4 DAC out to the drive amplifier,
//! PA3 LPUART1 RX (AF12) from and PA2 LPUART1 TX (AF12) to the ST-LINK virtual COM port, PB4 (Arduino D5) the load cell's
//! HX711 `DOUT` (input, pull-up), PB5 (D4) its `PD_SCK` (push-pull output).

mod analog;
mod clocks;
mod interrupts;
mod loadcell;
mod reset;
mod store;
mod uart;
mod watchdog;

pub use analog::{stream_faults, Stream, StreamFaults};
pub use clocks::{clock_name, clock_source, ClockSource};
pub use loadcell::{CycleDelay, LoadCell};
pub use reset::boot_error;
pub use store::{FlashError, InternalFlash, StoreFlash, STORE_BASE};
pub use uart::{link_send, LinkTx, Uart};
pub use watchdog::Watchdog;

use crate::hal::FrontEndScale;
use crate::units::Hz;
use reset::{interrupted_step, reset_cause, Step};

// The image's defmt global logger (RTT).
use defmt_rtt as _;

/// The image's panic handler: say so over defmt, then stop for good ([`stop`]). Where it
/// panicked is the backtrace's to show: RTT, which carries the log, needs the debug probe that
/// shows it (probe-rs prints it at the fault), and without one the watchdog resets the core and
/// the boot reports the reset's cause. Logging the location (or the message) too would keep
/// every panic site's location in the image (docs/firmware.md).
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: the backtrace shows where");
    stop()
}

/// `defmt::panic!` and its kin have logged their message already: stop for good without a
/// second line.
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    stop()
}

/// A permanent fault: interrupts off, UsageFault disabled (SHCSR.USGFAULTENA, bit 18; ARMv7-M
/// ARM B3.2.13) so that the undefined instruction `udf` escalates to HardFault (B1.5.8), where a
/// debugger stops and the image never returns.
fn stop() -> ! {
    cortex_m::interrupt::disable();
    // SAFETY: a read-modify-write of one SCB register with interrupts off, on the way to a
    // fault that never returns.
    unsafe {
        (*cortex_m::peripheral::SCB::PTR)
            .shcsr
            .modify(|r| r & !(1 << 18));
    }
    cortex_m::asm::udf()
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
/// same front end `hal_sim::FrontEnd::default()` simulates ([`FrontEndScale::PROBE`]).
pub const SCALE: FrontEndScale = FrontEndScale {
    sample_rate: Hz(SAMPLE_RATE_HZ as f32),
    ..FrontEndScale::PROBE
};

/// The board's converter scale.
pub fn scale() -> FrontEndScale {
    SCALE
}

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

/// A bring-up step that failed (portable, so the session's handling of it is tested on the
/// host). The board carries on degraded; [`boot_error`] holds the first.
pub use crate::boot::BootError;

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

/// The board's parts, as the application takes them over (the independent watchdog running).
pub type Parts = super::Parts<Stream, Watchdog, StoreFlash, Uart, LinkTx, LoadCell>;

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
    let watchdog = watchdog::start(safe_clock);

    let p = clocks::start(clocks::choose(safe_clock, hse_failed));
    let flash = store::open(p.FLASH, interrupted == Some(Step::Flash));

    // The converters: not on HSI16 alone (readings are refused after a clock hang), not after
    // a boot that hung setting them up.
    let hw = if safe_clock {
        None
    } else if interrupted == Some(Step::Converters) {
        reset::record(BootError::ConverterHang);
        None
    } else {
        Some(reset::during(Step::Converters, || {
            analog::converters(analog::ConverterPins {
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
            })
        }))
    };

    let (uart, link_tx) = uart::open(p.LPUART1, p.PA3, p.PA2, p.DMA1_CH4, p.DMA1_CH6);
    let load_cell = loadcell::open(p.PB4, p.PB5);

    Parts {
        load_cell,
        stream: Stream::new(hw),
        watchdog,
        flash,
        uart,
        link_tx,
    }
}
