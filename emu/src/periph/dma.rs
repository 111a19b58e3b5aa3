//! DMA1 (RM0440 "Direct memory access controller (DMA)"; stm32-metapac `bdma_v1`), DMAMUX1
//! (RM0440 "DMA request multiplexer (DMAMUX)"; `dmamux_v1`) and LPUART1 (RM0440 "Low-power
//! universal asynchronous receiver transmitter (LPUART)"; `usart_v4` LPUART).
//!
//! DMA1 covers: 8 channels with EN, DIR, CIRC, PINC/MINC, PSIZE/MSIZE (zero-extension or
//! truncation between sizes, RM0440 DMA "Programmable data width, data alignment and
//! endianness"), CNDTR with reload in circular mode, HT/TC/TE flags and their interrupts, GIF,
//! IFCR; a transfer error (an address no memory or register answers, or flash as destination)
//! sets TEIF and disables the channel. Each request is served at once (one transfer per
//! request): the bus arbitration, the channel priorities and the transfer's few bus cycles of
//! latency are left out, as are memory-to-memory transfers.
//! DMAMUX1 covers the request routing: DMA1 channel n takes the request DMAREQ_ID of DMAMUX
//! channel n − 1 (RM0440 DMAMUX: DMA1 channels 1..8 on DMAMUX channels 0..7). Request IDs from
//! the device data: ADC1 5, DAC1 CH1 6, ADC2 36, LPUART1 RX 34, LPUART1 TX 35. Leaves out
//! synchronisation, event generation and the request generators (stored only).
//!
//! LPUART1 covers: UE/RE/TE with REACK/TEACK, BRR and PRESC (baud = 256 × f_ck / PRESC / BRR,
//! f_ck the kernel clock CCIPR.LPUART1SEL selects),
//! RX bytes from the harness on a line at the host's rate ([`LINE_BAUD`], 10 bits, 8N1), each
//! sampled by the receiver at the middles of its own bit times from the start edge (a receiver
//! off the line's rate misreads bits, sees no start bit or a framing error, FE; beyond the 8N1
//! frame's tolerance the run records the rule, RM0440 LPUART "Tolerance of the LPUART receiver
//! to clock deviation"), RDR/RXNE, ORE on a byte
//! arriving with RXNE set (unless OVRDIS), IDLE one frame after the last byte, the RX DMA
//! request (CR3.DMAR), the interrupt (RXNEIE, IDLEIE, EIE with ORE); TX: a byte written to TDR
//! is captured and takes one frame time on the line, TXE and TC clear meanwhile, and with
//! CR3.DMAT set (and TE, UE) a free transmitter requests the next byte from the DMA (LPUART1
//! TX). Leaves out: FIFO mode, parity, 9-bit and 7-bit words, stop bits other than one,
//! noise errors, auto baud, wake-up, a receiver still in one frame when the next starts, the
//! TX double buffering (TDR takes the next byte only once the previous one is sent: TXE and TC
//! fall together), the TX interrupts (TXEIE, TCIE).

/// DMAMUX request IDs (device data `request:`).
pub mod req {
    /// ADC1.
    pub const ADC1: u32 = 5;
    /// DAC1 channel 1.
    pub const DAC1_CH1: u32 = 6;
    /// LPUART1 RX.
    pub const LPUART1_RX: u32 = 34;
    /// LPUART1 TX.
    pub const LPUART1_TX: u32 = 35;
    /// ADC2.
    pub const ADC2: u32 = 36;
}

/// NVIC positions of DMA1 channels 1..8 (RM0440 vector table; device data `DMA1_CHANNELx`).
pub const DMA1_IRQ: [usize; 8] = [11, 12, 13, 14, 15, 16, 17, 96];

/// One DMA channel.
#[derive(Clone, Debug, Default)]
pub struct Channel {
    /// CCR.
    pub ccr: u32,
    /// CNDTR (remaining).
    pub ndtr: u32,
    /// CNDTR as programmed (for circular reload and HT).
    pub ndtr0: u32,
    /// CPAR.
    pub par: u32,
    /// CMAR.
    pub mar: u32,
    /// Transfers done in the current cycle (offset of the pointers).
    pub done: u32,
}

