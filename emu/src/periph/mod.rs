//! The STM32G474RE's peripherals the image uses, at register level, and the bus that routes the
//! CPU's accesses to them through their RCC clock gates.
//!
//! Addresses are those of stm32-metapac's `stm32g474re` (generated from ST's device data, as
//! embassy uses them) and RM0440's memory map (2.2.2, Table 3 "STM32G4 series memory map and
//! peripheral register boundary addresses").
//!
//! # Clock gating (RM0440 RCC, "Peripheral clock enable registers")
//! With its enable bit clear a peripheral's registers cannot be accessed: the model ignores
//! the write, reads 0, and records the access as a rule violation ([`Violation`]).
//!
//! Each peripheral module states what it leaves out. An access to an address no model covers
//! stops the run naming the address: nothing reads as a silent zero.

pub mod analog;
pub mod dma;
pub mod flash;
pub mod gpio;
pub mod iwdg;
pub mod rcc;

pub use rcc::SysClock;

/// What reset the core (RCC_CSR flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// AIRCR.SYSRESETREQ (SFTRSTF).
    Software,
    /// The IWDG ran out (IWDGRSTF).
    Watchdog,
    /// The NRST pin (PINRSTF).
    Pin,
}

/// A documented rule the image broke, with the cycle it happened at.
#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    /// Core cycle.
    pub at: u64,
    /// The rule and its source.
    pub rule: String,
}

/// Which peripheral an address belongs to, and its clock gate (enable register offset, bit).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dev {
    Rcc,
    Pwr,
    Flash,
    Iwdg,
    Dbgmcu,
    Gpio(usize),
    Otp,
    Tim6,
    Lpuart1,
    Dma1,
    Dmamux1,
    Adc(usize),
    AdcCommon,
    Dac1,
    Syscfg,
}

/// A clock gate: the enable register and the bit.
type Gate = Option<(rcc::Enr, u32)>;

fn route(addr: u32) -> Option<(Dev, u32, Gate)> {
    use rcc::Enr::{Ahb1, Ahb2, Apb1r1, Apb1r2, Apb2};
    let (dev, base, gate) = match addr {
        0x4000_1000..=0x4000_13FF => (Dev::Tim6, 0x4000_1000, Some((Apb1r1, 4))),
        0x4001_0000..=0x4001_002F => (Dev::Syscfg, 0x4001_0000, Some((Apb2, 0))),
        0x4000_8000..=0x4000_83FF => (Dev::Lpuart1, 0x4000_8000, Some((Apb1r2, 0))),
        0x4002_0000..=0x4002_03FF => (Dev::Dma1, 0x4002_0000, Some((Ahb1, 0))),
        0x4002_0800..=0x4002_0BFF => (Dev::Dmamux1, 0x4002_0800, Some((Ahb1, 2))),
        0x5000_0000..=0x5000_00FF => (Dev::Adc(0), 0x5000_0000, Some((Ahb2, 13))),
        0x5000_0100..=0x5000_01FF => (Dev::Adc(1), 0x5000_0100, Some((Ahb2, 13))),
        0x5000_0300..=0x5000_03FF => (Dev::AdcCommon, 0x5000_0300, Some((Ahb2, 13))),
        0x5000_0800..=0x5000_0BFF => (Dev::Dac1, 0x5000_0800, Some((Ahb2, 16))),
        0x4000_3000..=0x4000_33FF => (Dev::Iwdg, 0x4000_3000, None),
        0x4000_7000..=0x4000_73FF => (Dev::Pwr, 0x4000_7000, Some((Apb1r1, 28))),
        0x4002_1000..=0x4002_13FF => (Dev::Rcc, 0x4002_1000, None),
        0x4002_2000..=0x4002_23FF => (Dev::Flash, 0x4002_2000, Some((Ahb1, 8))),
        0x4800_0000..=0x4800_1BFF => {
            let n = ((addr - 0x4800_0000) / 0x400) as usize;
            (
                Dev::Gpio(n),
                0x4800_0000 + 0x400 * n as u32,
                Some((Ahb2, n as u32)),
            )
        }
        0x1FFF_7000..=0x1FFF_7FFF => (Dev::Otp, 0x1FFF_7000, None),
        0xE004_2000..=0xE004_23FF => (Dev::Dbgmcu, 0xE004_2000, None),
        _ => return None,
    };
    Some((dev, addr - base, gate))
}

/// Time integration across clock changes: seconds at core cycle `cycle` while HCLK was `hz`.
#[derive(Clone, Debug)]
struct ClockSegment {
    cycle: u64,
    seconds: f64,
    hz: f64,
}

/// The analog pins the ADCs sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pin {
    /// PA0 = ADC12_IN1 (the board's sense current, TIA output).
    Pa0,
    /// PA1 = ADC12_IN2 (the drive monitor).
    Pa1,
}

/// VREF+ = VDDA on the NUCLEO-G474RE, V.
pub const VREF: f64 = 3.3;

/// What is wired to the board's pins: DAC1 OUT1 (PA4) drives it, the ADCs sample it, and the
/// GPIO ports' outputs drive it and their inputs read it.
pub trait Wiring: std::any::Any {
    /// DAC1 channel 1's output became `volts` at time `t` (s).
    fn dac_output(&mut self, t: f64, volts: f64);
    /// The voltage on `pin` at time `t` (s).
    fn pin_voltage(&mut self, t: f64, pin: Pin) -> f64;
    /// GPIO port `port` (0 = A) drives its output pins `mask` to `levels` at time `t` (s); pins
    /// outside `mask` are not driven by the port (input, analog or alternate-function mode).
    /// Called at every write that may change them (ODR, BSRR, BRR, MODER) and at resets.
    fn gpio_outputs(&mut self, _t: f64, _port: usize, _mask: u32, _levels: u32) {}
    /// The pins of GPIO port `port` that something outside drives at time `t` (s): (mask,
    /// levels); the others read their pull. Nothing by default.
    fn gpio_inputs(&mut self, _t: f64, _port: usize) -> (u32, u32) {
        (0, 0)
    }
}

