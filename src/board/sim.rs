//! The simulated probe (`hal-sim`) behind the driver traits.

use crate::engine::PIPELINE_BATCHES;
use crate::hal::{AdcFrame, FrontEndScale, SampleStream, StreamError};
use crate::loadcell::{ForceLog, ForceSource, Hx711, LoadCellError, RawForce};
use crate::units::{AdcCode, DacCode, Hz};
use core::cell::RefCell;
use hal_sim::loadcell::{Delay, Dout, Hx711Sim, Sck};
use hal_sim::{AdcPair, SimProbe};

/// Largest batch the adapter takes in one call.
pub const MAX_BATCH: usize = 256;

/// A [`SampleStream`] backed by a [`SimProbe`], with the firmware's DMA pipeline: a DAC batch
/// plays [`PIPELINE_BATCHES`] calls after it is queued (the first calls only fill the
/// pipeline), so that a plan takes effect on the host exactly as late as on the target. Its
/// load cell (when the scene has one) is read after every batch by the
/// firmware's own driver ([`Hx711`]) through the simulated chip's pins into a [`ForceLog`],
/// stamped with the probe's sample count: the board's load-cell task, polled at the batch
/// rate (200 Hz, above the chip's 80 conversions a second).
#[derive(Clone, Debug)]
pub struct SimBoard {
    /// The simulated hardware.
    pub probe: SimProbe,
    /// The probe's load cell (its converter), when the scene has one.
    pub load_cell: Option<RefCell<Hx711Sim>>,
    /// The load cell's conversions read so far.
    pub forces: ForceLog,
    /// The first error the load-cell driver reported.
    pub load_cell_error: Option<LoadCellError>,
    /// The DAC batches queued and not yet played (codes and length).
    queued: heapless::Deque<([u16; MAX_BATCH], usize), { PIPELINE_BATCHES + 1 }>,
}

impl SimBoard {
    /// Wrap a simulated probe.
    pub fn new(probe: SimProbe) -> Self {
        Self {
            load_cell: probe.load_cell().map(RefCell::new),
            probe,
            forces: ForceLog::new(),
            load_cell_error: None,
            queued: heapless::Deque::new(),
        }
    }

    /// Read the load cell once, if the scene has one: a finished conversion goes to the log.
    fn poll_load_cell(&mut self) {
        let Some(chip) = &self.load_cell else {
            return;
        };
        chip.borrow_mut().follow(&self.probe);
        let at = self.probe.samples();
        let got = Hx711::new(Delay(chip), Dout(chip), Sck(chip)).and_then(|mut hx| hx.read());
        match got {
            Ok(Some(c)) => self.forces.push(at, c),
            Ok(None) => {}
            Err(e) => {
                self.load_cell_error.get_or_insert(e);
            }
        }
    }
}

impl ForceSource for SimBoard {
    fn contact_force(&self, from: u64, to: u64) -> Option<RawForce> {
        self.forces
            .over(from, to, self.probe.front_end().sample_rate_hz as f32)
    }
}

/// Scale of a simulated front end.
pub fn scale_of(fe: &hal_sim::FrontEnd) -> FrontEndScale {
    FrontEndScale {
        sample_rate: Hz(fe.sample_rate_hz as f32),
        drive_volts_per_code: (fe.drive_gain * fe.vref_v / hal_sim::frontend::CODES) as f32,
        amps_per_code: fe.amps_per_code() as f32,
        monitor_volts_per_code: fe.monitor_volts_per_code() as f32,
        reconstruction_corner: Hz(fe.reconstruction_hz as f32),
        antialias_corner: Hz(fe.antialias_hz as f32),
    }
}

