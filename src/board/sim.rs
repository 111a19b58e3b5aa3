//! The simulated probe (`hal-sim`) behind the driver traits.

use crate::hal::{AdcFrame, FrontEndScale, SampleStream, StreamError};
use crate::units::{AdcCode, DacCode, Hz};
use hal_sim::{AdcPair, SimProbe};

/// Largest batch the adapter takes in one call.
pub const MAX_BATCH: usize = 256;

/// A [`SampleStream`] backed by a [`SimProbe`]: the DAC batch plays and is captured in the same
/// call (latency 0).
#[derive(Clone, Debug)]
pub struct SimBoard {
    /// The simulated hardware.
    pub probe: SimProbe,
}

impl SimBoard {
    /// Wrap a simulated probe.
    pub fn new(probe: SimProbe) -> Self {
        Self { probe }
    }
}

/// Scale of a simulated front end.
pub fn scale_of(fe: &hal_sim::FrontEnd) -> FrontEndScale {
    FrontEndScale {
        sample_rate: Hz(fe.sample_rate_hz as f32),
        drive_volts_per_code: (fe.drive_gain * fe.vref_v / hal_sim::frontend::CODES) as f32,
        amps_per_code: fe.amps_per_code() as f32,
        monitor_volts_per_code: fe.monitor_volts_per_code() as f32,
    }
}

impl SampleStream for SimBoard {
    fn exchange(&mut self, dac: &[DacCode], adc: &mut [AdcFrame]) -> Result<(), StreamError> {
        if dac.len() != adc.len() || dac.len() > MAX_BATCH {
            return Err(StreamError::BatchSize);
        }
        let mut codes = [0u16; MAX_BATCH];
        let mut pairs = [AdcPair::default(); MAX_BATCH];
        let n = dac.len();
        for (c, d) in codes.iter_mut().zip(dac) {
            *c = d.0;
        }
        self.probe.exchange(&codes[..n], &mut pairs[..n]);
        for (a, p) in adc.iter_mut().zip(&pairs[..n]) {
            *a = AdcFrame {
                current: AdcCode(p.current),
                monitor: AdcCode(p.monitor),
            };
        }
        Ok(())
    }

    fn latency_batches(&self) -> usize {
        0
    }

    fn scale(&self) -> FrontEndScale {
        scale_of(self.probe.front_end())
    }
}

use crate::calibration::{FitError, PowerLaw, QModel};
use crate::engine::SampleEngine;
use crate::measure::{Method, Procedure, Reading, Settings};
use crate::runner::{run_sweep, RunError};
use crate::status::Failure;
use crate::sweep::{SettingsError, SweepPoint, SweepSettings};
use crate::units::{Farads, Seconds, Siemens, Volts};
use hal_sim::{NoiseScene, Phantom, Scene};

/// Why a simulated reading could not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimError {
    /// The settings were rejected.
    Settings(SettingsError),
    /// The run stopped early.
    Run(RunError),
    /// The calibration fit failed.
    Fit(FitError),
    /// The air reference found no resonance to fit.
    Air(Failure),
}

/// One reading of `scene` (noise stream `seed`) with `method` and `settings`, mapped through
/// `cal`; `on_point` sees every measured point.
pub fn read(
    scene: &Scene,
    seed: u64,
    method: Method,
    settings: impl Into<Settings>,
    cal: &PowerLaw,
    on_point: impl FnMut(&SweepPoint),
) -> Result<Reading, SimError> {
    let mut board = SimBoard::new(SimProbe::new(*scene, seed));
    let mut engine = SampleEngine::new();
    let scale = board.scale();
    let settings: Settings = settings.into();
    let mut m =
        Procedure::new(method, &settings, &scale, engine.samples()).map_err(SimError::Settings)?;
    run_sweep(&mut board, &mut engine, &mut m, cal, on_point).map_err(SimError::Run)
}

/// The reference phantoms a unit is calibrated on (paper 003 samples A–E).
pub const CALIBRATION_PHANTOMS: [Phantom; 5] = [
    hal_sim::phantoms::A,
    hal_sim::phantoms::B,
    hal_sim::phantoms::C,
    hal_sim::phantoms::D,
    hal_sim::phantoms::E,
];

/// Most repeats per phantom [`calibrate`] takes.
pub const MAX_REPEATS: usize = 25;

