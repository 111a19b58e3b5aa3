//! The instrument: the session (commands, state), the command parser, the power-on self-test,
//! the continuous mode, the measurement task apart from RTIC, the other tasks' decisions apart
//! from RTIC (`tasks`: the sample batch, the UART receive, the host link's receive loop), the
//! watchdog's rules and the defmt log lines. May import every layer below it (reading, unit,
//! estimate, engine, leaves); never a board.

pub mod command;
pub mod continuous;
pub mod link;
#[cfg(feature = "defmt")]
pub mod log;
pub mod measure;
pub mod selftest;
pub mod session;
pub mod tasks;
pub mod watchdog;
