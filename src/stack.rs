//! The stack's high-water mark: cortex-m-rt (feature `paint-stack`) paints the whole stack,
//! from `_stack_end` (its lowest address; with flip-link the bottom of RAM) up to
//! `_stack_start` (its top), with [`PAINT`] before `main`; the deepest the stack has grown is
//! where the paint is first found scrubbed off, scanning up from the bottom. The firmware logs
//! it after `status` and at the QEMU image's exit (`stack` line of `log`); on the host
//! there is no painted stack.

/// The paint (cortex-m-rt's `STACK_PAINT_VALUE`).
pub const PAINT: u32 = 0xCCCC_CCCC;

/// The stack's size and the most of it ever used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackUsage {
    /// Bytes from the top of the stack down to the deepest word written since `idle` started
    /// (`repaint`): the tasks and interrupts.
    pub used_bytes: u32,
    /// The same before: `init` (board bring-up; under QEMU the simulator's set-up) and the
    /// tasks up to their first wait.
    pub init_bytes: u32,
    /// Bytes of the whole stack region.
    pub size_bytes: u32,
}

/// The high-water mark of `init`, kept by [`repaint`].
#[cfg(target_os = "none")]
static INIT_USED: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

/// Words left unpainted below the stack pointer by `repaint` (firmware): the caller's frame
/// may still spill there.
pub const REPAINT_GUARD_WORDS: usize = 64;

/// Bytes used of the words `stack` (lowest address first, the top of the stack after the
/// last word), painted with [`PAINT`] where never written: everything above the lowest
/// scrubbed word.
pub fn used_of(stack: impl IntoIterator<Item = u32>) -> (u32, u32) {
    let (mut n, mut untouched, mut scrubbed) = (0u32, 0u32, false);
    for w in stack {
        n += 1;
        if !scrubbed && w == PAINT {
            untouched += 1;
        } else {
            scrubbed = true;
        }
    }
    (4 * (n - untouched), 4 * n)
}

/// The stack region `[lowest, top)` (linker symbols; with flip-link the bottom of RAM up to
/// the statics).
#[cfg(target_os = "none")]
fn region() -> (usize, usize) {
    extern "C" {
        static _stack_end: u32;
        static _stack_start: u32;
    }
    (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

#[cfg(target_os = "none")]
fn scan() -> (u32, u32) {
    let (lo, hi) = region();
    let words = hi.saturating_sub(lo) / 4;
    used_of((0..words).map(|i| {
        // SAFETY: lo + 4 i lies inside [lo, hi), every word of it readable RAM, word aligned
        // (cortex-m-rt aligns `_stack_end` to 4 bytes). Volatile reads of words the live
        // frames (or an interrupt) may write are still defined; only the lowest scrubbed word
        // matters, far below them.
        unsafe { core::ptr::read_volatile((lo as *const u32).add(i)) }
    }))
}

/// At the start of `idle`, with interrupts masked: keep the boot's high-water mark (`init`,
/// and the tasks up to their first wait), then paint the stack again from its bottom up to
/// [`REPAINT_GUARD_WORDS`] below the stack pointer, so that [`usage`] tells the running
/// tasks' and interrupts' depth apart from the bring-up's. (At the end of `init` its own frame
/// would still be live and count as used.)
#[cfg(target_os = "none")]
pub fn repaint() {
    cortex_m::interrupt::free(|_| {
        let (used, _) = scan();
        INIT_USED.store(used, core::sync::atomic::Ordering::Relaxed);
        let (lo, _) = region();
        let sp = cortex_m::register::msp::read() as usize;
        let end = sp.saturating_sub(4 * REPAINT_GUARD_WORDS);
        let mut p = lo;
        while p + 4 <= end {
            // SAFETY: [lo, sp - guard) is stack below every live frame (ARM EABI has no red
            // zone) and interrupts are masked: nothing else uses these words now.
            unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
            p += 4;
        }
    });
}

/// The painted stack's usage now (firmware), `None` on the host.
#[cfg(target_os = "none")]
pub fn usage() -> Option<StackUsage> {
    let (used_bytes, size_bytes) = scan();
    Some(StackUsage {
        used_bytes,
        init_bytes: INIT_USED.load(core::sync::atomic::Ordering::Relaxed),
        size_bytes,
    })
}

/// The painted stack's usage now (firmware), `None` on the host.
#[cfg(not(target_os = "none"))]
pub fn usage() -> Option<StackUsage> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mark_is_the_lowest_scrubbed_word() {
        // Bottom first: 3 painted words, then a scrubbed one, a painted one (a local that
        // happened to hold the paint, or skipped), and the top.
        let s = [PAINT, PAINT, PAINT, 7, PAINT, 9];
        assert_eq!(used_of(s), (12, 24));
        assert_eq!(used_of([PAINT; 4]), (0, 16));
        assert_eq!(used_of([1u32; 4]), (16, 16));
        assert_eq!(used_of([]), (0, 0));
    }
}