/// Nothing connected: the board without the probe's front end; both inputs at 0 V.
#[derive(Clone, Debug, Default)]
pub struct Unconnected;

impl Wiring for Unconnected {
    fn dac_output(&mut self, _t: f64, _volts: f64) {}
    fn pin_voltage(&mut self, _t: f64, _pin: Pin) -> f64 {
        0.0
    }
}

/// The memories a DMA reaches.
pub struct Mem<'a> {
    /// Flash (read only for the DMA).
    pub flash: &'a mut [u8],
    /// SRAM1+2.
    pub sram: &'a mut [u8],
    /// CCM SRAM.
    pub ccm: &'a mut [u8],
}

impl Mem<'_> {
    fn slot(&mut self, addr: u32, size: usize, write: bool) -> Option<&mut [u8]> {
        use crate::machine::*;
        let a = addr as usize;
        let (buf, base): (&mut [u8], u32) =
            if (FLASH_BASE..FLASH_BASE + FLASH_SIZE as u32).contains(&addr) {
                if write {
                    return None;
                }
                (self.flash, FLASH_BASE)
            } else if (SRAM_BASE..SRAM_BASE + SRAM_SIZE as u32).contains(&addr) {
                (self.sram, SRAM_BASE)
            } else if (CCM_ALIAS..CCM_ALIAS + CCM_SIZE as u32).contains(&addr) {
                (self.ccm, CCM_ALIAS)
            } else if (CCM_BASE..CCM_BASE + CCM_SIZE as u32).contains(&addr) {
                (self.ccm, CCM_BASE)
            } else {
                return None;
            };
        let off = a - base as usize;
        buf.get_mut(off..off + size)
    }

    fn read(&mut self, addr: u32, size: usize) -> Option<u32> {
        let b = self.slot(addr, size, false)?;
        let mut w = [0u8; 4];
        w[..size].copy_from_slice(b);
        Some(u32::from_le_bytes(w))
    }

    fn write(&mut self, addr: u32, size: usize, v: u32) -> Option<()> {
        let b = self.slot(addr, size, true)?;
        b.copy_from_slice(&v.to_le_bytes()[..size]);
        Some(())
    }
}

/// The peripherals.
pub struct Peripherals {
    /// RCC.
    pub rcc: rcc::Rcc,
    /// PWR.
    pub pwr: rcc::Pwr,
    /// Flash interface.
    pub flash: flash::FlashIf,
    /// IWDG.
    pub iwdg: iwdg::Iwdg,
    /// DBGMCU.
    pub dbgmcu: gpio::Dbgmcu,
    /// GPIOA..GPIOG.
    pub gpio: Vec<gpio::Gpio>,
    /// TIM6.
    pub tim6: analog::Tim6,
    /// DAC1.
    pub dac1: analog::Dac,
    /// ADC1, ADC2.
    pub adc: [analog::Adc; 2],
    /// ADC12 common.
    pub adc_common: analog::AdcCommon,
    /// DMA1 + DMAMUX1.
    pub dma: dma::Dma,
    /// LPUART1.
    pub lpuart: dma::Lpuart,
    /// SYSCFG's registers (stored; MEMRMP reads the boot mapping: main flash, banks not
    /// swapped). Leaves out: the memory remap's effect, bank swap, CCM SRAM protection and
    /// erase, EXTI line routing (EXTICR stored), the FPU interrupt enables.
    pub syscfg: [u32; 10],
    /// What is wired to the pins: the analog front end and the digital devices.
    pub wiring: Box<dyn Wiring>,
    /// The documented rules the image broke.
    pub violations: Vec<Violation>,
    /// The CPU stored into the flash mapping; the array is to be restored.
    pub flash_restore_pending: bool,
    clock: ClockSegment,
    reset_pending: Option<ResetCause>,
    stop_requested: bool,
    /// Time of the last switch of SYSCLK to the PLL above 80 MHz (seconds), for the AHB /2
    /// hold rule.
    pll_switch_at: Option<f64>,
    /// DAC output codes in time order (s, code), for tests and traces (bounded).
    pub dac_trace: Vec<(f64, u32)>,
    /// A TRGO from a software update event (UG) waits for `advance`.
    pending_trgo: bool,
}

impl Default for Peripherals {
    fn default() -> Self {
        Peripherals {
            rcc: rcc::Rcc::default(),
            pwr: rcc::Pwr::default(),
            flash: flash::FlashIf::default(),
            iwdg: iwdg::Iwdg::default(),
            dbgmcu: gpio::Dbgmcu::default(),
            gpio: (0..7).map(gpio::Gpio::new).collect(),
            tim6: analog::Tim6::new(),
            dac1: analog::Dac::default(),
            adc: [analog::Adc::default(), analog::Adc::default()],
            adc_common: analog::AdcCommon::default(),
            dma: dma::Dma::default(),
            lpuart: dma::Lpuart::default(),
            syscfg: [0; 10],
            wiring: Box::new(Unconnected),
            violations: Vec::new(),
            flash_restore_pending: false,
            clock: ClockSegment {
                cycle: 0,
                seconds: 0.0,
                hz: rcc::HSI_HZ,
            },
            reset_pending: None,
            stop_requested: false,
            pll_switch_at: None,
            dac_trace: Vec::new(),
            pending_trgo: false,
        }
    }
}

