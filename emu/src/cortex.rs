//! The Cortex-M4 system around the CPU that unicorn does not model: the NVIC, the system control
//! block, SysTick, the DWT cycle counter and the FPU's context control — as registers of the
//! system control space (ARMv7-M Architecture Reference Manual, ARM DDI 0403E, B3 "System
//! Address Map"; Cortex-M4 TRM) — and the exception model's priorities (B1.5.4 "Exception
//! priorities and preemption").
//!
//! Exception *entry and return* need the CPU's registers and are in [`crate::machine`]; this
//! module decides which exception is taken and keeps the pending/active/enabled state.
//!
//! Time is counted in core (HCLK) cycles by the caller (`now`).
//!
//! Leaves out: the MPU, the ITM/TPIU/FPB, the debug halting registers (DHCSR reads 0: no
//! debugger attached), secure/non-secure banking (v8-M only), fault status registers' contents
//! beyond what the harness sets, SysTick's external reference clock (CLKSOURCE = 0 counts HCLK/8
//! as on the STM32G4, RM0440 7.2 "System timer (SysTick) clock"), sleep-on-exit, WFE/SEV events,
//! and the NVIC's interrupt active-bit registers beyond reads.

/// Number of external interrupts the G474's NVIC has (RM0440 Table 97: positions 0..=101).
pub const NUM_IRQ: usize = 102;
/// Exception numbers (ARMv7-M B1.5.2).
pub const EXC_NMI: usize = 2;
/// HardFault.
pub const EXC_HARDFAULT: usize = 3;
/// PendSV.
pub const EXC_PENDSV: usize = 14;
/// SysTick.
pub const EXC_SYSTICK: usize = 15;
/// First external interrupt (IRQ 0).
pub const EXC_IRQ0: usize = 16;
/// Number of exception numbers tracked.
pub const NUM_EXC: usize = EXC_IRQ0 + NUM_IRQ;

/// The STM32G4 implements 4 priority bits (the upper nibble; RM0440 "Nested vectored interrupt
/// controller (NVIC)": 16 programmable priority levels).
const PRIO_MASK: u8 = 0xF0;

/// Pending/active/enabled/priority state of every exception.
#[derive(Clone, Debug)]
pub struct Nvic {
    pending: [bool; NUM_EXC],
    active: [bool; NUM_EXC],
    enabled: [bool; NUM_EXC],
    /// Programmed priority byte (upper nibble implemented) for exceptions 4.. (SHPR, IPR).
    prio: [u8; NUM_EXC],
}

impl Default for Nvic {
    fn default() -> Self {
        let mut enabled = [false; NUM_EXC];
        // System exceptions are always enabled (MemManage/BusFault/UsageFault escalate to
        // HardFault when their SHCSR enable is clear; this model escalates always).
        enabled[..EXC_IRQ0].fill(true);
        Nvic {
            pending: [false; NUM_EXC],
            active: [false; NUM_EXC],
            enabled,
            prio: [0; NUM_EXC],
        }
    }
}

impl Nvic {
    /// Pend exception `exc`.
    pub fn pend(&mut self, exc: usize) {
        self.pending[exc] = true;
    }

    /// Pend external interrupt `irq` (position in the vector table after the 16 system ones).
    pub fn pend_irq(&mut self, irq: usize) {
        self.pending[EXC_IRQ0 + irq] = true;
    }

    /// Is `exc` pending?
    pub fn is_pending(&self, exc: usize) -> bool {
        self.pending[exc]
    }

    /// Is `exc` active?
    pub fn is_active(&self, exc: usize) -> bool {
        self.active[exc]
    }

    /// Is external interrupt `irq` enabled?
    pub fn irq_enabled(&self, irq: usize) -> bool {
        self.enabled[EXC_IRQ0 + irq]
    }

    /// The priority of `exc` as a signed number (lower is more urgent): NMI -2, HardFault -1,
    /// the rest their programmed byte.
    pub fn priority(&self, exc: usize) -> i16 {
        match exc {
            EXC_NMI => -2,
            EXC_HARDFAULT => -1,
            _ => self.prio[exc] as i16,
        }
    }

