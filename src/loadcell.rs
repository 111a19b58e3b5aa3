//! The contact-force load cell: an HX711 24-bit bridge ADC on two pins (embedded-hal 1.0), its
//! calibration to newtons, and the force over a reading's window.
//!
//! # Driver
//!
//! [`Hx711`] is our own, over `embedded_hal::digital` and `embedded_hal::delay`. The `hx711`
//! crate (0.7, embedded-hal 1.0) was the candidate; it does not fit a bounded boot: its
//! constructor resets the chip and then waits in an unbounded `nb::block!` for the first
//! conversion (50 ms at 80 SPS, 400 ms at 10 SPS, forever with the chip missing). This driver
//! never waits for the chip: [`Hx711::read`] returns `Ok(None)` until a conversion is ready.
//! A read is 25 clock pulses of [`PULSE_NS`] high and low; a pulse held high beyond 60 µs powers
//! the chip down (the read is lost), so on the target a read runs in a critical section (25 pulses:
//! well inside the sample interrupt's slack of 2.5 ms per batch).
//!
//! # Force over a window
//!
//! [`ForceLog`] keeps the last [`FORCE_LOG`] force samples, each stamped with the sample
//! engine's sample count; [`ForceLog::over`] gives the contact force during a reading as its mean
//! with the standard uncertainty of that mean and the change across the window (the fitted
//! slope times the window length): a force that changes during the reading is unstable contact,
//! not a number. All of it `no_std`, allocation free, panic free.

use crate::units::Newtons;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{InputPin, OutputPin};

/// A raw HX711 conversion (24-bit two's complement, sign-extended).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadCellCounts(pub i32);

impl LoadCellCounts {
    /// The converter's positive full scale; its negative one is `-(FULL + 1)`. A conversion at
    /// either is a saturated bridge (overload, or a broken wire), not a force.
    pub const FULL: i32 = (1 << 23) - 1;

    /// True at either rail.
    pub fn saturated(self) -> bool {
        self.0 >= Self::FULL || self.0 < -Self::FULL
    }
}

/// What went wrong reading the load cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadCellError {
    /// A pin could not be read or driven.
    Pin,
    /// The conversion sits at a rail.
    Saturated,
}

/// `PD_SCK`'s high time and its low time in a clock pulse, ns: the HX711 datasheet's minima
/// T3 and T4, 0.2 µs each (Avia Semiconductor, HX711 datasheet, Fig. 2's timing table), with
/// half again as margin. The high time also covers T2 (`DOUT` valid at most 0.1 µs after the
/// rising edge; the bit is read after the falling edge).
pub const PULSE_NS: u32 = 300;

/// HX711 on a data input and a clock output, channel A at gain 128.
pub struct Hx711<D, I, O> {
    delay: D,
    dout: I,
    sck: O,
}

impl<D: DelayNs, I: InputPin, O: OutputPin> Hx711<D, I, O> {
    /// Take the pins; the clock is driven low (the chip converts). Does not wait.
    pub fn new(delay: D, dout: I, mut sck: O) -> Result<Self, LoadCellError> {
        sck.set_low().map_err(|_| LoadCellError::Pin)?;
        Ok(Self { delay, dout, sck })
    }

    /// Power-cycle the chip: the clock high for 70 µs (over the 60 µs power-down time), then
    /// low. The first conversion comes after the chip's settling time (50 ms at 80 SPS).
    pub fn reset(&mut self) -> Result<(), LoadCellError> {
        self.sck.set_high().map_err(|_| LoadCellError::Pin)?;
        self.delay.delay_us(70);
        self.sck.set_low().map_err(|_| LoadCellError::Pin)
    }

    /// The conversion, if one is ready (`DOUT` low); `Ok(None)` otherwise. Never waits for the
    /// chip. 24 data pulses and one more for channel A at gain 128.
    pub fn read(&mut self) -> Result<Option<LoadCellCounts>, LoadCellError> {
        if self.dout.is_high().map_err(|_| LoadCellError::Pin)? {
            return Ok(None);
        }
        let mut v: u32 = 0;
        for _ in 0..24 {
            self.pulse()?;
            let bit = self.dout.is_high().map_err(|_| LoadCellError::Pin)?;
            v = (v << 1) | bit as u32;
        }
        self.pulse()?;
        // Sign-extend the 24-bit two's complement value.
        let c = LoadCellCounts(((v << 8) as i32) >> 8);
        if c.saturated() {
            return Err(LoadCellError::Saturated);
        }
        Ok(Some(c))
    }