/// Bounded length of [`Peripherals::dac_trace`].
const DAC_TRACE_MAX: usize = 100_000;

impl Peripherals {
    /// A system reset: every peripheral to its reset state, except what survives (the flash
    /// array is the board's; the option bytes; RCC_CSR's reset flags, to which `cause` adds;
    /// the fault injections; what is wired to the pins; bytes still on their way to LPUART1).
    /// The clock restarts on HSI16.
    pub fn reset(&mut self, cause: ResetCause, now: u64) {
        let seconds = self.clock_seconds(now);
        let csr = self.rcc.csr & 0xFE00_0000;
        let hse_present = self.rcc.hse_present;
        let mut flash = self.flash.clone();
        flash.reset();
        let violations = std::mem::take(&mut self.violations);
        let wiring = std::mem::replace(&mut self.wiring, Box::new(Unconnected));
        let rx = std::mem::take(&mut self.lpuart.rx);
        let tx = std::mem::take(&mut self.lpuart.tx);
        let trace = std::mem::take(&mut self.dac_trace);
        let adc_faults = self.adc.each_ref().map(|a| a.never_ready);
        *self = Peripherals {
            flash,
            violations,
            wiring,
            dac_trace: trace,
            ..Peripherals::default()
        };
        self.lpuart.rx = rx;
        self.lpuart.tx = tx;
        self.rcc.hse_present = hse_present;
        self.adc[0].never_ready = adc_faults[0];
        self.adc[1].never_ready = adc_faults[1];
        let flag = match cause {
            ResetCause::Software => 1 << 28,
            ResetCause::Watchdog => 1 << 29,
            ResetCause::Pin => 1 << 26,
        };
        // Every reset source also drives NRST low: PINRSTF is set with it (RM0440 RCC "Reset").
        self.rcc.csr = csr | flag | (1 << 26);
        self.clock = ClockSegment {
            cycle: now,
            seconds,
            hz: rcc::HSI_HZ,
        };
        // The ports are back in their reset modes: what the outputs drove is released.
        for n in 0..self.gpio.len() {
            self.gpio_drive(n, seconds);
        }
    }

    /// Tell the wiring what port `n` drives now (at `t` s).
    fn gpio_drive(&mut self, n: usize, t: f64) {
        let (mask, levels) = self.gpio[n].outputs();
        self.wiring.gpio_outputs(t, n, mask, levels);
    }

    /// Seconds since power-on at core cycle `now`.
    pub fn clock_seconds(&self, now: u64) -> f64 {
        self.clock.seconds + (now - self.clock.cycle) as f64 / self.clock.hz
    }

    /// The core cycle at which `seconds` is reached at the present clock (not before `now`).
    fn cycle_at(&self, seconds: f64, now: u64) -> u64 {
        let c = self.clock.cycle as f64 + (seconds - self.clock.seconds) * self.clock.hz;
        (c.ceil().max(0.0) as u64).max(now)
    }

    fn retime(&mut self, now: u64) {
        let hz = self.rcc.hclk();
        if hz != self.clock.hz {
            let seconds = self.clock_seconds(now);
            self.clock = ClockSegment {
                cycle: now,
                seconds,
                hz,
            };
        }
        self.tim6.cycles_per_tick = self.rcc.cycles_per_tim1_tick().max(1.0) as u64;
    }

    fn violate(&mut self, now: u64, rule: String) {
        self.violations.push(Violation { at: now, rule });
    }

    /// A reset the peripherals asked for (the IWDG), taken by the machine.
    pub fn reset_cause_pending(&mut self) -> Option<ResetCause> {
        self.reset_pending.take()
    }

    /// A write that needs the CPU stopped so that [`Peripherals::advance`] runs at once (a
    /// DMA channel enabled with a request waiting, a reset).
    pub fn wants_stop(&mut self) -> bool {
        std::mem::take(&mut self.stop_requested)
    }

    fn adc_hz(&self) -> f64 {
        self.adc_common
            .adc_hz(self.rcc.adc12_kernel_hz(), self.rcc.hclk())
    }

    /// The next core cycle at which some peripheral has an event.
    pub fn next_event(&self, now: u64) -> Option<u64> {
        let secs = [
            self.iwdg.next_event(),
            self.flash.next_event(),
            self.adc[0].next_event(),
            self.adc[1].next_event(),
            self.lpuart.next_event(),
        ];
        secs.into_iter()
            .flatten()
            .map(|s| self.cycle_at(s, now))
            .chain(self.tim6.next_event())
            .min()
    }

    /// The interrupt lines asserted (NVIC positions).
    pub fn irq_lines(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self.dma.irqs().collect();
        if self.tim6.irq() || self.dac1.irq() {
            v.push(54); // TIM6_DAC
        }
        if self.adc[0].irq() || self.adc[1].irq() {
            v.push(18); // ADC1_2
        }
        if self.lpuart.irq() {
            v.push(91);
        }
        v
    }

