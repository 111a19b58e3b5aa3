//! The firmware's HX711 driver (`pzt_probe::loadcell`) against the simulated chip and load cell
//! (`hal_sim::loadcell`) through the embedded-hal 1.0 pins: what it reads is the cell's force to
//! within its noise, it never waits for the chip, and a clock held high past the chip's 60 µs
//! power-down time loses the conversion in hand.

use core::cell::RefCell;
use hal_sim::loadcell::{Delay, Dout, Hx711Sim, LoadCell, Sck, SETTLING_PERIODS};
use pzt_probe::loadcell::{ForceLog, Hx711, LoadCellCal, LoadCellCounts, LoadCellError};

type Driver<'a> =
    Hx711<Delay<&'a RefCell<Hx711Sim>>, Dout<&'a RefCell<Hx711Sim>>, Sck<&'a RefCell<Hx711Sim>>>;

fn driver(chip: &RefCell<Hx711Sim>) -> Driver<'_> {
    Hx711::new(Delay(chip), Dout(chip), Sck(chip)).expect("infallible pins")
}

/// Polled at 1 kHz for 3 s with the cell tared in free air and then loaded with 30 mN: every
/// conversion is read once (80 SPS), the driver never blocks (a poll without data is `None`),
/// and the mean force over the last 1.5 s is the load times (1 + creep) within 4 σ of the mean of
/// the cell's noise.
#[test]
fn reads_the_cell_through_the_pins() {
    let cell = LoadCell::default();
    let chip = RefCell::new(Hx711Sim::new(cell, 11));
    let mut hx = driver(&chip);
    let fs = 10_000.0;
    // Tare: the mean of the first 0.5 s of conversions in free air.
    let (mut tare_sum, mut tare_n) = (0i64, 0i64);
    let mut log = ForceLog::new();
    let mut cal = None;
    let mut nones = 0;
    for ms in 1..=3000u64 {
        let t = ms as f64 / 1000.0;
        let load = if t < 0.5 { 0.0 } else { 0.030 };
        chip.borrow_mut().advance(t, load);
        match hx.read().expect("no pin errors, no saturation") {
            None => nones += 1,
            Some(c) if t < 0.5 => {
                tare_sum += c.0 as i64;
                tare_n += 1;
            }
            Some(c) => {
                cal.get_or_insert(LoadCellCal {
                    newtons_per_count: (1.0 / cell.counts_per_n) as f32,
                    tare: LoadCellCounts((tare_sum / tare_n) as i32),
                });
                log.push(ms * 10, c);
            }
        }
    }
    let (made, read) = chip.borrow().counts();
    assert_eq!(made, read, "every conversion read");
    // 3 s at 80 SPS less the 50 ms settling.
    let expected = ((3.0 - SETTLING_PERIODS / cell.rate_hz) * cell.rate_hz) as u64;
    assert!(made.abs_diff(expected) <= 1, "{made} conversions");
    assert!(nones > 2000, "polls without data answer at once");
    let cal = cal.expect("loaded conversions");
    let w = cal.contact_force(
        &log.over(15_000, 30_000, fs)
            .expect("force over the last 1.5 s"),
    );
    assert!((w.samples as i64 - 120).abs() <= 1, "{}", w.samples);
    // Creep after 1.0..2.5 s under load is between (1 − e^-1) and (1 − e^-2.5) of its full
    // 0.5 %; the tare's own noise (36 conversions) and the window's both count.
    let lo = 0.030 * (1.0 + cell.creep_fraction * (1.0 - (-1.0f64).exp()));
    let hi = 0.030 * (1.0 + cell.creep_fraction * (1.0 - (-2.5f64).exp()));
    let noise = cell.noise_n * (1.0 / 120.0 + 1.0 / 36.0f64).sqrt();
    let drift = cell.drift_n_per_s * 3.0;
    let m = w.mean.0 as f64;
    assert!(
        m > lo - 4.0 * noise - drift && m < hi + 4.0 * noise + drift,
        "{m} N not in [{lo}, {hi}] ± {noise}"
    );
    // The window's σ is the noise over sqrt(n) (its scatter within 4 sqrt(1/(2n)) = 26 %; the
    // creep's curvature over the window adds 0.3 % of the noise).
    let want = cell.noise_n / 120f64.sqrt();
    assert!(
        (w.sigma.0 as f64 / want - 1.0).abs() < 0.26,
        "{} vs {want}",
        w.sigma.0
    );
}

/// A clock held high past 60 µs (the driver's reset, or an interrupt stretching a pulse) powers
/// the chip down: the conversion in hand is lost, the next read finds no data, and conversions
/// resume a settling time after the clock goes low again. (A pulse stretched in the middle of a
/// read would leave the remaining bits high: a wrong number the chip gives no sign of, which is
/// why the firmware reads inside a critical section, `src/loadcell.rs`.)
#[test]
fn a_clock_held_high_powers_the_chip_down() {
    let chip = RefCell::new(Hx711Sim::new(LoadCell::default(), 12));
    chip.borrow_mut().advance(0.1, 0.02);
    // The driver's reset holds the clock high for 70 µs, as a read interrupted for that long
    // would.
    driver(&chip).reset().unwrap();
    let mut hx = driver(&chip);
    assert_eq!(hx.read(), Ok(None));
    chip.borrow_mut().advance(0.1 + 0.049, 0.02);
    assert_eq!(hx.read(), Ok(None), "settling");
    chip.borrow_mut().advance(0.1 + 0.051, 0.02);
    assert!(matches!(hx.read(), Ok(Some(_))));
}

/// An overloaded (or open) bridge converts at a rail: a typed error, not a force.
#[test]
fn a_saturated_bridge_is_an_error() {
    let cell = LoadCell::quiet();
    let chip = RefCell::new(Hx711Sim::new(cell, 13));
    chip.borrow_mut().advance(0.1, 10.0);
    let mut hx = driver(&chip);
    assert_eq!(hx.read(), Err(LoadCellError::Saturated));
    // After a reset the driver reads again once the load is in range.
    hx.reset().unwrap();
    chip.borrow_mut().advance(0.2, 0.03);
    let c = hx.read().unwrap().expect("a conversion after settling");
    let f = LoadCellCal {
        newtons_per_count: (1.0 / cell.counts_per_n) as f32,
        tare: LoadCellCounts((cell.offset_n * cell.counts_per_n).round() as i32),
    }
    .force(c);
    // 0.03 N plus 0.2 s of drift, to the count's rounding.
    assert!(
        (f.0 as f64 - 0.03 - 0.2 * cell.drift_n_per_s).abs() < 1e-6,
        "{f:?}"
    );
}
