//! TIM6 (RM0440 "Basic timers (TIM6/TIM7)"; stm32-metapac `timer_v2` basic), DAC1 (RM0440
//! "Digital-to-analog converter (DAC)"; `dac_v7`), ADC1/ADC2 and their common registers (RM0440
//! "Analog-to-digital converters (ADC)"; `adc_g4`, `adccommon_g4`).
//!
//! Trigger numbers are the device data's (stm32-data, as embassy's generated tables use them):
//! TIM6_TRGO is DAC trigger 7 (TSEL1) and ADC12 regular external trigger 13 (EXTSEL).
//!
//! TIM6 covers: CEN, UDIS, URS, OPM, ARPE; PSC and ARR with their shadow registers loaded at
//! update events; UG; UIF; the update event as TRGO (MMS = 010); DIER.UIE as the TIM6_DAC
//! interrupt. Leaves out: UIFREMAP, dithering, the update DMA request (UDE), MMS values other
//! than update and reset.
//!
//! DAC1 channel 1 covers: EN1 with DACRDY1 (ready at once), TEN1/TSEL1 (hardware trigger: DHR to
//! DOR at the trigger, the DMA request with DMAEN1, DMAUDR1 on a trigger while the previous
//! request is unserved), SWTRIG1, DHR12R1/DHR12L1/DHR8R1 (word accesses only: narrower ones are a
//! bus error, RM0440 DAC "DAC registers": accessed by words), the output-buffer calibration
//! (CEN1 with OTRIM1: CAL_FLAG1 valid tTRIM = 50 µs after the trim is written; the channel's
//! offset is the board's, 12 codes), MCR.MODE1 stored, MCR.HFSEL against HCLK at each trigger
//! (RM0440 DAC_MCR: 01 above 80 MHz, 10 above 160 MHz; the board checks it). Leaves out: channel 2, wave generation,
//! sample-and-hold, the buffer's settling (DOR reaches the pin at once), the sawtooth/increment
//! triggers, the output voltage's offset error (the trim's effect on the pin).
//!
//! ADC1/ADC2 cover: deep power-down (DEEPPWD), the regulator (ADVREGEN, 20 µs start-up
//! tADCVREG_STUP), calibration (ADCAL, 116 ADC clocks, single-ended and differential CALFACT),
//! ADEN/ADDIS with ADRDY, ADSTART/ADSTP, one regular channel (SQR1.L = 0) with its sampling time
//! (SMPR) and the successive approximation's 12.5, 10.5, 8.5 or 6.5 clocks at the resolution
//! (CFGR.RES: 12, 10, 8, 6 bits; the code the resolution's, right- or left-aligned by
//! CFGR.ALIGN, RM0440 ADC "Data management": left-aligned 12/10/8-bit data end at bit 15, 6-bit
//! data at bit 7), the external trigger (EXTSEL/EXTEN, rising/falling
//! edge of a pulse), CONT, DR with EOC/EOS/OVR (OVRMOD), the DMA request (DMAEN, DMACFG), IER
//! as the ADC1_2 interrupt; the common CCR (CKMODE, PRESC, DUAL stored), the ADC kernel clock
//! (CCIPR.ADC12SEL: SYSCLK) or HCLK/1,/2,/4. Leaves out: sequences of more than one channel,
//! injected conversions, dual modes' coupling (DUAL is stored and checked against the rules
//! only), oversampling, analog watchdogs, offsets (and their sign extension), auto-delay, differential inputs, the internal channels (VREFINT, temperature, VBAT).

/// Trigger sources the models know.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trigger {
    /// TIM6's TRGO (update event).
    Tim6Trgo,
}

/// TIM6_TRGO as DAC1 TSEL1 (device data: `DAC_CHX_TRG7`).
pub const DAC_TSEL_TIM6_TRGO: u32 = 7;
/// TIM6_TRGO as ADC12 EXTSEL (device data: `ADC_EXT_TRG13`).
pub const ADC_EXTSEL_TIM6_TRGO: u32 = 13;

/// TIM6.
#[derive(Clone, Debug, Default)]
pub struct Tim6 {
    cr1: u32,
    cr2: u32,
    dier: u32,
    sr: u32,
    psc: u32,
    arr: u32,
    /// Shadow (active) prescaler and auto-reload.
    psc_sh: u32,
    arr_sh: u32,
    /// Core cycle of the last counter reset (update or enable).
    epoch: u64,
    /// Counter value at `epoch` (the counter keeps its value while stopped).
    cnt0: u32,
    /// Core cycles per timer clock tick (from the APB1 prescaler), set by the board.
    pub cycles_per_tick: u64,
}

impl Tim6 {
    /// A reset TIM6 (ARR = 0xFFFF).
    pub fn new() -> Tim6 {
        Tim6 {
            arr: 0xFFFF,
            arr_sh: 0xFFFF,
            cycles_per_tick: 1,
            ..Tim6::default()
        }
    }

