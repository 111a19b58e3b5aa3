//! The probe at the pins: hal-sim's simulated PZT plate and tissue behind the same analog front
//! end the host and QEMU boards use (`hal_sim::SimProbe`: DAC code in, sense-current and
//! drive-monitor codes out, one sample per period).
//!
//! Coupling (contract): every DAC1 output update (a TIM6 trigger) starts one sample period of
//! the probe: `SimProbe::exchange` samples the ADC pair at the start of the period, then steps
//! the plant through it with the new code held — the order of the hardware, where the ADCs
//! start converting on the same trigger and sample 1.1 µs after the DAC's update (47.5 ADC clocks
//! at 42.5 MHz), well inside the reconstruction filter's rise. The ADCs' sampling instants in
//! that period read that pair: PA0 the sense current, PA1 the drive monitor, as the voltage
//! whose 12-bit conversion is hal-sim's code. Periods in which the DAC is not updated (the drive
//! stopped) run with the code held. The probe's sample rate is the front end's (10 kHz), which
//! the image's TIM6 must match: the probe's time is counted in its own periods.
//!
//! The load cell: the scene's HX711 (`hal_sim::loadcell::Hx711Sim`, the chip the host and QEMU
//! boards' firmware reads, with the cell's transfer, noise, drift and creep) on PB4 (`DOUT`, an
//! input of the board) and PB5 (`PD_SCK`, an output), powered with the board at `t = 0` and
//! settling before its first conversion. Its time is the core clock's: at every access of the
//! board to port B (a read of IDR, a write that may change PB5) the chip is advanced to that
//! instant with the probe's contact force of the moment, the time `PD_SCK` stayed high is
//! counted (high beyond 60 µs powers it down), then the clock edge is applied. Data bits change
//! on `PD_SCK`'s rising edge, MSB first; the 25th pulse ends the read. Left out (the chip model's
//! own, `hal-sim/src/loadcell.rs`): the 26th and 27th pulses' channel and gain selection (every
//! read is channel A at gain 128), the RATE pin (the cell's rate, 80 SPS), the chip's own
//! timing limits on `PD_SCK` (minimum high and low times, data-ready to first edge), and the
//! vibration of the probe in the cell's signal. A `PD_SCK` pin not in output mode is low.

use core::cell::RefCell;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{InputPin, OutputPin};
use hal_sim::loadcell::{Delay, Dout, Hx711Sim, Sck};
use hal_sim::{AdcPair, Scene, SimProbe};

use crate::periph::{Pin, Wiring, VREF};

/// hal-sim's probe wired to DAC1 OUT1, PA0 and PA1.
pub struct HalSimProbe {
    probe: SimProbe,
    /// The DAC code held.
    code: u16,
    /// Start of the current period (s), if one started.
    period_start: Option<f64>,
    period_s: f64,
    pair: AdcPair,
    /// The scene's load cell (`None`: the scene has none; `DOUT` then reads its pull-up).
    chip: Option<RefCell<Hx711Sim>>,
    /// The level on `PD_SCK`.
    sck: bool,
    /// Time of the chip's last pin event, s.
    pins_t: f64,
}

/// The HX711's pins: port B (index 1), `DOUT` on PB4, `PD_SCK` on PB5 (docs/firmware.md,
/// "Load cell").
const LOAD_CELL_PORT: usize = 1;
const DOUT_PIN: u32 = 4;
const SCK_PIN: u32 = 5;

impl HalSimProbe {
    /// The hal-sim probe at `m`'s analog pins (`None` when another front end, or none, is wired).
    pub fn at_pins(m: &mut crate::Machine) -> Option<&mut HalSimProbe> {
        let any: &mut dyn std::any::Any = m.board_mut().periph.wiring.as_mut();
        any.downcast_mut::<HalSimProbe>()
    }

    /// The probe on `scene` with noise seed `seed`.
    pub fn new(scene: Scene, seed: u64) -> HalSimProbe {
        let period_s = scene.front_end.dt();
        let probe = SimProbe::new(scene, seed);
        let chip = probe.load_cell_at_power_on().map(RefCell::new);
        HalSimProbe {
            probe,
            code: hal_sim::frontend::MID_CODE,
            period_start: None,
            period_s,
            pair: AdcPair::default(),
            chip,
            sck: false,
            pins_t: 0.0,
        }
    }

