//! The simulated probe: DAC codes in, ADC codes out, one sample at a time through the exactly
//! discretised chain.

use crate::events::{Knock, KnockTrain, SCHEDULE_STEP_S};
use crate::frontend::{AdcChannel, FrontEnd, StuckAdc, MAX_CODE, MID_CODE};
use crate::loadcell::Hx711Sim;
use crate::plant::{chain, chain_two_modes, Discrete, State, CHAIN2_STATES, CHAIN_STATES};
use crate::scenes::Scene;
use crate::tissue::Tissue;
use core::f64::consts::PI;
use probe_rng::Rng;

/// One ADC conversion pair: sense current and drive monitor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdcPair {
    /// Sense-current channel code.
    pub current: u16,
    /// Drive-monitor channel code.
    pub monitor: u16,
}

/// The exactly discretised chain: 8 states, or 10 with a second mechanical mode (only scenes
/// that have one pay for it). The first eight states mean the same in both. (No boxing: the
/// crate is `no_std` without an allocator; 320 bytes more per probe do not matter.)
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
enum Plant {
    One(Discrete<CHAIN_STATES>),
    Two(Discrete<CHAIN2_STATES>),
}

impl Plant {
    fn new(scene: &Scene) -> Self {
        let fe = &scene.front_end;
        let k = scene.kelvin();
        match &scene.second_mode {
            None => Plant::One(chain(
                &k,
                &scene.pzt,
                fe.reconstruction_hz,
                fe.antialias_hz,
                fe.dt(),
            )),
            Some(m) => Plant::Two(chain_two_modes(
                &k,
                &scene.pzt,
                &m.kelvin(),
                m.force_factor_n_v,
                fe.reconstruction_hz,
                fe.antialias_hz,
                fe.dt(),
            )),
        }
    }
    #[inline]
    fn x(&self, i: usize) -> f64 {
        match self {
            Plant::One(d) => d.x[i],
            Plant::Two(d) => d.x[i],
        }
    }
    fn add(&mut self, i: usize, dx: f64) {
        match self {
            Plant::One(d) => d.x[i] += dx,
            Plant::Two(d) => d.x[i] += dx,
        }
    }
    /// Same physics, new matrices; the shared states carry over (a second mode appearing starts
    /// at rest, one disappearing is dropped).
    fn carry_from(&mut self, old: &Plant) {
        for i in 0..CHAIN_STATES {
            let v = old.x(i);
            match self {
                Plant::One(d) => d.x[i] = v,
                Plant::Two(d) => d.x[i] = v,
            }
        }
        if let (Plant::Two(new), Plant::Two(old)) = (self, old) {
            new.x[CHAIN_STATES..].copy_from_slice(&old.x[CHAIN_STATES..]);
        }
    }
}

/// Mixed into a probe's seed for its load cell's noise stream.
const LOAD_CELL_STREAM: u64 = 0x10ad_ce11;

/// The simulated probe hardware.
#[derive(Clone, Debug)]
pub struct SimProbe {
    /// The scene as given (time-varying parts included).
    base: Scene,
    /// Its static physics now.
    scene: Scene,
    plant: Plant,
    rng: Rng,
    samples: u64,
    mains_phase: f64,
    noise_sigma_a: f64,
    stuck_dac: Option<u16>,
    stuck_adc: Option<StuckAdc>,
    /// Sample count at which the schedule is next looked at (`u64::MAX`: never).
    next_schedule: u64,
    knocks: Option<KnockTrain>,
    /// Sample count of the next knock (`u64::MAX`: none).
    next_knock: u64,
    /// The noise stream's seed (the load cell's is derived from it).
    seed: u64,
}

