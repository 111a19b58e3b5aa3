//! The session: what the probe does with each host command, independent of the board.
//!
//! It owns the unit's [`UnitProfile`] (loaded from the store at boot), the active method and
//! settings, and the reference readings of a calibration in progress. Each [`Command`] is
//! served by [`Session::handle`] through an [`Io`]: the board's point source (readings go
//! through the one driver, [`crate::reading::driver::read`], and end in the one pipeline), the store,
//! and the sink of [`Event`]s (the firmware's defmt log; the host tests' list). The RTIC
//! application only binds these to its channels; the host tests drive the same code on the
//! simulated probe.

use crate::boot::BootError;
use crate::engine::sweep::SweepPoint;
use crate::instrument::command::{Command, CommandError, StreamRequest};
use crate::instrument::continuous::StreamReading;
use crate::instrument::selftest::{self, SelfTestFault, SelfTestReport};
use crate::loadcell::{ForceWindow, LoadCellCal, RawForce};
use crate::reading::driver::{read, PointSource, Stop};
use crate::reading::{Method, Procedure, Reading, Settings, DEFAULT_METHOD};
use crate::status::{Failure, Status};
use crate::unit::calibration::PowerLaw;
use crate::unit::profile::{self, AirReference, Reference, UnitProfile, AIR_SWEEP};
use crate::unit::store::{LoadSource, Loaded, Saved, StoreError};
use crate::units::{KPa, Newtons, Seconds};

/// Reference readings kept for a calibration fit.
pub const MAX_REFERENCES: usize = 32;
/// Points of an air-reference sweep ([`AIR_SWEEP`]: 61).
pub const AIR_POINTS: usize = 64;

/// What the session tells the outside world (the firmware logs each as one defmt line).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// The unit profile was loaded from the store (at power-on or on `reload`).
    Loaded(LoadSource),
    /// The active method and its settings.
    Settings(Method, Settings),
    /// An admittance point of the reading in progress, with its plan's tag.
    Point {
        /// Plan tag.
        tag: u16,
        /// The point.
        point: SweepPoint,
    },
    /// A reading ended.
    Reading(Reading),
    /// A self-test ended (power-on or `selftest`).
    SelfTest(SelfTestReport),
    /// What the user can do about the failed reading just reported.
    Hint(Failure),
    /// A window did not arrive in time (plan tag).
    Stalled(u16),
    /// The air reference was taken.
    Air(AirReference),
    /// A reference reading was added: its modulus, resonance, and the count so far.
    Reference {
        /// The reference's modulus.
        modulus: KPa,
        /// What the unit read on it.
        reference: Reference,
        /// References held.
        n: u16,
    },
    /// A new calibration is in use.
    Calibration(PowerLaw),
    /// The load cell's calibration (none: the unit reads without a force) and the force
    /// window, after `force`, `weigh`, an `air` that tared the cell, and `status`.
    LoadCell {
        /// Sensitivity and tare.
        cal: Option<LoadCellCal>,
        /// Where readings are taken.
        window: ForceWindow,
    },
    /// The profile was stored.
    Saved(Saved),
    /// Storing failed.
    StoreFailed(StoreError),
    /// A command was refused, with why.
    Refused(Refusal),
    /// The commands, the methods and the default method.
    Help,
    /// A reading of a continuous stream (`stream`), handed on without waiting:
    /// one the report channel had no room for is dropped (its `seq` is missing).
    Stream(StreamReading),
    /// A stream ended.
    StreamEnd {
        /// Probe time when it started.
        start: Seconds,
        /// Readings the tracker made (the next `seq`).
        readings: u32,
        /// Of those, how many were `ok`.
        ok: u32,
        /// Of those, how many could not be handed on (the report channel was full).
        dropped: u32,
        /// The most work between a window and the next plan ([`Io::take_plan_work`]).
        plan_work: Option<u32>,
    },
    /// The session's state.
    Status(StatusReport),
}

/// The session's state, as `status` reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatusReport {
    /// Active method.
    pub method: Method,
    /// Calibration in use.
    pub calibration: PowerLaw,
    /// The store held no valid profile at boot and none was stored since.
    pub fallback: bool,
    /// An air reference is held.
    pub air: bool,
    /// A contact condition (Q model) is held.
    pub q_model: bool,
    /// Reference readings held.
    pub references: u16,
    /// The last self-test: `None` when none ran, else passed or its fault.
    pub selftest: Option<Result<(), SelfTestFault>>,
    /// The board's first failed bring-up step, if any ([`Io::boot_error`]).
    pub boot: Option<BootError>,
}

