//! A simulated NOR flash with fault injection, behind the `embedded-storage` traits.
//!
//! It behaves like the STM32G4's program flash where it matters to a record store:
//!
//! * erase sets whole sectors to `0xFF`; program can only clear bits, and (like the STM32's
//!   `PROGERR`) programming a word that is not erased is refused with [`SimFlashError::NotErased`];
//! * reads, writes and erases are checked for alignment and bounds.
//!
//! Faults a test can inject:
//!
//! * [`SimFlash::cut_power_after_program`]: power is lost after `n` more bytes have been
//!   programmed; the write in progress stops there (the bytes before the cut are programmed,
//!   the rest of the write keeps its old, erased content) and every later operation fails with
//!   [`SimFlashError::PowerLoss`] until [`SimFlash::power_cycle`];
//! * [`SimFlash::cut_power_after_erase`]: the same for erasing (an interrupted erase leaves the
//!   sector partly erased, partly old data);
//! * [`SimFlash::flip_bit`]: a bit of the stored content inverts (retention error, disturbance).

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

/// Errors of the simulated flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimFlashError {
    /// Offset or length not a multiple of the access size.
    NotAligned,
    /// Access beyond the capacity.
    OutOfBounds,
    /// Programming a location that is not erased.
    NotErased,
    /// The (simulated) power failed during or before this operation.
    PowerLoss,
}

impl NorFlashError for SimFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            SimFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            SimFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            SimFlashError::NotErased | SimFlashError::PowerLoss => NorFlashErrorKind::Other,
        }
    }
}

impl From<NorFlashErrorKind> for SimFlashError {
    fn from(k: NorFlashErrorKind) -> Self {
        match k {
            NorFlashErrorKind::NotAligned => SimFlashError::NotAligned,
            _ => SimFlashError::OutOfBounds,
        }
    }
}

/// A simulated NOR flash of `CAP` bytes, erase sectors of `ERASE` bytes and program words of
/// `WRITE` bytes (defaults: 4 KiB, 2 KiB sectors, 8-byte double words as on the STM32G474).
#[derive(Clone, Debug)]
pub struct SimFlash<const CAP: usize = 4096, const ERASE: usize = 2048, const WRITE: usize = 8> {
    data: [u8; CAP],
    program_budget: Option<usize>,
    erase_budget: Option<usize>,
    dead: bool,
    programmed_bytes: u64,
    erased_sectors: u64,
}

impl<const CAP: usize, const ERASE: usize, const WRITE: usize> Default
    for SimFlash<CAP, ERASE, WRITE>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize, const ERASE: usize, const WRITE: usize> SimFlash<CAP, ERASE, WRITE> {
    /// A fully erased flash.
    pub const fn new() -> Self {
        Self {
            data: [0xFF; CAP],
            program_budget: None,
            erase_budget: None,
            dead: false,
            programmed_bytes: 0,
            erased_sectors: 0,
        }
    }

    /// The raw content.
    pub fn contents(&self) -> &[u8] {
        &self.data
    }

    /// Lose power once `n` more bytes have been programmed (0: before the next byte).
    pub fn cut_power_after_program(&mut self, n: usize) {
        self.program_budget = Some(n);
    }

    /// Lose power once `n` more bytes have been erased (0: before the next byte).
    pub fn cut_power_after_erase(&mut self, n: usize) {
        self.erase_budget = Some(n);
    }

    /// Restore power: clears pending faults and the power-loss state; content is kept.
    pub fn power_cycle(&mut self) {
        self.program_budget = None;
        self.erase_budget = None;
        self.dead = false;
    }

    /// True after a simulated power loss, until [`power_cycle`](Self::power_cycle).
    pub fn lost_power(&self) -> bool {
        self.dead
    }

    /// Invert bit `bit` (0..8) of the byte at `offset`; out-of-range arguments are ignored.
    pub fn flip_bit(&mut self, offset: usize, bit: u8) {
        if let Some(b) = self.data.get_mut(offset) {
            *b ^= 1u8 << (bit & 7);
        }
    }

    /// Bytes programmed since creation (wear and cost accounting).
    pub fn programmed_bytes(&self) -> u64 {
        self.programmed_bytes
    }

    /// Sectors erased since creation.
    pub fn erased_sectors(&self) -> u64 {
        self.erased_sectors
    }
}

