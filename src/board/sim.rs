//! The simulated probe (`hal-sim`) behind the driver traits.

use crate::hal::{AdcFrame, FrontEndScale, SampleStream, StreamError};
use crate::units::{AdcCode, DacCode, Hz};
use hal_sim::{AdcPair, SimProbe};

/// Largest batch the adapter takes in one call.
pub const MAX_BATCH: usize = 256;

/// A [`SampleStream`] backed by a [`SimProbe`]: the DAC batch plays and is captured in the same
/// call (latency 0).
#[derive(Clone, Debug)]
pub struct SimBoard {
    /// The simulated hardware.
    pub probe: SimProbe,
}

impl SimBoard {
    /// Wrap a simulated probe.
    pub fn new(probe: SimProbe) -> Self {
        Self { probe }
    }
}

/// Scale of a simulated front end.
pub fn scale_of(fe: &hal_sim::FrontEnd) -> FrontEndScale {
    FrontEndScale {
        sample_rate: Hz(fe.sample_rate_hz as f32),
        drive_volts_per_code: (fe.drive_gain * fe.vref_v / hal_sim::frontend::CODES) as f32,
        amps_per_code: fe.amps_per_code() as f32,
        monitor_volts_per_code: fe.monitor_volts_per_code() as f32,
    }
}

impl SampleStream for SimBoard {
    fn exchange(&mut self, dac: &[DacCode], adc: &mut [AdcFrame]) -> Result<(), StreamError> {
        if dac.len() != adc.len() || dac.len() > MAX_BATCH {
            return Err(StreamError::BatchSize);
        }
        let mut codes = [0u16; MAX_BATCH];
        let mut pairs = [AdcPair::default(); MAX_BATCH];
        let n = dac.len();
        for (c, d) in codes.iter_mut().zip(dac) {
            *c = d.0;
        }
        self.probe.exchange(&codes[..n], &mut pairs[..n]);
        for (a, p) in adc.iter_mut().zip(&pairs[..n]) {
            *a = AdcFrame {
                current: AdcCode(p.current),
                monitor: AdcCode(p.monitor),
            };
        }
        Ok(())
    }

    fn latency_batches(&self) -> usize {
        0
    }

    fn scale(&self) -> FrontEndScale {
        scale_of(self.probe.front_end())
    }
}
