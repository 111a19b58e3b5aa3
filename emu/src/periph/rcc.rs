//! RCC (RM0440 "Reset and clock control (RCC)"; registers from stm32-metapac `rcc_g4`) and PWR
//! (RM0440 "Power control (PWR)"; `pwr_g4`).
//!
//! RCC covers: HSI16/HSE/PLL/LSI/HSI48/LSE enables with their ready flags (ready at once, or
//! never for an oscillator the board's fault injection removes), SW → SWS, the AHB/APB
//! prescalers, the main PLL's R output, the peripheral clock enables and resets, CCIPR kernel
//! clock selections (ADC12 and LPUART1 derived), CSR's reset flags, the CSS enable. It derives
//! HCLK and PCLK1 for the time base.
//! Leaves out: oscillator start-up times (ready at once), HSI/HSE trimming, the PLL's P and Q
//! outputs' frequencies, MCO, the CSS detector itself (an HSE failure is a fault to inject, not
//! modelled yet), low-power modes, the backup domain beyond LSE flags, the clock recovery
//! system.
//!
//! PWR covers VOS (range 1/2) and R1MODE (boost) with VOSF clear (the regulator settles at
//! once), as register values the clock rules read. Leaves out: the regulator's timing, low-power
//! modes, wake-up pins, PVD/PVM, pull-up/down control beyond storing it.

/// Kernel/bus clock frequencies derived from the RCC's configuration, Hz.
pub type SysClock = f64;

/// HSI16, Hz.
pub const HSI_HZ: f64 = 16e6;
/// The NUCLEO-G474RE's HSE crystal (X3), Hz.
pub const HSE_HZ: f64 = 24e6;

/// A peripheral clock enable register (RM0440 7.4: RCC_AHB1ENR … RCC_APB2ENR), in the order
/// of [`Rcc::enr`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Enr {
    /// AHB1ENR (DMA1, DMAMUX1, FLASH).
    Ahb1,
    /// AHB2ENR (GPIO, ADC12, DAC1).
    Ahb2,
    /// AHB3ENR.
    Ahb3,
    /// APB1ENR1 (TIM6, PWR).
    Apb1r1,
    /// APB1ENR2 (LPUART1).
    Apb1r2,
    /// APB2ENR (SYSCFG).
    Apb2,
}

impl Enr {
    /// Every enable register, in the order of [`Rcc::enr`].
    pub const ALL: [Enr; 6] = [
        Enr::Ahb1,
        Enr::Ahb2,
        Enr::Ahb3,
        Enr::Apb1r1,
        Enr::Apb1r2,
        Enr::Apb2,
    ];

    /// The register's offset in RCC.
    pub fn offset(self) -> u32 {
        [0x48, 0x4C, 0x50, 0x58, 0x5C, 0x60][self as usize]
    }

    /// The enable register at offset `off`, if it is one.
    pub fn at(off: u32) -> Option<Enr> {
        Self::ALL.into_iter().find(|r| r.offset() == off)
    }
}

/// The RCC's registers.
#[derive(Clone, Debug)]
pub struct Rcc {
    /// CR.
    pub cr: u32,
    /// ICSCR.
    pub icscr: u32,
    /// CFGR (SWS derived on read).
    pub cfgr: u32,
    /// PLLCFGR.
    pub pllcfgr: u32,
    /// CIER.
    pub cier: u32,
    /// Reset registers AHB1/2/3, APB1R1/R2, APB2 (0x28, 0x2C, 0x30, 0x38, 0x3C, 0x40).
    pub rstr: [u32; 6],
    /// Enable registers, in the order of [`Enr`] (index by [`Rcc::enr_index`]).
    pub enr: [u32; 6],
    /// Sleep-mode enables (stored).
    pub smenr: [u32; 6],
    /// CCIPR.
    pub ccipr: u32,
    /// CCIPR2.
    pub ccipr2: u32,
    /// BDCR.
    pub bdcr: u32,
    /// CSR (reset flags and LSI).
    pub csr: u32,
    /// CRRCR (HSI48).
    pub crrcr: u32,
    /// The HSE crystal oscillates (fault injection: false = HSERDY never rises).
    pub hse_present: bool,
}