/// One more byte out of a power-loss `budget` (none: no fault pending); at zero the power is
/// lost (`dead`) before the byte.
fn spend(budget: &mut Option<usize>, dead: &mut bool) -> Result<(), SimFlashError> {
    if let Some(left) = budget.as_mut() {
        if *left == 0 {
            *dead = true;
            return Err(SimFlashError::PowerLoss);
        }
        *left -= 1;
    }
    Ok(())
}

impl<const CAP: usize, const ERASE: usize, const WRITE: usize> ErrorType
    for SimFlash<CAP, ERASE, WRITE>
{
    type Error = SimFlashError;
}

impl<const CAP: usize, const ERASE: usize, const WRITE: usize> ReadNorFlash
    for SimFlash<CAP, ERASE, WRITE>
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), SimFlashError> {
        if self.dead {
            return Err(SimFlashError::PowerLoss);
        }
        check_read(self, offset, bytes.len())?;
        let o = offset as usize;
        bytes.copy_from_slice(&self.data[o..o + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        CAP
    }
}

impl<const CAP: usize, const ERASE: usize, const WRITE: usize> NorFlash
    for SimFlash<CAP, ERASE, WRITE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), SimFlashError> {
        if self.dead {
            return Err(SimFlashError::PowerLoss);
        }
        check_erase(self, from, to)?;
        for sector in (from as usize..to as usize).step_by(ERASE) {
            for b in &mut self.data[sector..sector + ERASE] {
                spend(&mut self.erase_budget, &mut self.dead)?;
                *b = 0xFF;
            }
            self.erased_sectors += 1;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SimFlashError> {
        if self.dead {
            return Err(SimFlashError::PowerLoss);
        }
        check_write(self, offset, bytes.len())?;
        let o = offset as usize;
        if self.data[o..o + bytes.len()].iter().any(|&b| b != 0xFF) {
            return Err(SimFlashError::NotErased);
        }
        for (dst, src) in self.data[o..o + bytes.len()].iter_mut().zip(bytes) {
            spend(&mut self.program_budget, &mut self.dead)?;
            *dst &= *src;
            self.programmed_bytes += 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nor_semantics_and_faults() {
        let mut f: SimFlash<4096, 2048, 8> = SimFlash::new();
        assert_eq!(f.write(3, &[0; 8]), Err(SimFlashError::NotAligned));
        assert_eq!(f.write(4096, &[0; 8]), Err(SimFlashError::OutOfBounds));
        f.write(0, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        assert_eq!(f.write(0, &[0; 8]), Err(SimFlashError::NotErased));
        let mut b = [0u8; 8];
        f.read(0, &mut b).unwrap();
        assert_eq!(b, [1, 2, 3, 4, 5, 6, 7, 8]);
        f.flip_bit(0, 1);
        f.read(0, &mut b).unwrap();
        assert_eq!(b[0], 3);
        f.cut_power_after_program(3);
        assert_eq!(f.write(8, &[0; 8]), Err(SimFlashError::PowerLoss));
        assert!(f.lost_power());
        assert_eq!(f.read(0, &mut b), Err(SimFlashError::PowerLoss));
        f.power_cycle();
        f.read(8, &mut b).unwrap();
        assert_eq!(b, [0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);
        f.cut_power_after_erase(10);
        assert_eq!(f.erase(0, 2048), Err(SimFlashError::PowerLoss));
        f.power_cycle();
        f.read(8, &mut b).unwrap();
        assert_eq!(b, [0xFF, 0xFF, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);
        f.erase(0, 2048).unwrap();
        f.read(8, &mut b).unwrap();
        assert_eq!(b, [0xFF; 8]);
        assert_eq!(f.erase(0, 100), Err(SimFlashError::NotAligned));
    }
}
