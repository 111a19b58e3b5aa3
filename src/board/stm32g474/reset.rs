//! What the STM32 board keeps across a reset and learns from one: the first failed bring-up
//! step of this boot ([`boot_error`]), the boot-step marker in RAM a reset does not clear
//! ([`Step`]), the reset's cause, and the clock security system's NMI, which resets the core
//! into a boot on HSI16.

use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{AtomicU8, Ordering};
use embassy_stm32::pac;

use super::BootError;

/// First boot error (0: none).
static BOOT_ERROR: AtomicU8 = AtomicU8::new(0);

/// Record `e` as a failed bring-up step, unless an earlier one is recorded.
pub(super) fn record(e: BootError) {
    let _ = BOOT_ERROR.compare_exchange(0, e as u8, Ordering::Relaxed, Ordering::Relaxed);
}

/// The first bring-up step that failed, if any — complete once [`init`](super::init) and
/// [`Stream::start`](super::Stream::start) have run.
pub fn boot_error() -> Option<BootError> {
    let v = BOOT_ERROR.load(Ordering::Relaxed);
    BootError::ALL.into_iter().find(|e| *e as u8 == v)
}

/// A step whose waits are embassy's own and unbounded. The watchdog runs from the start of
/// [`init`](super::init); the step in progress is kept in RAM that a reset does not clear, so
/// the boot after a watchdog reset ([`reset_cause`]) knows which step hung and goes around it
/// with a typed [`BootError`] instead of hanging again (no reset loop).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub(super) enum Step {
    /// `embassy_stm32::init` (RCC, flash latency).
    Clock = 1,
    /// TIM6, DAC1 (with its calibration), ADC1 and ADC2.
    Converters = 2,
    /// A flash erase or program of the store.
    Flash = 3,
    /// Not a step: the clock security system saw the HSE fail while the image ran; its NMI
    /// (`NonMaskableInt`) wrote this and reset the core, and the boot after a software reset
    /// that finds it runs from HSI16 through the PLL ([`BootError::HseFailure`]).
    HseFailed = 4,
}

/// Tag of a valid marker (upper half-word); the second word is the first's complement, so the
/// random contents of SRAM at power-on are not taken for a step.
const STEP_MAGIC: u32 = 0x5EB0_0000;

/// The step in progress: not zeroed by the start-up code (`.uninit`), so it survives a reset
/// (not a power cycle).
#[link_section = ".uninit.pzt_boot_step"]
static mut STEP: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

/// Mark `step` as the one in progress (`None`: none).
fn set_step(step: Option<Step>) {
    let v = step.map_or(0, |s| STEP_MAGIC | s as u32);
    // SAFETY: two aligned words of our own static; volatile so the marker is in RAM before the
    // step's first wait.
    unsafe {
        let p = addr_of_mut!(STEP) as *mut u32;
        p.write_volatile(v);
        p.add(1).write_volatile(!v);
    }
}

/// Run `f` as the boot step `step`: marked in progress while it runs (a reset in it is
/// recorded as that step hanging), no step after.
pub(super) fn during<R>(step: Step, f: impl FnOnce() -> R) -> R {
    set_step(Some(step));
    let r = f();
    set_step(None);
    r
}

/// What caused the last reset, as far as the boot-step marker cares.
#[derive(Clone, Copy)]
pub(super) struct ResetCause {
    /// The independent watchdog (IWDGRSTF).
    pub(super) watchdog: bool,
    /// A software reset (SFTRSTF): the clock security system's NMI resets this way.
    pub(super) software: bool,
}

/// What caused the last reset; the reset flags are cleared, so the next boot reads its own
/// cause (they are sticky until RMVF).
///
/// Gap: embassy-stm32 0.6 has no reset-cause API. RAW 12/17: RCC_CSR read-modify-write,
/// IWDGRSTF and SFTRSTF read and RMVF set in one access (RM0440 7.4.28 RCC_CSR, numbered by
/// the register order: see docs/bringup.md).
pub(super) fn reset_cause() -> ResetCause {
    pac::RCC.csr().modify(|w| {
        let cause = ResetCause {
            watchdog: w.iwdgrstf(),
            software: w.sftrstf(),
        };
        w.set_rmvf(true);
        cause
    })
}

/// The clock security system's NMI (RM0440 7.2, RCC clocks: "Clock security system (CSS)"): the HSE failed
/// while it clocked the PLL; the hardware has switched SYSCLK to HSI16 (16 MHz, PLL off), under
/// TIM6, LPUART1 and the monotonic set up for 170 MHz. Rather than run on mis-timed, the core
/// is reset; the boot after it finds the marker and runs from HSI16 through the PLL at 170 MHz
/// with [`BootError::HseFailure`] (no reset loop: that boot does not start the HSE again).
/// The reset also clears the CSS flag (CSSF), which would otherwise re-enter this handler for
/// ever (RCC_CICR.CSSC is not written: no raw access spent on it).
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    set_step(Some(Step::HseFailed));
    cortex_m::peripheral::SCB::sys_reset()
}

/// The step the run before this boot was in when the watchdog reset it.
pub(super) fn interrupted_step() -> Option<Step> {
    // SAFETY: two aligned words of our own static; after a power-on they hold whatever SRAM
    // came up with, which the complement check and the tag reject (read as plain words).
    let (a, b) = unsafe {
        let p = addr_of!(STEP) as *const u32;
        (p.read_volatile(), p.add(1).read_volatile())
    };
    if a != !b || a & 0xFFFF_0000 != STEP_MAGIC {
        return None;
    }
    [Step::Clock, Step::Converters, Step::Flash, Step::HseFailed]
        .into_iter()
        .find(|s| *s as u32 == a & 0xFFFF)
}
