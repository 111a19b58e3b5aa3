//! The load cell beside the resonator: a strain-gauge bridge read by an HX711 24-bit ADC, as
//! the firmware's driver sees it — two pins (`PD_SCK` in, `DOUT` out) and time.
//!
//! The cell carries the scene's contact force (the simulator gives it, [`Hx711Sim::advance`]);
//! what the chip converts is that force plus what a real cell adds:
//!
//! * a zero offset (the bridge's imbalance; tared away with the air reference),
//! * an offset drift (thermal, linear in time),
//! * creep: under a constant load the reading approaches `(1 + creep_fraction)` of it with time
//!   constant `creep_tau_s` (first order; the load's step itself is seen at once),
//! * white noise per conversion.
//!
//! The chip converts at `rate_hz` (80 or 10 SPS). A finished conversion pulls `DOUT` low; each
//! rising `PD_SCK` edge shifts out one bit, MSB first (24 bits, two's complement), and 1–3 more
//! pulses choose the next conversion's channel and gain (datasheet, "Serial Interface"). `PD_SCK`
//! held high for more than 60 µs powers the chip down: the conversion in hand is lost and after
//! power-up the first conversion comes after the settling time (four conversion periods at
//! 80 SPS). Time on the pin side passes through the driver's delays ([`Delay`]): a read that
//! stretches a clock pulse beyond 60 µs (an interrupt in the middle of it) is seen as it would be
//! on the board. A pulse shorter than the datasheet's minimum high or low time (T3, T4: 0.2 µs)
//! is outside what the chip guarantees; the model (ours: the datasheet says no more) then loses
//! the conversion being read, so that `DOUT` reads high for the rest of it.
//!
//! The vibration of the probe at ~230 Hz is outside the chip's sinc filter's passband at 10 or
//! 80 SPS; the cell here sees the static contact force only.

use core::cell::RefCell;
use core::convert::Infallible;
use probe_rng::Rng;

/// The load cell and its converter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadCell {
    /// Converter counts per newton (bridge sensitivity × excitation × gain 128).
    pub counts_per_n: f64,
    /// Zero offset, N.
    pub offset_n: f64,
    /// White noise per conversion, N (RMS).
    pub noise_n: f64,
    /// Offset drift, N/s.
    pub drift_n_per_s: f64,
    /// Creep: the fraction of the load the reading adds under a constant load.
    pub creep_fraction: f64,
    /// Creep time constant, s.
    pub creep_tau_s: f64,
    /// Conversion rate, Hz.
    pub rate_hz: f64,
}

impl Default for LoadCell {
    /// A 100 g (0.98 N) bridge of 2 mV/V at 4.3 V excitation on an HX711 at gain 128 and 80 SPS
    /// (±20 mV full scale = ±2²³ counts): 8.6 mV/N → 3.6e6 counts/N. Noise 0.1 mN RMS per
    /// conversion (the chip's ~90 nV RMS input noise at 80 SPS is 0.01 mN; the cell's own and
    /// the supply's dominate); 2 mN zero offset, 0.01 mN/s drift, 0.5 % creep over 1 s: typical
    /// of such cells' data sheets (creep 0.03–0.5 % FS per 30 min at its worst end, scaled to a
    /// reading's seconds as an assumption, not a measurement).
    fn default() -> Self {
        Self {
            counts_per_n: 3.6e6,
            offset_n: 2e-3,
            noise_n: 1e-4,
            drift_n_per_s: 1e-5,
            creep_fraction: 0.005,
            creep_tau_s: 1.0,
            rate_hz: 80.0,
        }
    }
}

impl LoadCell {
    /// The default cell without noise, drift or creep (its offset kept): every conversion is
    /// the load plus the offset, to the count.
    pub fn quiet() -> Self {
        Self {
            noise_n: 0.0,
            drift_n_per_s: 0.0,
            creep_fraction: 0.0,
            ..Self::default()
        }
    }
}

/// Standard gravity, m/s² (the conventional value of the CGPM, 1901): the weight of a known mass.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.806_65;

/// Shortest `PD_SCK` high time (T3) and low time (T4) of a clock pulse, s (datasheet, Fig. 2's
/// timing table: 0.2 µs each).
pub const PULSE_MIN_S: f64 = 0.2e-6;

/// Longest time `PD_SCK` may stay high before the chip powers down, s (datasheet: 60 µs).
pub const POWER_DOWN_S: f64 = 60e-6;
/// Conversion periods from power-up (or reset) to the first conversion at 80 SPS (datasheet:
/// output settling 50 ms).
pub const SETTLING_PERIODS: f64 = 4.0;

