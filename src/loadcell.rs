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
//! A read is 25 clock pulses of 1 µs high and 1 µs low; a pulse held high beyond 60 µs powers the
//! chip down (the read is lost), so on the target a read runs in a critical section (about
//! 50 µs: well inside the sample interrupt's slack of 5 ms per batch).
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
        self.delay.delay_us(1);
        self.sck.set_low().map_err(|_| LoadCellError::Pin)?;
        self.delay.delay_us(1);
        Ok(())
    }
}

/// A load cell's calibration: newtons per count, and the zero (tare) taken with the tip in free
/// air.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadCellCal {
    /// Newtons per count (the cell's sensitivity; from a known weight).
    pub newtons_per_count: f32,
    /// The counts of zero force.
    pub tare: LoadCellCounts,
}

impl LoadCellCal {
    /// The force of `c`.
    pub fn force(&self, c: LoadCellCounts) -> Newtons {
        let d = c.0 as i64 - self.tare.0 as i64;
        Newtons((d as f64 * self.newtons_per_count as f64) as f32)
    }
}

/// Force samples a [`ForceLog`] keeps: 1.6 s at 80 SPS, longer than any one reading's window
/// but the slowest methods' (which see their last 1.6 s).
pub const FORCE_LOG: usize = 128;

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

/// The last [`FORCE_LOG`] force samples, each at a sample count of the engine.
#[derive(Clone, Debug, Default)]
pub struct ForceLog {
    samples: heapless::Deque<(u64, f32), FORCE_LOG>,
}

impl ForceLog {
    /// An empty log.
    pub const fn new() -> Self {
        Self {
            samples: heapless::Deque::new(),
        }
    }

    /// Add the force `f` taken at sample count `at` (the oldest sample goes when full).
    pub fn push(&mut self, at: u64, f: Newtons) {
        if self.samples.is_full() {
            self.samples.pop_front();
        }
        let _ = self.samples.push_back((at, f.0));
    }

    /// Forget every sample (the probe was lifted, the cell re-tared).
    pub fn clear(&mut self) {
        self.samples.clear();
    }

    /// The most recent sample and its sample count.
    pub fn last(&self) -> Option<(u64, Newtons)> {
        self.samples.back().map(|&(at, f)| (at, Newtons(f)))
    }

    /// The force over samples `from..=to` of the engine at `sample_rate` Hz: mean, its standard
    /// uncertainty and the change across the window, from a least-squares line through the
    /// samples. `None` with fewer than three samples in the window (the cell is not being read,
    /// or the window is shorter than three conversions).
    pub fn over(&self, from: u64, to: u64, sample_rate: f32) -> Option<ContactForce> {
        if !(sample_rate > 0.0) || to < from {
            return None;
        }
        let fs = sample_rate as f64;
        let inside = || {
            self.samples
                .iter()
                .filter(move |(at, f)| (from..=to).contains(at) && f.is_finite())
        };
        let n = inside().count();
        if n < 3 {
            return None;
        }
        let nf = n as f64;
        let t = |at: u64| (at - from) as f64 / fs;
        let tm = inside().map(|&(at, _)| t(at)).sum::<f64>() / nf;
        let ym = inside().map(|&(_, f)| f as f64).sum::<f64>() / nf;
        let (mut stt, mut sty) = (0.0, 0.0);
        for &(at, f) in inside() {
            let dt = t(at) - tm;
            stt += dt * dt;
            sty += dt * (f as f64 - ym);
        }
        let slope = if stt > 0.0 { sty / stt } else { 0.0 };
        let mut ss = 0.0;
        for &(at, f) in inside() {
            let r = f as f64 - ym - slope * (t(at) - tm);
            ss += r * r;
        }
        let scatter = libm::sqrt(ss / (nf - 2.0));
        let window = (to - from) as f64 / fs;
        Some(ContactForce {
            mean: Newtons(ym as f32),
            sigma: Newtons((scatter / libm::sqrt(nf)) as f32),
            change: Newtons((slope * window) as f32),
            samples: n.min(u16::MAX as usize) as u16,
        })
    }
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
        // 80 SPS: a sample every 125 engine samples; 0.030 N rising 1 mN/s; ±0.1 mN.
        let e = 1e-4;
        for k in 0..40u64 {
            let t = k as f64 / 80.0;
            let f = 0.030 + 1e-3 * t + if k % 2 == 0 { e } else { -e };
            log.push(k * 125, Newtons(f as f32));
        }
        // Samples 8..=31 (24 of them: whole pairs).
        let w = log.over(8 * 125, 31 * 125, fs).unwrap();
        assert_eq!(w.samples, 24);
        let t_mean = (8.0 + 31.0) / 2.0 / 80.0;
        assert!((w.mean.0 as f64 - (0.030 + 1e-3 * t_mean)).abs() < 1e-8);
        // The ±e pattern tilts the fitted line by a little: its projection on the centred time
        // over whole pairs is −e/2 per sample, so the slope is 1e-3 − 12 e / Σ dt² · (1/80).
        let n = 24.0;
        let dt = |k: f64| (k - 19.5) / 80.0;
        let stt: f64 = (8..32).map(|k| dt(k as f64) * dt(k as f64)).sum();
        let sty_pattern: f64 = (8..32)
            .map(|k| dt(k as f64) * if k % 2 == 0 { e } else { -e })
            .sum();
        let slope = 1e-3 + sty_pattern / stt;
        let window = (31.0 - 8.0) * 125.0 / 10_000.0f64;
        assert!((w.change.0 as f64 - slope * window).abs() < 1e-8, "{:?}", w);
        // Residuals: the pattern less its projection on the line, Σr² = n e² − sty²/stt.
        let scatter = ((n * e * e - sty_pattern * sty_pattern / stt) / (n - 2.0)).sqrt();
        let sigma = scatter / n.sqrt();
        assert!(
            (w.sigma.0 as f64 / sigma - 1.0).abs() < 1e-4,
            "{} vs {sigma}",
            w.sigma.0
        );
        // Too few samples, empty or inverted windows: no force.
        assert!(log.over(0, 250, fs).is_some());
        assert!(log.over(0, 124, fs).is_none());
        assert!(log.over(10, 5, fs).is_none());
        assert!(log.over(0, 10_000, 0.0).is_none());
    }

    /// The log keeps the last FORCE_LOG samples.
    #[test]
    fn the_log_keeps_the_newest() {
        let mut log = ForceLog::new();
        for k in 0..(FORCE_LOG as u64 + 10) {
            log.push(k, Newtons(k as f32));
        }
        assert_eq!(
            log.last(),
            Some((FORCE_LOG as u64 + 9, Newtons((FORCE_LOG + 9) as f32)))
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