    fn pulse(&mut self) -> Result<(), LoadCellError> {
        self.sck.set_high().map_err(|_| LoadCellError::Pin)?;
        self.delay.delay_ns(PULSE_NS);
        self.sck.set_low().map_err(|_| LoadCellError::Pin)?;
        self.delay.delay_ns(PULSE_NS);
        Ok(())
    }
}

/// A load cell's calibration: newtons per count (from a known weight, [`LoadCellCal::weighed`]),
/// and the zero (tare) taken with the tip in free air, with the air reference.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadCellCal {
    /// Newtons per count (the cell's sensitivity; from a known weight).
    pub newtons_per_count: f32,
    /// The counts of zero force.
    pub tare: LoadCellCounts,
}

impl LoadCellCal {
    /// The calibration from the cell's counts in free air (`zero`) and under a known weight
    /// `weight` (counts `loaded`); `None` unless the weight is positive and moved the counts
    /// by at least a thousand (a cell that does not answer, or a weight it cannot see).
    pub fn weighed(zero: &RawForce, loaded: &RawForce, weight: Newtons) -> Option<Self> {
        let span = loaded.mean - zero.mean;
        let npc = weight.0 as f64 / span;
        (weight.0 > 0.0 && span >= 1000.0 && npc.is_finite()).then(|| Self {
            newtons_per_count: npc as f32,
            tare: zero.counts(),
        })
    }

    /// The force of `c`.
    pub fn force(&self, c: LoadCellCounts) -> Newtons {
        let d = c.0 as i64 - self.tare.0 as i64;
        Newtons((d as f64 * self.newtons_per_count as f64) as f32)
    }

    /// The contact force of a window of counts.
    pub fn contact_force(&self, w: &RawForce) -> ContactForce {
        let k = self.newtons_per_count as f64;
        ContactForce {
            mean: Newtons(((w.mean - self.tare.0 as f64) * k) as f32),
            sigma: Newtons((w.sigma * k) as f32),
            change: Newtons((w.change * k) as f32),
            samples: w.samples,
        }
    }

    /// A force known by other means (a balance and a stage) as the window of counts this cell
    /// would have read for it, exactly and steady: for captures taken without the cell.
    pub fn stated(&self, f: Newtons) -> RawForce {
        RawForce {
            mean: self.tare.0 as f64 + f.0 as f64 / self.newtons_per_count as f64,
            sigma: 0.0,
            change: 0.0,
            samples: 0,
        }
    }

    /// True when the sensitivity is finite and positive.
    pub fn is_valid(&self) -> bool {
        self.newtons_per_count.is_finite() && self.newtons_per_count > 0.0
    }
}

/// The contact forces a unit reads at: below `min` a reading is `too_light`, above `max`
/// `too_hard` (the calibration's force compensation is vouched for inside). Settable
/// (`force <min mN> <max mN>`), kept with the unit profile.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ForceWindow {
    /// Lightest press that is a reading.
    pub min: Newtons,
    /// Hardest press that is a reading.
    pub max: Newtons,
}

/// Why a force window was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ForceWindowError {
    /// A bound is not a finite number.
    NotFinite,
    /// `min` below [`ForceWindow::LIGHTEST`], or `max` above [`ForceWindow::HARDEST`].
    OutOfRange,
    /// `min` not below `max`.
    Empty,
}

impl ForceWindow {
    /// The default: 12–55 mN, around the calibration's 15–50 mN (paper 003 pressed at 30 mN).
    pub const DEFAULT: ForceWindow = ForceWindow {
        min: Newtons(0.012),
        max: Newtons(0.055),
    };
    /// The lightest bound a window may have: below it the press is no contact
    /// ([`NO_CONTACT_FORCE`]).
    pub const LIGHTEST: Newtons = NO_CONTACT_FORCE;
    /// The hardest bound a window may have: the tip's contact radius reaches the shaft's near
    /// 0.2 N on the softest calibrated phantom, and the cell's range is 1 N.
    pub const HARDEST: Newtons = Newtons(0.2);