/// DMA1 with DMAMUX1's channel routing.
#[derive(Clone, Debug, Default)]
pub struct Dma {
    /// Channels 1..8.
    pub ch: [Channel; 8],
    /// ISR flags (4 bits per channel).
    pub isr: u32,
    /// DMAMUX1 CxCR (16).
    pub mux: [u32; 16],
    mux_other: [u32; 8],
}

/// One transfer a request asks for: read `src` (size), write `dst` (size).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transfer {
    /// Channel index 0..8.
    pub ch: usize,
    /// Source address and access size in bytes.
    pub src: (u32, usize),
    /// Destination address and size.
    pub dst: (u32, usize),
}

impl Dma {
    /// The enabled channel that serves request `id`, if any.
    pub fn channel_for(&self, id: u32) -> Option<usize> {
        (0..8).find(|&n| self.mux[n] & 0xFF == id && self.ch[n].ccr & 1 != 0)
    }

    /// The next transfer of channel `n` (addresses and sizes from CCR, CPAR/CMAR, the
    /// transfers done so far).
    pub fn next_transfer(&self, n: usize) -> Transfer {
        let c = &self.ch[n];
        let size = |code: u32| 1usize << code.min(2);
        let psize = size((c.ccr >> 8) & 3);
        let msize = size((c.ccr >> 10) & 3);
        let pinc = c.ccr & (1 << 6) != 0;
        let minc = c.ccr & (1 << 7) != 0;
        let pa = c.par + if pinc { c.done * psize as u32 } else { 0 };
        let ma = c.mar + if minc { c.done * msize as u32 } else { 0 };
        if c.ccr & (1 << 4) != 0 {
            Transfer {
                ch: n,
                src: (ma, msize),
                dst: (pa, psize),
            }
        } else {
            Transfer {
                ch: n,
                src: (pa, psize),
                dst: (ma, msize),
            }
        }
    }

    /// Account for a completed transfer of channel `n` (flags, counts, circular reload).
    pub fn complete(&mut self, n: usize) {
        let c = &mut self.ch[n];
        c.done += 1;
        c.ndtr = c.ndtr.saturating_sub(1);
        let shift = 4 * n;
        if c.ndtr == c.ndtr0 / 2 {
            self.isr |= (1 << 2 | 1) << shift;
        }
        if c.ndtr == 0 {
            self.isr |= (1 << 1 | 1) << shift;
            if c.ccr & (1 << 5) != 0 {
                c.ndtr = c.ndtr0;
                c.done = 0;
            } else {
                // Normal mode: the channel stops requesting (EN stays set, CNDTR 0).
            }
        }
    }

    /// A transfer error on channel `n`: TEIF, the channel disabled.
    pub fn error(&mut self, n: usize) {
        self.isr |= (1 << 3 | 1) << (4 * n);
        self.ch[n].ccr &= !1;
    }

    /// Can channel `n` transfer (enabled with transfers left)?
    pub fn ready(&self, n: usize) -> bool {
        self.ch[n].ccr & 1 != 0 && self.ch[n].ndtr != 0
    }

