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

use crate::calibration::FitError;
use crate::engine::SampleEngine;
use crate::measure::{Method, Procedure, Reading, Settings};
use crate::profile::{air_from_points, calibrate, AirReference, Reference, UnitProfile};
use crate::runner::{run_reading, RunError};
use crate::status::Failure;
use crate::sweep::{SettingsError, SweepPoint};
use crate::units::KPa;
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
    /// The air reference could not be taken.
    Air(Failure),
}

/// One reading of `scene` (noise stream `seed`) with `method` and `settings`, concluded with
/// the unit's profile `unit` through the one pipeline; `on_point` sees every measured point.
pub fn read(
    scene: &Scene,
    seed: u64,
    method: Method,
    settings: impl Into<Settings>,
    unit: &UnitProfile,
    on_point: impl FnMut(&SweepPoint),
) -> Result<Reading, SimError> {
    let mut board = SimBoard::new(SimProbe::new(*scene, seed));
    let mut engine = SampleEngine::new();
    let settings: Settings = settings.into();
    // Settings errors are the caller's to see, not a failed reading.
    Procedure::new(method, &settings, &board.scale(), 0, unit).map_err(SimError::Settings)?;
    run_reading(&mut board, &mut engine, method, &settings, unit, on_point).map_err(SimError::Run)
}

/// A continuous stream on `scene` (noise stream `seed`) with the tracker `config`, concluded
/// with `unit`: every reading to `on_reading` until the probe time passes `seconds` (the
/// reading that passes it is the last). Returns the readings taken.
pub fn stream(
    scene: &Scene,
    seed: u64,
    config: &crate::stream::TrackerConfig,
    unit: &UnitProfile,
    seconds: f64,
    mut on_reading: impl FnMut(&crate::stream::StreamReading),
) -> Result<u32, SimError> {
    let mut board = SimBoard::new(SimProbe::new(*scene, seed));
    let mut engine = SampleEngine::new();
    let mut tracker = config
        .validate(&board.scale(), unit)
        .map_err(SimError::Settings)?;
    let mut src = crate::reading::SyncSource::new(&mut board, &mut engine);
    let n = crate::reading::block_on(crate::stream::run(&mut src, &mut tracker, unit, |r| {
        on_reading(r);
        (r.t_s.0 as f64) < seconds
    }));
    Ok(n)
}

/// The reference phantoms a unit is calibrated on (paper 003 samples A–E).
pub const CALIBRATION_PHANTOMS: [Phantom; 5] = [
    hal_sim::phantoms::A,
    hal_sim::phantoms::B,
    hal_sim::phantoms::C,
    hal_sim::phantoms::D,
    hal_sim::phantoms::E,
];

/// Most repeats per phantom [`calibrate_unit`] takes.
pub const MAX_REPEATS: usize = 25;

/// Noise stream of the simulated unit's air reference.
pub const AIR_SEED: u64 = 77;

/// The whole profile of the simulated unit, as a user of the real instrument makes it: the air
/// reference in free air ([`air_reference`]), then [`calibrate_unit_with`] on A–E × `repeats`
/// with `method` and `settings` under `noise`. `on_reading` is called after each reference
/// reading (for progress).
pub fn unit_profile_with(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
    on_reading: impl FnMut(),
) -> Result<UnitProfile, SimError> {
    let hardware = Scene::free_air();
    let air = air_reference(&hardware, noise, AIR_SEED)?;
    calibrate_unit_with(air, method, settings, noise, repeats, seed0, on_reading)
}

/// [`unit_profile_with`] without progress.
pub fn unit_profile(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
) -> Result<UnitProfile, SimError> {
    unit_profile_with(method, settings, noise, repeats, seed0, || {})
}

