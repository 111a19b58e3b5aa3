//! The emulated STM32G474RE: unicorn's Cortex-M4 CPU, the memory map of RM0440 2.2 ("Memory
//! organization", Figure 3 and Table 3), the system control space ([`crate::cortex`]), the
//! peripherals ([`crate::periph`]), exception entry and return, and the time base.
//!
//! # Time
//! Time is the core clock: one executed instruction is one HCLK cycle (an approximation: the
//! Cortex-M4 takes 1 cycle for most data-processing instructions, 2+ for loads, stores,
//! branches, divisions and flash wait states the ART accelerator does not hide; real code runs at
//! roughly 1.2–1.6 cycles per instruction, so emulated durations of busy code are short by that
//! factor). Cycles spent asleep in WFI are added up to the next event. The count is exact and
//! deterministic: the same image and inputs give the same cycle of every event.
//!
//! # Exceptions
//! unicorn 2.1.5 models the M-profile CPU's registers (BASEPRI, PRIMASK, CONTROL, MSP/PSP,
//! IPSR) but no NVIC: entry is done here (ARMv7-M B1.5.6 "Exception entry behavior": the basic
//! or, with CONTROL.FPCA, extended frame on the stack in use, 8-byte aligned with xPSR bit 9,
//! EXC_RETURN in LR, IPSR, the vector from VTOR); unicorn detects a branch to an EXC_RETURN value
//! in handler mode and raises EXCP_EXCEPTION_EXIT (8), which its interrupt hook hands here, where
//! the frame is popped (B1.5.8 "Exception return behavior"). The FP frame is stacked eagerly
//! (lazy stacking's reserved space is written at once: the same values, different timing).
//! Exceptions are taken at the start of a translated block (the CPU's own exits end blocks:
//! branches, MSR to the masks, WFI, exception returns), never inside an IT block.
//!
//! Leaves out: WFI's wake-up on an exception that PRIMASK masks (the CPU sleeps to the next
//! event instead), WFE/SEV, sleep-on-exit, MemManage/BusFault/UsageFault as separate handlers
//! (faults escalate to HardFault; an access to an address nothing answers stops the run, as a
//! missing model more likely than a bus error the image expects), lockup, debug halting.

use unicorn_engine::{Arch, ArmCpuModel, HookType, MemType, Mode, Prot, RegisterARM, Unicorn};

use crate::cortex::{self, Scs, EXC_HARDFAULT, EXC_IRQ0};
use crate::elf::Elf;
use crate::periph::{Mem, Peripherals, SysClock};
use crate::Error;

/// Flash: 512 KiB at 0x0800_0000 (RM0440 3.3.1, two banks of 256 KiB in dual-bank mode).
pub const FLASH_BASE: u32 = 0x0800_0000;
/// Flash size.
pub const FLASH_SIZE: usize = 512 * 1024;
/// SRAM1 (80 KiB) and SRAM2 (16 KiB), contiguous at 0x2000_0000 (RM0440 2.4).
pub const SRAM_BASE: u32 = 0x2000_0000;
/// SRAM1 + SRAM2 size.
pub const SRAM_SIZE: usize = 96 * 1024;
/// CCM SRAM: 32 KiB at 0x1000_0000 (I-code/D-code) and aliased right after SRAM2 at
/// 0x2001_8000 (RM0440 2.4 "CCM SRAM").
pub const CCM_BASE: u32 = 0x1000_0000;
/// The CCM SRAM's alias on the system bus.
pub const CCM_ALIAS: u32 = 0x2001_8000;
/// CCM SRAM size.
pub const CCM_SIZE: usize = 32 * 1024;

/// xPSR's EPSR.IT bits, IT[7:2] at [15:10] and IT[1:0] at [26:25] (ARMv7-M B1.4.2): non-zero
/// inside an IT block.
const IT_BITS: u32 = 0x0600_FC00;

/// Why a run stopped for good.
#[derive(Clone, Debug, PartialEq)]
pub enum Exit {
    /// The cycle limit of the run was reached.
    Limit,
    /// The CPU ran into something the emulator does not model or the image cannot survive.
    Fault(String),
}

impl From<unicorn_engine::uc_error> for Error {
    fn from(e: unicorn_engine::uc_error) -> Self {
        Error::Setup(format!("unicorn: {e:?}"))
    }
}

/// Everything the CPU's hooks reach: memory, the SCS, the peripherals, the clock.
pub struct Board {
    /// Core (HCLK) cycles since power-on.
    pub now: u64,
    /// The code hook stops the CPU at this cycle.
    deadline: u64,
    /// A stop requested by a hook (deadline, an exception to take, a fault).
    stopped: bool,
    /// Set when the exception state changed (pend, enable, priority, return): the code hook
    /// checks the masks before the next instruction.
    pub irq_dirty: bool,
    /// Some pending, enabled exception could preempt if the masks allow it: the code hook
    /// reads BASEPRI/PRIMASK before each instruction.
    irq_armed: bool,
    /// Instructions per translated block, by (start address, size in bytes).
    blocks: std::collections::HashMap<(u32, u32), u64>,
    /// A fault the hooks found (an unmodelled register, a bad exception return).
    pub fault: Option<String>,
    /// The system control space.
    pub scs: Scs,
    /// The STM32 peripherals.
    pub periph: Peripherals,
    /// Flash contents (bank 1 and 2): mapped read/execute into the CPU, programmed by the
    /// flash interface model.
    pub flash: Box<[u8]>,
    /// SRAM1+SRAM2.
    pub sram: Box<[u8]>,
    /// CCM SRAM.
    pub ccm: Box<[u8]>,
    /// Cycles executed (instructions) as opposed to slept in WFI.
    pub executed: u64,
    /// When set, how many times each translated block (start address, size in bytes) ran
    /// ([`Board::profile`]).
    pub block_runs: Option<std::collections::HashMap<(u32, u32), u64>>,
}