    /// Interrupt lines asserted (NVIC positions).
    pub fn irqs(&self) -> impl Iterator<Item = usize> + '_ {
        (0..8).filter_map(move |n| {
            let flags = (self.isr >> (4 * n)) & 0xE;
            let ie = self.ch[n].ccr & 0xE;
            (flags & ie != 0).then_some(DMA1_IRQ[n])
        })
    }

    /// DMA1 register read.
    pub fn read(&self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.isr,
            0x04 => 0,
            0x08..=0xA4 => {
                let n = ((off - 0x08) / 20) as usize;
                let c = &self.ch[n];
                match (off - 0x08) % 20 {
                    0 => c.ccr,
                    4 => c.ndtr,
                    8 => c.par,
                    12 => c.mar,
                    _ => 0,
                }
            }
            _ => return None,
        })
    }

    /// DMA1 register write; returns a rule violation, if any.
    pub fn write(&mut self, off: u32, v: u32) -> Option<Option<String>> {
        match off {
            0x00 => {}
            0x04 => {
                // IFCR: CGIFx clears all four flags of the channel.
                for n in 0..8 {
                    let bits = (v >> (4 * n)) & 0xF;
                    let clear = if bits & 1 != 0 { 0xF } else { bits };
                    self.isr &= !(clear << (4 * n));
                }
            }
            0x08..=0xA4 => {
                let n = ((off - 0x08) / 20) as usize;
                let reg = (off - 0x08) % 20;
                let c = &mut self.ch[n];
                let enabled = c.ccr & 1 != 0;
                let name = ["CCR", "CNDTR", "CPAR", "CMAR", "?"][(reg / 4) as usize];
                // A CCR write that clears EN is the channel's disable: its other bits are
                // read-only while EN = 1 (RM0440 DMA_CCRx) and keep their values, which is no
                // reconfiguration of an enabled channel.
                let changed = match reg {
                    0 => v & 1 != 0 && (c.ccr ^ v) & 0x7FFE != 0,
                    4 => c.ndtr != v & 0xFFFF,
                    8 => c.par != v,
                    12 => c.mar != v,
                    _ => false,
                };
                let before = [c.ccr, c.ndtr, c.par, c.mar, 0][(reg / 4) as usize];
                let violation = (enabled && changed).then(|| {
                    format!(
                        "DMA1 channel {} {name} changed from {before:#x} to {v:#x} while the channel is enabled (RM0440 DMA: configured only with EN = 0)",
                        n + 1
                    )
                });
                match reg {
                    0 => {
                        if v & 1 != 0 && !enabled {
                            c.done = 0;
                        }
                        if !enabled {
                            c.ccr = v & 0x7FFF;
                        } else {
                            // Only EN (and the interrupt enables) take effect while enabled.
                            c.ccr = (c.ccr & !0xF) | (v & 0xF);
                        }
                    }
                    4 if !enabled => {
                        c.ndtr = v & 0xFFFF;
                        c.ndtr0 = c.ndtr;
                    }
                    8 if !enabled => c.par = v,
                    12 if !enabled => c.mar = v,
                    _ => {}
                }
                return Some(violation);
            }
            _ => return None,
        }
        Some(None)
    }

    /// DMAMUX1 register read.
    pub fn mux_read(&self, off: u32) -> Option<u32> {
        Some(match off {
            0x00..=0x3C => self.mux[(off / 4) as usize],
            0x80 | 0x84 | 0x140 | 0x144 => 0,
            0x100..=0x10C => self.mux_other[((off - 0x100) / 4) as usize],
            _ => return None,
        })
    }

    /// DMAMUX1 register write.
    pub fn mux_write(&mut self, off: u32, v: u32) -> Option<Option<String>> {
        match off {
            0x00..=0x3C => {
                let n = (off / 4) as usize;
                let violation = (n < 8 && self.ch[n].ccr & 1 != 0 && (self.mux[n] ^ v) & 0xFF != 0).then(|| {
                    format!("DMAMUX1 channel {n} request changed while DMA1 channel {} is enabled (RM0440 DMAMUX)", n + 1)
                });
                self.mux[n] = v;
                Some(violation)
            }
            0x84 | 0x144 => Some(None),
            0x100..=0x10C => {
                self.mux_other[((off - 0x100) / 4) as usize] = v;
                Some(None)
            }
            _ => None,
        }
    }
}

/// The RX line's rate, Bd: the host's, as the ST-LINK virtual COM port sends it
/// (docs/protocol.md: 115 200 Bd, 8N1).
pub const LINE_BAUD: f64 = 115_200.0;