/// The simulated HX711 with its load cell.
#[derive(Clone, Debug)]
pub struct Hx711Sim {
    cell: LoadCell,
    rng: Rng,
    /// Simulation time, s.
    t_s: f64,
    /// The load the cell carries now, N.
    load_n: f64,
    /// The creep part of the reading, N.
    creep_n: f64,
    /// Time of the next conversion, s.
    next_conversion_s: f64,
    /// The conversion waiting to be read.
    ready: Option<i32>,
    /// Bits shifted out of `ready` so far; 24 and more: the gain pulses.
    clocked: u8,
    /// The bit on `DOUT` while shifting.
    bit: bool,
    sck: bool,
    /// How long `PD_SCK` has been high, s (pin-side time).
    sck_high_s: f64,
    /// Pin-side time since `PD_SCK`'s last edge, s (infinite before the first).
    since_edge_s: f64,
    powered: bool,
    /// Conversions finished and read (for tests and the log).
    conversions: u64,
    reads: u64,
}

impl Hx711Sim {
    /// A chip that has been converting for a while, on the instrument: its next conversion
    /// falls due one conversion period after `t = 0` (no settling wait), its creep settled
    /// at `load_n` (the force it carries from the start).
    pub fn running(cell: LoadCell, seed: u64, load_n: f64) -> Self {
        let mut c = Self::new(cell, seed);
        c.next_conversion_s = 1.0 / cell.rate_hz;
        c.load_n = load_n;
        c.creep_n = cell.creep_fraction * load_n;
        c
    }

    /// The chip on `cell`, noise drawn from `seed`, powered and settling from `t = 0`.
    pub fn new(cell: LoadCell, seed: u64) -> Self {
        Self {
            cell,
            rng: Rng::new(seed),
            t_s: 0.0,
            load_n: 0.0,
            creep_n: 0.0,
            next_conversion_s: SETTLING_PERIODS / cell.rate_hz,
            ready: None,
            clocked: 0,
            bit: false,
            sck: false,
            sck_high_s: 0.0,
            since_edge_s: f64::INFINITY,
            powered: true,
            conversions: 0,
            reads: 0,
        }
    }

    /// The simulator's side: time is now `t_s` and the cell carries `load_n` (the contact
    /// force). Creep follows the load; conversions fall due at the chip's rate (a conversion
    /// not read before the next one is overwritten, as on the chip).
    pub fn advance(&mut self, t_s: f64, load_n: f64) {
        let dt = (t_s - self.t_s).max(0.0);
        self.t_s = self.t_s.max(t_s);
        if self.cell.creep_tau_s > 0.0 {
            let target = self.cell.creep_fraction * load_n;
            let k = 1.0 - libm::exp(-dt / self.cell.creep_tau_s);
            self.creep_n += (target - self.creep_n) * k;
        }
        self.load_n = load_n;
        if !self.powered {
            return;
        }
        while self.next_conversion_s <= self.t_s {
            let reading = self.load_n
                + self.creep_n
                + self.cell.offset_n
                + self.cell.drift_n_per_s * self.next_conversion_s
                + self.cell.noise_n * self.rng.normal();
            let counts = libm::round(reading * self.cell.counts_per_n);
            let full = ((1u32 << 23) - 1) as f64;
            self.ready = Some(counts.clamp(-full - 1.0, full) as i32);
            self.clocked = 0;
            self.conversions += 1;
            self.next_conversion_s += 1.0 / self.cell.rate_hz;
        }
    }

    /// Follow `probe`: time is the probe's, the load its contact force now.
    pub fn follow(&mut self, probe: &crate::SimProbe) {
        self.advance(probe.time_s(), probe.contact_force_n());
    }

    /// Conversions made and conversions read out so far.
    pub fn counts(&self) -> (u64, u64) {
        (self.conversions, self.reads)
    }

    /// True while the chip is powered (not held down by `PD_SCK`).
    pub fn powered(&self) -> bool {
        self.powered
    }

