//! The flash interface (RM0440 "Embedded flash memory (FLASH)"; registers from stm32-metapac
//! `flash_g4c3`): ACR (latency, prefetch, caches), the KEYR unlock sequence, CR/SR, OPTR with
//! the bank mode, page erase and double-word programming of the array in dual-bank mode
//! (2 KiB pages, bank 2 at 0x0804_0000).
//!
//! Covers: LOCK and the key sequence (a wrong key locks CR until reset); PG programming of a
//! double word (two word writes, the first 8-byte aligned) with PROGERR (target not erased),
//! PGAERR (misaligned), SIZERR (not a word write), PGSERR (PG with PER, or a write without PG),
//! WRPERR never (no write protection configured); PER + BKER + PNB + STRT page erase; BSY for
//! the operation's duration (page erase 22 ms, double word 82 µs: RM0440/datasheet typical
//! programming times), EOP when EOPIE is set; the array keeps its contents across resets.
//! Leaves out: option byte programming (OPTSTRT, OBL_LAUNCH), mass erase, fast programming,
//! read protection, PCROP/WRP/securable areas, ECC, the ART caches' effect on timing, stalls of
//! reads of a bank being written, the flash interrupt.

/// Page size in dual-bank mode.
pub const PAGE: usize = 2048;
/// Bank size in dual-bank mode.
pub const BANK: usize = 256 * 1024;

/// Duration of a page erase, s (datasheet tERASE typical 22 ms).
pub const ERASE_S: f64 = 22e-3;
/// Duration of a double-word program, s (datasheet tPROG typical 82 µs).
pub const PROGRAM_S: f64 = 82e-6;

/// An operation in progress: it ends at `until` (seconds) with `result` to apply.
#[derive(Clone, Debug)]
struct Busy {
    until: f64,
    erase_page: Option<usize>,
    program: Option<(usize, u64)>,
}

/// The flash interface's registers and operation state.
#[derive(Clone, Debug)]
pub struct FlashIf {
    /// ACR.
    pub acr: u32,
    /// CR.
    pub cr: u32,
    /// SR (BSY derived).
    sr: u32,
    /// OPTR (option bytes as loaded: DBANK at bit 22).
    pub optr: u32,
    key_stage: u8,
    /// Locked until reset after a wrong key.
    key_error: bool,
    busy: Option<Busy>,
    /// First word of a double word being programmed: (offset, value).
    half: Option<(usize, u32)>,
    /// Bytes the CPU's store put into the read-only mapping that the model undoes: (offset,
    /// bytes the array must hold).
    restore: Vec<(usize, Vec<u8>)>,
    /// Fault injection: BSY never clears.
    pub stuck_busy: bool,
}

impl Default for FlashIf {
    fn default() -> Self {
        FlashIf {
            // ACR reset value 0x0000_0600: ICEN | DCEN.
            acr: 0x600,
            // CR: LOCK | OPTLOCK.
            cr: 0xC000_0000,
            sr: 0,
            // A G474RE as delivered: RDP level 0 (0xAA), DBANK = 1, nBOOT1 etc. set.
            optr: 0xFFEF_F8AA,
            key_stage: 0,
            key_error: false,
            busy: None,
            half: None,
            restore: Vec::new(),
            stuck_busy: false,
        }
    }
}

/// What a register write asks of the board: a rule violation to record.
pub type Note = Option<String>;

impl FlashIf {
    /// Reset of the interface (system reset): registers, not the array nor the option bytes.
    pub fn reset(&mut self) {
        let optr = self.optr;
        let stuck = self.stuck_busy;
        *self = FlashIf {
            optr,
            stuck_busy: stuck,
            ..FlashIf::default()
        };
    }

    /// Dual-bank mode (OPTR.DBANK).
    pub fn dual_bank(&self) -> bool {
        self.optr & (1 << 22) != 0
    }

    /// ACR.LATENCY.
    pub fn latency(&self) -> u32 {
        self.acr & 0xF
    }

    fn bsy(&self) -> bool {
        self.busy.is_some()
    }

    /// When the operation in progress ends, s.
    pub fn next_event(&self) -> Option<f64> {
        if self.stuck_busy {
            return None;
        }
        self.busy.as_ref().map(|b| b.until)
    }

