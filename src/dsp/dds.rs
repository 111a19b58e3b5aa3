//! Direct digital synthesis: a 32-bit phase accumulator and a 256-entry Q15 sine table with
//! linear interpolation.
//!
//! Accuracy: the interpolated table deviates from `sin` by at most `(2 pi / 256)^2 / 8 = 7.5e-5`
//! of full scale (2.5 LSB of Q15), far below the 12-bit DAC's LSB (2.4e-4 of full scale). The
//! demodulator uses the very same table values as its reference, so the table error does not
//! enter the admittance. Cost: one table pair lookup, one multiply, shifts (about 10
//! instructions per sine on the Cortex-M4F). Frequency resolution: `fs / 2^32` (2.3 uHz at
//! 10 kHz); frequency changes keep the phase continuous.

/// Table size (entries per turn).
pub const TABLE_BITS: u32 = 8;
const TABLE_LEN: usize = 1 << TABLE_BITS;

/// Quarter turn in phase units.
pub const QUARTER_TURN: u32 = 1 << 30;

const fn sin_taylor(x: f64) -> f64 {
    // x in [-pi, pi]; 16 terms of the Taylor series are exact to f64 rounding there.
    let mut term = x;
    let mut sum = x;
    let mut k = 1;
    while k < 16 {
        term = -term * x * x / ((2 * k) as f64 * (2 * k + 1) as f64);
        sum += term;
        k += 1;
    }
    sum
}

const fn make_table() -> [i16; TABLE_LEN + 1] {
    let mut t = [0i16; TABLE_LEN + 1];
    let mut i = 0;
    while i <= TABLE_LEN {
        let mut x = 2.0 * core::f64::consts::PI * i as f64 / TABLE_LEN as f64;
        if x > core::f64::consts::PI {
            x -= 2.0 * core::f64::consts::PI;
        }
        let v = sin_taylor(x) * 32767.0;
        // round half away from zero
        let r = if v >= 0.0 { v + 0.5 } else { v - 0.5 };
        t[i] = r as i16;
        i += 1;
    }
    t
}

/// Q15 sine table with a guard entry (`SINE[256] == SINE[0]`).
pub static SINE: [i16; TABLE_LEN + 1] = make_table();

/// `sin(2 pi phase / 2^32)` in Q15 (±32767).
#[inline(always)]
pub fn sin_q15(phase: u32) -> i32 {
    let idx = (phase >> (32 - TABLE_BITS)) as usize;
    let frac = ((phase >> (32 - TABLE_BITS - 15)) & 0x7FFF) as i32;
    // idx <= 255 so idx + 1 <= 256 is inside the guarded table.
    let a = SINE[idx & (TABLE_LEN - 1)] as i32;
    let b = SINE[(idx & (TABLE_LEN - 1)) + 1] as i32;
    a + (((b - a) * frac) >> 15)
}

/// `cos(2 pi phase / 2^32)` in Q15.
#[inline(always)]
pub fn cos_q15(phase: u32) -> i32 {
    sin_q15(phase.wrapping_add(QUARTER_TURN))
}

/// Frequency tuning word for `freq_hz` at `sample_rate_hz` (0 for invalid input).
pub fn tuning_word(freq_hz: f64, sample_rate_hz: f64) -> u32 {
    let w = freq_hz / sample_rate_hz * 4_294_967_296.0;
    if (0.0..4_294_967_295.0).contains(&w) {
        (w + 0.5) as u32
    } else {
        0
    }
}

/// Frequency in Hz of a tuning word.
pub fn frequency_hz(ftw: u32, sample_rate_hz: f64) -> f64 {
    ftw as f64 * sample_rate_hz / 4_294_967_296.0
}

/// At most `n` samples from `phase` on (advancing `ftw` a sample), up to and including the one
/// whose step wraps the phase (a cycle boundary of the reference): how many, and whether that one
/// is among them. The wrapping sample is `(2^32 − 1 − phase) / ftw` samples on (never for `ftw`
/// 0).
#[inline(always)]
pub fn run_to_wrap(phase: u32, ftw: u32, n: usize) -> (usize, bool) {
    match (!phase).checked_div(ftw) {
        Some(k) if (k as usize) < n => (k as usize + 1, true),
        _ => (n, false),
    }
}

/// Phase accumulator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Dds {
    /// Current phase (2^32 per turn).
    pub phase: u32,
    /// Phase increment per sample.
    pub ftw: u32,
}

impl Dds {
    /// Advance one sample, returning the phase before the step.
    #[inline(always)]
    pub fn step(&mut self) -> u32 {
        let p = self.phase;
        self.phase = p.wrapping_add(self.ftw);
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_matches_f64_sine() {
        let mut worst = 0.0f64;
        for k in 0..100_000u64 {
            let phase = (k.wrapping_mul(2_654_435_761) & 0xFFFF_FFFF) as u32;
            let x = phase as f64 / 4_294_967_296.0 * 2.0 * core::f64::consts::PI;
            let err = (sin_q15(phase) as f64 / 32767.0 - x.sin()).abs();
            worst = worst.max(err);
        }
        // (2 pi / 256)^2 / 8 = 7.5e-5 interpolation bound plus 2 Q15 LSB of rounding.
        assert!(worst < 7.6e-5 + 2.0 / 32767.0, "worst {worst}");
    }

    #[test]
    fn cos_is_quarter_turn_ahead() {
        assert_eq!(cos_q15(0), 32767);
        assert_eq!(sin_q15(0), 0);
        assert_eq!(sin_q15(QUARTER_TURN), 32767);
        assert_eq!(sin_q15(3 * QUARTER_TURN), -32767);
    }

    #[test]
    fn tuning_word_round_trip() {
        let w = tuning_word(232.3, 10_000.0);
        assert!((frequency_hz(w, 10_000.0) - 232.3).abs() < 2.4e-6);
        assert_eq!(tuning_word(f64::NAN, 10_000.0), 0);
        assert_eq!(tuning_word(-5.0, 10_000.0), 0);
        assert_eq!(tuning_word(1e9, 10_000.0), 0);
    }
}