    /// A window from `min` to `max`, validated.
    pub fn new(min: Newtons, max: Newtons) -> Result<Self, ForceWindowError> {
        if !min.0.is_finite() || !max.0.is_finite() {
            return Err(ForceWindowError::NotFinite);
        }
        if min.0 < Self::LIGHTEST.0 || max.0 > Self::HARDEST.0 {
            return Err(ForceWindowError::OutOfRange);
        }
        if !(min.0 < max.0) {
            return Err(ForceWindowError::Empty);
        }
        Ok(Self { min, max })
    }

    /// True when the window would pass [`Self::new`].
    pub fn is_valid(&self) -> bool {
        Self::new(self.min, self.max).is_ok()
    }
}

impl Default for ForceWindow {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Below this contact force the tip is not pressed on anything (free air reads 0 ± the cell's
/// noise and the tare's age; a touch that light gives no reading): 3 mN.
pub const NO_CONTACT_FORCE: Newtons = Newtons(0.003);

/// Largest change of the contact force across one reading's window: a press that changes more
/// moved the resonance during the reading (1.2–1.9 % of modulus per mN on the soft phantoms,
/// docs/physics.md) and is `force_unstable`, not a number. 2 mN.
pub const MAX_FORCE_CHANGE: Newtons = Newtons(0.002);

/// Smallest change of the contact force across a window that explains a reading the estimator
/// refused (a press that moved shifts the resonance during the reading, and the estimator sees
/// a resonance that will not sit still): 0.5 mN, the force resolution the force compensation
/// needs (docs/physics.md: 1.2–1.9 % of modulus per mN on the soft phantoms, a 2 % reading
/// wants the force to ±0.5 mN). A change must also stand out of the cell's noise
/// ([`ContactForce::moved`]). Below [`MAX_FORCE_CHANGE`] such a press still gives a reading
/// when the estimator accepts it: the calibration applies at the window's mean force.
pub const MOVING_FORCE_CHANGE: Newtons = Newtons(0.0005);

/// Where a reading gets its contact force: the load cell's counts over samples `from..=to` of
/// the sample engine (`None`: no load cell on this board, or it gave fewer than three
/// conversions in the window). The board's load-cell task fills a [`ForceLog`]; a board
/// answers from it.
pub trait ForceSource {
    /// The counts over `from..=to`.
    fn contact_force(&self, from: u64, to: u64) -> Option<RawForce>;
}

/// Conversions a [`ForceLog`] keeps one by one: 1.6 s at 80 SPS, longer than the default
/// method's reading.
pub const FORCE_LOG: usize = 128;
/// Conversions averaged into one block of a [`ForceLog`]'s long memory: 0.1 s at 80 SPS.
pub const FORCE_BLOCK: usize = 8;
/// Block means a [`ForceLog`] keeps: 6.4 s at 80 SPS, the length of the slowest readings
/// (the stepped sweeps).
pub const FORCE_BLOCKS: usize = 64;

/// The load cell's counts over a window, before its calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawForce {
    /// Mean counts.
    pub mean: f64,
    /// Standard uncertainty of the mean, counts (the samples' scatter about their line over
    /// `sqrt(n)`).
    pub sigma: f64,
    /// The change across the window, counts: the fitted slope times the window's length.
    pub change: f64,
    /// Samples averaged (conversions, or block means for a window longer than the log's
    /// single conversions reach).
    pub samples: u16,
}

impl RawForce {
    /// The mean as counts (rounded, saturating).
    pub fn counts(&self) -> LoadCellCounts {
        LoadCellCounts(libm::round(self.mean) as i32)
    }
}

/// The contact force over a window.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContactForce {
    /// Mean force.
    pub mean: Newtons,
    /// Standard uncertainty of the mean (the samples' scatter about their line over `sqrt(n)`).
    pub sigma: Newtons,
    /// The change across the window: the fitted slope times the window's length.
    pub change: Newtons,
    /// Samples averaged.
    pub samples: u16,
}