    /// Process the events due by `now`, in time order, and serve waiting DMA requests.
    pub fn advance(&mut self, now: u64, mem: &mut Mem<'_>) {
        if std::mem::take(&mut self.pending_trgo) {
            self.trgo(now, mem);
        }
        self.serve_pending(now, mem);
        loop {
            // Events in seconds (other clock domains) are processed at their own time, so that
            // their `until <= t` tests hold however the cycle they fall in rounds.
            let t_of = |p: &Self, s: Option<f64>| s.map(|s| (p.cycle_at(s, 0), Some(s)));
            let candidates = [
                (0, self.tim6.next_event().map(|c| (c, None))),
                (1, t_of(self, self.adc[0].next_event())),
                (2, t_of(self, self.adc[1].next_event())),
                (3, t_of(self, self.lpuart.next_event())),
                (4, t_of(self, self.flash.next_event())),
                (5, t_of(self, self.iwdg.next_event())),
            ];
            let Some((which, (at, secs))) = candidates
                .into_iter()
                .filter_map(|(w, c)| c.map(|c| (w, c)))
                .filter(|&(_, (c, _))| c <= now)
                .min_by_key(|&(w, (c, _))| (c, w))
            else {
                break;
            };
            let t = secs.unwrap_or_else(|| self.clock_seconds(at));
            match which {
                0 => {
                    if self.tim6.overflow(at) {
                        self.trgo(at, mem);
                    }
                }
                1 | 2 => {
                    let i = which - 1;
                    self.adc[i].advance_calibration(t);
                    if let Some((sample_t, end)) = self.adc[i].converting {
                        if self.cycle_at(end, 0) <= now {
                            let (ch, _) = self.adc[i].channel();
                            let pin = match ch {
                                1 => Some(Pin::Pa0),
                                2 => Some(Pin::Pa1),
                                _ => None,
                            };
                            let code = match pin {
                                Some(p) => {
                                    let v = self.wiring.pin_voltage(sample_t, p);
                                    ((v / VREF * 4096.0).floor()).clamp(0.0, 4095.0) as u32
                                }
                                None => {
                                    self.violate(at, format!("ADC{} converts channel {ch}, which the board does not wire (model: IN1 = PA0, IN2 = PA1)", i + 1));
                                    0
                                }
                            };
                            let hz = self.adc_hz();
                            if self.adc[i].finish(code, hz) {
                                self.request([dma::req::ADC1, dma::req::ADC2][i], at, mem);
                            }
                        }
                    }
                }
                3 => {
                    let f_ck = self.rcc.lpuart1_kernel_hz();
                    if self.lpuart.advance(t, f_ck) {
                        self.request(dma::req::LPUART1_RX, at, mem);
                    }
                    if let Some(rule) = self.lpuart.rate_mismatch.take() {
                        self.violate(at, rule);
                    }
                    if self.lpuart.tx_request() {
                        self.request(dma::req::LPUART1_TX, at, mem);
                    }
                }
                4 => self.flash.advance(t, mem.flash),
                _ => {
                    if self.iwdg.expired(t) {
                        self.reset_pending = Some(ResetCause::Watchdog);
                        break;
                    }
                }
            }
        }
    }

    /// TIM6_TRGO at cycle `at`: the DAC and the ADCs waiting for it.
    fn trgo(&mut self, at: u64, mem: &mut Mem<'_>) {
        let t = self.clock_seconds(at);
        let (out, req, violation) = self.dac1.trigger(analog::Trigger::Tim6Trgo);
        if let Some(v) = violation {
            self.violate(at, v);
        }
        let need = analog::dac_hfsel_needed(self.rcc.hclk());
        if out.is_some() && !self.dac1.hfsel_flagged && self.dac1.hfsel() < need {
            self.dac1.hfsel_flagged = true;
            let v = format!(
                "DAC1 converting with DAC_MCR.HFSEL {:#04b} at HCLK {:.0} MHz, which needs {need:#04b} (RM0440 DAC_MCR)",
                self.dac1.hfsel(),
                self.rcc.hclk() / 1e6
            );
            self.violate(at, v);
        }
        if let Some(code) = out {
            self.dac_out(t, code);
        }
        if req {
            self.request(dma::req::DAC1_CH1, at, mem);
        }
        let hz = self.adc_hz();
        for adc in &mut self.adc {
            adc.trigger(analog::Trigger::Tim6Trgo, t, hz);
        }
    }

    fn dac_out(&mut self, t: f64, code: u32) {
        self.wiring.dac_output(t, code as f64 * VREF / 4096.0);
        if self.dac_trace.len() < DAC_TRACE_MAX {
            self.dac_trace.push((t, code));
        }
    }

    /// Serve the requests that wait for a channel (after a channel was enabled).
    fn serve_pending(&mut self, now: u64, mem: &mut Mem<'_>) {
        if self.dac1.dma_pending {
            self.request(dma::req::DAC1_CH1, now, mem);
        }
        for (i, id) in [dma::req::ADC1, dma::req::ADC2].into_iter().enumerate() {
            if self.adc[i].dma_pending {
                self.request(id, now, mem);
            }
        }
        if self.lpuart.dma_pending {
            self.request(dma::req::LPUART1_RX, now, mem);
        }
        if self.lpuart.tx_request() {
            self.request(dma::req::LPUART1_TX, now, mem);
        }
    }

    /// DMA request `id` at cycle `at`: one transfer on the channel routed to it, if any is
    /// enabled with transfers left; else the request waits.
    fn request(&mut self, id: u32, at: u64, mem: &mut Mem<'_>) {
        let Some(n) = self.dma.channel_for(id) else {
            return;
        };
        if !self.dma.ready(n) {
            return;
        }
        let tr = self.dma.next_transfer(n);
        let value = match self.dma_read(tr.src.0, tr.src.1, at, mem) {
            Some(v) => v,
            None => {
                self.dma.error(n);
                return;
            }
        };
        // Size conversion: a narrower destination keeps the LSBs, a wider one is zero-extended.
        let value = if tr.dst.1 < 4 {
            value & ((1u32 << (8 * tr.dst.1)) - 1)
        } else {
            value
        };
        if self.dma_write(tr.dst.0, tr.dst.1, value, at, mem).is_none() {
            self.dma.error(n);
            return;
        }
        match id {
            dma::req::DAC1_CH1 => self.dac1.dma_served(),
            dma::req::ADC1 => self.adc[0].dma_served(),
            dma::req::ADC2 => self.adc[1].dma_served(),
            dma::req::LPUART1_RX => self.lpuart.dma_served(),
            _ => {}
        }
        self.dma.complete(n);
    }