    fn running(&self) -> bool {
        self.cr1 & 1 != 0
    }

    fn tick_cycles(&self) -> u64 {
        self.cycles_per_tick * (self.psc_sh as u64 + 1)
    }

    fn cnt(&self, now: u64) -> u32 {
        if !self.running() {
            return self.cnt0;
        }
        let ticks = (now - self.epoch) / self.tick_cycles();
        ((self.cnt0 as u64 + ticks) % (self.arr_sh as u64 + 1)) as u32
    }

    /// Core cycles from one update event to the next: (PSC + 1) × (ARR + 1) timer clocks, from
    /// the shadow registers in force.
    pub fn update_period_cycles(&self) -> u64 {
        self.tick_cycles() * (self.arr_sh as u64 + 1)
    }

    /// The next update event (overflow), a core cycle.
    pub fn next_event(&self) -> Option<u64> {
        if !self.running() {
            return None;
        }
        let left = self.arr_sh as u64 + 1 - self.cnt0 as u64;
        Some(self.epoch + left * self.tick_cycles())
    }

    /// The update event at cycle `at` (an overflow or UG): shadows load, UIF unless masked,
    /// counter to 0. Returns true if TRGO pulses (MMS = update).
    fn update(&mut self, at: u64, from_ug: bool) -> bool {
        if self.cr1 & 2 != 0 && !from_ug {
            // UDIS: no update event.
            self.epoch = at;
            self.cnt0 = 0;
            return false;
        }
        self.psc_sh = self.psc;
        self.arr_sh = self.arr;
        self.epoch = at;
        self.cnt0 = 0;
        if !(from_ug && self.cr1 & 4 != 0) {
            self.sr |= 1;
        }
        if !from_ug && self.cr1 & 8 != 0 {
            self.cr1 &= !1; // OPM: stop at the update
        }
        (self.cr2 >> 4) & 7 == 2
    }

    /// Process the overflow due at `at` (= `next_event`); true if TRGO pulses.
    pub fn overflow(&mut self, at: u64) -> bool {
        self.update(at, false)
    }

    /// The TIM6_DAC interrupt line (UIE and UIF).
    pub fn irq(&self) -> bool {
        self.dier & 1 != 0 && self.sr & 1 != 0
    }

    /// Register read.
    pub fn read(&self, off: u32, now: u64) -> Option<u32> {
        Some(match off {
            0x00 => self.cr1,
            0x04 => self.cr2,
            0x0C => self.dier,
            0x10 => self.sr,
            0x14 => 0,
            0x24 => self.cnt(now),
            0x28 => self.psc,
            0x2C => self.arr,
            _ => return None,
        })
    }

    /// Register write; returns true if TRGO pulses (UG with MMS = update, or MMS = reset).
    pub fn write(&mut self, off: u32, v: u32, now: u64) -> Option<bool> {
        match off {
            0x00 => {
                let was = self.running();
                if was {
                    self.cnt0 = self.cnt(now);
                    self.epoch = now;
                }
                self.cr1 = v & 0x198F;
                if self.running() && !was {
                    self.epoch = now;
                } else if !self.running() && was {
                    // cnt0 holds the count.
                }
            }
            0x04 => self.cr2 = v & 0x70,
            0x0C => self.dier = v & 0x101,
            0x10 => self.sr &= v & 1,
            0x14 => {
                if v & 1 != 0 {
                    let mms = (self.cr2 >> 4) & 7;
                    let trgo = self.update(now, true);
                    return Some(trgo || mms == 0);
                }
            }
            0x24 => {
                self.cnt0 = v & 0xFFFF;
                self.epoch = now;
            }
            0x28 => self.psc = v & 0xFFFF,
            0x2C => {
                self.arr = v & 0xFFFF;
                if self.cr1 & 0x80 == 0 {
                    // No preload: the new ARR applies at once.
                    if self.running() {
                        self.cnt0 = self.cnt(now);
                        self.epoch = now;
                    }
                    self.arr_sh = self.arr;
                }
            }
            _ => return None,
        }
        Some(false)
    }
}

/// The DAC channel 1 offset in trim codes of this board's part: CAL_FLAG1 reads 1 once OTRIM1
/// is at or above it (RM0440 DAC "DAC channel output buffer calibration").
pub const DAC_OFFSET_TRIM: u32 = 12;
/// tTRIM, s: the wait after an OTRIM write before CAL_FLAG is valid (datasheet 50 µs max).
pub const DAC_TTRIM_S: f64 = 50e-6;