impl ContactForce {
    /// Standard uncertainty of [`Self::change`]: the slope of a line through `n` evenly spaced
    /// samples over a window `T` has the uncertainty `s / sqrt(n T² / 12)`, so its change over
    /// `T` has `sqrt(12) s / sqrt(n) = sqrt(12) σ_mean`.
    pub fn change_sigma(&self) -> Newtons {
        Newtons(libm::sqrtf(12.0) * self.sigma.0)
    }

    /// True when the press moved during the window: a change of at least
    /// [`MOVING_FORCE_CHANGE`] that is also three of its standard uncertainties (a change the
    /// cell's noise makes one window in 370).
    pub fn moved(&self) -> bool {
        let c = libm::fabsf(self.change.0);
        c.is_finite() && c >= MOVING_FORCE_CHANGE.0 && c > 3.0 * self.change_sigma().0
    }
}

/// The load cell's recent conversions, each at a sample count of the engine: the last
/// [`FORCE_LOG`] one by one, and the last [`FORCE_BLOCKS`] means of [`FORCE_BLOCK`]
/// consecutive ones, so that a window is covered whole whether it is a 0.4 s hold or a 6 s
/// sweep (in 1.5 KiB). Counts, not newtons: the calibration is unit data
/// ([`crate::unit::profile::UnitProfile`]) and applies in the reading's pipeline. Each entry keeps the
/// low 32 bits of its sample count: a count is recovered against the window asked for, exact
/// while the entries lie within 2³² samples (5 days at 10 kHz) of it.
#[derive(Clone, Debug, Default)]
pub struct ForceLog {
    samples: heapless::Deque<(u32, i32), FORCE_LOG>,
    /// Each block's mid-point and the sum of its counts (exact: a sum of [`FORCE_BLOCK`]
    /// 24-bit conversions fits `i32`).
    blocks: heapless::Deque<(u32, i32), FORCE_BLOCKS>,
    /// The block being filled: conversions, the sum of their counts and of their sample
    /// counts' offsets from the first one's, and the first one's.
    block: (u8, i64, u64, u64),
    /// True once a conversion was dropped from the single ones.
    dropped: bool,
}

impl ForceLog {
    /// An empty log.
    pub const fn new() -> Self {
        Self {
            samples: heapless::Deque::new(),
            blocks: heapless::Deque::new(),
            block: (0, 0, 0, 0),
            dropped: false,
        }
    }

    /// Add the conversion `c` taken at sample count `at` (the oldest goes when full).
    pub fn push(&mut self, at: u64, c: LoadCellCounts) {
        if self.samples.is_full() {
            self.samples.pop_front();
            self.dropped = true;
        }
        let _ = self.samples.push_back((at as u32, c.0));
        let (n, sum, offsets, first) = &mut self.block;
        if *n == 0 {
            *first = at;
        }
        *n += 1;
        *sum += c.0 as i64;
        *offsets += at.saturating_sub(*first);
        if *n as usize == FORCE_BLOCK {
            let k = FORCE_BLOCK as u64;
            let mid = *first + *offsets / k;
            // Saturating only for counts beyond the converter's 24 bits.
            let total = (*sum).clamp(i32::MIN as i64, i32::MAX as i64) as i32;
            if self.blocks.is_full() {
                self.blocks.pop_front();
            }
            let _ = self.blocks.push_back((mid as u32, total));
            self.block = (0, 0, 0, 0);
        }
    }

    /// Forget every sample (the probe was lifted, the cell re-tared).
    pub fn clear(&mut self) {
        *self = Self::new();
    }

    /// The most recent conversion and the low 32 bits of its sample count.
    pub fn last(&self) -> Option<(u32, LoadCellCounts)> {
        self.samples.back().map(|&(at, c)| (at, LoadCellCounts(c)))
    }