/// Calibrate the simulated unit as the paper calibrated its prototype: `repeats` readings of
/// each of the phantoms A–E with `method` and `settings` under `noise`, noise seeds
/// `seed0, seed0 + 1, ...`, and a weighted least-squares fit of `f = a + b E^c` to every
/// resonance (weights from each reading's own uncertainty). Readings without a resonance are
/// left out.
pub fn calibrate(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
) -> Result<PowerLaw, SimError> {
    calibrate_unit(method, settings, noise, repeats, seed0).map(|(law, _)| law)
}

/// [`calibrate`], and also the unit's Q(E) curve from the same reference readings (for methods
/// that measure Q; `None` otherwise): the contact condition the calibration holds for.
pub fn calibrate_unit(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
) -> Result<(PowerLaw, Option<QModel>), SimError> {
    calibrate_unit_with(method, settings, noise, repeats, seed0, || {})
}

/// [`calibrate_unit`], calling `on_reading` after each reference reading (for progress).
pub fn calibrate_unit_with(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
    mut on_reading: impl FnMut(),
) -> Result<(PowerLaw, Option<QModel>), SimError> {
    let repeats = repeats.clamp(1, MAX_REPEATS);
    let settings: Settings = settings.into();
    let mut data = [(0.0f64, 0.0f64, 0.0f64); 5 * MAX_REPEATS];
    let mut qs = [(0.0f64, 0.0f64); 5 * MAX_REPEATS];
    let mut nq = 0;
    let mut n = 0;
    // Any curve will do for the reference readings: only their resonance is used.
    let cal = PowerLaw::paper_experiment();
    for (pi, p) in CALIBRATION_PHANTOMS.iter().enumerate() {
        let scene = Scene::on_phantom(p).with_noise(noise);
        for r in 0..repeats {
            let seed = seed0 + (pi * MAX_REPEATS + r) as u64;
            let reading = read(&scene, seed, method, settings, &cal, |_| {})?;
            if let (Some(f), Some(s)) = (reading.resonance, reading.resonance_sigma) {
                data[n] = (p.modulus_kpa, f.0 as f64, (s.0 as f64).max(1e-4));
                n += 1;
                if let Some(q) = reading.q {
                    qs[nq] = (p.modulus_kpa, q as f64);
                    nq += 1;
                }
            }
            on_reading();
        }
    }
    let law = PowerLaw::fit_robust(&mut data[..n]).map_err(SimError::Fit)?;
    Ok((law, QModel::fit(&qs[..nq])))
}

/// The air reference of a simulated unit, as the firmware's air-reference command takes it: a
/// stepped sweep of the free probe (170–290 Hz in 2 Hz steps, 50 ms settle, 100 ms integration,
/// 5 V; 9.2 s of probe time) and a Butterworth–Van Dyke fit of its admittance, which gives the
/// free resonance and Q and the static admittance `C0`, `G0` that
/// [`HoldSettings`](crate::estimate::hold::HoldSettings) needs.
/// `hardware` is the unit (its PZT and front end; its tissue is ignored), `seed` the noise stream.
pub fn air_reference(
    hardware: &Scene,
    noise: NoiseScene,
    seed: u64,
) -> Result<(crate::store::AirReference, Farads, Siemens), SimError> {
    let scene = Scene {
        tissue: None,
        ..*hardware
    }
    .with_noise(noise);
    let sweep = SweepSettings {
        start: Hz(170.0),
        stop: Hz(290.0),
        step: Hz(2.0),
        settle: Seconds(0.05),
        integrate: Seconds(0.1),
        drive: Volts(5.0),
    };
    let mut points: heapless::Vec<SweepPoint, 64> = heapless::Vec::new();
    read(
        &scene,
        seed,
        Method::SweepG,
        &sweep,
        &PowerLaw::paper_experiment(),
        |p| {
            let _ = points.push(*p);
        },
    )?;
    let i =
        crate::estimate::argmax(&points, |p| p.g_s).ok_or(SimError::Air(Failure::NoResonance))?;
    let b = crate::estimate::fit::fit_bvd(&points, points[i].freq.0 as f64, 30.0)
        .map_err(SimError::Air)?;
    let air = crate::store::AirReference {
        free_resonance: Hz(b.f0 as f32),
        free_q: b.q as f32,
    };
    let c0 = b.b0 / (2.0 * core::f64::consts::PI * b.f_ref);
    Ok((air, Farads(c0 as f32), Siemens(b.g0 as f32)))
}