/// Calibrate the simulated unit whose air reference is `air` as the paper calibrated its
/// prototype: `repeats` readings of each of the phantoms A–E with `method` and `settings`
/// under `noise`, noise seeds `seed0, seed0 + 1, ...`, and the one calibration procedure
/// ([`calibrate`]: robust weighted fit of `f = a + b E^c`, and the Q(E) contact condition).
/// Readings without a resonance or Q are left out.
pub fn calibrate_unit_with(
    air: AirReference,
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
    mut on_reading: impl FnMut(),
) -> Result<UnitProfile, SimError> {
    let repeats = repeats.clamp(1, MAX_REPEATS);
    let settings: Settings = settings.into();
    let mut refs = [Reference {
        modulus_kpa: 0.0,
        resonance_hz: 0.0,
        sigma_hz: 0.0,
        q: 0.0,
    }; 5 * MAX_REPEATS];
    let mut n = 0;
    // Before the fit the unit has its air reference and no calibration: the pipeline refuses
    // the modulus (`uncalibrated`) and keeps the resonance and Q the fit needs.
    let uncalibrated = UnitProfile {
        air: Some(air),
        ..UnitProfile::fallback()
    };
    for (pi, p) in CALIBRATION_PHANTOMS.iter().enumerate() {
        let scene = Scene::on_phantom(p).with_noise(noise);
        for r in 0..repeats {
            let seed = seed0 + (pi * MAX_REPEATS + r) as u64;
            let reading = read(&scene, seed, method, settings, &uncalibrated, |_| {})?;
            // The reference moduli (paper 003's A–E) are exact in f32.
            if let Some(x) = Reference::of(KPa(p.modulus_kpa as f32), &reading) {
                refs[n] = x;
                n += 1;
            }
            on_reading();
        }
    }
    let c = calibrate(&refs[..n], Some(&air)).map_err(SimError::Fit)?;
    Ok(UnitProfile {
        calibration: c.law,
        resonance: method.resonance(),
        q_model: Some(c.q_model),
        air: Some(air),
        contact: c.contact,
    })
}

/// The air reference of a simulated unit, taken as the firmware's `air` command takes it: a
/// sweep of the free probe ([`crate::profile::AIR_SWEEP`], 9.2 s of probe time) and
/// [`air_from_points`]. `hardware` is the unit (its PZT and front end; its tissue is ignored),
/// `seed` the noise stream.
pub fn air_reference(
    hardware: &Scene,
    noise: NoiseScene,
    seed: u64,
) -> Result<AirReference, SimError> {
    let scene = Scene {
        tissue: None,
        ..*hardware
    }
    .with_noise(noise);
    air_reference_on(&scene, seed)
}

/// The air-reference procedure on `scene` as it is (a user may take it touching something:
/// [`air_from_points`] then refuses it).
pub fn air_reference_on(scene: &Scene, seed: u64) -> Result<AirReference, SimError> {
    let mut points: heapless::Vec<SweepPoint, 64> = heapless::Vec::new();
    read(
        scene,
        seed,
        Method::SweepG,
        &crate::profile::AIR_SWEEP,
        &UnitProfile::fallback(),
        |p| {
            let _ = points.push(*p);
        },
    )?;
    air_from_points(&points).map_err(SimError::Air)
}

#[cfg(test)]
mod tests {
    use crate::hal::FrontEndScale;

    /// The simulated front end is the probe's: every factor of `FrontEndScale::PROBE` (written
    /// from the schematic's values) within an `f32` rounding of what `hal_sim::FrontEnd`
    /// derives in `f64` from its own parameters.
    #[test]
    fn simulated_front_end_is_the_probes() {
        let s = super::scale_of(&hal_sim::FrontEnd::default());
        let p = FrontEndScale::PROBE;
        assert_eq!(s.sample_rate, p.sample_rate);
        for (a, b) in [
            (s.drive_volts_per_code, p.drive_volts_per_code),
            (s.amps_per_code, p.amps_per_code),
            (s.monitor_volts_per_code, p.monitor_volts_per_code),
        ] {
            assert!((a - b).abs() <= 2.0 * f32::EPSILON * b, "{a} vs {b}");
        }
    }
}