impl Default for Rcc {
    fn default() -> Self {
        Rcc {
            // HSION and HSIRDY (RM0440 RCC_CR reset value 0x0000 0063 has HSION, HSIRDY...).
            cr: (1 << 8) | (1 << 10),
            icscr: 0x4000_0000,
            // SW = HSI16 after reset (SWS = 01).
            cfgr: 0x0000_0005,
            // PLLCFGR reset value 0x0000_1000 (PLLN = 16).
            pllcfgr: 0x0000_1000,
            cier: 0,
            rstr: [0; 6],
            // FLASHEN set at reset (AHB1ENR 0x0000_0100); APB1ENR1 RTCAPBEN (0x0000_0400).
            enr: [0x100, 0, 0, 0x400, 0, 0],
            smenr: [0; 6],
            ccipr: 0,
            ccipr2: 0,
            bdcr: 0,
            // Power-on: BORRSTF and PINRSTF.
            csr: (1 << 27) | (1 << 26),
            crrcr: 0,
            hse_present: true,
        }
    }
}

/// Divider of an AHB prescaler code (HPRE, RM0440 RCC_CFGR).
pub fn ahb_div(hpre: u32) -> u32 {
    match hpre & 0xF {
        0..=7 => 1,
        8 => 2,
        9 => 4,
        10 => 8,
        11 => 16,
        12 => 64,
        13 => 128,
        14 => 256,
        _ => 512,
    }
}

/// Divider of an APB prescaler code (PPRE1/PPRE2).
pub fn apb_div(ppre: u32) -> u32 {
    match ppre & 7 {
        0..=3 => 1,
        4 => 2,
        5 => 4,
        6 => 8,
        _ => 16,
    }
}

impl Rcc {
    /// Index into `enr`/`rstr`-like arrays for an enable register offset.
    pub fn enr_index(off: u32) -> Option<usize> {
        Enr::at(off).map(|r| r as usize)
    }

    /// Is bit `bit` of the enable register `reg` set?
    pub fn enabled(&self, reg: Enr, bit: u32) -> bool {
        self.enr[reg as usize] & (1 << bit) != 0
    }

    /// SYSCLK source from SWS (= SW: the switch completes at once): 1 HSI16, 2 HSE, 3 PLL.
    pub fn sws(&self) -> u32 {
        self.cfgr & 3
    }

    /// The main PLL's R output, Hz (0 when off or its R output disabled).
    pub fn pll_r_hz(&self) -> f64 {
        if self.cr & (1 << 25) == 0 || self.pllcfgr & (1 << 24) == 0 {
            return 0.0;
        }
        let src = match self.pllcfgr & 3 {
            2 => HSI_HZ,
            3 if self.hse_present && self.cr & (1 << 17) != 0 => HSE_HZ,
            _ => 0.0,
        };
        let m = ((self.pllcfgr >> 4) & 0xF) + 1;
        let n = (self.pllcfgr >> 8) & 0x7F;
        let r = 2 * (((self.pllcfgr >> 25) & 3) + 1);
        src / m as f64 * n as f64 / r as f64
    }

    /// SYSCLK, Hz.
    pub fn sysclk(&self) -> f64 {
        match self.sws() {
            1 => HSI_HZ,
            2 => HSE_HZ,
            3 => self.pll_r_hz(),
            _ => HSI_HZ,
        }
    }

    /// HCLK (the core clock), Hz.
    pub fn hclk(&self) -> SysClock {
        self.sysclk() / ahb_div(self.cfgr >> 4) as f64
    }

    /// APB1 prescaler divider.
    pub fn ppre1(&self) -> u32 {
        apb_div(self.cfgr >> 8)
    }

    /// PCLK1, Hz.
    pub fn pclk1(&self) -> f64 {
        self.hclk() / self.ppre1() as f64
    }

    /// Core cycles per tick of the APB1 timer clock (TIMPCLK1 = PCLK1 × 2 when the APB1
    /// prescaler is not 1: RM0440 RCC "Timer clock").
    pub fn cycles_per_tim1_tick(&self) -> f64 {
        let d = self.ppre1();
        if d == 1 {
            1.0
        } else {
            d as f64 / 2.0
        }
    }

    /// The ADC12 kernel clock selected in CCIPR.ADC12SEL, Hz (0: none; 1: PLL P, not modelled:
    /// 0; 2: SYSCLK).
    pub fn adc12_kernel_hz(&self) -> f64 {
        match (self.ccipr >> 28) & 3 {
            2 => self.sysclk(),
            _ => 0.0,
        }
    }

    /// LPUART1's kernel clock selected in CCIPR.LPUART1SEL (bits 11:10), Hz: 0 PCLK1, 1 SYSCLK,
    /// 2 HSI16, 3 LSE (not modelled: 0).
    pub fn lpuart1_kernel_hz(&self) -> f64 {
        match (self.ccipr >> 10) & 3 {
            0 => self.pclk1(),
            1 => self.sysclk(),
            2 => HSI_HZ,
            _ => 0.0,
        }
    }

