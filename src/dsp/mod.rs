//! Sample-rate signal processing: the sine synthesiser and the synchronous demodulator.
//!
//! Both run in the sample interrupt, in integer arithmetic only; the per-point solve that turns
//! the demodulator's sums into a phasor runs at low priority in f64.

pub mod dds;
pub mod lockin;
pub mod trig;
