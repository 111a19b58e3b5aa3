//! The session on the simulated probe, through the command parser, as a user drives the
//! firmware: a fresh unit refuses to read; `air` in free air, `calibrate add` on phantoms A–E,
//! `calibrate fit`, `store`; after a reboot (a new session on what the store loads) phantom B
//! reads within 3 % of its modulus; `air` while touching tissue is refused; a method switch
//! applies; free air reads `no_contact`.
//!
//! References: the phantoms' moduli (paper 003's samples, the scene's ground truth).

use hal_sim::flash::SimFlash;
use hal_sim::{phantoms, NoiseScene, Phantom, Scene, SimProbe};
use pzt_probe::board::sim::SimBoard;
use pzt_probe::boot::BootError;
use pzt_probe::engine::{PointPlan, PointRaw, SampleEngine};
use pzt_probe::hal::{FrontEndScale, SampleStream};
use pzt_probe::instrument::command::parse;
use pzt_probe::instrument::selftest::SelfTestReport;
use pzt_probe::instrument::session::{Event, Io, Refusal, Session};
use pzt_probe::reading::driver::{block_on, PointSource, SyncSource, Wanted};
use pzt_probe::unit::store::{Saved, Store, StoreError};
use pzt_probe::{Failure, Method, Status, UnitProfile};

type Flash = SimFlash<4096, 2048, 8>;

/// The simulated board: probe, engine, store, and the events seen.
struct SimIo {
    board: SimBoard,
    engine: SampleEngine,
    store: Store<Flash>,
    events: Vec<Event>,
    /// The bring-up step the board reports as failed.
    boot: Option<BootError>,
    /// Room for events offered without waiting (`None`: always room): a slow host.
    room: Option<usize>,
    /// A second window that closed in the batch of the last one a source returned.
    held: Option<PointRaw>,
}

impl SimIo {
    fn new(flash: Flash) -> Self {
        let scene = Scene::free_air().with_noise(NoiseScene::Bench);
        Self {
            board: SimBoard::new(SimProbe::new(scene, 11)),
            engine: SampleEngine::new(),
            store: Store::new(flash, 0).expect("store geometry"),
            events: Vec::new(),
            boot: None,
            room: None,
            held: None,
        }
    }
    /// A fresh board whose store holds the simulated unit's factory profile (as the QEMU
    /// image boots with).
    fn with_factory() -> Self {
        let mut io = Self::new(Flash::new());
        let p = pzt_probe::board::sim_factory::profile().expect("factory profile");
        io.store.save(&p).expect("store the factory profile");
        io
    }
    fn put_on(&mut self, scene: Scene) {
        self.board
            .probe
            .set_scene(scene.with_noise(NoiseScene::Bench));
    }
    fn source(&mut self) -> SyncSource<'_, SimBoard> {
        SyncSource::new(&mut self.board, &mut self.engine)
    }
}

impl PointSource for SimIo {
    fn scale(&self) -> FrontEndScale {
        self.board.scale()
    }
    fn now_sample(&self) -> u64 {
        self.engine.samples()
    }
    async fn load(&mut self, plan: PointPlan) -> bool {
        self.source().load(plan).await
    }
    async fn next(&mut self, wanted: &Wanted, budget: u64) -> Option<PointRaw> {
        // The second window of a batch, kept from the last call's source.
        let held = self.held.take();
        let mut src = self.source();
        src.held = held;
        let got = src.next(wanted, budget).await;
        let held = src.held.take();
        self.held = held;
        got
    }
    async fn stop(&mut self) {
        self.source().stop().await
    }
    async fn idle(&mut self, samples: u64) {
        self.source().idle(samples).await
    }
    fn contact_force(&mut self, from: u64, to: u64) -> Option<pzt_probe::loadcell::RawForce> {
        pzt_probe::loadcell::ForceSource::contact_force(&self.board, from, to)
    }
    async fn point(&mut self, tag: u16, point: &pzt_probe::engine::sweep::SweepPoint) {
        self.events.push(Event::Point { tag, point: *point });
    }
}