    /// Group priority of a priority value under `prigroup` (AIRCR.PRIGROUP: bits [PRIGROUP:0]
    /// are the subpriority; B1.5.4).
    fn group(prio: i16, prigroup: u8) -> i16 {
        if prio < 0 {
            return prio;
        }
        let mask: u16 = 0xFF << (prigroup + 1);
        (prio as u16 & mask) as i16
    }

    /// The execution priority from the active exceptions and the masks (B1.5.4): PRIMASK
    /// raises it to 0, FAULTMASK to -1, a non-zero BASEPRI to its group priority; 256 when
    /// nothing is active or masked (thread mode).
    pub fn execution_priority(
        &self,
        basepri: u8,
        primask: bool,
        faultmask: bool,
        prigroup: u8,
    ) -> i16 {
        let mut p: i16 = 256;
        for exc in 1..NUM_EXC {
            if self.active[exc] {
                p = p.min(Self::group(self.priority(exc), prigroup));
            }
        }
        if basepri & PRIO_MASK != 0 {
            p = p.min(Self::group((basepri & PRIO_MASK) as i16, prigroup));
        }
        if primask {
            p = p.min(0);
        }
        if faultmask {
            p = p.min(-1);
        }
        p
    }

    /// The pending, enabled exception that would be taken next regardless of masks: lowest
    /// group priority, then lowest subpriority... which with the priority value itself is
    /// the lowest priority value, then the lowest exception number (B1.5.4).
    pub fn highest_pending(&self) -> Option<(usize, i16)> {
        let mut best: Option<(usize, i16)> = None;
        for exc in 1..NUM_EXC {
            if self.pending[exc] && self.enabled[exc] {
                let p = self.priority(exc);
                if best.is_none_or(|(_, bp)| p < bp) {
                    best = Some((exc, p));
                }
            }
        }
        best
    }

    /// The exception to take now, if any: the highest pending one whose group priority is
    /// more urgent than the execution priority.
    pub fn takable(
        &self,
        basepri: u8,
        primask: bool,
        faultmask: bool,
        prigroup: u8,
    ) -> Option<usize> {
        let (exc, p) = self.highest_pending()?;
        let exec = self.execution_priority(basepri, primask, faultmask, prigroup);
        (Self::group(p, prigroup) < exec).then_some(exc)
    }

    /// Exception entry's bookkeeping: `exc` stops pending and becomes active.
    pub fn activate(&mut self, exc: usize) {
        self.pending[exc] = false;
        self.active[exc] = true;
    }

    /// Exception return's bookkeeping: `exc` is no longer active.
    pub fn deactivate(&mut self, exc: usize) {
        self.active[exc] = false;
    }

    /// Number of active exceptions (RETTOBASE is "one active").
    pub fn active_count(&self) -> usize {
        self.active.iter().filter(|a| **a).count()
    }
}

/// SysTick (ARMv7-M B3.3): a 24-bit down-counter reloaded from RVR; reaching 0 sets
/// COUNTFLAG and, with TICKINT, pends the SysTick exception.
#[derive(Clone, Debug, Default)]
pub struct SysTick {
    /// CSR: ENABLE (0), TICKINT (1), CLKSOURCE (2); COUNTFLAG (16) kept in `countflag`.
    csr: u32,
    rvr: u32,
    countflag: bool,
    /// Core cycle at which the counter next reaches 0 (when enabled).
    zero_at: u64,
    /// The counter value while disabled.
    held: u32,
}

impl SysTick {
    fn divider(&self) -> u64 {
        if self.csr & 4 != 0 {
            1
        } else {
            8
        }
    }

    fn enabled(&self) -> bool {
        self.csr & 1 != 0
    }

    /// Current counter value at `now`.
    fn cvr(&self, now: u64) -> u32 {
        if !self.enabled() {
            return self.held;
        }
        (self.zero_at.saturating_sub(now) / self.divider()) as u32
    }

    /// The next cycle at which the counter reaches 0 (an event), if counting.
    pub fn next_event(&self) -> Option<u64> {
        (self.enabled() && self.rvr != 0).then_some(self.zero_at)
    }

