//! # pzt-probe: firmware core of the resonant PZT hardness probe
//!
//! The portable part of the firmware: `no_std`, allocation-free, bounded in memory and free of
//! panics on any input. It holds the driver traits the hardware (or `hal-sim`) implements, the
//! sample-rate DSP the interrupt runs, the resonance estimators, the calibration and the
//! measurement state machine. The RTIC application (`src/bin/probe.rs`) and all MCU code sit
//! behind `cfg(target_os = "none")`.
//!
//! Data flow of one reading: [`reading::Procedure`] → [`engine::PointPlan`] →
//! [`engine::SampleEngine`] (DDS → DAC, ADC → exact sine-fit sums) →
//! [`engine::sweep::point_from_raw`] (admittance per point) → estimator ([`estimate`]) →
//! [`reading::pipeline`] (force window, contact, calibration) → [`reading::Reading`].
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// An enum whose variants each have a stable snake_case code and a one-line message, from one
/// table: the enum, then `ALL` (every variant, in declaration order), `code`, `message` and
/// `from_code` (the inverse of `code`), each after its own doc comment; and a test that the
/// codes round-trip and are unique.
macro_rules! coded_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident $(= $disc:literal)?: $code:literal => $message:literal;)*
        }
        $(#[$all_meta:meta])* const ALL;
        $(#[$code_meta:meta])* fn code;
        $(#[$message_meta:meta])* fn message;
    ) => {
        $(#[$meta])*
        pub enum $name {
            $($(#[$vmeta])* $variant $(= $disc)?,)*
        }

        impl $name {
            $(#[$all_meta])*
            pub const ALL: [$name; [$($code),*].len()] = [$($name::$variant),*];

            $(#[$code_meta])*
            pub const fn code(self) -> &'static str {
                match self {
                    $($name::$variant => $code,)*
                }
            }

            $(#[$message_meta])*
            pub const fn message(self) -> &'static str {
                match self {
                    $($name::$variant => $message,)*
                }
            }

            /// Parse a [`code`](Self::code).
            pub fn from_code(s: &str) -> Option<$name> {
                Self::ALL.into_iter().find(|e| e.code() == s)
            }
        }

        // The table's own test (one coded enum per module): every code parses back to its
        // variant and no two are the same, every message says something, and what is not a
        // code parses to nothing.
        #[cfg(test)]
        mod coded_enum_tests {
            use super::$name;

            #[test]
            fn codes_round_trip_and_are_unique() {
                for (i, a) in $name::ALL.iter().enumerate() {
                    assert_eq!($name::from_code(a.code()), Some(*a));
                    assert!(!a.message().is_empty(), "{a:?}");
                    for b in &$name::ALL[i + 1..] {
                        assert_ne!(a.code(), b.code());
                    }
                }
                assert_eq!($name::from_code("not a code"), None);
            }
        }
    };
}

// Layers, each importing only from those above it in this list (tests/layers.rs keeps the rule;
// docs/architecture.md draws it):
// leaves (units, status, counters, stack, boot, hal, linalg, loadcell, dsp) → engine → estimate
// → unit → reading → instrument → board.
pub mod boot;
pub mod counters;
pub mod dsp;
pub mod hal;
pub mod linalg;
pub mod loadcell;
pub mod stack;
pub mod status;
pub mod units;

pub mod board;
pub mod engine;
pub mod estimate;
pub mod instrument;
pub mod reading;
pub mod unit;

pub use reading::{Method, Reading, SweepMeasurement};
pub use status::{Failure, Status};
pub use unit::calibration::PowerLaw;
pub use unit::profile::{AirReference, UnitProfile};
pub use units::{AdcCode, DacCode, Farads, Hz, KPa, Newtons, Seconds, Siemens, Volts};