    fn dma_read(&mut self, addr: u32, size: usize, at: u64, mem: &mut Mem<'_>) -> Option<u32> {
        if let Some(v) = mem.read(addr, size) {
            return Some(v);
        }
        route(addr)?;
        self.read(addr, size, at).ok()
    }

    fn dma_write(
        &mut self,
        addr: u32,
        size: usize,
        v: u32,
        at: u64,
        mem: &mut Mem<'_>,
    ) -> Option<()> {
        if mem.write(addr, size, v).is_some() {
            return Some(());
        }
        route(addr)?;
        // A DMA write to a peripheral is a 32-bit bus access of the value (the AHB/APB bridge
        // replicates narrower data; the DAC takes it as a word).
        let (size, v) = if size < 4 { (4, v) } else { (size, v) };
        self.write(addr, size, v, at).ok()
    }

    /// A CPU store into the flash mapping (through unicorn's write-protection hook).
    pub fn flash_write(&mut self, array: &[u8], addr: u32, size: usize, value: u64, now: u64) {
        let t = self.clock_seconds(now);
        let off = (addr - crate::machine::FLASH_BASE) as usize;
        if !self.rcc.enabled(rcc::Enr::Ahb1, 8) {
            self.violate(
                now,
                format!("flash write at {addr:#010x} with FLASHEN clear"),
            );
        }
        if let Some(note) = self.flash.cpu_store(off, size, value as u32, t, array) {
            self.violate(
                now,
                format!("FLASH: {note} (RM0440 FLASH \"Flash memory programming sequence\")"),
            );
        }
    }

    /// Undo the CPU's stores into the read-only flash mapping.
    pub fn flash_restore(&mut self, array: &mut [u8]) {
        for (off, bytes) in self.flash.take_restore() {
            array[off..off + bytes.len()].copy_from_slice(&bytes);
        }
    }

    /// Read `size` bytes at `addr` (the CPU's or a DMA's access).
    pub fn read(&mut self, addr: u32, size: usize, now: u64) -> Result<u32, String> {
        let (dev, off, gate) =
            route(addr).ok_or_else(|| "no peripheral model at this address".to_string())?;
        if let Some((reg, bit)) = gate {
            if !self.rcc.enabled(reg, bit) {
                self.violate(now, format!("read of {dev:?} (+{off:#x}) with its clock off (RCC {:#x} bit {bit}): RM0440 RCC, peripheral clock enable registers", reg.offset()));
                return Ok(0);
            }
        }
        let t = self.clock_seconds(now);
        let word = off & !3;
        let shift = (off & 3) * 8;
        if dev == Dev::Dac1
            && size != 4
            && matches!(word, 0x08 | 0x0C | 0x10 | 0x20 | 0x24 | 0x28 | 0x2C)
        {
            self.violate(now, format!("{size}-byte read of DAC1 +{word:#x}: the DAC takes word accesses only (RM0440 DAC registers)"));
        }
        let v = self.peek(dev, word, t, now, true);
        v.map(|v| v >> shift)
            .ok_or_else(|| format!("{dev:?} register +{word:#x} not modelled"))
    }

    /// Register value (`consume`: the read's side effects, e.g. clearing EOC/RXNE).
    fn peek(&mut self, dev: Dev, word: u32, t: f64, now: u64, consume: bool) -> Option<u32> {
        match dev {
            Dev::Rcc => self.rcc.read(word),
            Dev::Pwr => self.pwr.read(word),
            Dev::Flash => self.flash.read(word),
            Dev::Iwdg => self.iwdg.read(word, t),
            Dev::Dbgmcu => self.dbgmcu.read(word),
            Dev::Gpio(n) => {
                if word == 0x10 {
                    self.gpio[n].external = self.wiring.gpio_inputs(t, n);
                }
                self.gpio[n].read(word)
            }
            Dev::Otp => Some(match 0x1FFF_7000 + word {
                // FLASHSIZE_BASE (0x1FFF_75E0): 512 KiB; package data, UID: zeros.
                0x1FFF_75E0 => 0x0200,
                _ => 0,
            }),
            Dev::Tim6 => self.tim6.read(word, now),
            Dev::Lpuart1 => {
                if consume {
                    self.lpuart.read(word)
                } else {
                    self.lpuart.clone().read(word)
                }
            }
            Dev::Dma1 => self.dma.read(word),
            Dev::Dmamux1 => self.dma.mux_read(word),
            Dev::Adc(i) => {
                if consume {
                    self.adc[i].read(word)
                } else {
                    self.adc[i].clone().read(word)
                }
            }
            Dev::AdcCommon => match word {
                0x0 => {
                    let a = |i: usize| self.adc[i].isr & 0x7FF;
                    Some(a(0) | a(1) << 16)
                }
                0x8 => Some(self.adc_common.ccr),
                0xC => Some(self.adc[0].dr & 0xFFFF | (self.adc[1].dr & 0xFFFF) << 16),
                0x10 => Some(0),
                _ => None,
            },
            Dev::Dac1 => self.dac1.read(word, t),
            Dev::Syscfg => self.syscfg.get((word / 4) as usize).copied(),
        }
    }