impl Io for SimIo {
    async fn emit(&mut self, e: Event) {
        self.events.push(e);
    }
    fn try_emit(&mut self, e: Event) -> bool {
        match self.room.as_mut() {
            Some(0) => false,
            Some(n) => {
                *n -= 1;
                self.events.push(e);
                true
            }
            None => {
                self.events.push(e);
                true
            }
        }
    }
    fn save(&mut self, p: &UnitProfile) -> Result<Saved, StoreError> {
        self.store.save(p)
    }
    fn load_profile(&mut self) -> pzt_probe::unit::store::Loaded {
        self.store.load()
    }
    fn boot_error(&self) -> Option<BootError> {
        self.boot
    }
}

/// Serve `line` through the parser and the session.
fn send(s: &mut Session, io: &mut SimIo, line: &str) -> bool {
    let cmd = parse(line.as_bytes(), &io.scale()).unwrap_or_else(|e| panic!("{line}: {e:?}"));
    block_on(s.handle(cmd, io))
}

/// The report of the first self-test the board saw (the boot's).
fn first_selftest(io: &SimIo) -> Option<SelfTestReport> {
    io.events.iter().find_map(|e| match e {
        Event::SelfTest(r) => Some(*r),
        _ => None,
    })
}

fn last_reading(io: &SimIo) -> pzt_probe::Reading {
    io.events
        .iter()
        .rev()
        .find_map(|e| match e {
            Event::Reading(r) => Some(*r),
            _ => None,
        })
        .expect("a reading")
}

fn boot(io: &mut SimIo) -> Session {
    Session::new(&io.store.load())
}

const CAL: [Phantom; 5] = [
    phantoms::A,
    phantoms::B,
    phantoms::C,
    phantoms::D,
    phantoms::E,
];

#[test]
fn a_user_session_from_fresh_unit_to_stored_profile_and_back() {
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    assert!(s.profile().air.is_none() && s.profile().q_model.is_none());

    // A fresh unit on tissue: no air reference, no number — and the hint says what to do.
    io.put_on(Scene::on_phantom(&phantoms::B));
    assert!(!send(&mut s, &mut io, "measure"));
    let r = last_reading(&io);
    assert_eq!(r.status, Status::Failed(Failure::NoAirReference), "{r:?}");
    assert!(r.modulus.is_none());
    assert_eq!(
        io.events.last(),
        Some(&Event::Hint(Failure::NoAirReference))
    );

    // The air reference taken touching the tissue is refused (Q far below a free probe's).
    assert!(!send(&mut s, &mut io, "air"));
    assert!(
        matches!(io.events.last(), Some(Event::Refused(Refusal::Air(_)))),
        "{:?}",
        io.events.last()
    );
    assert!(s.profile().air.is_none());

    // In free air it is taken: the free probe (232.3 Hz, Q 40 in hal-sim).
    io.put_on(Scene::free_air());
    assert!(send(&mut s, &mut io, "air"));
    let air = s.profile().air.expect("air reference");
    assert!((air.free_resonance.0 - 232.3).abs() < 0.1, "{air:?}");
    assert!((air.free_q / 40.0 - 1.0).abs() < 0.05, "{air:?}");

    // Still uncalibrated: the resonance is read, the modulus refused.
    io.put_on(Scene::on_phantom(&phantoms::B));
    assert!(!send(&mut s, &mut io, "measure"));
    assert_eq!(
        last_reading(&io).status,
        Status::Failed(Failure::Uncalibrated)
    );

    // Calibrate on A–E, three readings each, with the default method.
    for p in CAL {
        io.put_on(Scene::on_phantom(&p));
        for _ in 0..3 {
            assert!(
                send(&mut s, &mut io, &format!("calibrate add {}", p.modulus_kpa)),
                "{}: {:?}",
                p.name,
                io.events.last()
            );
        }
    }
    assert!(send(&mut s, &mut io, "calibrate fit"));
    assert!(s.profile().q_model.is_some());
    assert!(send(&mut s, &mut io, "store"));
    assert!(matches!(io.events.last(), Some(Event::Saved(_))));

    // An unsaved change is discarded by `reload`...
    assert!(send(&mut s, &mut io, "calibrate paper"));
    assert!(send(&mut s, &mut io, "reload"));
    assert_eq!(
        s.profile().calibration.source,
        pzt_probe::unit::calibration::Source::Fitted
    );
    // ... and a reboot is a new session on what the store loads.
    let mut s = boot(&mut io);
    assert!(s.profile().air.is_some() && s.profile().q_model.is_some());
    io.put_on(Scene::on_phantom(&phantoms::B));
    assert!(send(&mut s, &mut io, "measure"), "{:?}", last_reading(&io));
    let r = last_reading(&io);
    let e = r.modulus.expect("modulus").0 as f64;
    assert!((e / 279.0 - 1.0).abs() <= 0.03, "{e} kPa");
    assert_eq!(r.method, Method::Hold, "auto's first stage");

    // A method switch applies to the next reading.
    assert!(send(&mut s, &mut io, "method sweep-g"));
    assert!(send(&mut s, &mut io, "measure"));
    assert_eq!(last_reading(&io).method, Method::SweepG);
    assert!(matches!(
        io.events.iter().rev().nth(1),
        Some(Event::Point { .. })
    ));

    // Lifted into free air: no contact, not a number.
    assert!(send(&mut s, &mut io, "method auto"));
    io.put_on(Scene::free_air());
    assert!(!send(&mut s, &mut io, "measure"));
    assert_eq!(last_reading(&io).status, Status::Failed(Failure::NoContact));
}