    /// Process the wraps due by `now`; returns true if the exception is to be pended.
    pub fn advance(&mut self, now: u64) -> bool {
        let mut pend = false;
        while self.enabled() && self.rvr != 0 && self.zero_at <= now {
            self.countflag = true;
            pend |= self.csr & 2 != 0;
            self.zero_at += (self.rvr as u64 + 1) * self.divider();
        }
        pend
    }

    /// Register read at offset from 0xE000_E010.
    pub fn read(&mut self, off: u32, now: u64) -> u32 {
        match off {
            0x0 => {
                let v = self.csr | ((self.countflag as u32) << 16);
                self.countflag = false; // COUNTFLAG clears on read
                v
            }
            0x4 => self.rvr,
            0x8 => self.cvr(now),
            // CALIB: NOREF (no external reference as a separate clock), TENMS unknown (0).
            0xC => 1 << 31,
            _ => 0,
        }
    }

    /// Register write at offset from 0xE000_E010.
    pub fn write(&mut self, off: u32, v: u32, now: u64) {
        match off {
            0x0 => {
                let was = self.enabled();
                let cur = self.cvr(now);
                self.csr = v & 7;
                if self.enabled() && !was {
                    // Counting resumes from the current value; 0 reloads on the next tick.
                    self.zero_at = now + cur as u64 * self.divider();
                    if cur == 0 {
                        self.zero_at = now + (self.rvr as u64 + 1) * self.divider();
                    }
                } else if !self.enabled() && was {
                    self.held = cur;
                }
            }
            0x4 => self.rvr = v & 0x00FF_FFFF,
            0x8 => {
                // Any write clears the counter and COUNTFLAG; it reloads on the next tick.
                self.countflag = false;
                self.held = 0;
                if self.enabled() {
                    self.zero_at = now + (self.rvr as u64 + 1) * self.divider();
                }
            }
            _ => {}
        }
    }
}

/// The data watchpoint and trace unit's cycle counter (ARMv7-M C1.8.6): CYCCNT counts core
/// cycles while DWT_CTRL.CYCCNTENA and DEMCR.TRCENA are set.
#[derive(Clone, Debug, Default)]
pub struct Dwt {
    ctrl: u32,
    /// CYCCNT at `since` (when counting) or its held value.
    base: u32,
    since: u64,
}

impl Dwt {
    fn counting(&self, trcena: bool) -> bool {
        trcena && self.ctrl & 1 != 0
    }

    /// CYCCNT at `now`.
    pub fn cyccnt(&self, now: u64, trcena: bool) -> u32 {
        if self.counting(trcena) {
            self.base.wrapping_add((now - self.since) as u32)
        } else {
            self.base
        }
    }

    /// Freeze or restart the count when TRCENA changes (called before the change).
    pub fn retime(&mut self, now: u64, trcena_before: bool) {
        self.base = self.cyccnt(now, trcena_before);
        self.since = now;
    }

    /// Register read at offset from 0xE000_1000.
    pub fn read(&self, off: u32, now: u64, trcena: bool) -> u32 {
        match off {
            // NUMCOMP = 4 comparators, the counters present (NOCYCCNT = 0).
            0x0 => 0x4000_0000 | (self.ctrl & 1),
            0x4 => self.cyccnt(now, trcena),
            _ => 0,
        }
    }

    /// Register write at offset from 0xE000_1000.
    pub fn write(&mut self, off: u32, v: u32, now: u64, trcena: bool) {
        match off {
            0x0 => {
                self.base = self.cyccnt(now, trcena);
                self.since = now;
                self.ctrl = v & 1;
            }
            0x4 => {
                self.base = v;
                self.since = now;
            }
            _ => {}
        }
    }
}