impl Board {
    fn new() -> Board {
        Board {
            now: 0,
            deadline: u64::MAX,
            stopped: false,
            irq_dirty: true,
            irq_armed: false,
            blocks: std::collections::HashMap::new(),
            fault: None,
            scs: Scs::default(),
            periph: Peripherals::default(),
            flash: vec![0xFF; FLASH_SIZE].into_boxed_slice(),
            sram: vec![0; SRAM_SIZE].into_boxed_slice(),
            ccm: vec![0; CCM_SIZE].into_boxed_slice(),
            executed: 0,
            block_runs: None,
        }
    }

    /// The instructions executed at each address since `block_runs` was set, by address: every
    /// instruction of a block counts each time the block ran (a block left early by an
    /// exception counts whole, as the cycle count does).
    pub fn profile(&self) -> std::collections::BTreeMap<u32, u64> {
        let mut at = std::collections::BTreeMap::new();
        for (&(addr, size), &runs) in self.block_runs.iter().flatten() {
            let mut a = addr;
            while a < addr + size {
                *at.entry(a).or_insert(0) += runs;
                let h = self.mem_read(a, 2).unwrap_or(0);
                a += if h >> 11 >= 0b11101 { 4 } else { 2 };
            }
        }
        at
    }

    /// Read a 32-bit word of RAM or flash as the bus masters other than the CPU (DMA) see it.
    pub fn mem_read(&self, addr: u32, size: usize) -> Option<u32> {
        let (buf, off) = self.memory(addr)?;
        let b = buf.get(off..off + size)?;
        let mut w = [0u8; 4];
        w[..size].copy_from_slice(b);
        Some(u32::from_le_bytes(w))
    }

    /// Write RAM as a DMA does; flash is not writable this way (false).
    pub fn mem_write(&mut self, addr: u32, size: usize, v: u32) -> bool {
        let in_flash = (FLASH_BASE..FLASH_BASE + FLASH_SIZE as u32).contains(&addr);
        if in_flash {
            return false;
        }
        let Some((_, off)) = self.memory(addr) else {
            return false;
        };
        let buf: &mut [u8] = if (SRAM_BASE..SRAM_BASE + SRAM_SIZE as u32).contains(&addr) {
            &mut self.sram
        } else {
            &mut self.ccm
        };
        match buf.get_mut(off..off + size) {
            Some(b) => {
                b.copy_from_slice(&v.to_le_bytes()[..size]);
                true
            }
            None => false,
        }
    }

    fn memory(&self, addr: u32) -> Option<(&[u8], usize)> {
        let a = addr as usize;
        let within = |base: u32, len: usize| a >= base as usize && a < base as usize + len;
        if within(FLASH_BASE, FLASH_SIZE) {
            Some((&self.flash, a - FLASH_BASE as usize))
        } else if within(SRAM_BASE, SRAM_SIZE) {
            Some((&self.sram, a - SRAM_BASE as usize))
        } else if within(CCM_ALIAS, CCM_SIZE) {
            Some((&self.ccm, a - CCM_ALIAS as usize))
        } else if within(CCM_BASE, CCM_SIZE) {
            Some((&self.ccm, a - CCM_BASE as usize))
        } else {
            None
        }
    }

    /// The number of Thumb instructions in the block of `size` bytes at `addr` (a halfword
    /// whose top five bits are 0b11101, 0b11110 or 0b11111 starts a 32-bit instruction;
    /// ARMv7-M A5.1).
    fn block_instructions(&mut self, addr: u32, size: u32) -> u64 {
        if let Some(&n) = self.blocks.get(&(addr, size)) {
            return n;
        }
        let mut n = 0;
        let mut a = addr;
        while a < addr + size {
            let h = self.mem_read(a, 2).unwrap_or(0);
            a += if h >> 11 >= 0b11101 { 4 } else { 2 };
            n += 1;
        }
        let n = n.max(1);
        self.blocks.insert((addr, size), n);
        n
    }

    /// Pend the external interrupts whose lines are asserted (level-sensitive: a line still
    /// asserted when its handler returns pends it again; ARMv7-M B3.4.1).
    pub fn update_irqs(&mut self) {
        for irq in self.periph.irq_lines() {
            let exc = EXC_IRQ0 + irq;
            if !self.scs.nvic.is_active(exc) && !self.scs.nvic.is_pending(exc) {
                self.scs.nvic.pend_irq(irq);
                self.irq_dirty = true;
            }
        }
    }

    /// The core clock now, Hz (HCLK, from the RCC model).
    pub fn hclk(&self) -> SysClock {
        self.periph.rcc.hclk()
    }

    /// Seconds since power-on at core cycle `now` (integrating the clock's changes).
    pub fn seconds(&self) -> f64 {
        self.periph.clock_seconds(self.now)
    }
}

/// The emulated board with the CPU.
pub struct Machine {
    uc: Unicorn<'static, Board>,
    /// Number of resets (power-on not counted).
    pub resets: u32,
    /// The host's number for the next command frame (`probe_proto::HostMsg::Command::id`).
    next_command_id: u32,
    /// LPUART1 TX bytes read by [`Machine::last_reply`] so far, and its frame decoder.
    tx_read: usize,
    tx_frames: Box<probe_proto::Decoder<{ probe_proto::MAX_DEVICE_FRAME }>>,
    last_reply: Option<u32>,
}

fn reg<R: Into<i32>>(uc: &Unicorn<'_, Board>, r: R) -> u32 {
    uc.reg_read(r).unwrap_or(0) as u32
}

