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

use hal_sim::{AdcPair, Scene, SimProbe};

use crate::periph::{Analog, Pin, VREF};

/// hal-sim's probe wired to DAC1 OUT1, PA0 and PA1.
pub struct HalSimProbe {
    probe: SimProbe,
    /// The DAC code held.
    code: u16,
    /// Start of the current period (s), if one started.
    period_start: Option<f64>,
    period_s: f64,
    pair: AdcPair,
}

impl HalSimProbe {
    /// The hal-sim probe at `m`'s analog pins (`None` when another front end, or none, is wired).
    pub fn at_pins(m: &mut crate::Machine) -> Option<&mut HalSimProbe> {
        let any: &mut dyn std::any::Any = m.board_mut().periph.analog.as_mut();
        any.downcast_mut::<HalSimProbe>()
    }

    /// The probe on `scene` with noise seed `seed`.
    pub fn new(scene: Scene, seed: u64) -> HalSimProbe {
        let period_s = scene.front_end.dt();
        HalSimProbe {
            probe: SimProbe::new(scene, seed),
            code: hal_sim::frontend::MID_CODE,
            period_start: None,
            period_s,
            pair: AdcPair::default(),
        }
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

impl Analog for HalSimProbe {
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
}