/// System control block and the rest of the SCS the image uses (B3.2): VTOR, AIRCR (PRIGROUP,
/// SYSRESETREQ), ICSR's set/clear bits, SHPR priorities, CCR, CPACR, DEMCR, FPCCR.
#[derive(Clone, Debug)]
pub struct Scb {
    /// Vector table offset (VTOR).
    pub vtor: u32,
    /// AIRCR.PRIGROUP.
    pub prigroup: u8,
    /// SCR (sleep bits kept, unused).
    pub scr: u32,
    /// CCR; reset value with STKALIGN set (Cortex-M4).
    pub ccr: u32,
    /// CPACR.
    pub cpacr: u32,
    /// DEMCR (TRCENA is bit 24).
    pub demcr: u32,
    /// FPCCR (ASPEN|LSPEN at reset).
    pub fpccr: u32,
    /// SHCSR (enables of MemManage/BusFault/UsageFault; kept, faults escalate regardless).
    pub shcsr: u32,
    /// HFSR / CFSR as set by the harness on faults.
    pub hfsr: u32,
    /// CFSR.
    pub cfsr: u32,
    /// A system reset was requested through AIRCR.SYSRESETREQ.
    pub reset_requested: bool,
}

impl Default for Scb {
    fn default() -> Self {
        Scb {
            vtor: 0,
            prigroup: 0,
            scr: 0,
            ccr: 0x200,
            cpacr: 0,
            demcr: 0,
            fpccr: 0xC000_0000,
            shcsr: 0,
            hfsr: 0,
            cfsr: 0,
            reset_requested: false,
        }
    }
}

impl Scb {
    /// DEMCR.TRCENA.
    pub fn trcena(&self) -> bool {
        self.demcr & (1 << 24) != 0
    }
}

/// The system control space registers the harness answers (0xE000_0000..0xE00F_FFFF), less the
/// exception entry/return which need the CPU.
#[derive(Clone, Debug, Default)]
pub struct Scs {
    /// NVIC state.
    pub nvic: Nvic,
    /// SCB state.
    pub scb: Scb,
    /// SysTick.
    pub systick: SysTick,
    /// DWT.
    pub dwt: Dwt,
    /// The exception number in IPSR (the harness's copy; 0 in thread mode).
    pub ipsr: usize,
}

/// An SCS access the model does not know: the run fails naming it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unmodelled(pub u32);

impl Scs {
    /// Read `size` bytes at `addr` (absolute). `now` is the core cycle count.
    pub fn read(&mut self, addr: u32, size: usize, now: u64) -> Result<u32, Unmodelled> {
        let word = addr & !3;
        let shift = (addr & 3) * 8;
        let v = match word {
            0xE000_1000..=0xE000_1FFC => self.dwt.read(word - 0xE000_1000, now, self.scb.trcena()),
            // ICTR: INTLINESNUM = 3 (up to 128 interrupts).
            0xE000_E004 => 3,
            0xE000_E010..=0xE000_E01C => self.systick.read(word - 0xE000_E010, now),
            0xE000_E100..=0xE000_E13C => self.bits(word - 0xE000_E100, |n, e| n.enabled[e]),
            0xE000_E180..=0xE000_E1BC => self.bits(word - 0xE000_E180, |n, e| n.enabled[e]),
            0xE000_E200..=0xE000_E23C => self.bits(word - 0xE000_E200, |n, e| n.pending[e]),
            0xE000_E280..=0xE000_E2BC => self.bits(word - 0xE000_E280, |n, e| n.pending[e]),
            0xE000_E300..=0xE000_E33C => self.bits(word - 0xE000_E300, |n, e| n.active[e]),
            0xE000_E400..=0xE000_E4EC => {
                let irq = (word - 0xE000_E400) as usize;
                u32::from_le_bytes(core::array::from_fn(|i| {
                    self.nvic.prio.get(EXC_IRQ0 + irq + i).copied().unwrap_or(0)
                }))
            }
            // CPUID: Cortex-M4 r0p1.
            0xE000_ED00 => 0x410F_C241,
            0xE000_ED04 => self.icsr(),
            0xE000_ED08 => self.scb.vtor,
            0xE000_ED0C => 0xFA05_0000 | ((self.scb.prigroup as u32) << 8),
            0xE000_ED10 => self.scb.scr,
            0xE000_ED14 => self.scb.ccr,
            0xE000_ED18..=0xE000_ED20 => {
                let exc = (word - 0xE000_ED14) as usize;
                u32::from_le_bytes(core::array::from_fn(|i| self.nvic.prio[exc + i]))
            }
            0xE000_ED24 => self.scb.shcsr,
            0xE000_ED28 => self.scb.cfsr,
            0xE000_ED2C => self.scb.hfsr,
            0xE000_ED34 | 0xE000_ED38 => 0,
            0xE000_ED88 => self.scb.cpacr,
            // DHCSR: no debugger (C_DEBUGEN clear).
            0xE000_EDF0 => 0,
            0xE000_EDFC => self.scb.demcr,
            0xE000_EF34 => self.scb.fpccr,
            0xE000_EF38 | 0xE000_EF3C => 0,
            _ => return Err(Unmodelled(addr)),
        };
        let _ = size;
        Ok(v >> shift)
    }