/// The exception the core would take now under its masks (BASEPRI, PRIMASK, FAULTMASK) and
/// PRIGROUP, if any (ARMv7-M B1.5.4).
fn takable_exception(uc: &Unicorn<'_, Board>) -> Option<usize> {
    let basepri = reg(uc, RegisterARM::BASEPRI) as u8;
    let primask = reg(uc, RegisterARM::PRIMASK) & 1 != 0;
    let faultmask = reg(uc, RegisterARM::FAULTMASK) & 1 != 0;
    let b = uc.get_data();
    b.scs
        .nvic
        .takable(basepri, primask, faultmask, b.scs.scb.prigroup)
}

fn set<R: Into<i32>>(uc: &mut Unicorn<'_, Board>, r: R, v: u32) {
    uc.reg_write(r, v as u64).expect("register write");
}

/// Rebuild unicorn's cached translation flags after a change of IPSR or CONTROL (writing the
/// APSR flags is the one register write that calls `arm_rebuild_hflags`): the translator must
/// know handler mode to detect EXC_RETURN branches.
fn rebuild_hflags(uc: &mut Unicorn<'_, Board>) {
    let nzcv = reg(uc, RegisterARM::APSR_NZCV);
    set(uc, RegisterARM::APSR_NZCV, nzcv);
}

/// The stack pointer an exception stacks on and unstacks from: PSP (thread mode with
/// CONTROL.SPSEL set, `psp`) or MSP (ARMv7-M B1.4.1).
fn stack_pointer(psp: bool) -> RegisterARM {
    if psp {
        RegisterARM::PSP
    } else {
        RegisterARM::MSP
    }
}

/// Words of an exception frame: with the FP context (`fp`: S0–S15, FPSCR, a reserved word) 26,
/// else the basic 8 (R0–R3, R12, LR, PC, xPSR; ARMv7-M B1.5.6).
fn frame_words(fp: bool) -> u32 {
    if fp {
        26
    } else {
        8
    }
}

impl Machine {
    /// A board with `elf` programmed into its flash, powered on (reset, not yet run).
    pub fn new(elf: &Elf) -> Result<Machine, Error> {
        let mut board = Board::new();
        for s in &elf.segments {
            let start = s.paddr.wrapping_sub(FLASH_BASE) as usize;
            let end = start + s.data.len();
            if end > FLASH_SIZE {
                return Err(Error::Setup(format!(
                    "segment at {:#010x} ({} B) is not in flash: a flash programmer writes only flash",
                    s.paddr,
                    s.data.len()
                )));
            }
            board.flash[start..end].copy_from_slice(&s.data);
        }
        Self::with_board(board)
    }

