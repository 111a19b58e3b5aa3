//! Boot errors: a bring-up step of the board that failed, as the session and the log name it.
//!
//! The STM32 board (`src/board/stm32g474/`) records the first one ([`BootError`] is its
//! type); the session refuses what the failed step makes impossible with the step's name and
//! message ([`crate::instrument::session::Refusal::Boot`]) and shows it in `status`. Portable, so the
//! session's handling is tested on the host.

coded_enum! {
    /// A bring-up step that failed. The board carries on degraded.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    #[repr(u8)]
    pub enum BootError {
        /// FLASH_OPTR.DBANK is 0 (single-bank mode, 4 KiB pages): the store's flash driver is not
        /// created (embassy's `Flash::new_blocking` would panic) and every store access is refused.
        FlashSingleBank = 1: "flash_single_bank" => "boot: flash in single-bank mode (option byte DBANK = 0): calibration store disabled, set DBANK";
        /// LPUART1 did not take its configuration: no command line.
        Uart: "uart" => "boot: the host UART refused its configuration";
        /// The DAC's circular DMA transfer did not start: the sample stream is not started.
        DacStart: "dac_start" => "boot: the DAC's DMA transfer did not start: no drive, readings impossible; power-cycle";
        /// The DAC output buffer calibration found no trim (CAL_FLAG1 never rose): the DAC is not
        /// trusted with the drive and the sample stream is not started.
        DacCalibration: "dac_calibration" => "boot: DAC output buffer calibration failed: no drive, readings impossible; power-cycle, then service";
        /// The boot before did not get through embassy's clock setup (its waits on HSIRDY, PLLRDY,
        /// the flash latency and the clock switch have no bound; the watchdog ended it): this boot
        /// runs on HSI16 at 16 MHz without the PLL and does not start the sample stream.
        ClockHang: "clock_hang" => "boot: the clock setup hung on the boot before: running on HSI16 without converters, readings impossible; power-cycle";
        /// The boot before did not get through the converters' setup (embassy's ADC calibration and
        /// ready waits): TIM6, DAC1 and the ADCs are left alone, the stream is not started.
        ConverterHang: "converter_hang" => "boot: the ADC/DAC setup hung on the boot before: converters off, readings impossible; power-cycle";
        /// The run before hung in a flash erase or program (embassy's waits on FLASH_SR.BSY): the
        /// store's flash is not used this boot.
        FlashHang: "flash_hang" => "boot: a flash erase or program hung on the run before: calibration store disabled until reset";
        /// The HSE crystal did not start within its bound (RM0440 RCC_CR.HSERDY), or failed while
        /// the image ran (the clock security system switched the core to HSI16 and its NMI reset
        /// the core): this boot runs from HSI16 through the PLL (170 MHz at RC accuracy, about
        /// ±1 % over temperature) and does not start the HSE again.
        HseFailure: "hse_failure" => "boot: the 24 MHz crystal did not start or failed while running: running on the internal RC oscillator, frequencies carry its error; check the crystal";
    }
    /// Every boot error, in declaration order.
    const ALL;
    /// Stable snake_case code for the log and the command line.
    fn code;
    /// One line for a human: what failed, what it costs, what to do.
    fn message;
}

impl BootError {
    /// Whether the failed step leaves the board without its sample stream: every reading (and
    /// the self-test) is impossible and refused with this error.
    pub const fn blocks_readings(self) -> bool {
        matches!(
            self,
            BootError::DacStart
                | BootError::DacCalibration
                | BootError::ClockHang
                | BootError::ConverterHang
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beyond the `coded_enum!` table's own test: every message names the boot, and the
    /// discriminants count from 1.
    #[test]
    fn messages_say_boot_and_zero_is_no_error() {
        for (i, a) in BootError::ALL.iter().enumerate() {
            assert!(a.message().starts_with("boot: "), "{a:?}");
            assert_eq!(*a as u8, i as u8 + 1, "0 stays 'no error' on the board");
        }
        assert_eq!(BootError::from_code("none"), None);
    }

    #[test]
    fn only_the_steps_that_leave_no_stream_block_readings() {
        let blocking: Vec<_> = BootError::ALL
            .into_iter()
            .filter(|e| e.blocks_readings())
            .map(BootError::code)
            .collect();
        assert_eq!(
            blocking,
            [
                "dac_start",
                "dac_calibration",
                "clock_hang",
                "converter_hang"
            ]
        );
    }
}