/// Why a command was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refusal {
    /// The settings do not suit the active method.
    Settings(CommandError),
    /// The air reference could not be taken (code of the failure).
    Air(Failure),
    /// The reference reading has no resonance with Q.
    NoResonance,
    /// The reference reading's contact force was missing, outside the window or unsteady (the
    /// reading's code).
    BadReference(Failure),
    /// `weigh` could not take the load cell's sensitivity: no zero yet (take `air` first), the
    /// cell gave no counts, or the weight did not move them.
    Weigh,
    /// [`MAX_REFERENCES`] are held already.
    ReferencesFull,
    /// The calibration fit failed.
    Fit,
    /// A reading was asked for while the last self-test failed with this fault.
    SelfTest(SelfTestFault),
    /// A reading or a self-test was asked for on a board whose bring-up failed at a step that
    /// leaves it without its sample stream ([`BootError::blocks_readings`]).
    Boot(BootError),
}

impl Refusal {
    /// One line for a human.
    pub fn message(self) -> &'static str {
        match self {
            Refusal::Settings(e) => e.message(),
            Refusal::Air(f) => f.message(),
            Refusal::NoResonance => "no resonance in the reference reading",
            Refusal::BadReference(f) => f.message(),
            Refusal::Weigh => "weighing failed: take the air reference first (the zero), rest the weight on the tip, check the load cell",
            Refusal::ReferencesFull => "reference list full: fit or clear",
            Refusal::Fit => "calibration fit failed: add references over a wider range",
            Refusal::SelfTest(f) => f.message(),
            Refusal::Boot(e) => e.message(),
        }
    }
}

/// What a session needs from its board.
#[allow(async_fn_in_trait)] // used with concrete types only, in one task at a time
pub trait Io: PointSource {
    /// Tell the outside world.
    async fn emit(&mut self, e: Event);
    /// Store the profile power-loss safe.
    fn save(&mut self, p: &UnitProfile) -> Result<Saved, StoreError>;
    /// Load the newest stored profile (or the fallback).
    fn load_profile(&mut self) -> Loaded;
    /// Tell the outside world if it has room now, without waiting: false when the event was
    /// dropped (a stream's readings go this way, so a slow host never holds the measurement
    /// up).
    fn try_emit(&mut self, e: Event) -> bool;
    /// The most work between a window's arrival and the next plan's load since the last call
    /// (the board's unit: instructions under QEMU, core cycles on the STM32), and start
    /// again; `None` where the board does not measure it (by default).
    fn take_plan_work(&mut self) -> Option<u32> {
        None
    }
    /// The board's first failed bring-up step (none by default: boards that cannot fail to
    /// come up).
    fn boot_error(&self) -> Option<BootError> {
        None
    }
}

/// The probe's session state.
#[derive(Clone, Debug)]
pub struct Session {
    profile: UnitProfile,
    fallback: bool,
    method: Method,
    settings: Settings,
    refs: heapless::Vec<Reference, MAX_REFERENCES>,
    selftest: Option<Result<(), SelfTestFault>>,
    /// The load cell's counts over the last air reference: its zero for `weigh`.
    zero: Option<RawForce>,
}

/// How long `weigh` reads the load cell, s: 20 conversions at 80 SPS (the mean to 0.02 % of a
/// 10 g weight at the cell's 0.1 mN noise).
pub const WEIGH_S: f32 = 0.25;

impl Session {
    /// Power-on: load the profile from the store (and say where it came from), with the
    /// default method, then the self-test of the analog chain ([`crate::instrument::selftest`]): while it
    /// has failed, every reading is refused.
    pub async fn boot<I: Io>(io: &mut I) -> Self {
        let mut s = Self::load(io).await;
        s.selftest(io).await;
        s
    }

    async fn load<I: Io>(io: &mut I) -> Self {
        let loaded = io.load_profile();
        io.emit(Event::Loaded(loaded.source)).await;
        Self::new(&loaded)
    }