    /// Write `size` bytes `v` at `addr` (the CPU's or a DMA's access).
    pub fn write(&mut self, addr: u32, size: usize, v: u32, now: u64) -> Result<(), String> {
        let (dev, off, gate) =
            route(addr).ok_or_else(|| "no peripheral model at this address".to_string())?;
        if let Some((reg, bit)) = gate {
            if !self.rcc.enabled(reg, bit) {
                self.violate(now, format!("write of {v:#x} to {dev:?} (+{off:#x}) with its clock off (RCC {:#x} bit {bit}): RM0440 RCC, peripheral clock enable registers", reg.offset()));
                return Ok(());
            }
        }
        let t = self.clock_seconds(now);
        let word = off & !3;
        // Narrow writes: merge into the register (byte lanes), as the APB bridge does for
        // the peripherals that allow it (the DAC does not: its model sees the size).
        let full = if size < 4 && dev != Dev::Dac1 {
            let cur = self.peek(dev, word, t, now, false).unwrap_or(0);
            let shift = (off & 3) * 8;
            let mask = ((1u64 << (8 * size)) - 1) as u32;
            (cur & !(mask << shift)) | ((v & mask) << shift)
        } else {
            v
        };
        let ok = match dev {
            Dev::Rcc => self.rcc_write(word, full, now),
            Dev::Pwr => self.pwr.write(word, full),
            Dev::Flash => {
                let hclk = self.rcc.hclk();
                let before = self.flash.latency();
                let r = self.flash.write(word, full, t, &[]).map(|note| {
                    if let Some(n) = note {
                        self.violate(now, n);
                    }
                });
                if word == 0 && self.flash.latency() < before {
                    let need = rcc::wait_states_needed(hclk, self.pwr.range1(), self.pwr.boost());
                    if self.flash.latency() < need {
                        self.violate(now, format!("FLASH_ACR.LATENCY lowered to {} at HCLK {:.0} Hz, which needs {need} (RM0440 FLASH \"Read access latency\")", self.flash.latency(), hclk));
                    }
                }
                r
            }
            Dev::Iwdg => self.iwdg.write(word, full, t),
            Dev::Dbgmcu => self.dbgmcu.write(word, full),
            Dev::Gpio(n) => self.gpio[n].write(word, full).map(|()| {
                if matches!(word, 0x00 | 0x14 | 0x18 | 0x28) {
                    self.gpio_drive(n, t);
                }
            }),
            Dev::Otp => None,
            Dev::Tim6 => {
                self.retime(now);
                let trgo = self.tim6.write(word, full, now);
                if trgo == Some(true) {
                    self.stop_requested = true;
                    self.pending_trgo = true;
                }
                trgo.map(|_| ())
            }
            Dev::Lpuart1 => {
                let f_ck = self.rcc.lpuart1_kernel_hz();
                let r = self.lpuart.write(word, full, t, f_ck);
                // DMAT set, or TE/UE: a free transmitter asks for its first byte.
                self.stop_requested |= self.lpuart.tx_request();
                r
            }
            Dev::Dma1 => self.dma.write(word, full).map(|v| {
                if let Some(v) = v {
                    self.violate(now, v);
                }
                self.stop_requested = true;
            }),
            Dev::Dmamux1 => self.dma.mux_write(word, full).map(|v| {
                if let Some(v) = v {
                    self.violate(now, v);
                }
                self.stop_requested = true;
            }),
            Dev::Adc(i) => {
                let hz = self.adc_hz();
                self.adc[i].write(word, full, t, hz).map(|w| {
                    if let Some(v) = w.violation {
                        self.violate(now, format!("ADC{}: {v}", i + 1));
                    }
                })
            }
            Dev::AdcCommon => match word {
                0x8 => {
                    let old = self.adc_common.ccr;
                    // PRESC, CKMODE, DUAL (and DELAY, DMACFG, MDMA) with either ADC enabled.
                    let locked =
                        (0xF << 18) | (3 << 16) | 0x1F | (0xF << 8) | (1 << 13) | (3 << 14);
                    if (old ^ full) & locked != 0
                        && (self.adc[0].enabled() || self.adc[1].enabled())
                    {
                        self.violate(now, format!(
                            "ADC12_CCR {old:#x} -> {full:#x} (PRESC/CKMODE/DUAL/DELAY/MDMA) while ADC1 or ADC2 is enabled (RM0440 ADC_CCR: written only with ADEN = 0 in both)"
                        ));
                    }
                    self.adc_common.ccr = full;
                    Some(())
                }
                0x0 | 0xC | 0x10 => Some(()),
                _ => None,
            },
            Dev::Syscfg => match word {
                // MEMRMP: MEM_MODE and FB_MODE are kept as the boot set them (remap and bank
                // swap not modelled: a change is refused as unmodelled).
                0x00 if full & 0x107 != self.syscfg[0] & 0x107 => None,
                0x00..=0x24 => {
                    self.syscfg[(word / 4) as usize] = full;
                    Some(())
                }
                _ => None,
            },
            Dev::Dac1 => self.dac1.write(word, size, full, t).map(|w| {
                if let Some(v) = w.violation {
                    self.violate(now, format!("DAC1: {v}"));
                }
                if let Some(code) = w.output {
                    self.dac_out(t, code);
                }
            }),
        };
        ok.ok_or_else(|| format!("{dev:?} register +{word:#x} not modelled"))
    }