/// The largest relative deviation of the receiver's rate from the line's at which an 8N1
/// frame's stop bit, sampled at its middle 9.5 bit times after the start edge, still falls
/// inside its bit: 0.5 / 9.5. Ours, from the frame's geometry: RM0440's table of the
/// receiver's tolerance (which adds the oversampling's quantisation) is tighter, so the model
/// errs on the lenient side.
pub const RX_TOLERANCE: f64 = 0.5 / 9.5;

/// What a receiver at `rx_baud` makes of `byte` sent 8N1 at [`LINE_BAUD`]: each of its bits
/// sampled at the middle of the receiver's own bit time from the start edge (the start bit,
/// the data LSB first, the stop bit; the line idles high after it). `None` when the start bit
/// does not read low (no frame); else (data, stop bit read high).
pub fn sample_frame(byte: u8, rx_baud: f64) -> Option<(u8, bool)> {
    let line_bits_per_rx_bit = LINE_BAUD / rx_baud;
    let line = |k: u32| -> bool {
        let i = ((k as f64 + 0.5) * line_bits_per_rx_bit).floor();
        match i as i64 {
            0 => false,
            i @ 1..=8 => byte >> (i - 1) & 1 == 1,
            _ => true,
        }
    };
    if line(0) {
        return None;
    }
    let data = (0..8).fold(0u8, |d, k| d | (line(k + 1) as u8) << k);
    Some((data, line(9)))
}

/// LPUART1.
#[derive(Clone, Debug, Default)]
pub struct Lpuart {
    cr1: u32,
    cr2: u32,
    /// CR3.
    pub cr3: u32,
    brr: u32,
    presc: u32,
    /// ISR flags (RXNE 5, IDLE 4, ORE 3).
    isr: u32,
    rdr: u32,
    /// Bytes to receive, each with its arrival time (s).
    pub rx: std::collections::VecDeque<(f64, u8)>,
    /// When IDLE rises (s), after the last byte.
    idle_at: Option<f64>,
    /// The byte on the TX line is sent at this time (s); `None`: the transmitter is free.
    tx_busy_until: Option<f64>,
    /// A DMA request for the byte in RDR, not yet served.
    pub dma_pending: bool,
    /// Bytes the image transmitted.
    pub tx: Vec<u8>,
    /// The receiver's rate off the line's beyond [`RX_TOLERANCE`]: the rule, for the
    /// peripherals' violation list to take (once per reset).
    pub rate_mismatch: Option<String>,
    rate_mismatch_found: bool,
}

impl Lpuart {
    /// Enabled receiver?
    pub fn receiving(&self) -> bool {
        self.cr1 & 0b101 == 0b101
    }

    /// The baud rate at kernel clock `f_ck` Hz (RM0440 LPUART "Baud rate generation":
    /// 256 × f_ck / PRESC / BRR; 0 with BRR unset).
    pub fn baud(&self, f_ck: f64) -> f64 {
        if self.brr == 0 {
            return 0.0;
        }
        // RM0440 LPUART_PRESC: /1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256 (and 256 above).
        const DIV: [f64; 12] = [
            1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0, 32.0, 64.0, 128.0, 256.0,
        ];
        let div = DIV[(self.presc as usize).min(11)];
        256.0 * f_ck / div / self.brr as f64
    }

    /// The frame time at kernel clock `f_ck` Hz, s (10 bits).
    pub fn frame_s(&self, f_ck: f64) -> f64 {
        10.0 / self.baud(f_ck)
    }

    /// Queue `bytes` arriving back to back on the line from time `t0` ([`LINE_BAUD`]).
    pub fn send(&mut self, t0: f64, bytes: &[u8]) {
        let frame = 10.0 / LINE_BAUD;
        let mut t = self.rx.back().map_or(t0, |(last, _)| last.max(t0));
        for &b in bytes {
            t += frame;
            self.rx.push_back((t, b));
        }
    }