    /// The counts over samples `from..=to` of the engine at `sample_rate` Hz: mean, its
    /// standard uncertainty and the change across the window, from a least-squares line
    /// through the conversions — the single ones when they reach back to the window's start,
    /// else the block means (whose scatter is the conversions' over `sqrt(FORCE_BLOCK)`, and
    /// which the same line fits). `None` with fewer than three of them in the window (the cell
    /// is not being read, or the window is shorter than three conversions).
    pub fn over(&self, from: u64, to: u64, sample_rate: f32) -> Option<RawForce> {
        if !(sample_rate > 0.0) || to < from {
            return None;
        }
        // Each entry's distance before `to` in samples: what its low bits say (an entry "after"
        // `to` wraps to far before it and falls outside). Always below 2³².
        let before = move |at: u32| (to as u32).wrapping_sub(at);
        let reaches_back = !self.dropped
            || self
                .samples
                .front()
                .is_some_and(|&(at, _)| to.wrapping_sub(before(at) as u64) <= from);
        // Newest first, past the entries after `to`, through the window, to the first entry
        // before it (the log is in time order): the window's entries without a look at the
        // rest of the log (a stream reading's window holds a tenth of it).
        let window = to - from;
        let within = move |&(u, _): &(u32, i32)| u as u64 <= window;
        if reaches_back {
            let fine = self.samples.iter().rev().map(|&(at, c)| (before(at), c));
            line_over(
                fine.skip_while(move |p| !within(p)).take_while(within),
                window,
                1,
            )
        } else {
            let coarse = self.blocks.iter().rev().map(|&(at, c)| (before(at), c));
            let coarse = coarse.skip_while(move |p| !within(p)).take_while(within);
            line_over(coarse, window, FORCE_BLOCK as i64)
        }
    }
}