    fn with_board(board: Board) -> Result<Machine, Error> {
        let mut uc = Unicorn::new_with_data(Arch::ARM, Mode::THUMB | Mode::MCLASS, board)?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M4 as i32)?;
        // Memory: the board's buffers, mapped in place (the flash model and the DMA write
        // them directly). The Box contents never move.
        let (flash, sram, ccm) = {
            let b = uc.get_data_mut();
            (
                b.flash.as_mut_ptr(),
                b.sram.as_mut_ptr(),
                b.ccm.as_mut_ptr(),
            )
        };
        // SAFETY: the buffers live in the Board, which unicorn owns for its whole life, and are
        // never reallocated.
        unsafe {
            uc.mem_map_ptr(
                FLASH_BASE as u64,
                FLASH_SIZE as u64,
                Prot::READ | Prot::EXEC,
                flash.cast(),
            )?;
            // Boot from main flash (BOOT0 = 0, nBOOT1 = 1): flash is aliased at 0 (RM0440 2.6
            // "Boot configuration"), where VTOR's reset value points.
            uc.mem_map_ptr(0, FLASH_SIZE as u64, Prot::READ | Prot::EXEC, flash.cast())?;
            uc.mem_map_ptr(SRAM_BASE as u64, SRAM_SIZE as u64, Prot::ALL, sram.cast())?;
            uc.mem_map_ptr(CCM_ALIAS as u64, CCM_SIZE as u64, Prot::ALL, ccm.cast())?;
            uc.mem_map_ptr(CCM_BASE as u64, CCM_SIZE as u64, Prot::ALL, ccm.cast())?;
        }
        // Writes to flash: the flash interface model decides (programming) and restores the
        // array; unicorn's protection fault is handled here.
        uc.add_mem_hook(
            HookType::MEM_WRITE_PROT,
            FLASH_BASE as u64,
            (FLASH_BASE as usize + FLASH_SIZE - 1) as u64,
            |uc, _t: MemType, addr, size, value| {
                let b = uc.get_data_mut();
                let now = b.now;
                let (periph, flash) = (&mut b.periph, &mut b.flash);
                periph.flash_write(flash, addr as u32, size, value as u64, now);
                // Handled: unicorn then stores the value into the read-only page's backing array
                // too; the restore below puts the flash model's contents back before the next
                // instruction.
                b.periph.flash_restore_pending = true;
                true
            },
        )?;
        // Peripherals and the system control space as MMIO windows (4 KiB granules).
        for (base, size) in [
            (0x4000_0000u64, 0x0003_0000u64), // APB1, APB2, AHB1
            (0x4800_0000, 0x0000_2000),       // GPIOA..G (AHB2)
            (0x5000_0000, 0x0000_2000),       // ADC1..5, DAC1..4 (AHB2)
            (0x1FFF_7000, 0x0000_1000),       // OTP, UID, flash size (system memory)
            (0xE000_0000, 0x0010_0000),       // PPB: SCS, DWT, DBGMCU
        ] {
            uc.mmio_map(
                base,
                size,
                Some(move |uc: &mut Unicorn<'_, Board>, off: u64, sz: usize| {
                    let addr = (base + off) as u32;
                    Self::bus_read(uc, addr, sz) as u64
                }),
                Some(
                    move |uc: &mut Unicorn<'_, Board>, off: u64, sz: usize, v: u64| {
                        let addr = (base + off) as u32;
                        Self::bus_write(uc, addr, sz, v as u32);
                    },
                ),
            )?;
        }
        // Time and exception checks: every instruction.
        // Time and exception checks: at the start of every translated block (a few
        // instructions; the CPU's own exits end a block: branches, MSR to the masks, WFI,
        // exception returns). The block's instructions are counted when it starts.
        uc.add_block_hook(0, u32::MAX as u64, |uc, addr, size| {
            let b = uc.get_data_mut();
            if b.periph.flash_restore_pending {
                b.periph.flash_restore_pending = false;
                let (periph, flash) = (&mut b.periph, &mut b.flash);
                periph.flash_restore(flash);
            }
            let n = b.block_instructions(addr as u32, size);
            if b.now >= b.deadline {
                b.stopped = true;
                uc.emu_stop().ok();
                return;
            }
            if b.irq_dirty {
                b.irq_dirty = false;
                b.irq_armed = b.scs.nvic.highest_pending().is_some_and(|(_, p)| {
                    p < b
                        .scs
                        .nvic
                        .execution_priority(0, false, false, b.scs.scb.prigroup)
                });
            }
            // Inside an IT block the exception waits ([`Machine::in_it_block`]): the block runs,
            // or a stop here, mid-IT, would be the run loop's next start, forever.
            if b.irq_armed
                && reg(uc, RegisterARM::XPSR) & IT_BITS == 0
                && takable_exception(uc).is_some()
            {
                // Not executed: stop before the block and take the exception.
                uc.get_data_mut().stopped = true;
                uc.emu_stop().ok();
                return;
            }
            let b = uc.get_data_mut();
            b.now += n;
            b.executed += n;
            if let Some(runs) = b.block_runs.as_mut() {
                *runs.entry((addr as u32, size)).or_insert(0) += 1;
            }
        })?;
        // Exception return (EXCP_EXCEPTION_EXIT = 8) and the rest of the CPU's exceptions.
        uc.add_intr_hook(|uc, intno| {
            const EXCP_EXCEPTION_EXIT: u32 = 8;
            if intno == EXCP_EXCEPTION_EXIT {
                if let Err(e) = Self::exception_return(uc) {
                    uc.get_data_mut().fault = Some(e);
                    uc.emu_stop().ok();
                }
            } else {
                let pc = reg(uc, RegisterARM::PC);
                uc.get_data_mut().fault = Some(format!("CPU exception {intno} at {pc:#010x}"));
                uc.emu_stop().ok();
            }
        })?;
        let mut m = Machine {
            uc,
            resets: 0,
            next_command_id: 0,
            tx_read: 0,
            tx_frames: Box::default(),
            last_reply: None,
        };
        m.reset_cpu()?;
        Ok(m)
    }

    /// The board.
    pub fn board(&self) -> &Board {
        self.uc.get_data()
    }

    /// The board, mutable.
    pub fn board_mut(&mut self) -> &mut Board {
        self.uc.get_data_mut()
    }

    /// Read `len` bytes of emulated memory (any mapped address).
    pub fn read_memory(&self, addr: u32, len: usize) -> Option<Vec<u8>> {
        self.uc.mem_read_as_vec(addr as u64, len).ok()
    }

    /// A CPU register.
    pub fn register(&self, r: RegisterARM) -> u32 {
        reg(&self.uc, r)
    }

    /// The CPU's reset (ARMv7-M B1.5.5): MSP and PC from the vector table at 0 — flash, as
    /// BOOT0 = 0 with nBOOT1 = 1 maps it (RM0440 2.6 "Boot configuration") — thread mode,
    /// privileged, masks clear, FPU context inactive. The SCS is reset too.
    fn reset_cpu(&mut self) -> Result<(), Error> {
        let (sp, pc) = {
            let b = self.uc.get_data();
            let w = |o: usize| u32::from_le_bytes(b.flash[o..o + 4].try_into().unwrap());
            (w(0), w(4))
        };
        let b = self.uc.get_data_mut();
        b.scs = Scs::default();
        b.irq_dirty = true;
        set(&mut self.uc, RegisterARM::IPSR, 0);
        set(&mut self.uc, RegisterARM::CONTROL, 0);
        set(&mut self.uc, RegisterARM::PRIMASK, 0);
        set(&mut self.uc, RegisterARM::BASEPRI, 0);
        set(&mut self.uc, RegisterARM::FAULTMASK, 0);
        set(&mut self.uc, RegisterARM::MSP, sp & !3);
        set(&mut self.uc, RegisterARM::PSP, 0);
        set(&mut self.uc, RegisterARM::SP, sp & !3);
        set(&mut self.uc, RegisterARM::LR, 0xFFFF_FFFF);
        set(&mut self.uc, RegisterARM::XPSR_NZCVQG, 1 << 24);
        rebuild_hflags(&mut self.uc);
        set(&mut self.uc, RegisterARM::PC, pc | 1);
        if pc & 1 == 0 {
            return Err(Error::Setup(format!(
                "reset vector {pc:#010x} is not a Thumb address"
            )));
        }
        Ok(())
    }

    /// A system reset (AIRCR.SYSRESETREQ, the IWDG): CPU, SCS and peripherals reset; SRAM and
    /// flash keep their contents (RM0440 7.1.2 "System reset": SRAM is not erased); the RCC's
    /// reset flags record `cause`.
    pub fn system_reset(&mut self, cause: crate::periph::ResetCause) -> Result<(), Error> {
        self.resets += 1;
        let b = self.uc.get_data_mut();
        let now = b.now;
        b.periph.reset(cause, now);
        self.reset_cpu()
    }

    fn bus_read(uc: &mut Unicorn<'_, Board>, addr: u32, size: usize) -> u32 {
        let b = uc.get_data_mut();
        let now = b.now;
        let r = if addr >= 0xE000_0000 && !(0xE004_2000..0xE004_3000).contains(&addr) {
            b.scs
                .read(addr, size, now)
                .map_err(|u| format!("unmodelled system register {:#010x}", u.0))
        } else {
            let pc_dummy = 0;
            let _ = pc_dummy;
            b.periph.read(addr, size, now)
        };
        uc.get_data_mut().update_irqs();
        match r {
            Ok(v) => {
                let mask = if size >= 4 {
                    u32::MAX
                } else {
                    (1u32 << (8 * size)) - 1
                };
                v & mask
            }
            Err(e) => {
                let pc = reg(uc, RegisterARM::PC);
                let b = uc.get_data_mut();
                b.fault.get_or_insert(format!(
                    "read of {addr:#010x} ({size} B) at pc {pc:#010x}: {e}"
                ));
                // Stop before the next instruction (stopping inside the access would leave
                // the PC on this instruction and run it again).
                b.deadline = b.now;
                0
            }
        }
    }

    fn bus_write(uc: &mut Unicorn<'_, Board>, addr: u32, size: usize, v: u32) {
        let b = uc.get_data_mut();
        let now = b.now;
        let r = if addr >= 0xE000_0000 && !(0xE004_2000..0xE004_3000).contains(&addr) {
            b.scs
                .write(addr, size, v, now)
                .map_err(|u| format!("unmodelled system register {:#010x}", u.0))
        } else {
            b.periph.write(addr, size, v, now)
        };
        let b = uc.get_data_mut();
        // Any write may pend, enable or re-prioritise an exception, or change a deadline.
        b.irq_dirty = true;
        b.update_irqs();
        // Events the write started (a reset request, a DMA channel enabled with a request
        // waiting, a TRGO) are handled before the next instruction.
        if b.scs.scb.reset_requested || b.periph.wants_stop() {
            b.deadline = b.now;
        }
        if let Err(e) = r {
            let pc = reg(uc, RegisterARM::PC);
            let b = uc.get_data_mut();
            b.fault.get_or_insert(format!(
                "write of {v:#x} to {addr:#010x} ({size} B) at pc {pc:#010x}: {e}"
            ));
            b.deadline = b.now;
        }
    }

    /// Is the CPU inside an IT block (EPSR.IT non-zero, ARMv7-M A7.3)? An exception is not
    /// taken there by this model (the hardware may; the IT state would be stacked).
    fn in_it_block(&self) -> bool {
        reg(&self.uc, RegisterARM::XPSR) & IT_BITS != 0
    }

    /// Take exception `exc` (B1.5.6): push the frame, set LR to EXC_RETURN, enter handler mode
    /// at the vector.
    fn exception_entry(&mut self, exc: usize) -> Result<(), String> {
        let uc = &mut self.uc;
        let ipsr = reg(uc, RegisterARM::IPSR) & 0x1FF;
        let control = reg(uc, RegisterARM::CONTROL);
        let thread = ipsr == 0;
        let psp = thread && control & 2 != 0;
        let fpca = control & 4 != 0;
        let sp = reg(uc, stack_pointer(psp));
        let words = frame_words(fpca);
        let unaligned = sp.wrapping_sub(words * 4);
        let frame = unaligned & !7;
        let realigned = (unaligned & 4 != 0) as u32;
        let pc = reg(uc, RegisterARM::PC);
        let xpsr = reg(uc, RegisterARM::XPSR);
        let mut w = vec![
            reg(uc, RegisterARM::R0),
            reg(uc, RegisterARM::R1),
            reg(uc, RegisterARM::R2),
            reg(uc, RegisterARM::R3),
            reg(uc, RegisterARM::R12),
            reg(uc, RegisterARM::LR),
            pc & !1,
            (xpsr & !(1 << 9)) | realigned << 9 | 1 << 24,
        ];
        if fpca {
            for i in 0..16 {
                w.push(reg(uc, RegisterARM::S0 as i32 + i));
            }
            w.push(reg(uc, RegisterARM::FPSCR));
            w.push(0);
        }
        let bytes: Vec<u8> = w.iter().flat_map(|v| v.to_le_bytes()).collect();
        uc.mem_write(frame as u64, &bytes).map_err(|e| {
            format!("exception {exc}: stacking at {frame:#010x} failed ({e:?}): stack overflow?")
        })?;
        set(uc, stack_pointer(psp), frame);
        let exc_return =
            0xFFFF_FFE1 | (thread as u32) << 3 | (psp as u32) << 2 | (!fpca as u32) << 4;
        let vtor = uc.get_data().scs.scb.vtor;
        let mut vec = [0u8; 4];
        uc.mem_read(vtor as u64 + 4 * exc as u64, &mut vec)
            .map_err(|e| {
                format!(
                    "exception {exc}: vector fetch at {:#010x} failed ({e:?})",
                    vtor + 4 * exc as u32
                )
            })?;
        let handler = u32::from_le_bytes(vec);
        // Handler mode: MSP, FPCA clear.
        set(uc, RegisterARM::CONTROL, control & !(4 | 2));
        set(
            uc,
            RegisterARM::SP,
            if psp {
                reg(uc, RegisterARM::MSP)
            } else {
                frame
            },
        );
        set(uc, RegisterARM::IPSR, exc as u32);
        set(uc, RegisterARM::LR, exc_return);
        rebuild_hflags(uc);
        set(uc, RegisterARM::PC, handler | 1);
        let b = uc.get_data_mut();
        if std::env::var_os("STM32_EMU_TRACE_EXC").is_some() {
            eprintln!("exc {exc} at cycle {} from pc {pc:#010x}", b.now);
        }
        b.scs.nvic.activate(exc);
        b.scs.ipsr = exc;
        b.irq_dirty = true;
        Ok(())
    }

    /// EXC_RETURN reached (B1.5.8): pop the frame, restore xPSR (with IPSR) and CONTROL.
    fn exception_return(uc: &mut Unicorn<'_, Board>) -> Result<(), String> {
        let excret = reg(uc, RegisterARM::PC) | 1;
        let ipsr = reg(uc, RegisterARM::IPSR) as usize & 0x1FF;
        if excret & 0xFFFF_FF00 != 0xFFFF_FF00 {
            return Err(format!("EXC_RETURN {excret:#010x} with zero high bits"));
        }
        let (thread, psp) = match excret & 0xF {
            0x1 => (false, false),
            0x9 => (true, false),
            0xD => (true, true),
            _ => {
                return Err(format!(
                    "invalid EXC_RETURN {excret:#010x} (INVPC UsageFault)"
                ))
            }
        };
        let fp = excret & 0x10 == 0;
        {
            let b = uc.get_data_mut();
            if ipsr == 0 || !b.scs.nvic.is_active(ipsr) {
                return Err(format!(
                    "EXC_RETURN {excret:#010x} from exception {ipsr}, which is not active"
                ));
            }
            b.scs.nvic.deactivate(ipsr);
            let nested = b.scs.nvic.active_count();
            if thread && nested != 0 {
                return Err(format!(
                    "EXC_RETURN to thread mode with {nested} exception(s) still active (CCR.NONBASETHRDENA clear)"
                ));
            }
        }
        let frame = reg(uc, stack_pointer(psp));
        let words = frame_words(fp);
        let bytes = uc
            .mem_read_as_vec(frame as u64, words as usize * 4)
            .map_err(|e| format!("unstacking at {frame:#010x} failed ({e:?})"))?;
        let w = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
        let xpsr = w(7);
        let sp = frame + words * 4 + if xpsr & (1 << 9) != 0 { 4 } else { 0 };
        for (i, r) in [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R12,
            RegisterARM::LR,
        ]
        .into_iter()
        .enumerate()
        {
            set(uc, r, w(i));
        }
        if fp {
            for i in 0..16 {
                set(uc, RegisterARM::S0 as i32 + i as i32, w(8 + i));
            }
            set(uc, RegisterARM::FPSCR, w(24));
        }
        let control = reg(uc, RegisterARM::CONTROL) & !(4 | 2);
        let control = control | (fp as u32) << 2 | ((thread && psp) as u32) << 1;
        // The stacked xPSR's IPSR is the interrupted context's exception number.
        set(uc, RegisterARM::XPSR_NZCVQG, xpsr & !(1 << 9));
        set(uc, RegisterARM::CONTROL, control);
        set(uc, stack_pointer(psp), sp);
        set(uc, RegisterARM::SP, sp);
        rebuild_hflags(uc);
        set(uc, RegisterARM::PC, w(6) | 1);
        let b = uc.get_data_mut();
        b.scs.ipsr = (xpsr & 0x1FF) as usize;
        b.irq_dirty = true;
        b.update_irqs();
        Ok(())
    }

    /// Run until core cycle `until` (or a fault). Handles events, exceptions, WFI, resets.
    pub fn run_until(&mut self, until: u64) -> Exit {
        loop {
            let b = self.uc.get_data_mut();
            if let Some(f) = b.fault.take() {
                return Exit::Fault(f);
            }
            let now = b.now;
            // Peripherals' and SysTick's events due by now.
            let mut mem = Mem {
                flash: &mut b.flash,
                sram: &mut b.sram,
                ccm: &mut b.ccm,
            };
            b.periph.advance(now, &mut mem);
            b.update_irqs();
            if b.scs.systick.advance(now) {
                b.scs.nvic.pend(cortex::EXC_SYSTICK);
            }
            if let Some(cause) = b.periph.reset_cause_pending() {
                if let Err(e) = self.system_reset(cause) {
                    return Exit::Fault(e.to_string());
                }
                continue;
            }
            if b.scs.scb.reset_requested {
                if let Err(e) = self.system_reset(crate::periph::ResetCause::Software) {
                    return Exit::Fault(e.to_string());
                }
                continue;
            }
            if now >= until {
                return Exit::Limit;
            }
            let b = self.uc.get_data_mut();
            let next_event = b
                .periph
                .next_event(now)
                .into_iter()
                .chain(b.scs.systick.next_event())
                .min();
            let takable = takable_exception(&self.uc);
            let mut deadline = next_event.unwrap_or(u64::MAX).min(until);
            if let Some(exc) = takable {
                if self.in_it_block() {
                    deadline = deadline.min(now + 1);
                } else {
                    if let Err(e) = self.exception_entry(exc) {
                        return Exit::Fault(e);
                    }
                    continue;
                }
            }
            let b = self.uc.get_data_mut();
            b.deadline = deadline;
            b.stopped = false;
            b.irq_dirty = true;
            let start = reg(&self.uc, RegisterARM::PC) | 1;
            let r = self.uc.emu_start(start as u64, 0, 0, 0);
            let b = self.uc.get_data_mut();
            if let Some(f) = b.fault.take() {
                return Exit::Fault(f);
            }
            match r {
                Ok(()) if b.stopped => {}
                Ok(()) => {
                    // WFI (unicorn halts the CPU): sleep to the next event, or to the limit.
                    let pc = reg(&self.uc, RegisterARM::PC);
                    let b = self.uc.get_data_mut();
                    let wfi = b.mem_read(pc.wrapping_sub(2), 2) == Some(0xBF30);
                    if !wfi {
                        return Exit::Fault(format!(
                            "CPU stopped at {pc:#010x} without a known cause"
                        ));
                    }
                    // An exception already takable wakes it at once (ARMv7-M B1.5.19): one
                    // pended where none is taken, inside an IT block, before its WFI.
                    if takable_exception(&self.uc).is_none() {
                        let b = self.uc.get_data_mut();
                        b.now = next_event.unwrap_or(until).min(until).max(b.now);
                    }
                }
                Err(e) => {
                    let pc = reg(&self.uc, RegisterARM::PC);
                    use unicorn_engine::uc_error;
                    if e == uc_error::INSN_INVALID || e == uc_error::EXCEPTION {
                        // UDF (panic-probe's `udf`), an undefined instruction: UsageFault,
                        // escalated to HardFault (SHCSR.USGFAULTENA clear; B1.5.14).
                        let b = self.uc.get_data_mut();
                        b.scs.scb.cfsr |= 1 << 16; // UNDEFINSTR
                        b.scs.scb.hfsr |= 1 << 30; // FORCED
                        b.scs.nvic.pend(EXC_HARDFAULT);
                        if b.scs.nvic.is_active(EXC_HARDFAULT) {
                            return Exit::Fault(format!(
                                "lockup: fault in the HardFault handler at {pc:#010x}"
                            ));
                        }
                        if let Err(e) = self.exception_entry(EXC_HARDFAULT) {
                            return Exit::Fault(e);
                        }
                        continue;
                    }
                    return Exit::Fault(format!("CPU error {e:?} at pc {pc:#010x}"));
                }
            }
        }
    }

    /// Put `bytes` on LPUART1's RX line now, back to back at the receiver's baud rate.
    pub fn uart_send(&mut self, bytes: &[u8]) {
        let b = self.board_mut();
        let t = b.seconds();
        b.periph.lpuart.send(t, bytes);
    }

    /// Send the command line `line` as the host link does (`docs/protocol.md`): one
    /// `HostMsg::Command` frame on LPUART1's RX line now, numbered from 1. Err when the line
    /// does not fit a command frame (longer than `probe_proto::MAX_LINE` bytes).
    pub fn send_command(&mut self, line: &str) -> Result<u32, String> {
        let line = heapless::String::try_from(line).map_err(|_| {
            format!(
                "command longer than {} bytes: {line}",
                probe_proto::MAX_LINE
            )
        })?;
        self.next_command_id += 1;
        let id = self.next_command_id;
        let mut buf = [0u8; probe_proto::MAX_HOST_FRAME];
        let frame = probe_proto::encode_host(&probe_proto::HostMsg::Command { id, line }, &mut buf)
            .map_err(|_| "command frame does not fit".to_string())?;
        let frame = frame.to_vec();
        self.uart_send(&frame);
        Ok(id)
    }

    /// The number of the last command frame sent ([`Machine::send_command`]; 0 before the first).
    pub fn last_command(&self) -> u32 {
        self.next_command_id
    }

    /// The highest command number the image has replied to so far (`DeviceMsg::Reply`, sent
    /// once a command is served or refused, `docs/protocol.md`), read from the frames on LPUART1
    /// TX as the host decodes them; `None` before the first reply.
    pub fn last_reply(&mut self) -> Option<u32> {
        let tx = &self.uc.get_data().periph.lpuart.tx;
        let new = tx.get(self.tx_read..).unwrap_or_default().to_vec();
        self.tx_read = tx.len();
        for b in new {
            if let Some(Ok(body)) = self.tx_frames.feed(b) {
                if let Ok(probe_proto::DeviceFrame {
                    msg: probe_proto::DeviceMsg::Reply { id, .. },
                    ..
                }) = probe_proto::decode_device(body)
                {
                    self.last_reply = Some(self.last_reply.map_or(id, |r| r.max(id)));
                }
            }
        }
        self.last_reply
    }

    /// Seconds of emulated time since power-on.
    pub fn seconds(&self) -> f64 {
        self.board().seconds()
    }

    /// Core cycles since power-on.
    pub fn cycles(&self) -> u64 {
        self.board().now
    }
}

