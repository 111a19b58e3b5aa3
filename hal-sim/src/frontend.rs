//! Layer 3: the analog front end.
//!
//! DAC (12 bit, `vref`) → drive amplifier (gain `drive_gain`, AC-coupled around mid-scale) →
//! two-pole reconstruction filter → PZT. The PZT current goes through a transimpedance
//! amplifier (`tia_ohm`) and a two-pole anti-alias filter to ADC channel 0; the PZT voltage,
//! divided by `monitor_gain`, through an identical anti-alias filter to ADC channel 1 (the drive
//! monitor). Both ADC channels are 12 bit on `vref`, centred at mid-scale, clipped at the rails.
//!
//! Noise is white current noise at the TIA input with one-sided density
//! `current_noise_a_rthz`; sampled at `fs` it is a Gaussian of standard deviation
//! `n * sqrt(fs / 2)` per sample. Mains interference adds a sum of harmonics of 50 or 60 Hz.

/// Mains interference at the TIA input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mains {
    /// Mains frequency in Hz (50 or 60).
    pub fundamental_hz: f64,
    /// Current amplitude (A) of harmonics 1..=8 of the fundamental.
    pub harmonic_amplitude_a: [f64; 8],
}

/// One of the two ADC channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdcChannel {
    /// Sense current (transimpedance amplifier output).
    Current,
    /// Drive monitor (divided PZT voltage).
    Monitor,
}

/// Fault: an ADC channel that reads one code whatever its input (a converter or its input
/// stage stuck at a rail).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StuckAdc {
    /// The channel.
    pub channel: AdcChannel,
    /// The code it reads.
    pub code: u16,
}

/// Front-end parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrontEnd {
    /// Sample rate of both DAC and ADC in Hz.
    pub sample_rate_hz: f64,
    /// Converter reference in V (both converters span 0..vref over 4096 codes).
    pub vref_v: f64,
    /// Drive amplifier gain (PZT volts per DAC volt).
    pub drive_gain: f64,
    /// Reconstruction filter corner in Hz (two real poles).
    pub reconstruction_hz: f64,
    /// Anti-alias filter corner in Hz (two real poles, both channels).
    pub antialias_hz: f64,
    /// Transimpedance gain in ohm.
    pub tia_ohm: f64,
    /// Drive monitor divider (ADC volts per PZT volt).
    pub monitor_gain: f64,
    /// White current noise density at the TIA input, A/sqrt(Hz).
    pub current_noise_a_rthz: f64,
    /// Optional mains interference.
    pub mains: Option<Mains>,
}

/// Number of converter codes (12 bit).
pub const CODES: f64 = 4096.0;
/// Largest code.
pub const MAX_CODE: u16 = 4095;
/// Mid-scale code.
pub const MID_CODE: u16 = 2048;

impl Default for FrontEnd {
    fn default() -> Self {
        Self {
            sample_rate_hz: 10_000.0,
            vref_v: 3.3,
            drive_gain: 5.0,
            reconstruction_hz: 1_000.0,
            antialias_hz: 1_000.0,
            tia_ohm: 300e3,
            monitor_gain: 0.15,
            current_noise_a_rthz: 0.0,
            mains: None,
        }
    }
}

impl FrontEnd {
    /// Sample period in s.
    pub fn dt(&self) -> f64 {
        1.0 / self.sample_rate_hz
    }
    /// PZT drive volts for a DAC code (before the reconstruction filter).
    pub fn drive_volts(&self, code: u16) -> f64 {
        let c = code.min(MAX_CODE) as f64;
        self.drive_gain * (c - MID_CODE as f64) * self.vref_v / CODES
    }
    /// Per-sample standard deviation (A) of the white current noise.
    pub fn noise_sigma_a(&self) -> f64 {
        self.current_noise_a_rthz * libm::sqrt(self.sample_rate_hz / 2.0)
    }
    /// Sense current (A) per ADC code.
    pub fn amps_per_code(&self) -> f64 {
        self.vref_v / CODES / self.tia_ohm
    }
    /// PZT volts per monitor ADC code.
    pub fn monitor_volts_per_code(&self) -> f64 {
        self.vref_v / CODES / self.monitor_gain
    }
    /// Quantise an ADC input voltage (relative to mid-scale) to a code, clipping at the rails.
    pub fn adc_code(&self, volts_from_mid: f64) -> u16 {
        let c = libm::round(volts_from_mid / self.vref_v * CODES) + MID_CODE as f64;
        if c.is_nan() || c < 0.0 {
            0
        } else if c > MAX_CODE as f64 {
            MAX_CODE
        } else {
            c as u16
        }
    }
}
