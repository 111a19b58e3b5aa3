//! The little of ELF32 (little-endian, ARM) the emulator needs: the `PT_LOAD` segments at their
//! physical (load) addresses — the bytes a flash programmer writes — and symbol addresses.
//!
//! Leaves out: relocations, section flags, anything but 32-bit little-endian files.

use crate::Error;

/// A loadable segment: `data` goes at physical address `paddr`.
#[derive(Clone, Debug)]
pub struct Segment {
    /// Physical (load) address, `p_paddr`: for `.data` its image in flash, not its run address.
    pub paddr: u32,
    /// The file's bytes of the segment (`p_filesz`; the rest of `p_memsz` is the start-up
    /// code's to zero, not the programmer's).
    pub data: Vec<u8>,
}

/// An ELF file's loadable segments and symbol table.
#[derive(Clone, Debug)]
pub struct Elf {
    /// `PT_LOAD` segments with file contents.
    pub segments: Vec<Segment>,
    symbols: Vec<(String, u32)>,
}

fn u16_at(b: &[u8], o: usize) -> Result<u16, Error> {
    b.get(o..o + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or_else(|| Error::Elf(format!("truncated at {o:#x}")))
}

fn u32_at(b: &[u8], o: usize) -> Result<u32, Error> {
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| Error::Elf(format!("truncated at {o:#x}")))
}

impl Elf {
    /// Parse an ELF32 little-endian file.
    pub fn parse(b: &[u8]) -> Result<Elf, Error> {
        if b.len() < 52 || &b[..4] != b"\x7fELF" {
            return Err(Error::Elf("not an ELF file".into()));
        }
        if b[4] != 1 || b[5] != 1 {
            return Err(Error::Elf("not ELF32 little-endian".into()));
        }
        let phoff = u32_at(b, 28)? as usize;
        let shoff = u32_at(b, 32)? as usize;
        let phentsize = u16_at(b, 42)? as usize;
        let phnum = u16_at(b, 44)? as usize;
        let shentsize = u16_at(b, 46)? as usize;
        let shnum = u16_at(b, 48)? as usize;

        let mut segments = Vec::new();
        for i in 0..phnum {
            let p = phoff + i * phentsize;
            const PT_LOAD: u32 = 1;
            if u32_at(b, p)? != PT_LOAD {
                continue;
            }
            let offset = u32_at(b, p + 4)? as usize;
            let paddr = u32_at(b, p + 12)?;
            let filesz = u32_at(b, p + 16)? as usize;
            if filesz == 0 {
                continue;
            }
            let data = b
                .get(offset..offset + filesz)
                .ok_or_else(|| Error::Elf(format!("segment {i} beyond the file")))?
                .to_vec();
            segments.push(Segment { paddr, data });
        }

        let mut symbols = Vec::new();
        for i in 0..shnum {
            let s = shoff + i * shentsize;
            const SHT_SYMTAB: u32 = 2;
            if u32_at(b, s + 4)? != SHT_SYMTAB {
                continue;
            }
            let off = u32_at(b, s + 16)? as usize;
            let size = u32_at(b, s + 20)? as usize;
            let link = u32_at(b, s + 24)? as usize;
            let entsize = (u32_at(b, s + 36)? as usize).max(16);
            let strsec = shoff + link * shentsize;
            let stroff = u32_at(b, strsec + 16)? as usize;
            for k in 0..size / entsize {
                let e = off + k * entsize;
                let name_off = u32_at(b, e)? as usize;
                let value = u32_at(b, e + 4)?;
                let start = stroff + name_off;
                let end = b[start..]
                    .iter()
                    .position(|&c| c == 0)
                    .map(|n| start + n)
                    .ok_or_else(|| Error::Elf("unterminated symbol name".into()))?;
                if end > start {
                    symbols.push((String::from_utf8_lossy(&b[start..end]).into_owned(), value));
                }
            }
        }
        Ok(Elf { segments, symbols })
    }

    /// An image of raw segments (no symbols): hand-made test programs.
    pub fn from_segments(segments: Vec<Segment>) -> Elf {
        Elf {
            segments,
            symbols: Vec::new(),
        }
    }

    /// The address of symbol `name`, if the file has one.
    pub fn symbol(&self, name: &str) -> Option<u32> {
        self.symbols
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| *v)
    }
}