/// DAC1 (channel 1).
#[derive(Clone, Debug, Default)]
pub struct Dac {
    /// CR.
    pub cr: u32,
    dhr: u32,
    /// DOR1, the code on the output.
    pub dor: u32,
    sr: u32,
    ccr: u32,
    mcr: u32,
    shsr: [u32; 2],
    shhr: u32,
    shrr: u32,
    str_: [u32; 2],
    stmodr: u32,
    /// A DMA request raised at a trigger and not yet served.
    pub dma_pending: bool,
    /// DHR was written since the channel was enabled (a valid first code).
    dhr_written: bool,
    /// When the last OTRIM write's flag becomes valid (s) and the flag before it.
    trim_valid_at: f64,
    cal_flag_before: bool,
    /// A trigger happened with EN1 set.
    pub triggered_once: bool,
    /// A trigger found HFSEL below what HCLK needs (flagged once).
    pub hfsel_flagged: bool,
}

/// The DAC_MCR.HFSEL an AHB clock of `hclk` Hz needs at least (RM0440 DAC_MCR, "HFSEL: High
/// frequency interface mode selection": 01 for AHB above 80 MHz, 10 above 160 MHz).
pub fn dac_hfsel_needed(hclk: f64) -> u32 {
    if hclk > 160e6 {
        0b10
    } else if hclk > 80e6 {
        0b01
    } else {
        0
    }
}

/// What a DAC register write means for the board.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DacWrite {
    /// A documented rule broken by the write.
    pub violation: Option<String>,
    /// DOR changed (software trigger or no trigger): the new output.
    pub output: Option<u32>,
}

impl Dac {
    /// DAC_MCR.HFSEL.
    pub fn hfsel(&self) -> u32 {
        (self.mcr >> 14) & 3
    }

    fn cal_flag(&self, t: f64) -> bool {
        let now_flag = (self.ccr & 0x1F) >= DAC_OFFSET_TRIM;
        if t >= self.trim_valid_at {
            now_flag
        } else {
            self.cal_flag_before
        }
    }

    /// Register read at `t` (s).
    pub fn read(&self, off: u32, t: f64) -> Option<u32> {
        Some(match off {
            0x00 => self.cr,
            0x04 => 0,
            0x08 => self.dhr,
            0x0C => self.dhr << 4,
            0x10 => self.dhr >> 4,
            0x20 | 0x24 | 0x28 => 0,
            0x2C => self.dor,
            0x30 => 0,
            0x34 => {
                // DACRDY1 when enabled; CAL_FLAG1 from the trim.
                self.sr | ((self.cr & 1) << 11) | (self.cal_flag(t) as u32) << 14
            }
            0x38 => self.ccr,
            0x3C => self.mcr,
            0x40 => self.shsr[0],
            0x44 => self.shsr[1],
            0x48 => self.shhr,
            0x4C => self.shrr,
            0x58 => self.str_[0],
            0x5C => self.str_[1],
            0x60 => self.stmodr,
            _ => return None,
        })
    }

    /// Register write of `size` bytes at `t` (s).
    pub fn write(&mut self, off: u32, size: usize, v: u32, t: f64) -> Option<DacWrite> {
        let mut w = DacWrite::default();
        if size != 4 && matches!(off, 0x08 | 0x0C | 0x10 | 0x20 | 0x24 | 0x28) {
            w.violation = Some(format!(
                "{size}-byte access to DAC data register +{off:#x}: a bus error, the DAC takes word accesses only (RM0440 DAC registers)"
            ));
            return Some(w);
        }
        match off {
            0x00 => {
                let en = self.cr & 1 != 0;
                // TSEL1, TEN1, CEN1, WAVE1 and MAMP1 may change only with EN1 clear.
                let locked = (0xF << 2) | (1 << 1) | (1 << 14) | (3 << 6) | (0xF << 8);
                if en && (self.cr ^ v) & locked != 0 {
                    w.violation = Some(format!(
                        "DAC_CR {:#x} -> {v:#x}: TSEL1/TEN1/CEN1/WAVE1/MAMP1 changed while EN1 is set (RM0440 DAC_CR)",
                        self.cr
                    ));
                }
                if v & 1 != 0 && !en {
                    self.dhr_written = false;
                }
                self.cr = v & 0x7FFF_7FFF;
                if self.cr & 1 == 0 {
                    self.dma_pending = false;
                }
            }
            0x04 => {
                // SWTRIG1: DHR → DOR when TEN1 with TSEL1 = 0 (SWTRIG).
                if v & 1 != 0 && self.cr & 3 == 3 && (self.cr >> 2) & 0xF == 0 {
                    self.dor = self.dhr;
                    w.output = Some(self.dor);
                }
            }
            0x08 | 0x0C | 0x10 => {
                self.dhr = match off {
                    0x08 => v & 0xFFF,
                    0x0C => (v >> 4) & 0xFFF,
                    _ => (v & 0xFF) << 4,
                };
                self.dhr_written = true;
                if self.cr & 3 == 1 {
                    // No trigger: DOR follows DHR (one APB clock later).
                    self.dor = self.dhr;
                    w.output = Some(self.dor);
                }
            }
            0x20 | 0x24 | 0x28 => {}
            0x34 => self.sr &= !(v & (1 << 13)),
            0x38 => {
                self.cal_flag_before = self.cal_flag(t);
                self.ccr = v & 0x001F_001F;
                self.trim_valid_at = t + DAC_TTRIM_S;
            }
            0x3C => {
                if self.cr & 1 != 0 && (self.mcr ^ v) & 7 != 0 {
                    w.violation =
                        Some("DAC_MCR.MODE1 changed while EN1 is set (RM0440 DAC_MCR)".into());
                }
                self.mcr = v;
            }
            0x40 => self.shsr[0] = v,
            0x44 => self.shsr[1] = v,
            0x48 => self.shhr = v,
            0x4C => self.shrr = v,
            0x58 => self.str_[0] = v,
            0x5C => self.str_[1] = v,
            0x60 => self.stmodr = v,
            _ => return None,
        }
        Some(w)
    }