#[test]
fn settings_that_do_not_suit_the_method_are_refused() {
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    // auto takes two-stage settings; a stepped sweep is refused and the settings stay.
    assert!(!send(&mut s, &mut io, "sweep 200 260 2 0.02 0.03 5"));
    assert!(matches!(
        io.events.last(),
        Some(Event::Refused(Refusal::Settings(_)))
    ));
    assert!(send(&mut s, &mut io, "status"));
    match io.events.last() {
        Some(Event::Status(st)) => {
            assert_eq!(st.method, Method::Auto);
            assert!(st.fallback && !st.air && !st.q_model);
        }
        e => panic!("{e:?}"),
    }
}

#[test]
fn help_lists_every_method_and_the_default() {
    let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
    assert_eq!(pzt_probe::reading::METHOD_NAMES, names.join(","));
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    assert!(send(&mut s, &mut io, "help"));
    assert_eq!(io.events.last(), Some(&Event::Help));
    assert_eq!(s.method(), pzt_probe::reading::DEFAULT_METHOD);
}

/// An air reference taken while the drive does not follow the command (a DAC stuck at mid
/// scale) is refused as `drive_fault` and leaves the profile's air reference as it was.
#[test]
fn air_with_a_stuck_drive_is_refused_as_a_drive_fault() {
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    io.put_on(Scene::free_air());
    io.board.probe.set_stuck_dac(Some(2048));
    assert!(!send(&mut s, &mut io, "air"));
    assert_eq!(
        io.events.last(),
        Some(&Event::Refused(Refusal::Air(Failure::DriveFault))),
        "{:?}",
        io.events.last()
    );
    assert!(s.profile().air.is_none());
    // With the drive back, the same command takes it.
    io.board.probe.set_stuck_dac(None);
    assert!(send(&mut s, &mut io, "air"), "{:?}", io.events.last());
    assert!(s.profile().air.is_some());
}