    fn bits(&self, off: u32, f: impl Fn(&Nvic, usize) -> bool) -> u32 {
        let first = EXC_IRQ0 + (off as usize / 4) * 32;
        (0..32)
            .filter(|i| first + i < NUM_EXC && f(&self.nvic, first + i))
            .fold(0, |v, i| v | 1 << i)
    }

    fn set_bits(&mut self, off: u32, v: u32, f: impl Fn(&mut Nvic, usize)) {
        let first = EXC_IRQ0 + (off as usize / 4) * 32;
        for i in 0..32 {
            if v & (1 << i) != 0 && first + i < NUM_EXC {
                f(&mut self.nvic, first + i);
            }
        }
    }

    fn icsr(&self) -> u32 {
        let pending = self.nvic.highest_pending().map_or(0, |(e, _)| e as u32);
        let isr_pending = (EXC_IRQ0..NUM_EXC).any(|e| self.nvic.pending[e]);
        let rettobase = self.nvic.active_count() <= 1;
        (self.ipsr as u32 & 0x1FF)
            | (rettobase as u32) << 11
            | (pending & 0x1FF) << 12
            | (isr_pending as u32) << 22
            | (self.nvic.pending[EXC_SYSTICK] as u32) << 26
            | (self.nvic.pending[EXC_PENDSV] as u32) << 28
            | (self.nvic.pending[EXC_NMI] as u32) << 31
    }

