//! # hal-sim: the simulated resonant PZT hardness probe
//!
//! Host-side (and `no_std`, for the QEMU image) simulated hardware of the probe. It offers the
//! physics in layers, and every scene uses the least it needs:
//!
//! 1. [`tissue`]: the Kelvin model of paper 003 (eq. 1–2) — probe `m, k1, c1` plus the tissue's
//!    `k_m, c_m, m_m` from the appendix contact formulas with a Hertz contact radius;
//! 2. [`pzt`]: PZT electromechanics — static capacitance `C0`, force factor `alpha` (force per
//!    volt = charge per metre), optional dielectric leakage;
//! 3. [`frontend`]: the analog front end — DAC and drive amplifier with a reconstruction filter,
//!    transimpedance amplifier, anti-alias filters, 12-bit ADC quantisation and clipping, white
//!    current noise, optional mains interference.
//!
//! Scenes may add a second mechanical mode (a second motional branch, [`tissue::SecondMode`]) and
//! change during a reading ([`events`]: lift-off, thermal drift of the probe's own resonance,
//! knocks).
//!
//! The linear plant is discretised exactly ([`plant`]: matrix exponential of the continuous
//! state-space model with a zero-order-hold DAC), so one step per sample is exact, not a tiny Euler
//! step. Every random draw comes from a seeded generator (`probe_rng`, the project's one); a scene and a seed give the
//! same samples on every machine.
//!
//! The fitted constants and the reasoning behind them are in `docs/physics.md`.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod catalogue;
pub mod complex;
pub mod events;
pub mod flash;
pub mod frontend;
pub mod linalg;
pub mod loadcell;
pub mod lump;
pub mod phantoms;
pub mod plant;
pub mod probe;
pub mod pzt;
pub mod scenes;
pub mod tissue;

pub use complex::C64;
pub use events::{Drift, ForceChange, Knocks, LiftOff, Step};
pub use frontend::{AdcChannel, FrontEnd, Mains, StuckAdc};
pub use phantoms::Phantom;
pub use probe::{AdcPair, SimProbe};
pub use pzt::Pzt;
pub use scenes::{Fault, Layer, NoiseScene, Scene};
pub use tissue::{Contact, Kelvin, SecondMode, SensorMech, Tissue};
