//! The STM32 board's flash for the calibration store: the last two 2 KiB pages of bank 2,
//! through embassy's blocking driver on the whole flash ([`InternalFlash`]).

use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::{pac, peripherals, Peri};
use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

use super::reset::{during, record, Step};
use super::BootError;

/// Start of the calibration store: the last two 2 KiB pages of bank 2 (0x0807_F000), outside
/// the linker's FLASH region (bank 1 in the root `memory.x`, which names the store's pages
/// `_pzt_store_start`/`_pzt_store_end`; `tests/memory_map.rs` checks they agree), so a firmware
/// update keeps it.
pub const STORE_BASE: u32 = 0x7_F000;
/// The store's flash.
pub type StoreFlash = InternalFlash;

/// Errors of the internal flash driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// Bad alignment or range.
    Args(NorFlashErrorKind),
    /// The controller reported an error (embassy's reading of FLASH_SR).
    Controller(embassy_stm32::flash::Error),
    /// The flash is in single-bank mode (FLASH_OPTR.DBANK = 0): every access refused.
    SingleBank,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Args(k) => *k,
            FlashError::Controller(_) | FlashError::SingleBank => NorFlashErrorKind::Other,
        }
    }
}

impl From<NorFlashErrorKind> for FlashError {
    fn from(k: NorFlashErrorKind) -> Self {
        FlashError::Args(k)
    }
}

const FLASH_SIZE: usize = 512 * 1024;
const FLASH_PAGE: usize = 2048;

/// The internal flash as a NOR flash: embassy's blocking driver on the whole flash (dual-bank
/// mode, 2 KiB pages, 8-byte double words); offsets count from 0x0800_0000. The store lives in
/// bank 2 while the code runs from bank 1 (read-while-write).
///
/// embassy's `Flash<Blocking>` methods (`blocking_erase`, `blocking_write`) run without a
/// critical section — unlike its region drivers' blocking methods, which keep interrupts off
/// for the whole ~20 ms page erase and would overrun the sample stream — so the sample
/// interrupt keeps running while the measurement task erases or programs. embassy clears stale
/// FLASH_SR flags before each operation and, on the G4, turns the data cache off around it and
/// resets it (DCRST) before turning it back on (`flash/g.rs`).
pub struct InternalFlash(Option<Flash<'static, Blocking>>);

impl InternalFlash {
    fn flash(&mut self) -> Result<&mut Flash<'static, Blocking>, FlashError> {
        self.0.as_mut().ok_or(FlashError::SingleBank)
    }
}

impl ErrorType for InternalFlash {
    type Error = FlashError;
}

impl ReadNorFlash for InternalFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_read(self, offset, bytes.len())?;
        self.flash()?
            .blocking_read(offset, bytes)
            .map_err(FlashError::Controller)
    }

    fn capacity(&self) -> usize {
        FLASH_SIZE
    }
}

impl NorFlash for InternalFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = FLASH_PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_erase(self, from, to)?;
        let flash = self.flash()?;
        during(Step::Flash, || flash.blocking_erase(from, to)).map_err(FlashError::Controller)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_write(self, offset, bytes.len())?;
        let flash = self.flash()?;
        during(Step::Flash, || flash.blocking_write(offset, bytes)).map_err(FlashError::Controller)
    }
}

/// The flash for this boot: none after a boot that hung erasing or programming it (`hung`,
/// [`BootError::FlashHang`]) or in single-bank mode ([`BootError::FlashSingleBank`]); every
/// access to it is then refused.
pub(super) fn open(flash: Peri<'static, peripherals::FLASH>, hung: bool) -> InternalFlash {
    // Gap: embassy's `Flash::new_blocking` panics when FLASH_OPTR.DBANK does not match its
    // `dual-bank` feature (flash/g.rs `check_bank_setup`). RAW 6/17: DBANK read first
    // (RM0440 3.3.1 "Flash memory organization"; FLASH_OPTR), a typed boot error instead.
    InternalFlash(if hung {
        record(BootError::FlashHang);
        None
    } else if pac::FLASH.optr().read().dbank() {
        Some(Flash::new_blocking(flash))
    } else {
        record(BootError::FlashSingleBank);
        None
    })
}