    /// End the operation due by `t` (seconds), applying it to `array`.
    pub fn advance(&mut self, t: f64, array: &mut [u8]) {
        if self.stuck_busy {
            return;
        }
        if let Some(b) = &self.busy {
            if b.until <= t {
                let b = self.busy.take().unwrap();
                if let Some(p) = b.erase_page {
                    array[p * PAGE..(p + 1) * PAGE].fill(0xFF);
                }
                if let Some((off, v)) = b.program {
                    array[off..off + 8].copy_from_slice(&v.to_le_bytes());
                }
                if self.cr & (1 << 24) != 0 {
                    self.sr |= 1; // EOP
                }
            }
        }
    }

    /// Register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.acr,
            0x04 | 0x08 | 0x0C => 0,
            0x10 => self.sr | (self.bsy() as u32) << 16,
            0x14 => self.cr,
            0x18 => 0,
            0x20 => self.optr,
            0x24..=0x50 | 0x70 | 0x74 => 0,
            _ => return None,
        })
    }

    /// Register write at time `t` (seconds).
    pub fn write(&mut self, off: u32, v: u32, t: f64, array: &[u8]) -> Option<Note> {
        let _ = t;
        match off {
            0x00 => {
                // ICRST/DCRST only with the cache off (RM0440 FLASH_ACR): kept as written.
                self.acr = v & 0x0004_7F0F;
            }
            0x08 => {
                const KEY1: u32 = 0x4567_0123;
                const KEY2: u32 = 0xCDEF_89AB;
                match (self.key_stage, v) {
                    _ if self.key_error => {}
                    (0, KEY1) => self.key_stage = 1,
                    (1, KEY2) if self.cr & (1 << 31) != 0 => {
                        self.cr &= !(1 << 31);
                        self.key_stage = 0;
                    }
                    _ => {
                        self.key_error = true;
                        self.cr |= 1 << 31;
                        return Some(Some("FLASH_KEYR: wrong key sequence: CR locked until reset (RM0440 FLASH \"Unlocking the flash memory\")".into()));
                    }
                }
            }
            0x0C => {}
            0x10 => {
                // Error flags and EOP: write-one-to-clear.
                self.sr &= !(v & 0xC3FB);
            }
            0x14 => {
                if self.cr & (1 << 31) != 0 {
                    // Locked: only LOCK itself could be written, and it is set.
                    return Some(None);
                }
                if self.bsy() && v & 0xFFFF != self.cr & 0xFFFF {
                    return Some(Some("FLASH_CR changed while BSY (RM0440 FLASH: no CR change during an operation)".into()));
                }
                self.cr = v & 0xFF07_FFFF;
                if v & (1 << 16) != 0 {
                    // STRT: page erase.
                    self.cr &= !(1 << 16);
                    if self.cr & 2 != 0 && self.cr & 1 == 0 {
                        let bank = ((self.cr >> 11) & 1) as usize;
                        let pnb = ((self.cr >> 3) & 0x7F) as usize;
                        let page = bank * (BANK / PAGE) + pnb;
                        if self.bsy() {
                            self.sr |= 1 << 7; // PGSERR
                        } else {
                            self.busy = Some(Busy {
                                until: t + ERASE_S,
                                erase_page: Some(page),
                                program: None,
                            });
                        }
                    } else {
                        self.sr |= 1 << 7;
                    }
                }
            }
            0x18 | 0x20..=0x50 | 0x70 | 0x74 => {}
            _ => return None,
        }
        let _ = array;
        Some(None)
    }

    /// A CPU store of `size` bytes `value` to flash offset `off` at time `t`: a programming
    /// step or an error. The store itself is undone by [`FlashIf::take_restore`].
    pub fn cpu_store(&mut self, off: usize, size: usize, value: u32, t: f64, array: &[u8]) -> Note {
        self.restore.push((off, array[off..off + size].to_vec()));
        if self.cr & 1 == 0 || self.cr & 2 != 0 {
            self.sr |= 1 << 7; // PGSERR: a write without PG (or with PER)
            self.half = None;
            return Some(format!(
                "write to flash {off:#x} without FLASH_CR.PG (PGSERR)"
            ));
        }
        if size != 4 {
            self.sr |= 1 << 6; // SIZERR
            self.half = None;
            return Some(format!(
                "{size}-byte write to flash {off:#x} (SIZERR: words only)"
            ));
        }
        if self.bsy() {
            self.sr |= 1 << 7;
            return Some("flash write while BSY (PGSERR)".into());
        }
        match self.half.take() {
            None => {
                if !off.is_multiple_of(8) {
                    self.sr |= 1 << 5; // PGAERR
                    return Some(format!(
                        "double word at {off:#x} not 8-byte aligned (PGAERR)"
                    ));
                }
                self.half = Some((off, value));
            }
            Some((first, lo)) => {
                if off != first + 4 {
                    self.sr |= 1 << 5;
                    return Some(format!("second word at {off:#x} after {first:#x} (PGAERR)"));
                }
                let erased = array[first..first + 8].iter().all(|&b| b == 0xFF);
                let v = lo as u64 | (value as u64) << 32;
                if !erased && v != 0 {
                    self.sr |= 1 << 3; // PROGERR
                    return Some(format!(
                        "double word at {first:#x} programmed over non-erased data (PROGERR)"
                    ));
                }
                self.busy = Some(Busy {
                    until: t + PROGRAM_S,
                    erase_page: None,
                    program: Some((first, v)),
                });
            }
        }
        None
    }

    /// The bytes the CPU's stores overwrote in the read-only mapping, to put back.
    pub fn take_restore(&mut self) -> Vec<(usize, Vec<u8>)> {
        std::mem::take(&mut self.restore)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unlocked() -> FlashIf {
        let mut f = FlashIf::default();
        let a = vec![0xFF; 512 * 1024];
        f.write(0x08, 0x4567_0123, 0.0, &a).unwrap();
        f.write(0x08, 0xCDEF_89AB, 0.0, &a).unwrap();
        assert_eq!(f.read(0x14).unwrap() >> 31, 0, "unlocked");
        f
    }

    #[test]
    fn wrong_key_locks_until_reset() {
        let mut f = FlashIf::default();
        let a = vec![0xFF; 16];
        f.write(0x08, 0x1234_5678, 0.0, &a).unwrap().unwrap();
        f.write(0x08, 0x4567_0123, 0.0, &a).unwrap();
        f.write(0x08, 0xCDEF_89AB, 0.0, &a).unwrap();
        assert_eq!(f.read(0x14).unwrap() >> 31, 1);
        f.reset();
        let f2 = unlocked();
        assert_eq!(f2.read(0x14).unwrap() >> 31, 0);
    }

    #[test]
    fn double_word_programs_after_bsy_and_only_over_erased() {
        let mut f = unlocked();
        let mut a = vec![0xFF; 512 * 1024];
        f.write(0x14, 1 | (1 << 24), 0.0, &a).unwrap(); // PG, EOPIE
        let off = 0x7_F000;
        assert!(f.cpu_store(off, 4, 0x1122_3344, 0.0, &a).is_none());
        assert!(f.cpu_store(off + 4, 4, 0x5566_7788, 0.0, &a).is_none());
        assert_eq!(f.read(0x10).unwrap() >> 16 & 1, 1, "BSY");
        f.advance(PROGRAM_S / 2.0, &mut a);
        assert_eq!(a[off], 0xFF, "not yet");
        f.advance(PROGRAM_S, &mut a);
        assert_eq!(&a[off..off + 8], &0x5566_7788_1122_3344u64.to_le_bytes());
        assert_eq!(f.read(0x10).unwrap() & 0x1_0001, 1, "EOP, not BSY");
        // Programming over it again: PROGERR.
        assert!(f.cpu_store(off, 4, 0, 1.0, &a).is_none());
        assert!(f.cpu_store(off + 4, 4, 1, 1.0, &a).is_some());
        assert_ne!(f.read(0x10).unwrap() & (1 << 3), 0);
    }

    #[test]
    fn page_erase_of_bank_2() {
        let mut f = unlocked();
        let mut a = vec![0u8; 512 * 1024];
        // PER, BKER (bank 2), PNB 126 → 0x0807_F000.
        f.write(0x14, 2 | (1 << 11) | (126 << 3), 0.0, &a).unwrap();
        f.write(0x14, 2 | (1 << 11) | (126 << 3) | (1 << 16), 0.0, &a)
            .unwrap();
        f.advance(ERASE_S, &mut a);
        assert!(a[0x7_F000..0x7_F800].iter().all(|&b| b == 0xFF));
        assert!(a[0x7_F800..].iter().all(|&b| b == 0), "only that page");
        assert!(a[..0x7_F000].iter().all(|&b| b == 0));
    }
}