    /// The next event: a byte arriving, the idle line, the TX byte sent, s.
    pub fn next_event(&self) -> Option<f64> {
        let rx = self
            .receiving()
            .then(|| [self.rx.front().map(|r| r.0), self.idle_at])
            .into_iter()
            .flatten();
        rx.chain([self.tx_busy_until]).flatten().reduce(f64::min)
    }

    /// The transmitter asks the DMA for a byte: DMAT, TE and UE set, no byte on the line.
    pub fn tx_request(&self) -> bool {
        self.cr3 & (1 << 7) != 0 && self.cr1 & 0b1001 == 0b1001 && self.tx_busy_until.is_none()
    }

    /// The byte on the TX line sent by `t`: the transmitter is free.
    fn tx_advance(&mut self, t: f64) {
        if self.tx_busy_until.is_some_and(|u| u <= t) {
            self.tx_busy_until = None;
        }
    }

    /// Take the byte arriving by `t` into RDR, as the receiver at its own rate reads it;
    /// returns true if a DMA request is raised.
    pub fn advance(&mut self, t: f64, f_ck: f64) -> bool {
        self.tx_advance(t);
        let mut request = false;
        if let Some(&(at, b)) = self.rx.front() {
            if at <= t && self.receiving() {
                self.rx.pop_front();
                let baud = self.baud(f_ck);
                let deviation = baud / LINE_BAUD - 1.0;
                // (A NaN deviation, BRR unset, is beyond any tolerance.)
                let within = deviation.abs() <= RX_TOLERANCE;
                if !within && !self.rate_mismatch_found {
                    self.rate_mismatch_found = true;
                    self.rate_mismatch = Some(format!(
                        "LPUART1 receives at {baud:.0} Bd, the line runs at {LINE_BAUD:.0} Bd ({:+.1} %, beyond the 8N1 frame's ±{:.1} %): RM0440 LPUART \"Tolerance of the LPUART receiver to clock deviation\"",
                        100.0 * deviation,
                        100.0 * RX_TOLERANCE
                    ));
                }
                let frame = sample_frame(b, baud);
                if frame.is_some_and(|(_, stop)| !stop) {
                    self.isr |= 1 << 1; // FE
                }
                if let Some((b, _)) = frame {
                    if self.isr & (1 << 5) != 0 && self.cr3 & (1 << 12) == 0 {
                        self.isr |= 1 << 3; // ORE: the new byte is lost
                    } else {
                        self.rdr = b as u32;
                        self.isr |= 1 << 5;
                        if self.cr3 & (1 << 6) != 0 {
                            self.dma_pending = true;
                            request = true;
                        }
                    }
                }
                self.idle_at = Some(at + self.frame_s(f_ck));
            }
        }
        if let Some(at) = self.idle_at {
            if at <= t && self.rx.front().is_none_or(|r| r.0 > at) {
                self.idle_at = None;
                self.isr |= 1 << 4;
            }
        }
        request
    }

    /// The DMA read RDR.
    pub fn dma_served(&mut self) {
        self.dma_pending = false;
        self.isr &= !(1 << 5);
    }

    /// The LPUART1 interrupt line.
    pub fn irq(&self) -> bool {
        (self.cr1 & (1 << 5) != 0 && self.isr & (1 << 5 | 1 << 3) != 0)
            || (self.cr1 & (1 << 4) != 0 && self.isr & (1 << 4) != 0)
            || (self.cr3 & 1 != 0 && self.isr & (1 << 3 | 1 << 1) != 0)
    }

    /// Register read (RDR clears RXNE).
    pub fn read(&mut self, off: u32) -> Option<u32> {
        Some(match off {
            0x00 => self.cr1,
            0x04 => self.cr2,
            0x08 => self.cr3,
            0x0C => self.brr,
            0x10 | 0x14 | 0x18 | 0x20 => 0,
            0x1C => {
                let ue = self.cr1 & 1 != 0;
                let tx_free = (self.tx_busy_until.is_none() as u32) << 7
                    | (self.tx_busy_until.is_none() as u32) << 6;
                self.isr
                    | tx_free // TXE, TC
                    | ((ue && self.cr1 & 8 != 0) as u32) << 21
                    | ((ue && self.cr1 & 4 != 0) as u32) << 22
            }
            0x24 => {
                self.isr &= !(1 << 5);
                self.rdr
            }
            0x28 => 0,
            0x2C => self.presc,
            _ => return None,
        })
    }