    /// A trigger `trig` at time `t`: DHR to DOR if the channel waits for it. Returns (new
    /// output code, a DMA request raised, a rule violation).
    pub fn trigger(&mut self, trig: Trigger) -> (Option<u32>, bool, Option<String>) {
        let Trigger::Tim6Trgo = trig;
        if self.cr & 3 != 3 || (self.cr >> 2) & 0xF != DAC_TSEL_TIM6_TRGO {
            return (None, false, None);
        }
        let mut violation = None;
        if !self.triggered_once && !self.dhr_written {
            violation = Some(format!(
                "DAC1 channel 1's first trigger with no code written to DHR since EN1 (DOR takes DHR's {:#x}): RM0440 DAC \"DAC conversion\"",
                self.dhr
            ));
        }
        self.triggered_once = true;
        self.dor = self.dhr;
        let mut request = false;
        if self.cr & (1 << 12) != 0 && self.sr & (1 << 13) == 0 {
            if self.dma_pending {
                // The previous request is unserved: underrun; no new request.
                self.sr |= 1 << 13;
            } else {
                self.dma_pending = true;
                request = true;
            }
        }
        (Some(self.dor), request, violation)
    }

    /// The DMA wrote DHR12R1 (serving the request).
    pub fn dma_served(&mut self) {
        self.dma_pending = false;
        self.dhr_written = true;
    }

    /// DMAUDR1 with DMAUDRIE1: the TIM6_DAC interrupt line.
    pub fn irq(&self) -> bool {
        self.sr & (1 << 13) != 0 && self.cr & (1 << 13) != 0
    }
}

/// Sampling times in ADC clock cycles by SMP code (RM0440 ADC_SMPR1).
pub const SMP_CYCLES: [f64; 8] = [2.5, 6.5, 12.5, 24.5, 47.5, 92.5, 247.5, 640.5];
/// Successive-approximation time at 12 bits, ADC clock cycles.
pub const CONVERSION_CYCLES: f64 = 12.5;
/// Calibration time, ADC clock cycles (RM0440 ADC "Calibration": tCAL = 116 clocks).
pub const CAL_CYCLES: f64 = 116.0;
/// Regulator start-up time, s (datasheet tADCVREG_STUP 20 µs).
pub const VREG_STARTUP_S: f64 = 20e-6;

/// One ADC (ADC1 or ADC2).
#[derive(Clone, Debug)]
pub struct Adc {
    /// ISR.
    pub isr: u32,
    ier: u32,
    /// CR.
    pub cr: u32,
    /// CFGR.
    pub cfgr: u32,
    cfgr2: u32,
    smpr: [u32; 2],
    tr: [u32; 3],
    sqr: [u32; 4],
    /// DR.
    pub dr: u32,
    jsqr: u32,
    ofr: [u32; 4],
    awdcr: [u32; 2],
    /// DIFSEL.
    pub difsel: u32,
    calfact: u32,
    gcomp: u32,
    /// When the regulator is ready (s).
    vreg_ready_at: f64,
    /// A calibration in progress ends at (s).
    cal_until: Option<f64>,
    /// When ADCAL last cleared (s), for the ADEN rule.
    pub cal_done_at: Option<f64>,
    /// A conversion in progress: (sampling instant, end) in s.
    pub converting: Option<(f64, f64)>,
    /// A DMA request raised and not yet served.
    pub dma_pending: bool,
    /// Fault injection: ADRDY never rises after ADEN (a broken ADC or its supply).
    pub never_ready: bool,
}