/// Power-on with a fault: the self-test at boot names it, every reading (`measure`, `air`,
/// `calibrate add`) is refused with its message and no reading is taken, `status` shows it;
/// the other commands are served. Once the fault is gone a `selftest` passes and phantom B
/// reads within 3 % again. Each fault scene of `hal-sim` ends in its own fault.
#[test]
fn a_failed_selftest_refuses_every_reading_until_one_passes() {
    use hal_sim::{Fault, StuckAdc};
    use pzt_probe::instrument::selftest::{Channel, SelfTestFault};
    for fault in Fault::ALL {
        let mut io = SimIo::with_factory();
        io.put_on(fault.apply(Scene::on_phantom(&phantoms::B)));
        let b = fault.apply(Scene::on_phantom(&phantoms::B));
        io.board.probe.set_stuck_dac(b.stuck_dac);
        io.board.probe.set_stuck_adc(b.stuck_adc);
        let mut s = block_on(Session::boot(&mut io));
        let want = match fault {
            Fault::OpenPzt => SelfTestFault::OpenPzt,
            Fault::ShortedPzt => SelfTestFault::ShortedPzt,
            Fault::StuckDac => SelfTestFault::NoDrive,
            Fault::AdcRail => SelfTestFault::AdcRail(Channel::Current),
        };
        let report = first_selftest(&io);
        assert_eq!(
            report.map(|r| r.outcome),
            Some(Err(want)),
            "{}",
            fault.name()
        );
        assert_eq!(s.selftest_outcome(), Some(Err(want)));
        for line in ["measure", "air", "calibrate add 279"] {
            let before = io.events.len();
            assert!(!send(&mut s, &mut io, line), "{line}");
            assert_eq!(
                &io.events[before..],
                &[Event::Refused(Refusal::SelfTest(want))],
                "{}: {line}",
                fault.name()
            );
        }
        assert!(!Refusal::SelfTest(want).message().is_empty());
        // Other commands are served; status shows the fault.
        assert!(send(&mut s, &mut io, "method sweep-g"));
        assert!(send(&mut s, &mut io, "status"));
        assert!(matches!(
            io.events.last(),
            Some(Event::Status(st)) if st.selftest == Some(Err(want))
        ));
        // `reload` keeps the verdict on the hardware; a self-test on the faulty probe fails
        // again.
        assert!(send(&mut s, &mut io, "reload"));
        assert_eq!(s.selftest_outcome(), Some(Err(want)));
        assert!(!send(&mut s, &mut io, "selftest"));
        // Repaired: the self-test passes and readings are served again.
        io.put_on(Scene::on_phantom(&phantoms::B));
        io.board.probe.set_stuck_dac(None);
        io.board.probe.set_stuck_adc(None::<StuckAdc>);
        assert!(send(&mut s, &mut io, "selftest"), "{:?}", io.events.last());
        assert_eq!(s.selftest_outcome(), Some(Ok(())));
        assert!(send(&mut s, &mut io, "method auto"));
        assert!(send(&mut s, &mut io, "measure"), "{:?}", last_reading(&io));
        let e = last_reading(&io).modulus.expect("modulus").0 as f64;
        assert!((e / 279.0 - 1.0).abs() <= 0.03, "{}: {e} kPa", fault.name());
    }
}

/// Power-on on a healthy probe: the self-test passes against the stored air reference and
/// readings are served.
#[test]
fn boot_selftest_passes_on_a_healthy_probe() {
    let mut io = SimIo::with_factory();
    io.put_on(Scene::on_phantom(&phantoms::B));
    let mut s = block_on(Session::boot(&mut io));
    assert_eq!(s.selftest_outcome(), Some(Ok(())));
    let r = first_selftest(&io).expect("a self-test event");
    assert!(r.expected.from_air);
    assert!(send(&mut s, &mut io, "measure"), "{:?}", last_reading(&io));
}

/// A fresh unit (no air reference) whose plate is 30 % above the nominal 210 pF fails the
/// boot self-test on its capacitance: `measure` is refused, but `air` is served (the chain
/// works; the air reference re-measures C0), and the self-test then passes against it.
#[test]
fn a_capacitance_fault_lets_the_air_reference_be_retaken() {
    use pzt_probe::instrument::selftest::SelfTestFault;
    let mut io = SimIo::new(Flash::new());
    let mut plate = Scene::free_air();
    plate.pzt.c0_f *= 1.3;
    io.put_on(plate);
    let mut s = block_on(Session::boot(&mut io));
    assert_eq!(s.selftest_outcome(), Some(Err(SelfTestFault::Capacitance)));
    assert!(!send(&mut s, &mut io, "measure"));
    assert_eq!(
        io.events.last(),
        Some(&Event::Refused(Refusal::SelfTest(
            SelfTestFault::Capacitance
        )))
    );
    assert!(send(&mut s, &mut io, "air"), "{:?}", io.events.last());
    let c0 = s.profile().air.expect("air reference").static_capacitance.0 as f64;
    assert!((c0 / (1.3 * 210e-12) - 1.0).abs() < 0.01, "{c0:e} F");
    assert!(send(&mut s, &mut io, "selftest"), "{:?}", io.events.last());
    assert_eq!(s.selftest_outcome(), Some(Ok(())));
}