    /// RCC writes with the clock-switch rules: RM0440 6.1.5 (PWR "Dynamic voltage scaling
    /// management", the range 1 boost sequence: 1. the AHB divided by 2 before the switch to a
    /// higher frequency, 2. R1MODE cleared, 3. the wait states for the new frequency, 4. the
    /// switch, 5. at least 1 µs, then the AHB prescaler for the target HCLK), checked as: a switch
    /// to the PLL above 80 MHz with HPRE /1 in force breaks it (ST's HAL, `stm32g4xx_hal_rcc.c`
    /// `HAL_RCC_ClockConfig`, takes the same 80 MHz threshold for its intermediate /2), and so
    /// does HPRE back to /1 sooner than 1 µs after the switch; steps 2 and 3 as the flash
    /// latency table for range 1 normal or boost (3.3.3, Table 9), which every HCLK must
    /// satisfy when it applies.
    fn rcc_write(&mut self, off: u32, v: u32, now: u64) -> Option<()> {
        let t = self.clock_seconds(now);
        let hclk_before = self.rcc.hclk();
        let sws_before = self.rcc.sws();
        let r = self.rcc.write(off, v)?;
        let hclk = self.rcc.hclk();
        if hclk != hclk_before {
            let need = rcc::wait_states_needed(hclk, self.pwr.range1(), self.pwr.boost());
            if self.flash.latency() < need {
                self.violate(now, format!(
                    "HCLK raised to {hclk:.0} Hz with FLASH_ACR.LATENCY {} (needs {need}; range 1 {}, boost {}): RM0440 FLASH \"Read access latency\", PWR \"Dynamic voltage scaling management\"",
                    self.flash.latency(), self.pwr.range1(), self.pwr.boost()
                ));
            }
            self.retime(now);
        }
        if off == 0x08 {
            let sysclk = self.rcc.sysclk();
            let hpre = rcc::ahb_div(self.rcc.cfgr >> 4);
            if self.rcc.sws() != sws_before && self.rcc.sws() == 3 && sysclk > 80e6 {
                if hpre < 2 {
                    self.violate(now, format!(
                        "SYSCLK switched to the PLL at {:.0} MHz with HPRE /1 in force (RM0440 6.1.5, range 1 boost sequence: divide the AHB by 2 before switching above 80 MHz and wait 1 us before /1)",
                        sysclk / 1e6
                    ));
                } else {
                    self.pll_switch_at = Some(t);
                }
            } else if hpre == 1 {
                if let Some(at) = self.pll_switch_at.take() {
                    if t - at < 1e-6 {
                        self.violate(now, format!(
                            "AHB back to /1 {:.3} us after the switch to the PLL (RM0440 6.1.5 step 5: at least 1 us)",
                            (t - at) * 1e6
                        ));
                    }
                }
            }
        }
        if let Some((reg, bits)) = r {
            self.peripheral_reset(reg, bits, t);
        }
        self.retime(now);
        Some(())
    }