/// The least-squares line through the points `(u, y / per)` with `u` (samples before the
/// window's end) at most `window`: mean, its standard uncertainty and the change across the
/// window ([`ForceLog::over`]).
///
/// One pass of exact integer sums (`u < 2³²` and `|y| < 2³¹`: every product fits `i64`, every
/// sum `i128`), and the centred sums `n Σuu − (Σu)²`, `n Σuy − Σu Σy`, `n Σyy − (Σy)²` exact
/// too, so the only rounding is the few `f64` operations at the end (emulated `f64` per point
/// is dear on the Cortex-M4F). The residual `n Σr² = C_yy − C_uy²/C_uu` cancels in `f64` only
/// as far as the line explains the counts: by `f64`'s 1e-16 times `(ramp / scatter)²`.
fn line_over(points: impl Iterator<Item = (u32, i32)>, window: u64, per: i64) -> Option<RawForce> {
    let (mut n, mut su, mut sy) = (0i64, 0i64, 0i64);
    let (mut suu, mut suy, mut syy) = (0i128, 0i128, 0i128);
    for (u, y) in points {
        if u as u64 > window {
            continue;
        }
        let (u, y) = (u as i64, y as i64);
        n += 1;
        su += u;
        sy += y;
        suu += (u as u64 * u as u64) as i128;
        suy += (u * y) as i128;
        syy += (y * y) as i128;
    }
    if n < 3 {
        return None;
    }
    let nn = n as i128;
    let (su, sy) = (su as i128, sy as i128);
    let cuu = (nn * suu - su * su) as f64;
    let cuy = (nn * suy - su * sy) as f64;
    let cyy = (nn * syy - sy * sy) as f64;
    let (nf, per) = (n as f64, per as f64);
    // Counts per sample, of the time running backwards from the window's end.
    let slope = if cuu > 0.0 { cuy / cuu } else { 0.0 };
    let ss = ((cyy - slope * cuy) / nf).max(0.0);
    let scatter = libm::sqrt(ss / (nf - 2.0));
    Some(RawForce {
        mean: sy as f64 / nf / per,
        sigma: scatter / libm::sqrt(nf) / per,
        change: -slope * window as f64 / per,
        samples: n.min(u16::MAX as i64) as u16,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window's mean, slope and scatter against closed forms: a ramp with alternating ±e
    /// (zero mean, uncorrelated with the ramp over whole pairs) gives back the ramp's mean and
    /// change exactly and a scatter of `e·sqrt(n/(n−2))`.
    #[test]
    fn window_statistics_in_closed_form() {
        let mut log = ForceLog::new();
        let fs = 10_000.0;
        // 80 SPS: a conversion every 125 engine samples; 30 000 counts rising 6 400 counts/s
        // (80 a conversion); ±100 counts.
        let e = 100.0;
        for k in 0..40u64 {
            let c = 30_000 + 80 * k as i32 + if k % 2 == 0 { 100 } else { -100 };
            log.push(k * 125, LoadCellCounts(c));
        }
        // Conversions 8..=31 (24 of them: whole pairs).
        let w = log.over(8 * 125, 31 * 125, fs).unwrap();
        assert_eq!(w.samples, 24);
        let t_mean = (8.0 + 31.0) / 2.0 / 80.0;
        assert!((w.mean - (30_000.0 + 6_400.0 * t_mean)).abs() < 1e-8);
        // The ±e pattern tilts the fitted line by a little: its projection on the centred time.
        let n = 24.0;
        let dt = |k: f64| (k - 19.5) / 80.0;
        let stt: f64 = (8..32).map(|k| dt(k as f64) * dt(k as f64)).sum();
        let sty_pattern: f64 = (8..32)
            .map(|k| dt(k as f64) * if k % 2 == 0 { e } else { -e })
            .sum();
        let slope = 6_400.0 + sty_pattern / stt;
        let window = (31.0 - 8.0) * 125.0 / 10_000.0f64;
        assert!((w.change - slope * window).abs() < 1e-8, "{:?}", w);
        // Residuals: the pattern less its projection on the line, Σr² = n e² − sty²/stt.
        let scatter = ((n * e * e - sty_pattern * sty_pattern / stt) / (n - 2.0)).sqrt();
        let sigma = scatter / n.sqrt();
        assert!(
            (w.sigma / sigma - 1.0).abs() < 1e-9,
            "{} vs {sigma}",
            w.sigma
        );
        // Too few samples, empty or inverted windows: no force.
        assert!(log.over(0, 250, fs).is_some());
        assert!(log.over(0, 124, fs).is_none());
        assert!(log.over(10, 5, fs).is_none());
        assert!(log.over(0, 10_000, 0.0).is_none());
    }

    /// The one-pass integer sums against the two-pass `f64` least squares (the reference: the
    /// line through the points with times in seconds from the window's start) over random logs:
    /// counts anywhere in the converter's 24 bits, ramps and noise of any size, jittered
    /// conversion times, windows of every length, the block means' path included.
    #[test]
    fn line_agrees_with_the_two_pass_f64_reference() {
        fn reference(pts: &[(u64, f64)], from: u64, to: u64, fs: f64) -> Option<RawForce> {
            let inside: Vec<(f64, f64)> = pts
                .iter()
                .filter(|(at, _)| (from..=to).contains(at))
                .map(|&(at, y)| ((at - from) as f64 / fs, y))
                .collect();
            let n = inside.len() as f64;
            if inside.len() < 3 {
                return None;
            }
            let tm = inside.iter().map(|p| p.0).sum::<f64>() / n;
            let ym = inside.iter().map(|p| p.1).sum::<f64>() / n;
            let stt: f64 = inside.iter().map(|p| (p.0 - tm).powi(2)).sum();
            let sty: f64 = inside.iter().map(|p| (p.0 - tm) * (p.1 - ym)).sum();
            let slope = if stt > 0.0 { sty / stt } else { 0.0 };
            let ss: f64 = inside
                .iter()
                .map(|p| (p.1 - ym - slope * (p.0 - tm)).powi(2))
                .sum();
            Some(RawForce {
                mean: ym,
                sigma: (ss / (n - 2.0)).sqrt() / n.sqrt(),
                change: slope * (to - from) as f64 / fs,
                samples: inside.len() as u16,
            })
        }
        let mut rng = probe_rng::Rng::new(28);
        let fs = 10_000.0;
        let (mut worst_mean, mut worst_change, mut worst_sigma) = (0.0f64, 0.0f64, 0.0f64);
        let mut compared = [0usize; 2];
        for case in 0..400 {
            let mut log = ForceLog::new();
            let base = rng.next_u64() % (1 << 40);
            let level = (rng.uniform() - 0.5) * 1.6e7;
            let ramp = (rng.uniform() - 0.5) * 10f64.powf(rng.uniform() * 7.0);
            let noise = 10f64.powf(rng.uniform() * 4.0);
            let count = 20 + (rng.next_u64() % 600) as usize;
            let mut fine = Vec::new();
            let mut at = base;
            for k in 0..count {
                at += 100 + rng.next_u64() % 50;
                let y = level + ramp * k as f64 / 80.0 + noise * rng.normal();
                let c = (y.round() as i32).clamp(-(1 << 23), (1 << 23) - 1);
                log.push(at, LoadCellCounts(c));
                fine.push((at, c as f64));
            }
            let to = at - rng.next_u64() % 400;
            let from = to.saturating_sub(rng.next_u64() % (at - base + 2000));
            let got = log.over(from, to, fs as f32);
            let by_blocks = fine.len() > FORCE_LOG && fine[fine.len() - FORCE_LOG].0 > from;
            let pts: Vec<(u64, f64)> = if !by_blocks {
                fine
            } else {
                // The blocks' exact means at their mid-points (low 32 bits against `to`).
                let full = |a: u32| to.wrapping_sub((to as u32).wrapping_sub(a) as u64);
                log.blocks
                    .iter()
                    .map(|&(a, sum)| (full(a), sum as f64 / FORCE_BLOCK as f64))
                    .collect()
            };
            let want = reference(&pts, from, to, fs);
            match (got, want) {
                (None, None) => {}
                (Some(g), Some(w)) => {
                    assert_eq!(g.samples, w.samples, "case {case}");
                    compared[by_blocks as usize] += 1;
                    let scale = w.sigma * (w.samples as f64).sqrt() + 1.0;
                    worst_mean = worst_mean.max((g.mean - w.mean).abs() / scale);
                    worst_change = worst_change.max((g.change - w.change).abs() / scale);
                    worst_sigma = worst_sigma.max((g.sigma - w.sigma).abs() / (w.sigma + 1e-6));
                }
                (g, w) => panic!("case {case}: {g:?} vs {w:?}"),
            }
        }
        std::eprintln!(
            "{compared:?} compared; worst: mean {worst_mean:e} change {worst_change:e} \
             sigma {worst_sigma:e}"
        );
        assert!(compared.iter().all(|&c| c >= 50), "{compared:?}");
        // Mean and change in units of the scatter (plus one count), σ relative: rounding alone
        // (tolerances a hundred times the worst seen), far below anything the force window reads.
        assert!(worst_mean < 1e-12, "{worst_mean:e}");
        assert!(worst_change < 1e-10, "{worst_change:e}");
        assert!(worst_sigma < 1e-9, "{worst_sigma:e}");
    }

    /// The log keeps the last FORCE_LOG samples.
    #[test]
    fn the_log_keeps_the_newest() {
        let mut log = ForceLog::new();
        for k in 0..(FORCE_LOG as u64 + 10) {
            log.push(k, LoadCellCounts(k as i32));
        }
        assert_eq!(
            log.last(),
            Some((FORCE_LOG as u32 + 9, LoadCellCounts((FORCE_LOG + 9) as i32)))
        );
        assert!(log.over(0, 9, 1.0).is_none(), "the oldest ten are gone");
        assert_eq!(log.over(10, 20, 1.0).unwrap().samples, 11);
        // Three samples are a window, two are not.
        assert_eq!(log.over(10, 12, 1.0).unwrap().samples, 3);
        assert!(log.over(10, 11, 1.0).is_none());
        log.clear();
        assert_eq!(log.last(), None);
        assert!(log.over(0, u64::MAX, 1.0).is_none());
    }

    /// A window longer than the single conversions reach is read from the block means: a ramp
    /// over 4 s (three times the single ones' reach) gives back its mean and change exactly.
    #[test]
    fn long_windows_use_the_block_means() {
        let mut log = ForceLog::new();
        // 400 conversions (5 s at 80 SPS), 30 000 counts rising 8 a conversion.
        for k in 0..400u64 {
            log.push(k * 125, LoadCellCounts(30_000 + 8 * k as i32));
        }
        // Blocks of conversions 8j..8j+7: mid-point 8j + 3 (the offsets' mean, 3.5, floored at
        // the engine's sample resolution: 437 of 437.5 samples), mean 30 000 + 8 (8j + 3.5).
        let (from, to) = (80 * 125, 400 * 125);
        let w = log.over(from, to, 10_000.0).unwrap();
        assert_eq!(w.samples, 40, "{w:?}");
        let mean_k = (10.0 + 49.0) / 2.0 * 8.0 + 3.5;
        assert!((w.mean - (30_000.0 + 8.0 * mean_k)).abs() < 1e-6, "{w:?}");
        // The slope is 8 counts per 125 samples exactly; the window is 320 conversions long.
        assert!((w.change - 8.0 * 320.0).abs() < 1e-3, "{w:?}");
        // The last 1.6 s still come from the single conversions.
        let w = log.over(300 * 125, 400 * 125, 10_000.0).unwrap();
        assert_eq!(w.samples, 100);
    }

    /// Sample counts past 2³²: entries on either side of a wrap of the low 32 bits are found in
    /// their window, an entry after the window is not in it.
    #[test]
    fn sample_counts_past_32_bits() {
        let mut log = ForceLog::new();
        let base = (1u64 << 32) - 250;
        for k in 0..5u64 {
            log.push(base + 125 * k, LoadCellCounts(1000 + k as i32));
        }
        // Entries 0..=3 (base .. base + 375, across the wrap at base + 250).
        let w = log.over(base, base + 375, 10_000.0).unwrap();
        assert_eq!(w.samples, 4);
        assert!((w.mean - 1001.5).abs() < 1e-12, "{w:?}");
        // Entries 2..=4 only.
        let w = log.over(base + 250, base + 500, 10_000.0).unwrap();
        assert_eq!(w.samples, 3);
        assert!((w.mean - 1003.0).abs() < 1e-12, "{w:?}");
    }

    /// A window's counts to newtons: the mean about the tare, σ and change by the sensitivity;
    /// the sensitivity from a known weight; a weight the cell cannot see gives no calibration.
    #[test]
    fn windows_to_newtons_and_weighing() {
        let raw = |mean: f64| RawForce {
            mean,
            sigma: 36.0,
            change: -72.0,
            samples: 12,
        };
        let zero = raw(7200.4);
        let cal = LoadCellCal::weighed(&zero, &raw(7200.4 + 3.6e5), Newtons(0.1)).unwrap();
        assert_eq!(cal.tare, LoadCellCounts(7200));
        assert!((cal.newtons_per_count as f64 * 3.6e6 - 1.0).abs() < 1e-6);
        let f = cal.contact_force(&raw(7200.0 + 1.08e5));
        assert!((f.mean.0 - 0.030).abs() < 1e-7, "{:?}", f);
        assert!((f.sigma.0 - 1e-5).abs() < 1e-10);
        assert!((f.change.0 + 2e-5).abs() < 1e-10);
        assert_eq!(f.samples, 12);
        assert!(LoadCellCal::weighed(&zero, &raw(7200.4 + 999.0), Newtons(0.1)).is_none());
        assert!(LoadCellCal::weighed(&zero, &raw(7200.4 + 3.6e5), Newtons(0.0)).is_none());
        assert!(LoadCellCal::weighed(&zero, &raw(f64::NAN), Newtons(0.1)).is_none());
        assert!(cal.is_valid());
        assert!(!LoadCellCal {
            newtons_per_count: 0.0,
            ..cal
        }
        .is_valid());
    }

    /// Counts to newtons around the tare: within the f32 roundings of the sensitivity and the
    /// result (an ulp each).
    #[test]
    fn calibration_counts_to_newtons() {
        let cal = LoadCellCal {
            newtons_per_count: 1.0 / 3.6e6,
            tare: LoadCellCounts(7200),
        };
        assert_eq!(cal.force(LoadCellCounts(7200)), Newtons(0.0));
        assert!(
            (cal.force(LoadCellCounts(7200 + 108_000)).0 - 0.030).abs()
                <= 0.030 * 2.0 * f32::EPSILON
        );
        assert!(LoadCellCounts(LoadCellCounts::FULL).saturated());
        assert!(LoadCellCounts(-LoadCellCounts::FULL - 1).saturated());
        assert!(!LoadCellCounts(0).saturated());
        // One count inside either rail is a force.
        assert!(!LoadCellCounts(LoadCellCounts::FULL - 1).saturated());
        assert!(!LoadCellCounts(-LoadCellCounts::FULL).saturated());
    }
}
