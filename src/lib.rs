//! # pzt-probe: firmware core of the resonant PZT hardness probe
//!
//! The portable part of the firmware: `no_std`, allocation-free, bounded in memory and free of
//! panics on any input. It holds the driver traits the hardware (or `hal-sim`) implements, the
//! sample-rate DSP the interrupt runs, the resonance estimators, the calibration and the
//! measurement state machine. The RTIC application (`src/bin/probe.rs`) and all MCU code sit
//! behind `cfg(target_os = "none")`.
//!
//! Data flow of one reading: [`measure::SweepMeasurement`] → [`engine::PointPlan`] →
//! [`engine::SampleEngine`] (DDS → DAC, ADC → exact sine-fit sums) → [`sweep::point_from_raw`]
//! (admittance per point) → estimator ([`estimate`]) → [`calibration::PowerLaw::invert`] →
//! [`measure::Reading`].
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod board;
pub mod boot;
pub mod calibration;
pub mod command;
pub mod contact_law;
pub mod counters;
pub mod dsp;
pub mod engine;
pub mod estimate;
pub mod hal;
pub mod linalg;
pub mod loadcell;
#[cfg(feature = "defmt")]
pub mod log;
pub mod measure;
pub mod pipeline;
pub mod profile;
pub mod reading;
pub mod runner;
pub mod selftest;
pub mod session;
pub mod stack;
pub mod status;
pub mod store;
pub mod stream;
pub mod sweep;
pub mod units;
pub mod watchdog;

pub use calibration::PowerLaw;
pub use measure::{Method, Reading, SweepMeasurement};
pub use profile::{AirReference, UnitProfile};
pub use status::{Failure, Status};
pub use units::{AdcCode, DacCode, Farads, Hz, KPa, Newtons, Seconds, Siemens, Volts};