    fn set_sck(&mut self, high: bool) {
        if high != self.sck {
            // A high (falling edge) or low (rising edge) time below the minimum during a read.
            if self.since_edge_s < PULSE_MIN_S && self.clocked > 0 {
                self.ready = None;
                self.clocked = 0;
            }
            self.since_edge_s = 0.0;
        }
        if high && !self.sck {
            self.sck_high_s = 0.0;
            if let Some(v) = self.ready {
                if self.clocked < 24 {
                    self.bit = (v >> (23 - self.clocked)) & 1 == 1;
                }
                self.clocked = self.clocked.saturating_add(1);
            }
        }
        if !high && self.sck {
            if !self.powered {
                // Power-up: the chip resets and settles before its first conversion.
                self.powered = true;
                self.next_conversion_s = self.t_s + SETTLING_PERIODS / self.cell.rate_hz;
            } else if self.clocked >= 25 {
                // The 25th pulse (gain 128, channel A) ends the read.
                self.ready = None;
                self.clocked = 0;
                self.reads += 1;
            }
        }
        self.sck = high;
    }

    fn dout_high(&self) -> bool {
        match self.ready {
            Some(_) if self.powered && (1..=24).contains(&self.clocked) => self.bit,
            Some(_) if self.powered && self.clocked == 0 => false,
            _ => true,
        }
    }

    fn wait(&mut self, s: f64) {
        self.since_edge_s += s;
        if self.sck {
            self.sck_high_s += s;
            if self.sck_high_s > POWER_DOWN_S && self.powered {
                self.powered = false;
                self.ready = None;
                self.clocked = 0;
            }
        }
    }
}

/// Shared access to one simulated chip by its pins and delay.
pub trait ChipHandle {
    /// Run `f` on the chip.
    fn with<R>(&self, f: impl FnOnce(&mut Hx711Sim) -> R) -> R;
}

impl ChipHandle for &RefCell<Hx711Sim> {
    fn with<R>(&self, f: impl FnOnce(&mut Hx711Sim) -> R) -> R {
        f(&mut self.borrow_mut())
    }
}

/// The chip's `DOUT` pin (an input of the microcontroller).
pub struct Dout<H>(pub H);
/// The chip's `PD_SCK` pin (an output of the microcontroller).
pub struct Sck<H>(pub H);
/// The driver's delay: pin-side time that the chip sees (the `PD_SCK` high limit).
pub struct Delay<H>(pub H);

impl<H> embedded_hal::digital::ErrorType for Dout<H> {
    type Error = Infallible;
}
impl<H> embedded_hal::digital::ErrorType for Sck<H> {
    type Error = Infallible;
}

impl<H: ChipHandle> embedded_hal::digital::InputPin for Dout<H> {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.0.with(|c| c.dout_high()))
    }
    fn is_low(&mut self) -> Result<bool, Infallible> {
        Ok(!self.0.with(|c| c.dout_high()))
    }
}

impl<H: ChipHandle> embedded_hal::digital::OutputPin for Sck<H> {
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.with(|c| c.set_sck(true));
        Ok(())
    }
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.with(|c| c.set_sck(false));
        Ok(())
    }
}