impl Default for Adc {
    fn default() -> Self {
        Adc {
            isr: 0,
            ier: 0,
            // DEEPPWD set at reset.
            cr: 1 << 29,
            cfgr: 0x8000_0000,
            cfgr2: 0,
            smpr: [0; 2],
            tr: [0x0FFF_0000, 0x00FF_0000, 0x00FF_0000],
            sqr: [0; 4],
            dr: 0,
            jsqr: 0,
            ofr: [0; 4],
            awdcr: [0; 2],
            difsel: 0,
            calfact: 0,
            gcomp: 0,
            vreg_ready_at: f64::INFINITY,
            cal_until: None,
            cal_done_at: None,
            converting: None,
            dma_pending: false,
            never_ready: false,
        }
    }
}

/// What an ADC register write means for the board.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdcWrite {
    /// A documented rule broken by the write.
    pub violation: Option<String>,
}

impl Adc {
    /// ADEN with ADRDY reached?
    pub fn enabled(&self) -> bool {
        self.cr & 1 != 0
    }

    /// The channel converted (SQR1.SQ1) and its sampling time code.
    pub fn channel(&self) -> (u32, u32) {
        let ch = (self.sqr[0] >> 6) & 0x1F;
        let smp = if ch < 10 {
            (self.smpr[0] >> (3 * ch)) & 7
        } else {
            (self.smpr[1] >> (3 * (ch - 10))) & 7
        };
        (ch, smp)
    }

    /// The next event (end of calibration or conversion), s.
    pub fn next_event(&self) -> Option<f64> {
        [self.cal_until, self.converting.map(|c| c.1)]
            .into_iter()
            .flatten()
            .reduce(f64::min)
    }

    /// End the calibration due by `t`.
    pub fn advance_calibration(&mut self, t: f64) {
        if let Some(end) = self.cal_until {
            if end <= t {
                self.cal_until = None;
                self.cr &= !(1 << 31);
                self.cal_done_at = Some(end);
                // CALFACT: some factory-like value, single-ended and differential.
                self.calfact = if self.cr & (1 << 30) != 0 {
                    0x0040_0000 | (self.calfact & 0x7F)
                } else {
                    (self.calfact & 0x7F_0000) | 0x40
                };
            }
        }
    }

    /// An external trigger at `t`: starts a conversion if the ADC waits for this one.
    /// `adc_hz` is the ADC clock.
    pub fn trigger(&mut self, trig: Trigger, t: f64, adc_hz: f64) {
        let Trigger::Tim6Trgo = trig;
        let exten = (self.cfgr >> 10) & 3;
        let extsel = (self.cfgr >> 5) & 0x1F;
        if self.cr & 0b101 != 0b101
            || exten == 0
            || extsel != ADC_EXTSEL_TIM6_TRGO
            || self.converting.is_some()
        {
            return;
        }
        self.start(t, adc_hz);
    }

    /// The resolution, bits (CFGR.RES).
    pub fn resolution_bits(&self) -> u32 {
        [12, 10, 8, 6][((self.cfgr >> 3) & 3) as usize]
    }

    /// DR's value for the 12-bit conversion `code12` at the resolution and alignment.
    fn data(&self, code12: u32) -> u32 {
        let bits = self.resolution_bits();
        let code = code12 >> (12 - bits);
        match (self.cfgr & (1 << 15) != 0, bits) {
            (false, _) => code,
            (true, 6) => code << 2,
            (true, _) => code << (16 - bits),
        }
    }

    fn start(&mut self, t: f64, adc_hz: f64) {
        let (_, smp) = self.channel();
        let sampling = SMP_CYCLES[smp as usize] / adc_hz;
        // tSAR: 12.5 clocks at 12 bits, two fewer for each two bits less (RM0440 ADC
        // "Programmable resolution (RES) - fast conversion mode").
        let sar = CONVERSION_CYCLES - (12 - self.resolution_bits()) as f64;
        let total = (SMP_CYCLES[smp as usize] + sar) / adc_hz;
        self.converting = Some((t + sampling, t + total));
    }

    /// Finish the conversion (its end is due) of the voltage whose 12-bit code is `code12`;
    /// returns true if a DMA request is raised. Restarts in continuous mode or for a
    /// software-started sequence.
    pub fn finish(&mut self, code12: u32, adc_hz: f64) -> bool {
        let Some((_, end)) = self.converting.take() else {
            return false;
        };
        let code = self.data(code12);
        if self.isr & (1 << 2) != 0 {
            // DR not read since the last EOC: overrun.
            self.isr |= 1 << 4;
            if self.cfgr & (1 << 12) != 0 {
                self.dr = code;
            }
        } else {
            self.dr = code;
        }
        self.isr |= (1 << 2) | (1 << 3) | (1 << 1);
        let mut request = false;
        if self.cfgr & 1 != 0 {
            if self.dma_pending {
                self.isr |= 1 << 4;
            }
            self.dma_pending = true;
            request = true;
        }
        let exten = (self.cfgr >> 10) & 3;
        if self.cfgr & (1 << 13) != 0 && self.cr & 4 != 0 {
            self.start(end, adc_hz);
        } else if exten == 0 {
            // Software trigger, single mode: ADSTART clears at the end of the sequence.
            self.cr &= !4;
        }
        request
    }