    /// Register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.cr,
            0x04 => self.icscr,
            0x08 => (self.cfgr & !0xC) | ((self.cfgr & 3) << 2),
            0x0C => self.pllcfgr,
            0x18 => self.cier,
            // CIFR: no interrupt flags are modelled as raised.
            0x1C => 0,
            0x28 | 0x2C | 0x30 => self.rstr[((off - 0x28) / 4) as usize],
            0x38 | 0x3C | 0x40 => self.rstr[3 + ((off - 0x38) / 4) as usize],
            0x48 | 0x4C | 0x50 | 0x58 | 0x5C | 0x60 => self.enr[Self::enr_index(off)?],
            0x68 | 0x6C | 0x70 => self.smenr[((off - 0x68) / 4) as usize],
            0x78 | 0x7C | 0x80 => self.smenr[3 + ((off - 0x78) / 4) as usize],
            0x88 => self.ccipr,
            0x90 => self.bdcr,
            0x94 => self.csr,
            0x98 => self.crrcr,
            0x9C => self.ccipr2,
            _ => return None,
        })
    }

    /// Register write; returns the peripheral reset bits newly asserted, as (register offset
    /// of the reset register, mask).
    pub fn write(&mut self, off: u32, v: u32) -> Option<Option<(u32, u32)>> {
        match off {
            0x00 => {
                // Writable: HSION, HSIKERON, HSEON, HSEBYP, CSSON (set-only), PLLON.
                let csson = (self.cr | v) & (1 << 19);
                let w = v & ((1 << 8) | (1 << 9) | (1 << 16) | (1 << 18) | (1 << 24));
                let mut cr = w | csson;
                // Ready flags follow their enables (at once; HSE only when the crystal runs).
                if cr & (1 << 8) != 0 || self.sws() == 1 {
                    cr |= 1 << 8 | 1 << 10;
                }
                if cr & (1 << 16) != 0 && self.hse_present {
                    cr |= 1 << 17;
                }
                if cr & (1 << 24) != 0 {
                    cr |= 1 << 25;
                }
                self.cr = cr;
            }
            0x04 => self.icscr = (self.icscr & 0xFF) | (v & 0x7F00_0000),
            0x08 => {
                // SWS follows SW once the selected source is ready.
                let sw = v & 3;
                let ready = match sw {
                    1 => self.cr & (1 << 10) != 0,
                    2 => self.cr & (1 << 17) != 0,
                    3 => self.cr & (1 << 25) != 0,
                    _ => false,
                };
                let sw = if ready { sw } else { self.cfgr & 3 };
                self.cfgr = (v & 0x7F00_3FF0) | sw;
            }
            0x0C => self.pllcfgr = v & 0xFFF3_7FF3,
            0x18 => self.cier = v,
            0x20 => {}
            0x28 | 0x2C | 0x30 => {
                let i = ((off - 0x28) / 4) as usize;
                let new = v & !self.rstr[i];
                self.rstr[i] = v;
                return Some(Some((off, new)));
            }
            0x38 | 0x3C | 0x40 => {
                let i = 3 + ((off - 0x38) / 4) as usize;
                let new = v & !self.rstr[i];
                self.rstr[i] = v;
                return Some(Some((off, new)));
            }
            0x48 | 0x4C | 0x50 | 0x58 | 0x5C | 0x60 => self.enr[Self::enr_index(off)?] = v,
            0x68 | 0x6C | 0x70 => self.smenr[((off - 0x68) / 4) as usize] = v,
            0x78 | 0x7C | 0x80 => self.smenr[3 + ((off - 0x78) / 4) as usize] = v,
            0x88 => self.ccipr = v,
            0x90 => {
                let mut b = v & !((1 << 1) | (1 << 6));
                if b & 1 != 0 {
                    b |= 1 << 1; // LSERDY
                }
                self.bdcr = b;
            }
            0x94 => {
                // LSION → LSIRDY; RMVF clears the reset flags.
                let mut c = (self.csr & 0xFE00_0000) | (v & 1);
                if v & 1 != 0 {
                    c |= 2;
                }
                if v & (1 << 23) != 0 {
                    c &= !0xFE00_0000;
                }
                self.csr = c;
            }
            0x98 => self.crrcr = (v & 1) | ((v & 1) << 1),
            0x9C => self.ccipr2 = v,
            _ => return None,
        }
        Some(None)
    }
}