    /// Register write at time `t` (s), the kernel clock at `f_ck` Hz.
    pub fn write(&mut self, off: u32, v: u32, t: f64, f_ck: f64) -> Option<()> {
        match off {
            0x00 => self.cr1 = v,
            0x04 => self.cr2 = v,
            0x08 => self.cr3 = v,
            0x0C => self.brr = v & 0xF_FFFF,
            0x10 | 0x14 => {}
            0x18 => {
                if v & (1 << 3) != 0 {
                    self.isr &= !(1 << 5); // RXFRQ: flush RDR
                }
            }
            0x20 => self.isr &= !(v & ((1 << 3) | (1 << 4) | 0b111)),
            0x28 => {
                self.tx.push(v as u8);
                self.tx_busy_until = Some(t + self.frame_s(f_ck));
            }
            0x2C => self.presc = v & 0xF,
            _ => return None,
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circular_channel_reloads_and_flags_half_and_full() {
        // RM0440 DMA: in circular mode CNDTR reloads at 0; HTIF at half, TCIF at the end.
        let mut d = Dma::default();
        d.mux_write(0, req::ADC1).unwrap();
        d.write(0x08 + 4, 4).unwrap();
        d.write(0x08 + 8, 0x5000_0040).unwrap();
        d.write(0x08 + 12, 0x2000_0100).unwrap();
        // MINC, CIRC, PSIZE 16, MSIZE 16, HTIE, TCIE, EN.
        d.write(0x08, (1 << 7) | (1 << 5) | (1 << 8) | (1 << 10) | 0b111)
            .unwrap();
        assert_eq!(d.channel_for(req::ADC1), Some(0));
        assert_eq!(d.channel_for(req::ADC2), None);
        let t = d.next_transfer(0);
        assert_eq!((t.src, t.dst), ((0x5000_0040, 2), (0x2000_0100, 2)));
        d.complete(0);
        assert_eq!(d.isr & 0xF, 0);
        d.complete(0);
        assert_eq!(d.isr & 0xF, 0b0101, "GIF | HTIF");
        assert_eq!(d.irqs().collect::<Vec<_>>(), vec![11]);
        d.complete(0);
        d.complete(0);
        assert_eq!(d.isr & 0xF, 0b0111, "TCIF too");
        assert_eq!(d.ch[0].ndtr, 4, "reloaded");
        assert_eq!(d.next_transfer(0).dst.0, 0x2000_0100, "back to the start");
        // Reconfiguring while enabled breaks the rule and is ignored.
        assert!(d.write(0x08 + 12, 0x2000_0200).unwrap().is_some());
        assert_eq!(d.ch[0].mar, 0x2000_0100);
        // IFCR CGIF1 clears all four.
        d.write(0x04, 1).unwrap();
        assert_eq!(d.isr & 0xF, 0);
    }

    #[test]
    fn lpuart_bytes_arrive_a_frame_apart_then_idle() {
        let mut u = Lpuart::default();
        let pclk = 170e6;
        // BRR for the line's 115 200 Bd: 256 × 170 MHz / 115 200.
        let brr = (256.0 * pclk / LINE_BAUD).round() as u32;
        u.write(0x0C, brr, 0.0, pclk).unwrap();
        u.write(0x08, 1 << 6, 0.0, pclk).unwrap();
        u.write(0x00, 0b101 | (1 << 4), 0.0, pclk).unwrap();
        let frame = 10.0 / LINE_BAUD;
        u.send(0.0, b"ab");
        assert!((u.next_event().unwrap() - frame).abs() < 1e-15);
        assert!(u.advance(frame, pclk));
        u.dma_served();
        assert!(u.advance(2.0 * frame, pclk));
        assert!(!u.irq(), "no idle yet");
        // (The receiver's own frame time: BRR rounds its rate by 2 ppm.)
        assert!(!u.advance(3.0 * frame * 1.000_01, pclk));
        assert!(u.irq(), "IDLE with IDLEIE");
        assert_eq!(u.rdr, b'b' as u32);
        assert!(u.rate_mismatch.is_none());
    }

    /// A receiver at the line's rate reads every byte as sent; within the 8N1 frame's
    /// tolerance (0.5/9.5) too; at 9600 Bd on a 115 200 Bd line (the line's bits twelve to the
    /// receiver's one) it reads the bits of the wrong times, and the rule is recorded with the
    /// rates.
    #[test]
    fn lpuart_reads_the_line_at_its_own_rate() {
        for b in 0..=255u8 {
            assert_eq!(sample_frame(b, LINE_BAUD), Some((b, true)));
            assert_eq!(sample_frame(b, LINE_BAUD * 1.05), Some((b, true)), "{b}");
            assert_eq!(sample_frame(b, LINE_BAUD / 1.05), Some((b, true)), "{b}");
        }
        // 12 line bits per receiver bit: the start bit is sampled at line bit 6 (data bit 5),
        // the data past the frame (idle, high).
        assert_eq!(sample_frame(0b0010_0000, 9600.0), None);
        assert_eq!(sample_frame(0x00, 9600.0), Some((0xFF, true)));
        let mut u = Lpuart::default();
        let pclk = 170e6;
        // PRESC /6 (BRR is 20 bits): 256 × 170 MHz / 6 / 9600.
        u.write(0x2C, 3, 0.0, pclk).unwrap();
        let brr = (256.0 * pclk / 6.0 / 9600.0_f64).round() as u32;
        u.write(0x0C, brr, 0.0, pclk).unwrap();
        u.write(0x08, 1 << 6, 0.0, pclk).unwrap();
        u.write(0x00, 0b101, 0.0, pclk).unwrap();
        u.send(0.0, &[0x00]);
        u.advance(1.0, pclk);
        assert_eq!(u.rdr, 0xFF);
        let rule = u.rate_mismatch.expect("the rule");
        assert!(
            rule.contains("9600 Bd") && rule.contains("115200 Bd"),
            "{rule}"
        );
    }

    /// RM0440 LPUART "Transmission using DMA": with DMAT, TE and UE the free transmitter
    /// requests a byte; a byte written to TDR takes one frame (10 bits at 256 × f_ck / BRR baud)
    /// during which TXE and TC read clear and nothing is requested.
    #[test]
    fn lpuart_sends_a_byte_per_frame_time_on_dma_requests() {
        let mut u = Lpuart::default();
        let pclk = 170e6;
        // BRR for 115 200 Bd: 256 × 170 MHz / 115 200.
        let brr = (256.0 * pclk / 115_200.0_f64).round() as u32;
        u.write(0x0C, brr, 0.0, pclk).unwrap();
        u.write(0x00, 0b1001, 0.0, pclk).unwrap();
        assert!(!u.tx_request(), "no DMAT: no request");
        u.write(0x08, 1 << 7, 0.0, pclk).unwrap();
        assert!(u.tx_request());
        u.write(0x28, 0x5A, 1e-3, pclk).unwrap();
        let frame = 10.0 / 115_200.0;
        assert!(!u.tx_request());
        assert_eq!(u.read(0x1C).unwrap() & (3 << 6), 0, "TXE and TC clear");
        let sent = u.next_event().unwrap();
        assert!((sent - (1e-3 + frame)).abs() < 1e-9, "{sent}");
        u.advance(sent, pclk);
        assert!(u.tx_request());
        assert_eq!(u.read(0x1C).unwrap() & (3 << 6), 3 << 6);
        assert_eq!(u.tx, [0x5A]);
    }
}