impl SimProbe {
    /// A probe in `scene`, at rest, with noise (and knocks) drawn from `seed`.
    pub fn new(scene: Scene, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mains_phase = 2.0 * PI * rng.uniform();
        let fe = scene.front_end;
        let now = scene.at(0.0);
        let knocks = scene.knocks.map(|k| KnockTrain::new(k, seed));
        let mut p = Self {
            plant: Plant::new(&now),
            noise_sigma_a: fe.noise_sigma_a(),
            base: scene,
            scene: now,
            rng,
            samples: 0,
            mains_phase,
            stuck_dac: scene.stuck_dac,
            stuck_adc: scene.stuck_adc,
            next_schedule: u64::MAX,
            knocks,
            next_knock: u64::MAX,
            seed,
        };
        p.plan_schedule();
        p.plan_knock();
        p
    }

    /// The scene's static physics now (for a time-varying scene: at the current time).
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
        self.plant.x(State::Velocity.at())
    }
    /// Filtered sense current now (the anti-alias filter's output, before noise, mains and the
    /// ADC), A.
    pub fn sense_current_a(&self) -> f64 {
        self.plant.x(State::YI.at())
    }

    /// The load cell beside this probe's resonator (`None`: the scene has none): an HX711 that
    /// has been converting for a while, carrying the contact force of the moment, its noise a
    /// stream of its own derived from the probe's seed. The board keeps it, advances it with
    /// [`Hx711Sim::follow`] as the probe's time passes, and the firmware's driver reads it
    /// through [`crate::loadcell::Dout`], [`crate::loadcell::Sck`] and
    /// [`crate::loadcell::Delay`].
    pub fn load_cell(&self) -> Option<Hx711Sim> {
        self.base
            .load_cell
            .map(|c| Hx711Sim::running(c, self.seed ^ LOAD_CELL_STREAM, self.contact_force_n()))
    }

    /// The load cell as a board that powers up with it sees it (`None`: the scene has none): the
    /// HX711 powered at `t = 0` and settling before its first conversion, its noise the same
    /// stream as [`SimProbe::load_cell`]'s. The emulated STM32 board advances it in its own
    /// (core clock) time.
    pub fn load_cell_at_power_on(&self) -> Option<Hx711Sim> {
        self.base
            .load_cell
            .map(|c| Hx711Sim::new(c, self.seed ^ LOAD_CELL_STREAM))
    }

    /// The force the tip presses on the tissue now, N (the truth the load cell measures).
    pub fn contact_force_n(&self) -> f64 {
        self.scene.contact_force_n()
    }

    /// Change what is under the probe (lift-off, new tissue), keeping the dynamic state.
    pub fn set_tissue(&mut self, tissue: Option<Tissue>) {
        self.base.tissue = tissue;
        self.rebuild();
    }
    /// Replace the scene's physics (not the noise stream), keeping the dynamic state. Its
    /// time-varying parts count from the start of this probe's time.
    pub fn set_scene(&mut self, scene: Scene) {
        self.base = scene;
        self.noise_sigma_a = scene.front_end.noise_sigma_a();
        self.rebuild();
        self.plan_schedule();
    }
    /// Fault injection: the DAC output stuck at `code` (or released with `None`).
    pub fn set_stuck_dac(&mut self, code: Option<u16>) {
        self.stuck_dac = code;
    }
    /// Fault injection: an ADC channel stuck at one code (or released with `None`).
    pub fn set_stuck_adc(&mut self, stuck: Option<StuckAdc>) {
        self.stuck_adc = stuck;
    }

    fn rebuild(&mut self) {
        self.scene = self.base.at(self.time_s());
        let mut plant = Plant::new(&self.scene);
        plant.carry_from(&self.plant);
        self.plant = plant;
    }

    fn samples_at(&self, t_s: f64) -> u64 {
        let n = libm::ceil(t_s * self.scene.front_end.sample_rate_hz);
        if n.is_finite() && n < u64::MAX as f64 {
            (n as u64).max(self.samples)
        } else {
            u64::MAX
        }
    }

    fn plan_schedule(&mut self) {
        self.next_schedule = if self.base.is_time_varying() {
            self.samples + (SCHEDULE_STEP_S * self.scene.front_end.sample_rate_hz).max(1.0) as u64
        } else {
            u64::MAX
        };
    }

    fn plan_knock(&mut self) {
        self.next_knock = match &self.knocks {
            Some(k) => self.samples_at(k.next_time_s()),
            None => u64::MAX,
        };
    }

    /// Apply what happens at this sample: the schedule of changing physics (re-discretised only
    /// when the physics changed) and knocks.
    fn events(&mut self) {
        if self.samples >= self.next_schedule {
            let now = self.base.at(self.time_s());
            if now != self.scene {
                self.rebuild();
            }
            self.plan_schedule();
        }
        while self.samples >= self.next_knock {
            let Some(k) = self.knocks.as_mut().map(|t| t.pop()) else {
                break;
            };
            match k {
                Knock::Mechanical(dv) => self.plant.add(State::Velocity.at(), dv),
                Knock::Electrical(q) => {
                    let wa = 2.0 * PI * self.scene.front_end.antialias_hz;
                    self.plant.add(State::A1.at(), wa * q);
                }
            }
            self.plan_knock();
        }
    }

    /// Play `dac` (one code per sample period) and capture one ADC pair per sample of the same
    /// periods into `adc` (sampled at the start of each period). Extra entries of the longer
    /// slice are left untouched / not played.
    pub fn exchange(&mut self, dac: &[u16], adc: &mut [AdcPair]) {
        let n = dac.len().min(adc.len());
        let mut k = 0;
        while k < n {
            if self.samples >= self.next_schedule.min(self.next_knock) {
                self.events();
            }
            // Run to the next event (or the end) with the plant's variant matched once.
            let until = (self.next_schedule.min(self.next_knock)).saturating_sub(self.samples);
            let m = (n - k).min(usize::try_from(until.max(1)).unwrap_or(usize::MAX));
            let mut run = Run {
                fe: &self.scene.front_end,
                rng: &mut self.rng,
                samples: &mut self.samples,
                noise_sigma_a: self.noise_sigma_a,
                mains_phase: self.mains_phase,
                stuck_dac: self.stuck_dac,
                stuck_adc: self.stuck_adc,
            };
            let (dac, adc) = (&dac[k..k + m], &mut adc[k..k + m]);
            match &mut self.plant {
                Plant::One(d) => run.samples_through(d, dac, adc),
                Plant::Two(d) => run.samples_through(d, dac, adc),
            }
            k += m;
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

/// What one stretch of samples between events needs besides the plant.
struct Run<'a> {
    fe: &'a FrontEnd,
    rng: &'a mut Rng,
    samples: &'a mut u64,
    noise_sigma_a: f64,
    mains_phase: f64,
    stuck_dac: Option<u16>,
    stuck_adc: Option<StuckAdc>,
}

impl Run<'_> {
    /// Sample the ADC at the start of each period, then step the plant with the held DAC code.
    #[inline]
    fn samples_through<const N: usize>(
        &mut self,
        plant: &mut Discrete<N>,
        dac: &[u16],
        adc: &mut [AdcPair],
    ) {
        let fe = self.fe;
        let dt = fe.dt();
        for (code, out) in dac.iter().zip(adc.iter_mut()) {
            let mut i = plant.x[State::YI.at()];
            if self.noise_sigma_a > 0.0 {
                i += self.noise_sigma_a * self.rng.normal();
            }
            if let Some(m) = &fe.mains {
                let t = *self.samples as f64 * dt;
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
                monitor: fe.adc_code(plant.x[State::YV.at()] * fe.monitor_gain),
            };
            match self.stuck_adc {
                Some(StuckAdc {
                    channel: AdcChannel::Current,
                    code,
                }) => out.current = code.min(MAX_CODE),
                Some(StuckAdc {
                    channel: AdcChannel::Monitor,
                    code,
                }) => out.monitor = code.min(MAX_CODE),
                None => {}
            }
            let c = self.stuck_dac.unwrap_or(*code);
            plant.step(fe.drive_volts(c));
            *self.samples += 1;
        }
    }
}