    fn peripheral_reset(&mut self, reg: u32, bits: u32, t: f64) {
        match reg {
            // AHB1RSTR: DMA1RST (0), DMAMUX1RST (2), FLASHRST (8).
            0x28 => {
                if bits & 1 != 0 {
                    let mux = self.dma.mux;
                    self.dma = dma::Dma::default();
                    self.dma.mux = mux;
                }
                if bits & 4 != 0 {
                    self.dma.mux = [0; 16];
                }
                if bits & (1 << 8) != 0 {
                    self.flash.reset();
                }
            }
            // AHB2RSTR: GPIOx (0..6), ADC12RST (13), DAC1RST (16).
            0x2C => {
                for n in 0..7 {
                    if bits & (1 << n) != 0 {
                        self.gpio[n] = gpio::Gpio::new(n);
                        self.gpio_drive(n, t);
                    }
                }
                if bits & (1 << 13) != 0 {
                    let faults = self.adc.each_ref().map(|a| a.never_ready);
                    self.adc = [analog::Adc::default(), analog::Adc::default()];
                    self.adc[0].never_ready = faults[0];
                    self.adc[1].never_ready = faults[1];
                    self.adc_common = analog::AdcCommon::default();
                }
                if bits & (1 << 16) != 0 {
                    self.dac1 = analog::Dac::default();
                }
            }
            // APB1RSTR1: TIM6RST (4), PWRRST (28).
            0x38 => {
                if bits & (1 << 4) != 0 {
                    let cpt = self.tim6.cycles_per_tick;
                    self.tim6 = analog::Tim6::new();
                    self.tim6.cycles_per_tick = cpt;
                }
                if bits & (1 << 28) != 0 {
                    self.pwr = rcc::Pwr::default();
                }
            }
            // APB1RSTR2: LPUART1RST (0).
            0x3C if bits & 1 != 0 => {
                let rx = std::mem::take(&mut self.lpuart.rx);
                let tx = std::mem::take(&mut self.lpuart.tx);
                self.lpuart = dma::Lpuart::default();
                self.lpuart.rx = rx;
                self.lpuart.tx = tx;
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_peripheral_with_its_clock_off_ignores_writes_reads_zero_and_is_flagged() {
        // RM0440 RCC: APB1ENR1.PWREN (bit 28) clear after reset: PWR_CR1 is out of reach.
        let mut p = Peripherals::default();
        assert_eq!(p.read(0x4000_7000, 4, 10).unwrap(), 0);
        p.write(0x4000_7000, 4, 0x200, 11).unwrap();
        assert_eq!(p.violations.len(), 2);
        assert!(
            p.violations[0].rule.contains("clock off"),
            "{:?}",
            p.violations
        );
        // Clock on: the register reads its reset value (VOS = range 1) and takes writes.
        p.write(0x4002_1058, 4, 1 << 28, 12).unwrap();
        assert_eq!(p.read(0x4000_7000, 4, 13).unwrap(), 1 << 9);
        assert_eq!(p.violations.len(), 2, "no new violation");
        // FLASHEN is set at reset (AHB1ENR reset value 0x100): FLASH_ACR is reachable.
        assert_eq!(p.read(0x4002_2000, 4, 14).unwrap(), 0x600);
    }

    const RCC: u32 = 0x4002_1000;
    const CFGR: u32 = RCC + 0x08;
    const FLASH_ACR: u32 = 0x4002_2000;
    /// RCC_CFGR: SW = PLL (3).
    const SW_PLL: u32 = 3;
    /// RCC_CFGR.HPRE = /2 (code 8, bits 7:4).
    const HPRE_DIV2: u32 = 8 << 4;

    /// RM0440 6.1.5's steps 1–3 on a board at reset (HSI16): the 24 MHz HSE and the PLL at
    /// 170 MHz ready, the AHB divided by 2, range 1 boost (R1MODE = 0), `ws` wait states; at
    /// cycle 100.
    fn ready_to_switch(ws: u32) -> Peripherals {
        let mut p = Peripherals::default();
        p.write(RCC + 0x58, 4, 1 << 28, 1).unwrap(); // APB1ENR1.PWREN
        p.write(RCC, 4, (1 << 8) | (1 << 16), 2).unwrap(); // HSION, HSEON
        p.write(RCC + 0x0C, 4, 3 | (5 << 4) | (85 << 8) | (1 << 24), 3)
            .unwrap(); // HSE / 6 × 85 / 2, PLLREN
        p.write(RCC, 4, (1 << 8) | (1 << 16) | (1 << 24), 4)
            .unwrap(); // PLLON
        p.write(CFGR, 4, 1 | HPRE_DIV2, 5).unwrap(); // step 1: AHB /2 on HSI16
        p.write(0x4000_7080, 4, 0, 6).unwrap(); // step 2: PWR_CR5.R1MODE = 0 (boost)
        p.write(FLASH_ACR, 4, 0x600 | ws, 7).unwrap(); // step 3: wait states
        p
    }

    fn rules(p: &Peripherals) -> Vec<&str> {
        p.violations.iter().map(|v| v.rule.as_str()).collect()
    }

    #[test]
    fn the_switch_to_the_pll_in_one_write_with_the_ahb_at_1_breaks_the_boost_sequence() {
        // embassy-stm32 0.6's `rcc::init` with `ahb_pre = DIV1`: 4 wait states, then SW = PLL and
        // HPRE = /1 in one RCC_CFGR write. The AHB is never at /2 with the PLL applied.
        let mut p = ready_to_switch(4);
        p.write(CFGR, 4, SW_PLL, 100).unwrap();
        assert!((p.rcc.hclk() - 170e6).abs() < 1.0);
        let r = rules(&p);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!(r[0].starts_with("SYSCLK switched to the PLL"), "{r:?}");
    }

    /// RM0440 6.1.5 steps 4 and 5 after [`ready_to_switch`] with 2 wait states: SYSCLK to the
    /// PLL with the AHB at /2 at cycle 100 (HCLK 85 MHz), 4 wait states at cycle 110 if
    /// `raise_ws`, HPRE = /1 `hold` cycles after the switch.
    fn boost_switch(raise_ws: bool, hold: u64) -> Peripherals {
        let mut p = ready_to_switch(2);
        p.write(CFGR, 4, SW_PLL | HPRE_DIV2, 100).unwrap();
        assert!((p.rcc.hclk() - 85e6).abs() < 1.0);
        if raise_ws {
            p.write(FLASH_ACR, 4, 0x600 | 4, 110).unwrap();
        }
        p.write(CFGR, 4, SW_PLL, 100 + hold).unwrap();
        assert!((p.rcc.hclk() - 170e6).abs() < 1.0);
        p
    }

    #[test]
    fn the_ahb_back_to_1_within_1_us_of_the_switch_breaks_the_boost_sequence() {
        // 42 cycles at 85 MHz: 0.49 µs.
        let p = boost_switch(true, 42);
        let r = rules(&p);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!(r[0].starts_with("AHB back to /1 0.49"), "{r:?}");
    }

    #[test]
    fn the_boost_sequence_with_the_hold_and_the_wait_states_breaks_no_rule() {
        // As the board does it: 4 wait states, /1 1 µs (85 cycles at 85 MHz) after the switch.
        assert_eq!(rules(&boost_switch(true, 85)), Vec::<&str>::new());
        // With too few wait states for 170 MHz, /1 breaks the latency rule instead.
        let p = boost_switch(false, 170);
        let r = rules(&p);
        assert!(
            r.len() == 1
                && r[0].starts_with("HCLK raised to 170000000 Hz with FLASH_ACR.LATENCY 2"),
            "{r:?}"
        );
    }

    #[test]
    fn the_watchdog_resets_after_its_timeout_in_lsi_time() {
        // IWDG at reset: PR /4, RLR 0xFFF → 4096 × 4 / 32 kHz = 0.512 s, on HSI16 at 16 MHz.
        let mut p = Peripherals::default();
        let (mut f, mut s, mut c) = (vec![0u8; 16], vec![0u8; 16], vec![0u8; 16]);
        p.write(0x4000_3000, 4, 0xCCCC, 0).unwrap();
        let due = p.next_event(0).unwrap();
        assert_eq!(due, (0.512 * 16e6) as u64);
        let mut mem = Mem {
            flash: &mut f,
            sram: &mut s,
            ccm: &mut c,
        };
        p.advance(due - 1, &mut mem);
        assert_eq!(p.reset_cause_pending(), None);
        p.advance(due, &mut mem);
        assert_eq!(p.reset_cause_pending(), Some(ResetCause::Watchdog));
    }
}