    /// The DMA read DR.
    pub fn dma_served(&mut self) {
        self.dma_pending = false;
        self.isr &= !(1 << 2);
    }

    /// The ADC1_2 interrupt line.
    pub fn irq(&self) -> bool {
        self.isr & self.ier & 0x7FF != 0
    }

    /// Register read (a read of DR clears EOC).
    pub fn read(&mut self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.isr,
            0x04 => self.ier,
            0x08 => self.cr,
            0x0C => self.cfgr,
            0x10 => self.cfgr2,
            0x14 => self.smpr[0],
            0x18 => self.smpr[1],
            0x20 | 0x24 | 0x28 => self.tr[((off - 0x20) / 4) as usize],
            0x30..=0x3C => self.sqr[((off - 0x30) / 4) as usize],
            0x40 => {
                self.isr &= !(1 << 2);
                self.dr
            }
            0x4C => self.jsqr,
            0x60..=0x6C => self.ofr[((off - 0x60) / 4) as usize],
            0x80..=0x8C => 0,
            0xA0 | 0xA4 => self.awdcr[((off - 0xA0) / 4) as usize],
            0xB0 => self.difsel,
            0xB4 => self.calfact,
            0xC0 => self.gcomp,
            _ => return None,
        })
    }

    /// Register write at `t` (s); `adc_hz` is the ADC clock (0 when none is selected).
    pub fn write(&mut self, off: u32, v: u32, t: f64, adc_hz: f64) -> Option<AdcWrite> {
        let mut w = AdcWrite::default();
        match off {
            0x00 => self.isr &= !(v & 0x7FF),
            0x04 => self.ier = v & 0x7FF,
            0x08 => {
                let old = self.cr;
                // DEEPPWD, ADVREGEN, ADCALDIF are plain bits; ADCAL/ADEN/ADSTART set-only,
                // ADDIS/ADSTP commands.
                let mut cr = (old & !((1 << 29) | (1 << 28) | (1 << 30)))
                    | (v & ((1 << 29) | (1 << 28) | (1 << 30)));
                if cr & (1 << 29) != 0 {
                    cr &= !(1 << 28); // deep power-down: regulator off
                }
                if cr & (1 << 28) != 0 && old & (1 << 28) == 0 {
                    self.vreg_ready_at = t + VREG_STARTUP_S;
                }
                if cr & (1 << 28) == 0 {
                    self.vreg_ready_at = f64::INFINITY;
                }
                if v & (1 << 31) != 0 && old & (1 << 31) == 0 {
                    if old & 1 != 0 || cr & (1 << 28) == 0 || cr & (1 << 29) != 0 {
                        w.violation = Some("ADCAL set with ADEN set, the regulator off or in deep power-down (RM0440 ADC \"Calibration\")".into());
                    } else if t < self.vreg_ready_at {
                        w.violation = Some(format!(
                            "ADCAL set {:.2} us after ADVREGEN, before the regulator's start-up time tADCVREG_STUP (20 us): RM0440 ADC \"ADC voltage regulator\"",
                            (t - (self.vreg_ready_at - VREG_STARTUP_S)) * 1e6
                        ));
                    }
                    if adc_hz > 0.0 {
                        cr |= 1 << 31;
                        self.cal_until = Some(t + CAL_CYCLES / adc_hz);
                    } else {
                        w.violation = Some("ADCAL set with no ADC clock (CCIPR.ADC12SEL and ADC_CCR.CKMODE select none)".into());
                        cr |= 1 << 31;
                    }
                } else {
                    cr |= old & (1 << 31);
                }
                if v & 1 != 0 && old & 1 == 0 {
                    if let Some(done) = self.cal_done_at {
                        if adc_hz > 0.0 && (t - done) * adc_hz < 4.0 {
                            w.violation = Some(format!(
                                "ADEN set {:.1} ADC clocks after ADCAL cleared (RM0440 ADC \"Calibration\": at least 4)",
                                (t - done) * adc_hz
                            ));
                        }
                    }
                    if cr & (1 << 28) != 0 && cr & (1 << 31) == 0 {
                        cr |= 1;
                        if !self.never_ready {
                            self.isr |= 1; // ADRDY
                        }
                    }
                }
                if old & 1 != 0 {
                    cr |= 1;
                }
                if v & 2 != 0 && old & 1 != 0 {
                    // ADDIS: off (no conversion may be running: ADSTP first).
                    cr &= !1;
                    self.isr &= !1;
                    self.converting = None;
                }
                if v & 4 != 0 && cr & 1 != 0 {
                    cr |= 4;
                    if (self.cfgr >> 10) & 3 == 0 && self.converting.is_none() && adc_hz > 0.0 {
                        self.start(t, adc_hz);
                    }
                } else {
                    cr |= old & 4;
                }
                if v & (1 << 4) != 0 {
                    cr &= !4;
                    self.converting = None;
                }
                self.cr = cr;
            }
            0x0C => {
                if self.cr & 4 != 0 && (self.cfgr ^ v) != 0 {
                    w.violation = Some("ADC_CFGR changed while ADSTART is set (RM0440 ADC_CFGR: written only with ADSTART = 0)".into());
                }
                self.cfgr = v;
            }
            0x10 => self.cfgr2 = v,
            0x14 => self.smpr[0] = v,
            0x18 => self.smpr[1] = v,
            0x20 | 0x24 | 0x28 => self.tr[((off - 0x20) / 4) as usize] = v,
            0x30..=0x3C => self.sqr[((off - 0x30) / 4) as usize] = v,
            0x40 => {}
            0x4C => self.jsqr = v,
            0x60..=0x6C => self.ofr[((off - 0x60) / 4) as usize] = v,
            0xA0 | 0xA4 => self.awdcr[((off - 0xA0) / 4) as usize] = v,
            0xB0 => {
                if self.enabled() && self.difsel != v {
                    w.violation = Some("ADC_DIFSEL changed while ADEN is set (RM0440 ADC_DIFSEL: written only with ADEN = 0)".into());
                }
                self.difsel = v;
            }
            0xB4 => self.calfact = v,
            0xC0 => self.gcomp = v,
            _ => return None,
        }
        Some(w)
    }
}

