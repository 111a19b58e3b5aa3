//! Boards: the glue between the driver traits and real or simulated hardware.

#[cfg(feature = "sim")]
pub mod sim;