/// A board whose bring-up left it without its sample stream refuses every reading, `air`,
/// `calibrate add` and `selftest` with the failed step's typed error and message (not the
/// self-test's `no_samples`), serves the other commands and shows the step in `status`; a
/// failed step that leaves the stream running (the store's flash) refuses no reading.
#[test]
fn a_failed_boot_step_is_named_in_refusals_and_status() {
    for e in BootError::ALL {
        let mut io = SimIo::with_factory();
        io.put_on(Scene::on_phantom(&phantoms::B));
        io.boot = Some(e);
        let mut s = Session::new(&io.store.load());
        for line in ["measure", "air", "calibrate add 279", "selftest"] {
            let before = io.events.len();
            let served = send(&mut s, &mut io, line);
            if e.blocks_readings() {
                assert!(!served, "{e:?}: {line}");
                assert_eq!(
                    &io.events[before..],
                    &[Event::Refused(Refusal::Boot(e))],
                    "{e:?}: {line}"
                );
                assert_eq!(Refusal::Boot(e).message(), e.message());
            } else {
                assert!(
                    !io.events[before..]
                        .iter()
                        .any(|ev| matches!(ev, Event::Refused(Refusal::Boot(_)))),
                    "{e:?}: {line} is not refused for the boot error"
                );
            }
        }
        assert!(send(&mut s, &mut io, "method sweep-g"), "{e:?}");
        assert!(send(&mut s, &mut io, "status"), "{e:?}");
        assert!(
            matches!(io.events.last(), Some(Event::Status(st)) if st.boot == Some(e)),
            "{e:?}: {:?}",
            io.events.last()
        );
    }
    // A board that came up: `status` says so.
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    assert!(send(&mut s, &mut io, "status"));
    assert!(matches!(
        io.events.last(),
        Some(Event::Status(st)) if st.boot.is_none()
    ));
}

/// The load cell of a fresh unit, through the commands: `weigh` before any air reference has
/// no zero and is refused; `air` in free air tares the cell, `weigh 10` with 10 g resting on the
/// tip gives its sensitivity (the simulated cell's 3.6e6 counts/N, within the creep it carries
/// under the weight: 0.5 % at most); from then on every reading carries its contact force (here
/// 30 mN within 2 %: the cell's noise and drift), and `force 20 40` narrows the window, so that a
/// 15 mN press is `too_light`.
#[test]
fn the_load_cell_is_weighed_tared_and_bounds_the_readings() {
    let mut io = SimIo::new(Flash::new());
    let mut s = boot(&mut io);
    assert!(s.profile().load_cell.is_none());
    let weight = Scene::on_modulus_kpa(2.0e8).with_preload_n(10.0 * 9.806_65e-3);
    io.put_on(weight);
    assert!(!send(&mut s, &mut io, "weigh 10"));
    assert_eq!(
        io.events.last(),
        Some(&Event::Refused(Refusal::Weigh)),
        "no zero before an air reference"
    );

    io.put_on(Scene::free_air());
    assert!(send(&mut s, &mut io, "air"));
    io.put_on(weight);
    assert!(send(&mut s, &mut io, "weigh 10"), "{:?}", io.events.last());
    let cal = s.profile().load_cell.expect("a load cell calibration");
    let rel = cal.newtons_per_count as f64 * 3.6e6 - 1.0;
    assert!((-0.006..=0.001).contains(&rel), "{cal:?}");
    assert!(matches!(
        io.events.last(),
        Some(Event::LoadCell { cal: Some(_), .. })
    ));

    io.put_on(Scene::on_phantom(&phantoms::B));
    send(&mut s, &mut io, "measure");
    let r = last_reading(&io);
    let f = r.force.expect("the contact force").mean.0 as f64;
    assert!((f / 0.030 - 1.0).abs() <= 0.02, "{f} N");

    assert!(send(&mut s, &mut io, "force 20 40"));
    let w = s.profile().force_window;
    assert!(
        (w.min.0 - 0.020).abs() < 1e-8 && (w.max.0 - 0.040).abs() < 1e-8,
        "{w:?}"
    );
    io.put_on(Scene::on_phantom(&phantoms::B).with_preload_n(0.015));
    assert!(!send(&mut s, &mut io, "measure"));
    assert_eq!(last_reading(&io).status, Status::Failed(Failure::TooLight));
}