/// ADC12's common registers.
#[derive(Clone, Debug, Default)]
pub struct AdcCommon {
    /// CCR.
    pub ccr: u32,
}

impl AdcCommon {
    /// The ADC clock, Hz, from CKMODE/PRESC and the kernel clock or HCLK.
    pub fn adc_hz(&self, kernel_hz: f64, hclk: f64) -> f64 {
        const PRESC: [f64; 12] = [
            1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0, 32.0, 64.0, 128.0, 256.0,
        ];
        match (self.ccr >> 16) & 3 {
            0 => kernel_hz / PRESC[(((self.ccr >> 18) & 0xF) as usize).min(11)],
            1 => hclk,
            2 => hclk / 2.0,
            _ => hclk / 4.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tim6_updates_every_psc_plus_one_times_arr_plus_one_ticks() {
        // RM0440 TIM6/7: the counter counts 0..=ARR at CK_CNT = CK_PSC / (PSC + 1); the
        // update event (TRGO with MMS = 010) at each overflow. 170 MHz / 10 kHz = 17 000.
        let mut t = Tim6::new();
        t.write(0x04, 2 << 4, 0).unwrap();
        t.write(0x28, 0, 0).unwrap();
        t.write(0x2C, 16_999, 0).unwrap();
        // UG loads the shadows and pulses TRGO.
        assert_eq!(t.write(0x14, 1, 0), Some(true));
        t.write(0x00, 1, 100).unwrap();
        assert_eq!(t.next_event(), Some(17_100));
        assert_eq!(t.read(0x24, 100 + 16_998), Some(16_998));
        assert!(t.overflow(17_100));
        assert_eq!(t.next_event(), Some(34_100));
        // PSC is preloaded: a new value applies from the next update.
        t.write(0x28, 1, 20_000).unwrap();
        assert_eq!(t.next_event(), Some(34_100));
        t.overflow(34_100);
        assert_eq!(t.next_event(), Some(34_100 + 34_000));
    }

    #[test]
    fn dac_trigger_moves_dhr_to_dor_and_requests_dma() {
        let mut d = Dac::default();
        // TSEL1 = 7, TEN1, DMAEN1, then EN1.
        let cfg = (DAC_TSEL_TIM6_TRGO << 2) | 2 | (1 << 12);
        d.write(0x00, 4, cfg, 0.0).unwrap();
        d.write(0x08, 4, 0x800, 0.0).unwrap();
        d.write(0x00, 4, cfg | 1, 0.0).unwrap();
        // Changing TSEL while enabled breaks the rule.
        assert!(d
            .write(0x00, 4, (cfg | 1) ^ (1 << 2), 0.0)
            .unwrap()
            .violation
            .is_some());
        d.write(0x00, 4, cfg | 1, 0.0).unwrap();
        d.write(0x08, 4, 0x800, 0.0).unwrap();
        let (out, req, v) = d.trigger(Trigger::Tim6Trgo);
        assert_eq!((out, req, v.is_none()), (Some(0x800), true, true));
        // A second trigger with the request unserved: underrun, no new request.
        let (_, req, _) = d.trigger(Trigger::Tim6Trgo);
        assert!(!req);
        assert_ne!(d.read(0x34, 0.0).unwrap() & (1 << 13), 0);
        // Half-word data access: a bus error.
        assert!(d.write(0x08, 2, 1, 0.0).unwrap().violation.is_some());
    }

    #[test]
    fn dac_cal_flag_is_valid_ttrim_after_the_trim() {
        let mut d = Dac::default();
        d.write(0x38, 4, DAC_OFFSET_TRIM, 1.0).unwrap();
        assert_eq!(d.read(0x34, 1.0 + DAC_TTRIM_S / 2.0).unwrap() >> 14 & 1, 0);
        assert_eq!(d.read(0x34, 1.0 + DAC_TTRIM_S).unwrap() >> 14 & 1, 1);
    }

    #[test]
    fn adc_bring_up_rules() {
        // RM0440 ADC: DEEPPWD off, ADVREGEN, 20 us, ADCAL (116 clocks), >= 4 clocks, ADEN.
        let hz = 42.5e6;
        // An ADC out of deep power-down with its regulator on at 0, ADCAL set at `t_cal` s:
        // the ADC and whether that write broke the regulator's start-up rule.
        let calibrate_at = |t_cal: f64| {
            let mut a = Adc::default();
            a.write(0x08, 0, 0.0, hz).unwrap();
            a.write(0x08, 1 << 28, 0.0, hz).unwrap();
            let broken = a
                .write(0x08, (1 << 28) | (1 << 31), t_cal, hz)
                .unwrap()
                .violation
                .is_some();
            (a, broken)
        };
        assert!(
            calibrate_at(10e-6).1,
            "ADCAL 10 us after ADVREGEN: too early"
        );
        let (mut a, broken) = calibrate_at(20e-6);
        assert!(!broken, "ADCAL 20 us after ADVREGEN");
        let done = 20e-6 + CAL_CYCLES / hz;
        a.advance_calibration(done);
        assert_eq!(a.cr >> 31, 0, "ADCAL cleared by hardware");
        // ADEN 2 clocks later: too early.
        let v = a
            .write(0x08, (1 << 28) | 1, done + 2.0 / hz, hz)
            .unwrap()
            .violation;
        assert!(v.is_some(), "{v:?}");
        assert_eq!(a.isr & 1, 1, "ADRDY");
    }

    /// CFGR of the board's rings: EXTSEL 13 (TIM6_TRGO) rising, DMA circular.
    const RING_CFGR: u32 = (ADC_EXTSEL_TIM6_TRGO << 5) | (1 << 10) | 3;

    /// An ADC enabled at `hz` converting IN1 with SMP = 47.5 clocks, CFGR `cfgr`, started
    /// (ADSTART) at 1 ms, triggered by TIM6 at 2 ms.
    fn triggered_adc(hz: f64, cfgr: u32) -> Adc {
        let mut a = Adc::default();
        a.write(0x08, 1 << 28, 0.0, hz).unwrap();
        a.write(0x08, (1 << 28) | 1, 1e-3, hz).unwrap();
        a.write(0x30, 1 << 6, 1e-3, hz).unwrap();
        a.write(0x14, 4 << 3, 1e-3, hz).unwrap();
        a.write(0x0C, cfgr, 1e-3, hz).unwrap();
        a.write(0x08, (1 << 28) | 4, 1e-3, hz).unwrap();
        a.trigger(Trigger::Tim6Trgo, 2e-3, hz);
        a
    }

    #[test]
    fn adc_converts_on_trigger_with_sampling_plus_12_5_clocks() {
        let hz = 42.5e6;
        let mut a = triggered_adc(hz, RING_CFGR);
        let (s, e) = a.converting.unwrap();
        assert!((s - (2e-3 + 47.5 / hz)).abs() < 1e-15);
        assert!((e - (2e-3 + 60.0 / hz)).abs() < 1e-15);
        assert!(a.finish(0x123, hz));
        assert_eq!(a.dr, 0x123);
        assert!(a.converting.is_none(), "waits for the next trigger");
    }

    /// RM0440 ADC "Programmable resolution": RES = 10 bits converts in 10.5 clocks after the
    /// sampling, and DR holds the 10-bit code right-aligned, or left-aligned at bit 15 with
    /// ALIGN; 6 bits left-aligned end at bit 7.
    #[test]
    fn adc_resolution_sets_the_code_and_the_conversion_time() {
        let hz = 42.5e6;
        let cfgr = RING_CFGR;
        let mut a = triggered_adc(hz, cfgr | (1 << 3));
        let (_, e) = a.converting.unwrap();
        assert!((e - (2e-3 + 58.0 / hz)).abs() < 1e-15);
        assert!(a.finish(0xABC, hz));
        assert_eq!(a.dr, 0xABC >> 2);
        a.cfgr = cfgr | (1 << 3) | (1 << 15);
        assert_eq!(a.data(0xABC), (0xABC >> 2) << 6);
        a.cfgr = cfgr | (3 << 3) | (1 << 15);
        assert_eq!(a.data(0xABC), (0xABC >> 6) << 2);
    }
}