    /// Write `size` bytes `v` at `addr` (absolute).
    pub fn write(&mut self, addr: u32, size: usize, v: u32, now: u64) -> Result<(), Unmodelled> {
        let word = addr & !3;
        match word {
            0xE000_1000..=0xE000_1FFC => {
                let trcena = self.scb.trcena();
                self.dwt.write(word - 0xE000_1000, v, now, trcena)
            }
            0xE000_E010..=0xE000_E01C => self.systick.write(word - 0xE000_E010, v, now),
            0xE000_E100..=0xE000_E13C => {
                self.set_bits(word - 0xE000_E100, v, |n, e| n.enabled[e] = true)
            }
            0xE000_E180..=0xE000_E1BC => {
                self.set_bits(word - 0xE000_E180, v, |n, e| n.enabled[e] = false)
            }
            0xE000_E200..=0xE000_E23C => {
                self.set_bits(word - 0xE000_E200, v, |n, e| n.pending[e] = true)
            }
            0xE000_E280..=0xE000_E2BC => {
                self.set_bits(word - 0xE000_E280, v, |n, e| n.pending[e] = false)
            }
            0xE000_E400..=0xE000_E4EC => {
                // Byte-accessible: `size` bytes from `addr`.
                let first = EXC_IRQ0 + (addr - 0xE000_E400) as usize;
                for i in 0..size {
                    if first + i < NUM_EXC {
                        self.nvic.prio[first + i] = (v >> (8 * i)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_ED04 => {
                if v & (1 << 31) != 0 {
                    self.nvic.pending[EXC_NMI] = true;
                }
                if v & (1 << 28) != 0 {
                    self.nvic.pending[EXC_PENDSV] = true;
                }
                if v & (1 << 27) != 0 {
                    self.nvic.pending[EXC_PENDSV] = false;
                }
                if v & (1 << 26) != 0 {
                    self.nvic.pending[EXC_SYSTICK] = true;
                }
                if v & (1 << 25) != 0 {
                    self.nvic.pending[EXC_SYSTICK] = false;
                }
            }
            // VTOR: bits [31:7] (the G4's table of 118 entries needs 512-byte alignment; the
            // architecture's minimum is 128).
            0xE000_ED08 => self.scb.vtor = v & 0xFFFF_FF80,
            0xE000_ED0C => {
                // Writes without VECTKEY 0x05FA are ignored.
                if v >> 16 == 0x05FA {
                    self.scb.prigroup = ((v >> 8) & 7) as u8;
                    if v & (1 << 2) != 0 {
                        self.scb.reset_requested = true;
                    }
                }
            }
            0xE000_ED10 => self.scb.scr = v & 0x16,
            0xE000_ED14 => self.scb.ccr = (v & 0x31B) | 0x200,
            0xE000_ED18..=0xE000_ED20 => {
                let first = (addr - 0xE000_ED14) as usize;
                for i in 0..size {
                    let exc = first + i;
                    // Priorities of exceptions 4..=15; 7..=10 and 13 are reserved.
                    if (4..EXC_IRQ0).contains(&exc) {
                        self.nvic.prio[exc] = (v >> (8 * i)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_ED24 => self.scb.shcsr = v,
            // CFSR/HFSR: write-one-to-clear.
            0xE000_ED28 => self.scb.cfsr &= !v,
            0xE000_ED2C => self.scb.hfsr &= !v,
            0xE000_ED88 => self.scb.cpacr = v & 0x00F0_0000,
            0xE000_EDFC => {
                let before = self.scb.trcena();
                self.dwt.retime(now, before);
                self.scb.demcr = v & 0x010F_07F1;
            }
            0xE000_EF00 => {
                // STIR: pend interrupt INTID (unprivileged access only with CCR.USERSETMPEND;
                // the image runs privileged).
                let irq = (v & 0x1FF) as usize;
                if irq < NUM_IRQ {
                    self.nvic.pend_irq(irq);
                }
            }
            0xE000_EF34 => self.scb.fpccr = (v & 0xC000_0000) | (self.scb.fpccr & 0x3FF),
            0xE000_EF38 | 0xE000_EF3C => {}
            _ => return Err(Unmodelled(addr)),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// IRQ `n` at priority `prio` (its NVIC_IPR byte) and enabled (its NVIC_ISER bit), written
    /// through the registers as the firmware writes them.
    fn enable_at(scs: &mut Scs, n: u32, prio: u32) {
        scs.write(0xE000_E400 + n, 1, prio, 0).unwrap();
        scs.write(0xE000_E100 + 4 * (n / 32), 4, 1 << (n % 32), 0)
            .unwrap();
    }

    #[test]
    fn priorities_decide_preemption() {
        // ARMv7-M B1.5.4: a pending exception preempts only with a group priority more
        // urgent (numerically lower) than the execution priority.
        let mut scs = Scs::default();
        // IRQ 11 at priority 0x30, IRQ 36 at 0x10.
        enable_at(&mut scs, 11, 0x30);
        enable_at(&mut scs, 36, 0x10);
        // Pend both through ISPR and STIR.
        scs.write(0xE000_E200, 4, 1 << 11, 0).unwrap();
        scs.write(0xE000_EF00, 4, 36, 0).unwrap();
        let n = &scs.nvic;
        // Thread mode, unmasked: the more urgent (IRQ 36) first.
        assert_eq!(n.takable(0, false, false, 0), Some(EXC_IRQ0 + 36));
        // BASEPRI = 0x10 masks priority 0x10 and below (equal is masked).
        assert_eq!(n.takable(0x10, false, false, 0), None);
        // BASEPRI = 0x20 lets 0x10 through but not 0x30.
        assert_eq!(n.takable(0x20, false, false, 0), Some(EXC_IRQ0 + 36));
        // PRIMASK masks all configurable priorities.
        assert_eq!(n.takable(0, true, false, 0), None);
        // Only 4 bits are implemented: BASEPRI 0x1F acts as 0x10.
        assert_eq!(n.takable(0x1F, false, false, 0), None);
    }

    #[test]
    fn active_exception_blocks_equal_and_lower_priority() {
        let mut scs = Scs::default();
        enable_at(&mut scs, 11, 0x20);
        enable_at(&mut scs, 12, 0x20);
        scs.nvic.pend_irq(11);
        let exc = scs.nvic.takable(0, false, false, 0).unwrap();
        scs.nvic.activate(exc);
        scs.nvic.pend_irq(12);
        // Same priority: no preemption while IRQ 11 is active.
        assert_eq!(scs.nvic.takable(0, false, false, 0), None);
        scs.nvic.deactivate(exc);
        assert_eq!(scs.nvic.takable(0, false, false, 0), Some(EXC_IRQ0 + 12));
        // A disabled interrupt is never taken (ICER).
        scs.write(0xE000_E180, 4, 1 << 12, 0).unwrap();
        assert_eq!(scs.nvic.takable(0, false, false, 0), None);
        // ... and its pending bit reads back through ISPR, clears through ICPR.
        assert_eq!(scs.read(0xE000_E200, 4, 0).unwrap(), 1 << 12);
        scs.write(0xE000_E280, 4, 1 << 12, 0).unwrap();
        assert_eq!(scs.read(0xE000_E200, 4, 0).unwrap(), 0);
    }

    #[test]
    fn prigroup_splits_group_and_subpriority() {
        // PRIGROUP = 5: bits [7:6] group, [5:0] sub. 0x40 and 0x70 share group 0x40, so an
        // active 0x40 is not preempted by a pending 0x70 ... nor by 0x50.
        let mut scs = Scs::default();
        scs.write(0xE000_ED0C, 4, 0x05FA_0500, 0).unwrap();
        assert_eq!(scs.scb.prigroup, 5);
        scs.write(0xE000_E400, 4, 0x0000_5040, 0).unwrap();
        scs.write(0xE000_E100, 4, 3, 0).unwrap();
        scs.nvic.activate(EXC_IRQ0);
        scs.nvic.pend_irq(1);
        assert_eq!(scs.nvic.takable(0, false, false, 5), None);
        // Without the key, AIRCR ignores the write.
        scs.write(0xE000_ED0C, 4, 0x0000_0004, 0).unwrap();
        assert!(!scs.scb.reset_requested);
        scs.write(0xE000_ED0C, 4, 0x05FA_0004, 0).unwrap();
        assert!(scs.scb.reset_requested);
    }

    #[test]
    fn systick_period_is_reload_plus_one() {
        // B3.3.1: the counter counts RVR..0, so the period is RVR + 1 clocks; CLKSOURCE = 1 is
        // the core clock. COUNTFLAG reads 1 once after a wrap.
        let mut st = SysTick::default();
        st.write(0x4, 999, 0);
        st.write(0x8, 0, 0);
        st.write(0x0, 0b111, 0);
        assert_eq!(st.next_event(), Some(1000));
        assert!(!st.advance(999));
        assert_eq!(st.read(0x8, 400), 600);
        assert!(st.advance(1000));
        assert_eq!(st.next_event(), Some(2000));
        assert_eq!(st.read(0x0, 1000) >> 16, 1);
        assert_eq!(st.read(0x0, 1000) >> 16, 0);
        // Two periods due at once pend once (the exception is a single pending bit).
        assert!(st.advance(3500));
        assert_eq!(st.next_event(), Some(4000));
    }

    #[test]
    fn cyccnt_counts_only_with_trcena_and_cyccntena() {
        let mut scs = Scs::default();
        scs.write(0xE000_1000, 4, 1, 10).unwrap();
        assert_eq!(
            scs.read(0xE000_1004, 4, 100).unwrap(),
            0,
            "TRCENA clear: frozen"
        );
        scs.write(0xE000_EDFC, 4, 1 << 24, 100).unwrap();
        assert_eq!(scs.read(0xE000_1004, 4, 350).unwrap(), 250);
        scs.write(0xE000_1004, 4, u32::MAX, 350).unwrap();
        assert_eq!(
            scs.read(0xE000_1004, 4, 352).unwrap(),
            1,
            "wraps modulo 2^32"
        );
    }
}