    /// A session on what the store loaded, with the default method, before any self-test
    /// (readings are served; [`Session::boot`] runs the self-test first).
    pub fn new(loaded: &Loaded) -> Self {
        Self {
            profile: loaded.record,
            fallback: loaded.is_fallback(),
            method: DEFAULT_METHOD,
            settings: DEFAULT_METHOD.default_settings(),
            refs: heapless::Vec::new(),
            selftest: None,
            zero: None,
        }
    }

    /// The last self-test's outcome (`None`: none ran).
    pub fn selftest_outcome(&self) -> Option<Result<(), SelfTestFault>> {
        self.selftest
    }

    /// Run the self-test against the profile in use, keep and emit its outcome; true when it
    /// passed.
    async fn selftest<I: Io>(&mut self, io: &mut I) -> bool {
        let mut stalled = None;
        let r = selftest::run(io, &self.profile, |Stop::Stalled(tag)| stalled = Some(tag)).await;
        if let Some(tag) = stalled {
            io.emit(Event::Stalled(tag)).await;
        }
        self.selftest = Some(r.outcome);
        io.emit(Event::SelfTest(r)).await;
        r.passed()
    }

    /// Refuse a reading while the last self-test failed: emits the refusal, true when refused.
    async fn refused_by_selftest<I: Io>(&self, io: &mut I) -> bool {
        match self.selftest {
            Some(Err(f)) => {
                io.emit(Event::Refused(Refusal::SelfTest(f))).await;
                true
            }
            _ => false,
        }
    }

    /// Reference readings held for the next `calibrate fit` (its cost grows with them).
    pub fn references(&self) -> usize {
        self.refs.len()
    }

    /// The unit's profile in use.
    pub fn profile(&self) -> &UnitProfile {
        &self.profile
    }

    /// The active method.
    pub fn method(&self) -> Method {
        self.method
    }

    /// Serve one command; true when it succeeded (a reading: when it is `ok`).
    pub async fn handle<I: Io>(&mut self, cmd: Command, io: &mut I) -> bool {
        // Every reading is refused while the last self-test failed — but the air reference
        // when only the capacitance is off: the chain works (no open, short, rail or missing
        // drive), and `air` re-measures the very C0 it was compared with (a fresh unit's plate
        // off the nominal one; the self-test then runs against the new reference).
        // A board without its sample stream (a failed bring-up step) can neither read nor
        // test itself: refused with the step's name, not the self-test's `no_samples`.
        if let Some(e) = io.boot_error().filter(|e| e.blocks_readings()) {
            if matches!(
                cmd,
                Command::Measure
                    | Command::CalibrateAdd(_)
                    | Command::Air
                    | Command::SelfTest
                    | Command::Stream(_)
            ) {
                io.emit(Event::Refused(Refusal::Boot(e))).await;
                return false;
            }
        }
        let reading = match cmd {
            Command::Measure | Command::CalibrateAdd(_) | Command::Stream(_) => true,
            Command::Air => self.selftest != Some(Err(SelfTestFault::Capacitance)),
            _ => false,
        };
        if reading && self.refused_by_selftest(io).await {
            return false;
        }
        match cmd {
            Command::SelfTest => self.selftest(io).await,
            Command::Measure => {
                let r = self.reading(io, self.method, self.settings).await;
                io.emit(Event::Reading(r)).await;
                if let Status::Failed(f) = r.status {
                    io.emit(Event::Hint(f)).await;
                }
                r.status.is_ok()
            }
            Command::Method(m) => {
                self.method = m;
                self.settings = m.default_settings();
                io.emit(Event::Settings(self.method, self.settings)).await;
                true
            }
            Command::Settings(s) => {
                // Parsed and checked against the board by the parser; that they suit the
                // active method, by the method's own validation.
                match Procedure::new(self.method, &s, &io.scale(), 0, &self.profile) {
                    Ok(_) => {
                        self.settings = s;
                        io.emit(Event::Settings(self.method, self.settings)).await;
                        true
                    }
                    Err(e) => {
                        let why = Refusal::Settings(CommandError::Settings(e));
                        io.emit(Event::Refused(why)).await;
                        false
                    }
                }
            }
            Command::SettingsDefault => {
                self.settings = self.method.default_settings();
                io.emit(Event::Settings(self.method, self.settings)).await;
                true
            }
            Command::Air => self.air(io).await,
            Command::CalibrateAdd(e) => self.calibrate_add(io, e).await,
            Command::CalibrateFit => {
                match profile::calibrate(&self.refs, self.profile.air.as_ref()) {
                    Ok(c) => {
                        // The references were read with the active method: the curve maps its
                        // resonance.
                        self.profile.calibration = c.law;
                        self.profile.resonance = self.method.resonance();
                        self.profile.q_model = Some(c.q_model);
                        self.profile.contact = c.contact;
                        io.emit(Event::Calibration(c.law)).await;
                        true
                    }
                    Err(_) => {
                        io.emit(Event::Refused(Refusal::Fit)).await;
                        false
                    }
                }
            }
            Command::CalibrateClear => {
                self.refs.clear();
                true
            }
            Command::CalibratePaper => {
                self.profile.use_power_law(
                    PowerLaw::paper_experiment(),
                    crate::estimate::Resonance::Motional,
                );
                io.emit(Event::Calibration(self.profile.calibration)).await;
                true
            }
            Command::Store => match io.save(&self.profile) {
                Ok(s) => {
                    self.fallback = false;
                    io.emit(Event::Saved(s)).await;
                    true
                }
                Err(e) => {
                    io.emit(Event::StoreFailed(e)).await;
                    false
                }
            },
            Command::Help => {
                io.emit(Event::Help).await;
                true
            }
            Command::Stream(r) => self.stream(io, r).await,
            Command::Reload => {
                // Discards unsaved changes, not the self-test's verdict on the hardware.
                let selftest = self.selftest;
                *self = Self::load(io).await;
                self.selftest = selftest;
                true
            }
            Command::Status => {
                self.emit_load_cell(io).await;
                io.emit(Event::Status(StatusReport {
                    method: self.method,
                    calibration: self.profile.calibration,
                    fallback: self.fallback,
                    air: self.profile.air.is_some(),
                    q_model: self.profile.q_model.is_some(),
                    references: self.refs.len() as u16,
                    selftest: self.selftest,
                    boot: io.boot_error(),
                }))
                .await;
                true
            }
            Command::ForceWindow(w) => {
                self.profile.force_window = w;
                self.emit_load_cell(io).await;
                true
            }
            Command::Weigh(w) => self.weigh(io, w).await,
        }
    }

