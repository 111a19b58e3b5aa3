//! GPIO ports (RM0440 "General-purpose I/Os (GPIO)"; registers from stm32-metapac `gpio_v2`)
//! and the debug MCU block (RM0440 "Debug support (DBG)"; `dbgmcu_g4`).
//!
//! GPIO covers: the register file with the reset values of RM0440 (port A's SWD pins in AF,
//! pulls), BSRR set/reset of ODR, IDR from ODR for outputs and from the pull or the level a
//! device wired to the pin drives (`Wiring::gpio_inputs`) for inputs; the outputs' levels go to
//! the wiring (`Wiring::gpio_outputs`). Leaves out: open-drain outputs (OTYPER stored; an
//! output drives both levels), speed/drive effects, the lock sequence
//! (LCKR stored), alternate-function signal routing (AFR stored; the peripherals do not look at
//! the pins' modes), analog switches, EXTI.
//! DBGMCU covers the ID code (DEV_ID 0x469, the G47x/G48x) and the freeze registers as storage.

/// One GPIO port.
#[derive(Clone, Debug)]
pub struct Gpio {
    /// MODER.
    pub moder: u32,
    otyper: u32,
    ospeedr: u32,
    /// PUPDR.
    pub pupdr: u32,
    /// ODR.
    pub odr: u32,
    lckr: u32,
    afr: [u32; 2],
    /// Levels driven onto pins from outside (pin mask, levels).
    pub external: (u32, u32),
}

impl Gpio {
    /// Port `n` (0 = A) at reset.
    pub fn new(n: usize) -> Gpio {
        let (moder, ospeedr, pupdr) = match n {
            0 => (0xABFF_FFFF, 0x0C00_0000, 0x6400_0000),
            1 => (0xFFFF_FEBF, 0, 0x0000_0100),
            _ => (0xFFFF_FFFF, 0, 0),
        };
        Gpio {
            moder,
            otyper: 0,
            ospeedr,
            pupdr,
            odr: 0,
            lckr: 0,
            afr: [0; 2],
            external: (0, 0),
        }
    }

    /// The pins in output mode (MODER = 01) and the levels they drive (ODR): (mask, levels).
    pub fn outputs(&self) -> (u32, u32) {
        let mask = (0..16).fold(0, |m, pin| {
            m | (((self.moder >> (2 * pin)) & 3 == 1) as u32) << pin
        });
        (mask, self.odr & mask)
    }

    /// Input data: outputs read their ODR, inputs an external level, else their pull
    /// (pull-up 1, pull-down or floating 0).
    pub fn idr(&self) -> u32 {
        (0..16).fold(0, |v, pin| {
            let mode = (self.moder >> (2 * pin)) & 3;
            let pull = (self.pupdr >> (2 * pin)) & 3;
            let level = if mode == 1 {
                self.odr >> pin & 1
            } else if self.external.0 & (1 << pin) != 0 {
                self.external.1 >> pin & 1
            } else {
                (pull == 1) as u32
            };
            v | level << pin
        })
    }

    /// Register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.moder,
            0x04 => self.otyper,
            0x08 => self.ospeedr,
            0x0C => self.pupdr,
            0x10 => self.idr(),
            0x14 => self.odr,
            0x18 => 0,
            0x1C => self.lckr,
            0x20 => self.afr[0],
            0x24 => self.afr[1],
            0x28 => 0,
            _ => return None,
        })
    }

    /// Register write.
    pub fn write(&mut self, off: u32, v: u32) -> Option<()> {
        match off {
            0x00 => self.moder = v,
            0x04 => self.otyper = v & 0xFFFF,
            0x08 => self.ospeedr = v,
            0x0C => self.pupdr = v,
            0x10 => {}
            0x14 => self.odr = v & 0xFFFF,
            0x18 => self.odr = (self.odr | (v & 0xFFFF)) & !(v >> 16),
            0x1C => self.lckr = v,
            0x20 => self.afr[0] = v,
            0x24 => self.afr[1] = v,
            // BRR: reset bits.
            0x28 => self.odr &= !(v & 0xFFFF),
            _ => return None,
        }
        Some(())
    }
}

/// DBGMCU.
#[derive(Clone, Debug, Default)]
pub struct Dbgmcu {
    regs: [u32; 5],
}

impl Dbgmcu {
    /// Register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        match off {
            // IDCODE: REV_ID 0x2000 (rev. Y), DEV_ID 0x469.
            0x0 => Some(0x2000_0469),
            0x4..=0x10 => Some(self.regs[(off / 4) as usize]),
            _ => None,
        }
    }

    /// Register write.
    pub fn write(&mut self, off: u32, v: u32) -> Option<()> {
        match off {
            0x0 => Some(()),
            0x4..=0x10 => {
                self.regs[(off / 4) as usize] = v;
                Some(())
            }
            _ => None,
        }
    }
}
