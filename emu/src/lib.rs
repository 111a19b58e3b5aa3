//! # stm32-emu: an emulated NUCLEO-G474RE at register level
//!
//! Runs the unmodified STM32 image (`cargo fw`) from its reset vector on unicorn's Cortex-M4 CPU,
//! with the system control space ([`cortex`]) and the peripherals ([`periph`]) modelled from
//! RM0440 and the register definitions stm32-metapac is generated from; the defmt log is read
//! from the image's RTT up-buffer in emulated RAM ([`rtt`]), as probe-rs reads it.
//!
//! This crate links unicorn (GPL-2.0) and is GPL-2.0-or-later, unlike the rest of the
//! workspace: it is a program of its own that the tests and the bench run as a subprocess;
//! nothing in the firmware or the bench links it (README.md).

pub mod cortex;
pub mod elf;
pub mod machine;
pub mod periph;
pub mod probe;
pub mod rtt;

pub use machine::{Exit, Machine};

use std::fmt;

/// What keeps the emulator from running an image, in words.
#[derive(Debug)]
pub enum Error {
    /// A malformed or unsupported ELF file.
    Elf(String),
    /// A failure to set the machine up.
    Setup(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Elf(m) => write!(f, "ELF: {m}"),
            Error::Setup(m) => write!(f, "{m}"),
        }
    }
}

impl std::error::Error for Error {}