/// PWR's registers (stored), with the fields the clock rules read.
#[derive(Clone, Debug)]
pub struct Pwr {
    regs: [u32; 0x84 / 4],
}

impl Default for Pwr {
    fn default() -> Self {
        let mut regs = [0; 0x84 / 4];
        // CR1: VOS = 01 (range 1); CR3: EIWUL; CR5: R1MODE = 1 (normal, no boost).
        regs[0] = 1 << 9;
        regs[2] = 1 << 15;
        regs[0x80 / 4] = 1;
        Pwr { regs }
    }
}

impl Pwr {
    fn known(off: u32) -> bool {
        matches!(off, 0x00..=0x18 | 0x20..=0x5C | 0x80)
    }

    /// Register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        Self::known(off).then(|| self.regs[(off / 4) as usize])
    }

    /// Register write (SR1/SR2 read-only; VOSF never set: the regulator settles at once).
    pub fn write(&mut self, off: u32, v: u32) -> Option<()> {
        if !Self::known(off) {
            return None;
        }
        if off != 0x10 && off != 0x14 {
            self.regs[(off / 4) as usize] = v;
        }
        Some(())
    }

    /// Voltage range 1 (VOS = 01)?
    pub fn range1(&self) -> bool {
        (self.regs[0] >> 9) & 3 == 1
    }

    /// Range 1 boost mode (CR5.R1MODE = 0)?
    pub fn boost(&self) -> bool {
        self.regs[0x80 / 4] & 1 == 0
    }
}

/// Flash wait states HCLK needs (RM0440 FLASH "Read access latency", the table of wait states
/// by voltage range): range 1 boost 34/68/102/136/170 MHz for 0..4 WS; range 1 normal
/// 30/60/90/120/150; range 2 12/24/26.
pub fn wait_states_needed(hclk: f64, range1: bool, boost: bool) -> u32 {
    let steps: &[f64] = if !range1 {
        &[12e6, 24e6, 26e6]
    } else if boost {
        &[34e6, 68e6, 102e6, 136e6, 170e6]
    } else {
        &[30e6, 60e6, 90e6, 120e6, 150e6]
    };
    steps
        .iter()
        .position(|&f| hclk <= f + 1.0)
        .map_or(u32::MAX, |n| n as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pll_r_gives_170_mhz_from_the_hse_and_from_hsi16() {
        // RM0440 RCC: f(VCO) = f(in) × PLLN / PLLM, f(R) = f(VCO) / PLLR with PLLR code 0 = /2.
        let mut rcc = Rcc::default();
        rcc.write(0x00, (1 << 8) | (1 << 16)).unwrap();
        // HSE, M = 6 (code 5), N = 85, R = /2, REN.
        rcc.write(0x0C, 3 | (5 << 4) | (85 << 8) | (1 << 24))
            .unwrap();
        rcc.write(0x00, (1 << 8) | (1 << 16) | (1 << 24)).unwrap();
        assert!((rcc.pll_r_hz() - 170e6).abs() < 1.0);
        // SW = PLL: SWS follows, HCLK = 170 MHz; AHB /2 halves it.
        rcc.write(0x08, 3 | (8 << 4)).unwrap();
        assert_eq!(rcc.read(0x08).unwrap() & 0xF, 0xF);
        assert!((rcc.hclk() - 85e6).abs() < 1.0);
        // HSI16 source, M = 4.
        rcc.write(0x0C, 2 | (3 << 4) | (85 << 8) | (1 << 24))
            .unwrap();
        assert!((rcc.pll_r_hz() - 170e6).abs() < 1.0);
    }

    #[test]
    fn hse_ready_only_when_the_crystal_runs_and_sw_waits_for_ready() {
        let mut rcc = Rcc {
            hse_present: false,
            ..Rcc::default()
        };
        rcc.write(0x00, (1 << 8) | (1 << 16)).unwrap();
        assert_eq!(rcc.read(0x00).unwrap() & (1 << 17), 0);
        // Switching to a source that is not ready leaves SWS where it was (HSI16).
        rcc.write(0x08, 2).unwrap();
        assert_eq!((rcc.read(0x08).unwrap() >> 2) & 3, 1);
    }

    #[test]
    fn wait_states_follow_the_flash_latency_table() {
        assert_eq!(wait_states_needed(170e6, true, true), 4);
        assert_eq!(wait_states_needed(170e6, true, false), u32::MAX);
        assert_eq!(wait_states_needed(16e6, true, false), 0);
        assert_eq!(wait_states_needed(24e6, true, true), 0);
        assert_eq!(wait_states_needed(85e6, true, true), 2);
    }
}