fn stream_events(
    io: &SimIo,
) -> (
    Vec<pzt_probe::instrument::continuous::StreamReading>,
    Option<Event>,
) {
    let readings = io
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Stream(r) => Some(*r),
            _ => None,
        })
        .collect();
    let end = io
        .events
        .iter()
        .rev()
        .find(|e| matches!(e, Event::StreamEnd { .. }))
        .copied();
    (readings, end)
}

/// `stream 1` on phantom C: numbered readings without gaps, ok within 1 % of the truth after
/// the acquisition, until a reading ends a second after the start; the end says how many.
#[test]
fn stream_serves_numbered_readings_until_its_time_is_up() {
    let mut io = SimIo::with_factory();
    let mut s = boot(&mut io);
    io.put_on(Scene::on_phantom(&phantoms::C));
    assert!(send(&mut s, &mut io, "stream 1"));
    let (rs, end) = stream_events(&io);
    let Some(Event::StreamEnd {
        start,
        readings,
        ok,
        dropped,
        ..
    }) = end
    else {
        panic!("no stream end: {:?}", io.events.last());
    };
    assert_eq!(dropped, 0);
    assert_eq!(readings as usize, rs.len());
    for (k, r) in rs.iter().enumerate() {
        assert_eq!(r.seq as usize, k);
    }
    let last = rs.last().expect("readings").t_s.0;
    assert!(
        last >= start.0 + 1.0 && last < start.0 + 1.1,
        "{start:?} {last}"
    );
    let oks: Vec<_> = rs.iter().filter(|r| r.reading.status.is_ok()).collect();
    assert_eq!(ok as usize, oks.len());
    assert!(oks.len() >= 20, "{} ok of {}", oks.len(), rs.len());
    for r in &oks {
        let e = r.reading.modulus.expect("ok has a modulus").0 as f64;
        assert!((e / phantoms::C.modulus_kpa - 1.0).abs() < 0.03, "{r:?}");
    }
}

/// A slow host: the session offers each stream reading without waiting; those that find no
/// room are dropped and counted, the stream goes on.
#[test]
fn stream_drops_and_counts_readings_a_slow_host_has_no_room_for() {
    let mut io = SimIo::with_factory();
    let mut s = boot(&mut io);
    io.put_on(Scene::on_phantom(&phantoms::C));
    io.room = Some(5);
    send(&mut s, &mut io, "stream 0.5");
    let (rs, end) = stream_events(&io);
    assert_eq!(rs.len(), 5);
    let Some(Event::StreamEnd {
        readings, dropped, ..
    }) = end
    else {
        panic!("no stream end");
    };
    assert!(readings > 5, "{readings}");
    assert_eq!(dropped, readings - 5);
}

/// A failed self-test refuses a stream as it refuses a reading.
#[test]
fn stream_is_refused_while_the_selftest_fails() {
    let mut io = SimIo::with_factory();
    let mut s = boot(&mut io);
    io.board
        .probe
        .set_scene(hal_sim::Fault::OpenPzt.apply(Scene::free_air()));
    assert!(!send(&mut s, &mut io, "selftest"));
    assert!(!send(&mut s, &mut io, "stream 1"));
    assert!(matches!(
        io.events.last(),
        Some(Event::Refused(Refusal::SelfTest(_)))
    ));
}

/// `stream`'s tracker settings outside the tracker's ranges (`TrackerConfig::validate`: segment
/// 8–1000 ms, 1–8 segments a plan) are refused as settings before any reading is taken.
#[test]
fn stream_tracker_settings_out_of_range_are_refused_before_it_runs() {
    use pzt_probe::engine::sweep::SettingsError;
    use pzt_probe::instrument::command::CommandError;
    let mut io = SimIo::with_factory();
    let mut s = boot(&mut io);
    for line in [
        "stream 1 0.005",
        "stream 1 1.5",
        "stream 1 0.012 0",
        "stream 1 0.012 9",
    ] {
        let before = io.events.len();
        assert!(!send(&mut s, &mut io, line), "{line}");
        let new = io.events.get(before..).unwrap_or_default();
        assert!(
            matches!(
                new,
                [Event::Refused(Refusal::Settings(CommandError::Settings(
                    SettingsError::KnobOutOfRange
                )))]
            ),
            "{line}: {new:?}"
        );
    }
}