impl SampleStream for SimBoard {
    fn exchange(&mut self, dac: &[DacCode], adc: &mut [AdcFrame]) -> Result<bool, StreamError> {
        if dac.len() != adc.len() || dac.len() > MAX_BATCH {
            return Err(StreamError::BatchSize);
        }
        let mut codes = [0u16; MAX_BATCH];
        for (c, d) in codes.iter_mut().zip(dac) {
            *c = d.0;
        }
        if self.queued.push_back((codes, dac.len())).is_err() {
            return Err(StreamError::Overrun);
        }
        if self.queued.len() <= PIPELINE_BATCHES {
            return Ok(false);
        }
        let Some((codes, n)) = self.queued.pop_front() else {
            return Ok(false);
        };
        // Batches of one length only: the frames returned are those of the batch that played.
        if n != adc.len() {
            return Err(StreamError::BatchSize);
        }
        let mut pairs = [AdcPair::default(); MAX_BATCH];
        self.probe.exchange(&codes[..n], &mut pairs[..n]);
        for (a, p) in adc.iter_mut().zip(&pairs[..n]) {
            *a = AdcFrame {
                current: AdcCode(p.current),
                monitor: AdcCode(p.monitor),
            };
        }
        self.poll_load_cell();
        Ok(true)
    }

    fn latency_batches(&self) -> usize {
        PIPELINE_BATCHES
    }

    fn scale(&self) -> FrontEndScale {
        scale_of(self.probe.front_end())
    }
}

use crate::engine::sweep::{SettingsError, SweepPoint};
use crate::engine::SampleEngine;
use crate::loadcell::LoadCellCal;
use crate::reading::runner::{run_reading, RunError};
use crate::reading::{Method, Procedure, Reading, Settings};
use crate::status::Failure;
use crate::unit::calibration::FitError;
use crate::unit::profile::{air_from_points, calibrate, AirReference, Reference, UnitProfile};
use crate::units::{KPa, Newtons};
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

impl core::fmt::Display for SimError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Settings(e) => write!(f, "the settings were refused: {e}"),
            Self::Run(RunError::Stalled) => {
                f.write_str("a point did not complete within its sample budget")
            }
            Self::Run(RunError::Stream(e)) => write!(f, "the sample stream failed: {e:?}"),
            Self::Fit(FitError::TooFewPoints) => f.write_str(
                "the calibration fit needs at least four readings on three distinct moduli",
            ),
            Self::Fit(FitError::BadInput) => f.write_str(
                "the calibration fit was given a reading that is not finite or a modulus that is not positive",
            ),
            Self::Fit(FitError::NotSaturating) => {
                f.write_str("the calibration fit found no saturating curve in the references")
            }
            Self::Air(e) => write!(f, "the air reference failed: {e}"),
        }
    }
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
    config: &crate::instrument::continuous::TrackerConfig,
    unit: &UnitProfile,
    seconds: f64,
    on_reading: impl FnMut(&crate::instrument::continuous::StreamReading),
) -> Result<u32, SimError> {
    stream_moving(scene, seed, config, unit, seconds, |_| None, on_reading)
}

/// [`stream`] with the probe moving over the tissue: before every window the tissue under the
/// tip becomes `tissue_at(t)` at the probe time `t` (s) when it gives one (`Some(None)`: free
/// air), the probe's dynamic state carried over (the tip sliding over a phantom).
pub fn stream_moving(
    scene: &Scene,
    seed: u64,
    config: &crate::instrument::continuous::TrackerConfig,
    unit: &UnitProfile,
    seconds: f64,
    tissue_at: impl FnMut(f64) -> Option<Option<hal_sim::Tissue>>,
    mut on_reading: impl FnMut(&crate::instrument::continuous::StreamReading),
) -> Result<u32, SimError> {
    let mut board = SimBoard::new(SimProbe::new(*scene, seed));
    let mut engine = SampleEngine::new();
    let mut tracker = config
        .validate(&board.scale(), unit)
        .map_err(SimError::Settings)?;
    let mut src = Moving {
        inner: crate::reading::driver::SyncSource::new(&mut board, &mut engine),
        tissue_at,
    };
    let n = crate::reading::driver::block_on(crate::instrument::continuous::run(
        &mut src,
        &mut tracker,
        unit,
        |r| {
            on_reading(r);
            (r.t_s.0 as f64) < seconds
        },
    ));
    Ok(n)
}

/// A [`SyncSource`](crate::reading::driver::SyncSource) on a [`SimBoard`] whose tissue follows a path
/// in time ([`stream_moving`]).
struct Moving<'a, F> {
    inner: crate::reading::driver::SyncSource<'a, SimBoard>,
    tissue_at: F,
}

