//! The firmware's health counters: what the sample interrupt counts and the report task logs
//! (`counters` and `overrun` lines, `src/instrument/log.rs`, built with `defmt`). Plain atomics, written by
//! the interrupt with relaxed stores and read by the tasks.

use core::sync::atomic::{AtomicU32, Ordering};

/// Batches serviced by the sample interrupt.
pub static BATCHES: AtomicU32 = AtomicU32::new(0);
/// Batches whose interrupt overran its period (the next one was already pending).
pub static LATE: AtomicU32 = AtomicU32::new(0);
/// Engine ring overruns (a DAC batch forgotten before it was demodulated).
pub static RING: AtomicU32 = AtomicU32::new(0);
/// Finished points the interrupt could not hand on (channel full).
pub static DROPPED: AtomicU32 = AtomicU32::new(0);
/// Load-cell reads that failed (a pin error, or a conversion at a rail).
pub static LOAD_CELL_ERRORS: AtomicU32 = AtomicU32::new(0);
/// DMA transfer errors the board counted (its interrupt handlers, before the HAL's): the board
/// stops its sample stream at the first, and a stalled reading is then
/// [`Failure::DmaError`](crate::status::Failure::DmaError).
pub static DMA_ERRORS: AtomicU32 = AtomicU32::new(0);
/// Mean interrupt work per batch (board unit).
pub static ISR_MEAN: AtomicU32 = AtomicU32::new(0);
/// Largest interrupt work per batch (board unit).
pub static ISR_MAX: AtomicU32 = AtomicU32::new(0);

/// A snapshot of the overrun counters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Overruns {
    /// [`LATE`].
    pub late: u32,
    /// [`RING`].
    pub ring: u32,
    /// [`DROPPED`].
    pub dropped: u32,
}

impl Overruns {
    /// The counters now.
    pub fn now() -> Self {
        Self {
            late: LATE.load(Ordering::Relaxed),
            ring: RING.load(Ordering::Relaxed),
            dropped: DROPPED.load(Ordering::Relaxed),
        }
    }
    /// True when any overrun happened.
    pub fn any(&self) -> bool {
        self.late > 0 || self.ring > 0 || self.dropped > 0
    }
}

/// The sample interrupt's running statistics: it calls [`BatchStats::batch`] once per batch.
#[derive(Clone, Copy, Debug, Default)]
pub struct BatchStats {
    sum: u64,
    n: u32,
}

impl BatchStats {
    /// Count a batch that took `work` (board unit), with the engine's ring overruns so far and
    /// whether the next batch was already due (`late`).
    pub fn batch(&mut self, work: u32, ring_overruns: u32, late: bool) {
        self.sum += work as u64;
        self.n = self.n.saturating_add(1);
        // In f32 (24-bit mantissa: exact enough for a mean) rather than a u64 division, whose
        // library routine costs a kilobyte of flash.
        let mean = self.sum as f32 / self.n as f32;
        ISR_MEAN.store(mean as u32, Ordering::Relaxed);
        ISR_MAX.fetch_max(work, Ordering::Relaxed);
        RING.store(ring_overruns, Ordering::Relaxed);
        BATCHES.fetch_add(1, Ordering::Relaxed);
        if late {
            LATE.fetch_add(1, Ordering::Relaxed);
        }
    }
}