impl<H: ChipHandle> embedded_hal::delay::DelayNs for Delay<H> {
    fn delay_ns(&mut self, ns: u32) {
        self.0.with(|c| c.wait(ns as f64 * 1e-9));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::delay::DelayNs;
    use embedded_hal::digital::{InputPin, OutputPin};

    /// Read one conversion the way the datasheet's timing diagram does it, bit by bit, with a
    /// 1 µs high and low time (a reference for the test, not the firmware's driver).
    fn read_by_hand(chip: &RefCell<Hx711Sim>, high_us: u32) -> Option<i32> {
        read_timed(chip, high_us * 1000, 1000)
    }

    /// [`read_by_hand`] with `high_ns` and `low_ns` the clock's high and low times.
    fn read_timed(chip: &RefCell<Hx711Sim>, high_ns: u32, low_ns: u32) -> Option<i32> {
        let (mut dout, mut sck, mut delay) = (Dout(chip), Sck(chip), Delay(chip));
        if dout.is_high().unwrap() {
            return None;
        }
        let mut v: u32 = 0;
        for _ in 0..24 {
            sck.set_high().unwrap();
            delay.delay_ns(high_ns);
            sck.set_low().unwrap();
            v = (v << 1) | dout.is_high().unwrap() as u32;
            delay.delay_ns(low_ns);
        }
        sck.set_high().unwrap();
        delay.delay_ns(high_ns);
        sck.set_low().unwrap();
        // Sign-extend the 24-bit two's complement value.
        Some(((v << 8) as i32) >> 8)
    }

    /// The first conversion comes after the settling time; it is the load plus the offset, in
    /// counts, to the count (noise, drift and creep off).
    #[test]
    fn converts_the_load_after_settling() {
        let cell = LoadCell::quiet();
        let chip = RefCell::new(Hx711Sim::new(cell, 1));
        chip.borrow_mut().advance(0.049, 0.030);
        assert_eq!(read_by_hand(&chip, 1), None, "still settling at 49 ms");
        chip.borrow_mut().advance(0.051, 0.030);
        let want = libm::round((0.030 + cell.offset_n) * cell.counts_per_n) as i32;
        assert_eq!(read_by_hand(&chip, 1), Some(want));
        // Read once: DOUT goes high until the next conversion 12.5 ms later.
        assert_eq!(read_by_hand(&chip, 1), None);
        chip.borrow_mut().advance(0.0626, -0.010);
        let want = libm::round((-0.010 + cell.offset_n) * cell.counts_per_n) as i32;
        assert_eq!(
            read_by_hand(&chip, 1),
            Some(want),
            "negative loads in two's complement"
        );
        assert_eq!(chip.borrow().counts(), (2, 2));
    }

    /// A clock pulse stretched beyond 60 µs powers the chip down: the read is lost, and the
    /// next conversion comes a settling time after the clock returns low.
    #[test]
    fn a_stretched_clock_pulse_powers_the_chip_down() {
        let chip = RefCell::new(Hx711Sim::new(LoadCell::quiet(), 2));
        chip.borrow_mut().advance(0.1, 0.02);
        let (mut dout, mut sck, mut delay) = (Dout(&chip), Sck(&chip), Delay(&chip));
        assert!(dout.is_low().unwrap());
        sck.set_high().unwrap();
        delay.delay_us(70);
        assert!(!chip.borrow().powered());
        assert!(dout.is_high().unwrap(), "no data while powered down");
        sck.set_low().unwrap();
        chip.borrow_mut().advance(0.149, 0.02);
        assert!(dout.is_high().unwrap(), "settling after power-up");
        chip.borrow_mut().advance(0.151, 0.02);
        assert!(dout.is_low().unwrap());
    }

    /// Pulses at the datasheet's minimum high and low time (0.2 µs) read the conversion; a high
    /// or a low time below it loses the conversion (`DOUT` high for the rest of the read).
    #[test]
    fn pulses_below_the_minimum_lose_the_conversion() {
        let cell = LoadCell::quiet();
        let read = |high_ns: u32, low_ns: u32| {
            let chip = RefCell::new(Hx711Sim::new(cell, 4));
            chip.borrow_mut().advance(0.051, 0.030);
            read_timed(&chip, high_ns, low_ns)
        };
        let want = libm::round((0.030 + cell.offset_n) * cell.counts_per_n) as i32;
        assert_eq!(read(200, 200), Some(want));
        assert_ne!(read(150, 200), Some(want), "high time below T3");
        assert_ne!(read(200, 150), Some(want), "low time below T4");
    }

    /// Creep approaches `creep_fraction` of a constant load with its time constant (first
    /// order: 1 − 1/e after one τ); noise averages to its RMS over many conversions.
    #[test]
    fn creep_and_noise_as_specified() {
        let cell = LoadCell {
            offset_n: 0.0,
            drift_n_per_s: 0.0,
            ..LoadCell::default()
        };
        let chip = RefCell::new(Hx711Sim::new(cell, 3));
        let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0.0);
        let mut t = 0.0;
        while t < 60.0 {
            t += 0.0125;
            chip.borrow_mut().advance(t, 0.030);
            if let Some(v) = read_by_hand(&chip, 1) {
                let newtons = v as f64 / cell.counts_per_n;
                if t > 10.0 {
                    // After 10 τ the creep is 0.030 · 0.005 (within e^-10).
                    let r = newtons - 0.030 * (1.0 + cell.creep_fraction);
                    sum += r;
                    sum2 += r * r;
                    n += 1.0;
                }
            }
        }
        let mean = sum / n;
        let rms = libm::sqrt(sum2 / n - mean * mean);
        // 4000 conversions: the mean within 4σ/sqrt(n) (6 µN) plus the count's half-step, the
        // RMS within 4 sqrt(1/(2n)) = 4.5 %.
        assert!(mean.abs() < 4.0 * cell.noise_n / libm::sqrt(n) + 0.5 / cell.counts_per_n);
        assert!((rms / cell.noise_n - 1.0).abs() < 0.045, "rms {rms}");
    }
}