impl<F: FnMut(f64) -> Option<Option<hal_sim::Tissue>>> crate::reading::driver::PointSource
    for Moving<'_, F>
{
    fn scale(&self) -> FrontEndScale {
        self.inner.scale()
    }
    fn now_sample(&self) -> u64 {
        self.inner.now_sample()
    }
    async fn load(&mut self, plan: crate::engine::PointPlan) -> bool {
        self.inner.load(plan).await
    }
    async fn next(
        &mut self,
        wanted: &crate::reading::driver::Wanted,
        budget: u64,
    ) -> Option<crate::engine::PointRaw> {
        let probe = &mut self.inner.stream.probe;
        if let Some(t) = (self.tissue_at)(probe.time_s()) {
            if probe.scene().tissue != t {
                probe.set_tissue(t);
            }
        }
        self.inner.next(wanted, budget).await
    }
    async fn stop(&mut self) {
        self.inner.stop().await
    }
    async fn idle(&mut self, samples: u64) {
        self.inner.idle(samples).await
    }
    fn contact_force(&mut self, from: u64, to: u64) -> Option<RawForce> {
        self.inner.contact_force(from, to)
    }
}

/// The reference phantoms a unit is calibrated on (paper 003 samples A–E).
pub const CALIBRATION_PHANTOMS: [Phantom; 5] = [
    hal_sim::phantoms::A,
    hal_sim::phantoms::B,
    hal_sim::phantoms::C,
    hal_sim::phantoms::D,
    hal_sim::phantoms::E,
];

/// Most repeats per phantom [`calibrate_unit_with`] takes.
pub const MAX_REPEATS: usize = 25;

/// The contact forces the unit is calibrated at, N: the paper's 30 mN first, then the ends of
/// the force window's calibrated part (15 and 50 mN). A phantom's readings take them in turn.
pub const CALIBRATION_FORCES: [f64; 3] = [0.030, 0.015, 0.050];

/// The known weight the load cell's sensitivity is taken with: 10 g (98.1 mN), within the
/// 100 g cell's range and above the force window.
pub const CALIBRATION_WEIGHT_N: f64 = 0.010 * hal_sim::loadcell::STANDARD_GRAVITY_M_S2;

/// Noise stream of the simulated unit's air reference.
pub const AIR_SEED: u64 = 77;

/// The whole profile of the simulated unit, as a user of the real instrument makes it: the
/// load cell's sensitivity from a known weight ([`weigh`]), the air reference in free air with
/// the cell's tare ([`air_reference`]), then [`calibrate_unit_with`] on A–E × `repeats` with
/// `method` and `settings` under `noise`. `on_reading` is called after each reference reading
/// (for progress).
pub fn unit_profile_with(
    method: Method,
    settings: impl Into<Settings>,
    noise: NoiseScene,
    repeats: usize,
    seed0: u64,
    on_reading: impl FnMut(),
) -> Result<UnitProfile, SimError> {
    let hardware = Scene::free_air();
    let (air, tare) = air_reference(&hardware, noise, AIR_SEED)?;
    let load_cell = match tare {
        Some(zero) => {
            let loaded = weigh(&hardware, CALIBRATION_WEIGHT_N, AIR_SEED + 1)
                .ok_or(SimError::Air(Failure::NoForce))?;
            Some(
                LoadCellCal::weighed(&zero, &loaded, Newtons(CALIBRATION_WEIGHT_N as f32))
                    .ok_or(SimError::Air(Failure::NoForce))?,
            )
        }
        None => None,
    };
    calibrate_unit_with(
        air, load_cell, method, settings, noise, repeats, seed0, on_reading,
    )
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

/// Calibrate the simulated unit whose air reference is `air` (and load cell `load_cell`) as
/// the paper calibrated its prototype, and at several contact forces: `repeats` readings of
/// each of the phantoms A–E with `method` and `settings` under `noise`, pressed in turn at
/// each of [`CALIBRATION_FORCES`] (with a load cell; at 30 mN without one), noise seeds
/// `seed0, seed0 + 1, ...`, and the one calibration procedure ([`calibrate`]). Readings
/// without a resonance or Q are left out.
#[allow(clippy::too_many_arguments)] // the unit and the procedure, each named
pub fn calibrate_unit_with(
    air: AirReference,
    load_cell: Option<LoadCellCal>,
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
        force_n: 0.0,
    }; 5 * MAX_REPEATS];
    let mut n = 0;
    // Before the fit the unit has its air reference and no calibration: the pipeline refuses
    // the modulus (`uncalibrated`) and keeps the resonance, Q and force the fit needs.
    let uncalibrated = UnitProfile {
        air: Some(air),
        load_cell,
        ..UnitProfile::fallback()
    };
    for (pi, p) in CALIBRATION_PHANTOMS.iter().enumerate() {
        for r in 0..repeats {
            let force = match load_cell {
                Some(_) => CALIBRATION_FORCES[r % CALIBRATION_FORCES.len()],
                None => CALIBRATION_FORCES[0],
            };
            let scene = Scene::on_phantom(p).with_noise(noise).with_preload_n(force);
            let seed = seed0 + (pi * MAX_REPEATS + r) as u64;
            let reading = read(&scene, seed, method, settings, &uncalibrated, |_| {})?;
            // The reference moduli (paper 003's A–E) are exact in f32.
            if let Some(x) = reading.reference(KPa(p.modulus_kpa as f32)) {
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
        load_cell,
        force_window: crate::loadcell::ForceWindow::DEFAULT,
    })
}

