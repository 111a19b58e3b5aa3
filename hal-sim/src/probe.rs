//! The simulated probe: DAC codes in, ADC codes out, one sample at a time through the exactly
//! discretised chain.

use crate::frontend::{FrontEnd, MID_CODE};
use crate::plant::{chain, Discrete, CHAIN_STATES, VELOCITY, Y_I, Y_V};
use crate::rng::Rng;
use crate::scenes::Scene;
use crate::tissue::Tissue;
use core::f64::consts::PI;

/// One ADC conversion pair: sense current and drive monitor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdcPair {
    /// Sense-current channel code.
    pub current: u16,
    /// Drive-monitor channel code.
    pub monitor: u16,
}

/// The simulated probe hardware.
#[derive(Clone, Debug)]
pub struct SimProbe {
    scene: Scene,
    plant: Discrete<CHAIN_STATES>,
    rng: Rng,
    samples: u64,
    mains_phase: f64,
    noise_sigma_a: f64,
    stuck_dac: Option<u16>,
}

impl SimProbe {
    /// A probe in `scene`, at rest, with noise drawn from `seed`.
    pub fn new(scene: Scene, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mains_phase = 2.0 * PI * rng.uniform();
        let fe = scene.front_end;
        let k = scene.kelvin();
        Self {
            plant: chain(
                &k,
                &scene.pzt,
                fe.reconstruction_hz,
                fe.antialias_hz,
                fe.dt(),
            ),
            noise_sigma_a: fe.noise_sigma_a(),
            scene,
            rng,
            samples: 0,
            mains_phase,
            stuck_dac: scene.stuck_dac,
        }
    }

    /// The scene (as currently set).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }
    /// Front-end constants.
    pub fn front_end(&self) -> &FrontEnd {
        &self.scene.front_end
    }
    /// Simulated time since start, s.
    pub fn time_s(&self) -> f64 {
        self.samples as f64 / self.scene.front_end.sample_rate_hz
    }
    /// Samples since start.
    pub fn samples(&self) -> u64 {
        self.samples
    }
    /// Modal velocity now, m/s.
    pub fn velocity_m_s(&self) -> f64 {
        self.plant.x[VELOCITY]
    }

    /// Change what is under the probe (lift-off, new tissue), keeping the dynamic state.
    pub fn set_tissue(&mut self, tissue: Option<Tissue>) {
        self.scene.tissue = tissue;
        self.rebuild();
    }
    /// Replace the scene's physics (not the noise stream), keeping the dynamic state.
    pub fn set_scene(&mut self, scene: Scene) {
        self.scene = scene;
        self.noise_sigma_a = scene.front_end.noise_sigma_a();
        self.rebuild();
    }
    /// Fault injection: the DAC output stuck at `code` (or released with `None`).
    pub fn set_stuck_dac(&mut self, code: Option<u16>) {
        self.stuck_dac = code;
    }

    fn rebuild(&mut self) {
        let fe = self.scene.front_end;
        let x = self.plant.x;
        self.plant = chain(
            &self.scene.kelvin(),
            &self.scene.pzt,
            fe.reconstruction_hz,
            fe.antialias_hz,
            fe.dt(),
        );
        self.plant.x = x;
    }

    /// Play `dac` (one code per sample period) and capture one ADC pair per sample of the same
    /// periods into `adc` (sampled at the start of each period). Extra entries of the longer
    /// slice are left untouched / not played.
    pub fn exchange(&mut self, dac: &[u16], adc: &mut [AdcPair]) {
        let fe = self.scene.front_end;
        let dt = fe.dt();
        for (code, out) in dac.iter().zip(adc.iter_mut()) {
            let mut i = self.plant.x[Y_I];
            if self.noise_sigma_a > 0.0 {
                i += self.noise_sigma_a * self.rng.normal();
            }
            if let Some(m) = &fe.mains {
                let t = self.samples as f64 * dt;
                let mut acc = 0.0;
                for (h, amp) in m.harmonic_amplitude_a.iter().enumerate() {
                    if *amp != 0.0 {
                        let w = 2.0 * PI * m.fundamental_hz * (h + 1) as f64;
                        acc += amp * libm::sin(w * t + self.mains_phase * (h + 1) as f64);
                    }
                }
                i += acc;
            }
            *out = AdcPair {
                current: fe.adc_code(i * fe.tia_ohm),
                monitor: fe.adc_code(self.plant.x[Y_V] * fe.monitor_gain),
            };
            let c = self.stuck_dac.unwrap_or(*code);
            self.plant.step(fe.drive_volts(c));
            self.samples += 1;
        }
    }

    /// Let the probe run `n` samples with the DAC at mid-scale (drive off), discarding the ADC.
    pub fn idle(&mut self, n: usize) {
        let mut sink = [AdcPair::default(); 64];
        let zeros = [MID_CODE; 64];
        let mut left = n;
        while left > 0 {
            let k = left.min(64);
            self.exchange(&zeros[..k], &mut sink[..k]);
            left -= k;
        }
    }
}
