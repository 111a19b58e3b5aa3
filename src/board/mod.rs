//! Boards: the glue between the driver traits and real or simulated hardware.

#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "sim")]
pub mod sim_factory;
#[cfg(feature = "sim")]
pub mod sim_script;

#[cfg(all(target_os = "none", feature = "qemu"))]
pub mod qemu;
#[cfg(all(target_os = "none", feature = "stm32"))]
pub mod stm32g474;