    /// The scene called `name`: `free-air` (the probe lifted), a phantom of hal-sim's
    /// (`B`: the bench scene on it, 30 mN), a phantom pressed at another force (`B@8`: at
    /// 8 mN), or a known weight resting on the tip (`weight:10`: 10 g, as `weigh 10` expects);
    /// `None` for any other name.
    pub fn scene_named(name: &str) -> Option<Scene> {
        if let Some(grams) = name.strip_prefix("weight:") {
            let g: f64 = grams.parse().ok().filter(|g: &f64| *g > 0.0)?;
            return Some(
                Self::bench_scene(None)
                    .weighing(g * 1e-3 * hal_sim::loadcell::STANDARD_GRAVITY_M_S2),
            );
        }
        let (on, force) = match name.split_once('@') {
            Some((on, mn)) => (
                on,
                Some(mn.parse::<f64>().ok().filter(|f| *f >= 0.0)? * 1e-3),
            ),
            None => (name, None),
        };
        let scene = if on == "free-air" {
            Self::bench_scene(None)
        } else {
            Self::bench_scene(Some(&hal_sim::phantoms::by_name(on)?))
        };
        Some(match force {
            Some(f) => scene.with_preload_n(f),
            None => scene,
        })
    }

    /// The QEMU board's power-on scene on phantom `p` (`None`: free air): pressed at 30 mN,
    /// bench noise, seed 1.
    pub fn bench(p: Option<&hal_sim::Phantom>) -> HalSimProbe {
        HalSimProbe::new(Self::bench_scene(p), 1)
    }

    /// The bench scene on phantom `p` (`None`: the probe lifted into free air).
    pub fn bench_scene(p: Option<&hal_sim::Phantom>) -> Scene {
        let s = match p {
            Some(p) => Scene::on_phantom(p),
            None => Scene::free_air(),
        };
        s.with_noise(hal_sim::NoiseScene::Bench)
            .with_preload_n(0.03)
    }

    /// Move the probe to `scene` (the plant's state carries over, as when the user lifts or
    /// presses it).
    pub fn set_scene(&mut self, scene: Scene) {
        self.probe.set_scene(scene);
    }

    /// The simulated probe.
    pub fn probe(&self) -> &SimProbe {
        &self.probe
    }

    /// The load cell's chip at time `t`: the time `PD_SCK` stayed high since the last pin event
    /// counted, then the conversions due by `t` made with the contact force of the moment.
    fn chip_at(&mut self, t: f64) -> Option<&RefCell<Hx711Sim>> {
        let chip = self.chip.as_ref()?;
        if t > self.pins_t {
            // (Held beyond 4 s the chip is down either way: 60 µs power it down.)
            let ns = ((t - self.pins_t) * 1e9).min(u32::MAX as f64) as u32;
            Delay(chip).delay_ns(ns);
            self.pins_t = t;
        }
        chip.borrow_mut().advance(t, self.probe.contact_force_n());
        Some(chip)
    }

    fn step(&mut self) {
        let mut pair = [AdcPair::default()];
        self.probe.exchange(&[self.code], &mut pair);
        self.pair = pair[0];
    }

    /// Run held-code periods until the one containing `t` has started (a tolerance of a
    /// microsecond absorbs the rounding of the trigger instants).
    fn catch_up(&mut self, t: f64) {
        let Some(mut start) = self.period_start else {
            return;
        };
        while start + self.period_s <= t - 1e-6 {
            start += self.period_s;
            self.step();
        }
        self.period_start = Some(start);
    }
}

impl Wiring for HalSimProbe {
    fn dac_output(&mut self, t: f64, volts: f64) {
        self.catch_up(t);
        self.code = (volts / VREF * 4096.0).round().clamp(0.0, 4095.0) as u16;
        self.period_start = Some(t);
        self.step();
    }

    fn pin_voltage(&mut self, t: f64, pin: Pin) -> f64 {
        if self.period_start.is_none() {
            // Before the first DAC update: the probe rests with the drive at mid-scale.
            self.period_start = Some(t);
            self.step();
        }
        self.catch_up(t);
        let code = match pin {
            Pin::Pa0 => self.pair.current,
            Pin::Pa1 => self.pair.monitor,
        };
        // The middle of the code's interval: the 12-bit conversion gives the code back.
        (code as f64 + 0.5) * VREF / 4096.0
    }

    fn gpio_outputs(&mut self, t: f64, port: usize, mask: u32, levels: u32) {
        if port != LOAD_CELL_PORT {
            return;
        }
        let high = mask & levels & (1 << SCK_PIN) != 0;
        if high == self.sck {
            return;
        }
        self.sck = high;
        if let Some(chip) = self.chip_at(t) {
            let mut sck = Sck(chip);
            let _ = if high { sck.set_high() } else { sck.set_low() };
        }
    }