    /// One reading through the one driver with the session's profile, its points and any
    /// stall emitted as events.
    async fn reading<I: Io>(&self, io: &mut I, method: Method, settings: Settings) -> Reading {
        self.reading_with(io, method, settings, |_| {}).await
    }

    async fn reading_with<I: Io>(
        &self,
        io: &mut I,
        method: Method,
        settings: Settings,
        mut keep: impl FnMut(&SweepPoint),
    ) -> Reading {
        // The points go out as they come, through the board's own point sink
        // (PointSource::point); a stall is emitted after the reading, which borrows the board.
        let mut stalled = None;
        let r = read(
            io,
            method,
            &settings,
            &self.profile,
            |_, p| keep(p),
            |Stop::Stalled(tag)| stalled = Some(tag),
        )
        .await;
        if let Some(tag) = stalled {
            io.emit(Event::Stalled(tag)).await;
        }
        r
    }

    /// The one air-reference procedure: a sweep of the free probe and a BVD fit of its points
    /// ([`profile::air_from_points`], which refuses a probe that touches something), and the
    /// load cell's tare: its counts over the sweep are zero force (when the unit has a load
    /// cell and it answered; a silent cell keeps its tare, and readings say `no_force`).
    async fn air<I: Io>(&mut self, io: &mut I) -> bool {
        let mut pts: heapless::Vec<SweepPoint, AIR_POINTS> = heapless::Vec::new();
        let start = io.now_sample();
        let r = self
            .reading_with(io, Method::SweepG, Settings::Sweep(AIR_SWEEP), |p| {
                let _ = pts.push(*p);
            })
            .await;
        let air = match r.status {
            Status::Failed(
                f @ (Failure::DriveFault | Failure::DmaError | Failure::BadSettings),
            ) => Err(f),
            _ => profile::air_from_points(&pts),
        };
        let zero = io.contact_force(start, io.now_sample());
        match air {
            Ok(a) => {
                self.profile.air = Some(a);
                self.zero = zero;
                if let (Some(cal), Some(z)) = (self.profile.load_cell.as_mut(), zero) {
                    cal.tare = z.counts();
                }
                io.emit(Event::Air(a)).await;
                if self.profile.load_cell.is_some() {
                    self.emit_load_cell(io).await;
                }
                true
            }
            Err(f) => {
                io.emit(Event::Refused(Refusal::Air(f))).await;
                false
            }
        }
    }