/// The air reference of a simulated unit, taken as the firmware's `air` command takes it: a
/// sweep of the free probe ([`crate::unit::profile::AIR_SWEEP`], 9.2 s of probe time) and
/// [`air_from_points`], with the load cell's counts over the sweep (its tare; `None` without a
/// load cell). `hardware` is the unit (its PZT, front end and load cell; its tissue is
/// ignored), `seed` the noise stream.
pub fn air_reference(
    hardware: &Scene,
    noise: NoiseScene,
    seed: u64,
) -> Result<(AirReference, Option<RawForce>), SimError> {
    let scene = Scene {
        tissue: None,
        ..*hardware
    }
    .with_noise(noise);
    air_reference_on(&scene, seed)
}

/// The air-reference procedure on `scene` as it is (a user may take it touching something:
/// [`air_from_points`] then refuses it), with the load cell's counts over it.
pub fn air_reference_on(
    scene: &Scene,
    seed: u64,
) -> Result<(AirReference, Option<RawForce>), SimError> {
    let mut points: heapless::Vec<SweepPoint, 64> = heapless::Vec::new();
    let mut board = SimBoard::new(SimProbe::new(*scene, seed));
    let mut engine = SampleEngine::new();
    let settings: Settings = (&crate::unit::profile::AIR_SWEEP).into();
    run_reading(
        &mut board,
        &mut engine,
        Method::SweepG,
        &settings,
        &UnitProfile::fallback(),
        |p| {
            let _ = points.push(*p);
        },
    )
    .map_err(SimError::Run)?;
    let air = air_from_points(&points).map_err(SimError::Air)?;
    Ok((air, board.contact_force(0, board.probe.samples())))
}

/// The load cell's counts with `weight_n` newtons resting on the tip of the unit `hardware`
/// (a weight on a steel stud: the tissue rigid), the drive off, over 0.5 s: the factory's
/// sensitivity step ([`LoadCellCal::weighed`]). `None` without a load cell.
pub fn weigh(hardware: &Scene, weight_n: f64, seed: u64) -> Option<RawForce> {
    let scene = hardware.weighing(weight_n);
    let mut board = SimBoard::new(SimProbe::new(scene, seed));
    let dac = [DacCode::MID; crate::engine::BATCH];
    let mut adc = [AdcFrame::default(); crate::engine::BATCH];
    let n = (0.5 * scene.front_end.sample_rate_hz) as usize / crate::engine::BATCH;
    let mut played = 0;
    while played < n {
        played += board.exchange(&dac, &mut adc).ok()? as usize;
    }
    board.contact_force(0, board.probe.samples())
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
