//! Driver traits: what the measurement core needs from the hardware (or from `hal-sim`).
//!
//! The probe streams: the DAC plays one [`DacCode`] per sample period and the ADC converts one
//! [`AdcFrame`] (sense current + drive monitor) per sample period, both at
//! [`FrontEndScale::sample_rate`]. Streams move in batches; on the STM32 a batch is one half of a
//! circular DMA buffer, in `hal-sim` a call of the plant.

use crate::units::{AdcCode, DacCode, Hz};

/// One ADC conversion pair.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcFrame {
    /// Sense current (transimpedance amplifier output).
    pub current: AdcCode,
    /// Drive monitor (divided PZT voltage).
    pub monitor: AdcCode,
}

/// Errors a sample stream can report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamError {
    /// The DAC and ADC batches have different lengths or exceed the driver's batch size.
    BatchSize,
    /// The batch came too late: samples were lost (DMA overrun).
    Overrun,
}

/// A synchronous DAC/ADC sample stream.
pub trait SampleStream {
    /// Queue `dac` as the next batch to play and fill `adc` with the frames captured during the
    /// batch queued [`latency_batches`](Self::latency_batches) calls earlier: `Ok(true)`, or
    /// `Ok(false)` while the first batches fill the pipeline (nothing has played yet; `adc` is
    /// untouched).
    fn exchange(&mut self, dac: &[DacCode], adc: &mut [AdcFrame]) -> Result<bool, StreamError>;
    /// Calls between queueing a DAC batch and receiving the ADC frames captured while it played.
    fn latency_batches(&self) -> usize;
    /// Scale of the converters and amplifiers.
    fn scale(&self) -> FrontEndScale;
}

/// Conversion of codes to physical units for one board.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrontEndScale {
    /// DAC and ADC sample rate.
    pub sample_rate: Hz,
    /// PZT drive volts per DAC code (after the drive amplifier).
    pub drive_volts_per_code: f32,
    /// Sense current in amperes per ADC code.
    pub amps_per_code: f32,
    /// PZT volts per drive-monitor ADC code.
    pub monitor_volts_per_code: f32,
    /// Corner of the reconstruction filter between the DAC and the PZT (two real poles).
    pub reconstruction_corner: Hz,
    /// Corner of the anti-alias filters before both ADC channels (two real poles each).
    pub antialias_corner: Hz,
}

impl FrontEndScale {
    /// The probe's front end (the STM32 board's): 12-bit DAC and ADC on a 3.3 V reference at
    /// 10 kHz, drive amplifier gain 5, transimpedance 300 kΩ, drive-monitor divider 0.15,
    /// reconstruction and anti-alias filters of two real poles at 1 kHz — the
    /// front end `hal_sim::FrontEnd::default()` simulates (`board::sim` tests that they agree).
    pub const PROBE: FrontEndScale = FrontEndScale {
        sample_rate: Hz(10_000.0),
        drive_volts_per_code: 5.0 * 3.3 / 4096.0,
        amps_per_code: 3.3 / 4096.0 / 300e3,
        monitor_volts_per_code: 3.3 / 4096.0 / 0.15,
        reconstruction_corner: Hz(1_000.0),
        antialias_corner: Hz(1_000.0),
    };

    /// Largest drive amplitude in codes (mid-scale to rail).
    pub const MAX_AMPLITUDE_CODES: u16 = 2047;

    /// Largest drive amplitude in volts.
    pub fn max_drive_volts(&self) -> f32 {
        self.drive_volts_per_code * Self::MAX_AMPLITUDE_CODES as f32
    }
}

/// A monotonic time base.
pub trait TimeBase {
    /// Seconds since an arbitrary epoch.
    fn now(&self) -> crate::units::Seconds;
}