/// The first external interrupt's exception number, re-exported for the tests.
pub const IRQ0: usize = EXC_IRQ0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elf::Segment;

    /// Hand-assembled (llvm-mc, thumbv7em) at 0x0800_0200:
    ///
    /// ```text
    /// reset: IPR[0] = 0x40; ISER0 = 1; BASEPRI = 0x20; vmov.f32 s0, #1.0
    ///        r2 = 7; STIR = 0 (IRQ0 pending, masked); r2 += 1
    ///        [0x2000_0004] = [0x2000_0000]   (handler count before unmasking)
    ///        BASEPRI = 0                      (IRQ0 taken here)
    ///        r2 += 1; r6 = s0; loop: wfi; b loop
    /// handler: r2 = 99; s0 = 2.0; [0x2000_0000] += 1; r7 = lr; bx lr
    /// ```
    const PROGRAM: [u8; 88] = [
        0x12, 0x48, 0x40, 0x21, 0x01, 0x70, 0x12, 0x48, 0x01, 0x21, 0x01, 0x60, 0x20, 0x21, 0x81,
        0xf3, 0x11, 0x88, 0xb7, 0xee, 0x00, 0x0a, 0x0f, 0x48, 0x00, 0x21, 0x07, 0x22, 0x01, 0x60,
        0x52, 0x1c, 0x4f, 0xf0, 0x00, 0x53, 0x1d, 0x68, 0x5d, 0x60, 0x00, 0x21, 0x81, 0xf3, 0x11,
        0x88, 0x52, 0x1c, 0x10, 0xee, 0x10, 0x6a, 0x30, 0xbf, 0xfd, 0xe7, 0x63, 0x22, 0xb0, 0xee,
        0x00, 0x0a, 0x4f, 0xf0, 0x00, 0x53, 0x1d, 0x68, 0x01, 0x35, 0x1d, 0x60, 0x77, 0x46, 0x70,
        0x47, 0x00, 0xe4, 0x00, 0xe0, 0x00, 0xe1, 0x00, 0xe0, 0x00, 0xef, 0x00, 0xe0,
    ];
    const SP0: u32 = 0x2000_8000;

    fn machine() -> Machine {
        let mut vt = vec![0u8; 0x200];
        let mut put = |i: usize, v: u32| vt[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
        put(0, SP0);
        put(1, 0x0800_0201);
        put(16, 0x0800_0239);
        vt.extend_from_slice(&PROGRAM);
        let elf = Elf::from_segments(vec![Segment {
            paddr: FLASH_BASE,
            data: vt,
        }]);
        Machine::new(&elf).unwrap()
    }

    fn word(m: &Machine, a: u32) -> u32 {
        u32::from_le_bytes(m.read_memory(a, 4).unwrap().try_into().unwrap())
    }

    #[test]
    fn basepri_defers_the_interrupt_and_return_restores_the_frame() {
        let mut m = machine();
        assert_eq!(m.run_until(1_000), Exit::Limit);
        // ARMv7-M B1.5.4: pending at priority 0x40 under BASEPRI 0x20: not taken until BASEPRI
        // is lowered; then taken before the next instruction.
        assert_eq!(word(&m, 0x2000_0004), 0, "handler ran while masked");
        assert_eq!(word(&m, 0x2000_0000), 1, "handler ran once");
        // B1.5.8: the frame restored the caller-saved r2 (7 + 1 + 1), the handler's 99 is gone.
        assert_eq!(m.register(RegisterARM::R2), 9);
        // The extended frame (CONTROL.FPCA set by the thread's FP instruction) restored s0.
        assert_eq!(m.register(RegisterARM::R6), 1.0f32.to_bits());
        // EXC_RETURN: thread, MSP, FP frame = 0xFFFF_FFE9 (B1.5.8 Table B1-8).
        assert_eq!(m.register(RegisterARM::R7), 0xFFFF_FFE9);
        // Back in thread mode with the stack as before, asleep in WFI; nothing active.
        assert_eq!(m.register(RegisterARM::IPSR), 0);
        assert_eq!(m.register(RegisterARM::SP), SP0);
        assert_eq!(m.board().scs.nvic.active_count(), 0);
        assert!(
            m.board().executed < 100,
            "WFI slept the rest: {}",
            m.board().executed
        );
        assert_eq!(m.cycles(), 1_000);
    }

    /// Hand-assembled (llvm-mc, thumbv7em) at 0x0800_0200, with an IT block across the 4 KiB
    /// boundary at 0x0800_1000 (a translated block ends there, inside the IT block):
    ///
    /// ```text
    /// reset:    IPR[0] = 0x40; ISER0 = 1; r0 = &STIR; r1 = 0; r2 = 0; cmp r1, r1; b.w straddle
    /// handler:  [0x2000_0000] += 1; [0x2000_0004] = r2; bx lr
    /// straddle: (0x0800_0FFC) itt eq; streq r1, [r0]  (IRQ0 pending, inside the IT block)
    ///           (0x0800_1000) addeq r2, #1; add.w r2, r2, #10; loop: wfi; b loop
    /// ```
    const IT_HEAD: [u8; 52] = [
        0x09, 0x48, 0x40, 0x21, 0x01, 0x70, 0x09, 0x48, 0x01, 0x21, 0x01, 0x60, 0x08, 0x48, 0x00,
        0x21, 0x00, 0x22, 0x89, 0x42, 0x00, 0xf0, 0xf2, 0xbe, 0x4f, 0xf0, 0x00, 0x53, 0x1c, 0x68,
        0x01, 0x34, 0x1c, 0x60, 0x5a, 0x60, 0x70, 0x47, 0x00, 0x00, 0x00, 0xe4, 0x00, 0xe0, 0x00,
        0xe1, 0x00, 0xe0, 0x00, 0xef, 0x00, 0xe0,
    ];
    const IT_TAIL: [u8; 14] = [
        0x04, 0xbf, 0x01, 0x60, 0x01, 0x32, 0x02, 0xf1, 0x0a, 0x02, 0x30, 0xbf, 0xfd, 0xe7,
    ];

    /// An interrupt pended inside an IT block that a translated block's end splits waits for
    /// the block's end and is then taken once (the model takes none inside an IT block,
    /// [`Machine::in_it_block`]); the run returns at its limit rather than restarting the
    /// split block's second half forever. Run on a thread: a livelock fails the test.
    #[test]
    fn an_interrupt_pended_inside_a_split_it_block_is_taken_after_it() {
        let run = std::thread::spawn(|| {
            let mut vt = vec![0u8; 0x200];
            let mut put = |i: usize, v: u32| vt[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
            put(0, SP0);
            put(1, 0x0800_0201);
            put(16, 0x0800_0219);
            let mut program = vec![0u8; 0xDFC];
            program[..IT_HEAD.len()].copy_from_slice(&IT_HEAD);
            program.extend_from_slice(&IT_TAIL);
            vt.extend_from_slice(&program);
            let elf = Elf::from_segments(vec![Segment {
                paddr: FLASH_BASE,
                data: vt,
            }]);
            let mut m = Machine::new(&elf).unwrap();
            let exit = m.run_until(2_000);
            let r2 = m.register(RegisterARM::R2);
            (exit, word(&m, 0x2000_0000), word(&m, 0x2000_0004), r2)
        });
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || tx.send(run.join()).ok());
        let got = rx
            .recv_timeout(std::time::Duration::from_secs(20))
            .expect("the run did not return: a livelock at the split IT block");
        let (exit, count, r2_at_entry, r2) = got.unwrap();
        assert_eq!(exit, Exit::Limit);
        assert_eq!(count, 1, "handler runs");
        assert_eq!(r2_at_entry & 1, 1, "the IT block ended before the handler");
        assert_eq!(r2, 11, "the frame restored r2");
    }
}