    fn gpio_inputs(&mut self, t: f64, port: usize) -> (u32, u32) {
        if port != LOAD_CELL_PORT {
            return (0, 0);
        }
        match self.chip_at(t) {
            Some(chip) => {
                let high = Dout(chip).is_high().unwrap_or(true);
                (1 << DOUT_PIN, (high as u32) << DOUT_PIN)
            }
            None => (0, 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::Peripherals;

    const GPIOB: u32 = 0x4800_0400;
    /// Core cycles per µs on HSI16 (the clock at reset).
    const US: u64 = 16;

    /// The board's pins at reset with GPIOB clocked, PB5 an output (low), PB4 an input with
    /// its pull-up, the probe on phantom B at 30 mN with a quiet load cell (its offset only).
    fn board() -> (Peripherals, hal_sim::loadcell::LoadCell) {
        let cell = hal_sim::loadcell::LoadCell::quiet();
        let scene = hal_sim::Scene {
            load_cell: Some(cell),
            ..hal_sim::Scene::on_phantom(&hal_sim::phantoms::B).with_preload_n(0.030)
        };
        let mut p = Peripherals::default();
        p.wiring = Box::new(HalSimProbe::new(scene, 1));
        p.write(
            0x4002_1000 + crate::periph::rcc::Enr::Ahb2.offset(),
            4,
            1 << 1,
            0,
        )
        .unwrap();
        // MODER: PB4 input, PB5 output (the rest at reset); PUPDR: PB4 pull-up.
        let moder = p.read(GPIOB, 4, 0).unwrap();
        let moder = (moder & !(0xF << 8)) | (1 << 10);
        p.write(GPIOB, 4, moder, 1).unwrap();
        p.write(GPIOB + 0x0C, 4, 1 << 8, 2).unwrap();
        (p, cell)
    }

    fn dout(p: &mut Peripherals, at: u64) -> bool {
        p.read(GPIOB + 0x10, 4, at).unwrap() >> 4 & 1 == 1
    }

    fn sck(p: &mut Peripherals, at: u64, high: bool) {
        let v = if high { 1 << 5 } else { 1 << 21 };
        p.write(GPIOB + 0x18, 4, v, at).unwrap();
    }

    /// One read as the HX711 datasheet's timing diagram has it, through the GPIO registers at
    /// core-clock times from `at`: 24 pulses of 1 µs high and low, bits read after each falling
    /// edge, a 25th pulse; the sign-extended value and the cycle after it.
    fn read(p: &mut Peripherals, mut at: u64) -> (i32, u64) {
        let mut v = 0u32;
        for k in 0..25 {
            sck(p, at, true);
            sck(p, at + US, false);
            if k < 24 {
                v = (v << 1) | dout(p, at + US + 1) as u32;
            }
            at += 2 * US;
        }
        (((v << 8) as i32) >> 8, at)
    }

    /// The HX711 at PB4/PB5 in core-clock time: settling after power-up (no conversion at
    /// 49 ms, one at 51 ms: four periods at 80 SPS), the conversion the cell's transfer of the
    /// scene's force to the count (`round((F + offset) × counts/N)`), `DOUT` high once read,
    /// `PD_SCK` held high 70 µs powers it down, and after it goes low a settling time again.
    #[test]
    fn the_load_cell_converts_the_scenes_force_on_its_pins() {
        let (mut p, cell) = board();
        let ms = 1000 * US;
        assert!(dout(&mut p, 49 * ms), "settling at 49 ms");
        assert!(!dout(&mut p, 51 * ms), "a conversion at 51 ms");
        let (v, end) = read(&mut p, 51 * ms);
        let want = ((0.030 + cell.offset_n) * cell.counts_per_n).round() as i32;
        assert_eq!(v, want);
        assert!(
            dout(&mut p, end + US),
            "read: DOUT high until the next conversion"
        );
        // Power-down: 70 µs high, then low at 100 ms; settled again 50 ms later.
        let t = 100 * ms;
        assert!(
            !dout(&mut p, t - 70 * US),
            "the conversion of 87.5 ms waits"
        );
        sck(&mut p, t - 70 * US, true);
        sck(&mut p, t, false);
        assert!(dout(&mut p, t + 49 * ms), "settling after the power-down");
        assert!(!dout(&mut p, t + 51 * ms));
    }
}