    async fn emit_load_cell<I: Io>(&self, io: &mut I) {
        io.emit(Event::LoadCell {
            cal: self.profile.load_cell,
            window: self.profile.force_window,
        })
        .await;
    }

    /// The load cell's sensitivity from the known weight `w` resting on the tip: its counts
    /// over [`WEIGH_S`] with the drive off, against the zero of the last air reference
    /// ([`LoadCellCal::weighed`]). The unit then reads with a load cell.
    async fn weigh<I: Io>(&mut self, io: &mut I, w: Newtons) -> bool {
        let fs = io.scale().sample_rate.0 as f64;
        let start = io.now_sample();
        io.idle((WEIGH_S as f64 * fs) as u64).await;
        let loaded = io.contact_force(start, io.now_sample());
        let cal = self
            .zero
            .zip(loaded)
            .and_then(|(z, l)| LoadCellCal::weighed(&z, &l, w));
        match cal {
            Some(c) => {
                self.profile.load_cell = Some(c);
                self.emit_load_cell(io).await;
                true
            }
            None => {
                io.emit(Event::Refused(Refusal::Weigh)).await;
                false
            }
        }
    }

    /// `stream <seconds> [<segment_s> [<plan_segments>]]`: the continuous tracker
    /// ([`crate::instrument::continuous`]) with the request's configuration
    /// ([`StreamRequest::tracker`], validated before anything runs; refused as a settings error)
    /// and the session's profile, until a reading ends `seconds` after the start. Every reading
    /// is offered to the outside world without waiting ([`Io::try_emit`]): the tracker's plans
    /// and the sample interrupt never wait on a slow host; a reading that finds no room is
    /// dropped and counted (its `seq` is missing from the log). True when any reading was `ok`.
    async fn stream<I: Io>(&mut self, io: &mut I, request: StreamRequest) -> bool {
        let scale = io.scale();
        // Built in place (out of line): not a 4 KiB temporary in the task's frame.
        let mut slot = None;
        if let Err(e) = request
            .tracker()
            .validate_into(&scale, &self.profile, &mut slot)
        {
            let why = Refusal::Settings(CommandError::Settings(e));
            io.emit(Event::Refused(why)).await;
            return false;
        }
        let Some(tracker) = slot.as_mut() else {
            return false;
        };
        let fs = scale.sample_rate.0 as f64;
        let start = io.now_sample() as f64 / fs;
        let end = start + request.seconds.0 as f64;
        let (mut ok, mut dropped) = (0u32, 0u32);
        let _ = io.take_plan_work();
        let readings =
            crate::instrument::continuous::run_with(io, tracker, &self.profile, |io, r| {
                ok += r.reading.status.is_ok() as u32;
                dropped += !io.try_emit(Event::Stream(*r)) as u32;
                (r.t_s.0 as f64) < end
            })
            .await;
        let plan_work = io.take_plan_work();
        io.emit(Event::StreamEnd {
            start: Seconds(start as f32),
            readings,
            ok,
            dropped,
            plan_work,
        })
        .await;
        ok > 0
    }

    /// A reference reading on a phantom of modulus `e` for the calibration fit.
    async fn calibrate_add<I: Io>(&mut self, io: &mut I, e: KPa) -> bool {
        let r = self.reading(io, self.method, self.settings).await;
        io.emit(Event::Reading(r)).await;
        let why = match r.reference(e) {
            Some(x) => match self.refs.push(x) {
                Ok(()) => {
                    io.emit(Event::Reference {
                        modulus: e,
                        reference: x,
                        n: self.refs.len() as u16,
                    })
                    .await;
                    return true;
                }
                Err(_) => Refusal::ReferencesFull,
            },
            None => match r.status {
                Status::Failed(f) if f.is_press() => Refusal::BadReference(f),
                _ => Refusal::NoResonance,
            },
        };
        io.emit(Event::Refused(why)).await;
        false
    }
}
