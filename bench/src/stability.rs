//! The stability study: every method through every scene of `hal_sim::catalogue`, each reading
//! classified as a correct reading, a correct failure code, a wrong failure code, or a silent
//! wrong number; and the continuous mode's scenes ([`stream_catalogue`]), each stream's
//! readings classed the same way and the stream checked against what it must do ([`Must`]).

use crate::scene::Target;
use crate::stream::{settled_after, summarize, StreamScene, Streamed};
use hal_sim::catalogue::Case;
use hal_sim::{phantoms, ForceChange, LiftOff, NoiseScene};
use pzt_probe::board::sim::read;
use pzt_probe::instrument::continuous::{StreamReading, TrackerConfig};
use pzt_probe::reading::{Method, Reading, Settings};
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::Status;

/// How one reading turned out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    /// A modulus within 3 stated standard uncertainties of the truth.
    Correct,
    /// One of the failure codes the scene accepts.
    CorrectFailure,
    /// A failure code, but not one the scene accepts (or a failure where a reading was due).
    WrongFailure,
    /// A modulus where none was due, or one further than 3 σ from the truth.
    SilentWrong,
}

impl Outcome {
    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Correct => "correct",
            Outcome::CorrectFailure => "correct-failure",
            Outcome::WrongFailure => "wrong-failure",
            Outcome::SilentWrong => "silent-wrong",
        }
    }
}

/// Classify `r` against what `case` expects.
pub fn classify(case: &Case, r: &Reading) -> Outcome {
    match r.status {
        Status::Ok => match (case.truth_kpa, r.modulus, r.modulus_sigma) {
            (Some(t), Some(e), Some(s)) if (e.0 as f64 - t).abs() <= 3.0 * s.0 as f64 => {
                Outcome::Correct
            }
            _ => Outcome::SilentWrong,
        },
        Status::Failed(f) => {
            if case.accept.contains(&f.code()) {
                Outcome::CorrectFailure
            } else {
                Outcome::WrongFailure
            }
        }
    }
}

/// A unit calibrated for one method: the method's settings and the unit's whole profile
/// (calibration, Q model, air reference).
pub struct Unit {
    /// The method's settings.
    pub settings: Settings,
    /// The unit's profile, made by the core's procedure.
    pub profile: UnitProfile,
}

/// A method's unit: the simulated unit's air reference, then A–E × `repeats` at bench noise
/// with the method's default settings.
pub fn calibrated(method: Method, repeats: usize) -> Option<Unit> {
    let settings = method.default_settings();
    let profile =
        crate::unit::simulated(method, &settings, NoiseScene::Bench, repeats, 700_000).ok()?;
    Some(Unit { settings, profile })
}

/// One reading of `case` through the one pipeline, as the firmware and `measure` take it.
pub fn run_case(case: &Case, method: Method, unit: &Unit, seed: u64) -> Option<Reading> {
    read(
        &case.scene,
        seed,
        method,
        unit.settings,
        &unit.profile,
        |_| {},
    )
    .ok()
}

/// What one method did over the catalogue: its readings counted by outcome.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Tally {
    /// Readings made.
    pub readings: usize,
    /// Readings that reported a modulus (`ok`).
    pub ok: usize,
    /// Of those, the ones within 3 combined standard uncertainties of the truth.
    pub ok_within_3_sigma: usize,
    /// Of those, the ones in a scene where no modulus is due (a number where none exists).
    pub ok_without_truth: usize,
    /// Failure codes the scene accepts.
    pub correct_failures: usize,
    /// Failure codes it does not accept (lost readings).
    pub wrong_failures: usize,
    /// The lost readings, by scene and code: how many of each.
    pub lost: Vec<(&'static str, &'static str, usize)>,
}

impl Tally {
    /// Count one reading of `case`.
    pub fn add(&mut self, case: &Case, r: &Reading) {
        self.readings += 1;
        match (r.status, case.truth_kpa) {
            (Status::Ok, None) => {
                self.ok += 1;
                self.ok_without_truth += 1;
            }
            (Status::Ok, Some(_)) => {
                self.ok += 1;
                if classify(case, r) == Outcome::Correct {
                    self.ok_within_3_sigma += 1;
                }
            }
            (Status::Failed(_), _) => {
                if classify(case, r) == Outcome::CorrectFailure {
                    self.correct_failures += 1;
                } else {
                    self.wrong_failures += 1;
                    let code = r.status.code();
                    match self
                        .lost
                        .iter_mut()
                        .find(|(s, c, _)| *s == case.name && *c == code)
                    {
                        Some(l) => l.2 += 1,
                        None => self.lost.push((case.name, code, 1)),
                    }
                }
            }
        }
    }

    /// Fraction of the `ok` readings within 3 combined standard uncertainties of the truth (1
    /// when there are none).
    pub fn within_fraction(&self) -> f64 {
        if self.ok == 0 {
            1.0
        } else {
            self.ok_within_3_sigma as f64 / self.ok as f64
        }
    }
}

/// Seeds of the readings: the map's cells and the default strategy's statement use
/// `FIRST_SEED, FIRST_SEED + 1, ...`.
pub const FIRST_SEED: u64 = 5000;

/// `method` (calibrated as `unit`) through every case in `cases`, noise seeds
/// `FIRST_SEED .. FIRST_SEED + seeds`, through the one pipeline.
pub fn tally(cases: &[Case], method: Method, unit: &Unit, seeds: u64) -> Tally {
    let mut t = Tally::default();
    for case in cases {
        for seed in FIRST_SEED..FIRST_SEED + seeds {
            if let Some(r) = run_case(case, method, unit, seed) {
                t.add(case, &r);
            }
        }
    }
    t
}

/// The statement for `method`: how many readings reported a modulus over `scenes`
/// scenes × `seeds` seeds, how many of those lie within 3 of their stated standard
/// uncertainties, and how many are numbers where none is due.
pub fn statement(method: Method, t: &Tally, scenes: usize, seeds: u64) -> String {
    let lost: Vec<String> = t
        .lost
        .iter()
        .map(|(s, c, n)| format!("{s} {c} ×{n}"))
        .collect();
    let lost = if lost.is_empty() {
        String::new()
    } else {
        format!(": {}", lost.join(", "))
    };
    format!(
        "{}: {} readings ({} scenes × seeds {}–{}); {} reported a modulus, {} of them ({:.1} %) \
         within 3 combined standard uncertainties of the truth, {} a number where none is due; \
         {} correct failure codes, {} wrong failure codes (lost readings{})",
        method.name(),
        t.readings,
        scenes,
        FIRST_SEED,
        FIRST_SEED + seeds.max(1) - 1,
        t.ok,
        t.ok_within_3_sigma,
        100.0 * t.within_fraction(),
        t.ok_without_truth,
        t.correct_failures,
        t.wrong_failures,
        lost,
    )
}

/// What a stream must do in a continuous scene (times in probe time, s; tolerances fractions
/// of the truth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Must {
    /// No `ok` reading ends in `[from_s, to_s)`.
    NoOk {
        /// Start, s.
        from_s: f64,
        /// End, s (infinite: to the end of the stream).
        to_s: f64,
    },
    /// Every reading from `within_s` after `at_s` until the truth's next change is ok and
    /// within `tol` of the truth.
    Settle {
        /// The event, s.
        at_s: f64,
        /// Time allowed, s.
        within_s: f64,
        /// Tolerance, a fraction.
        tol: f64,
    },
    /// Every reading ending from `from_s` on reports `code`.
    Code {
        /// Start, s.
        from_s: f64,
        /// The status code.
        code: &'static str,
    },
    /// After the first [`STREAM_SETTLE_S`]: at least `min_ok_per_s` ok readings a second, their
    /// RMS error at most `max_rms` and none off the truth by more than `max_err`.
    Rate {
        /// Ok readings per second.
        min_ok_per_s: f64,
        /// RMS error, a fraction.
        max_rms: f64,
        /// Largest error of one ok reading, a fraction.
        max_err: f64,
    },
}

/// The stream's figures count the readings that end after this probe time, s; before it (the
/// acquisition) any failure code is a correct one.
pub use crate::stream::SETTLE_S as STREAM_SETTLE_S;

impl Must {
    /// What it asks, for people.
    pub fn describe(&self) -> String {
        match *self {
            Must::NoOk { from_s, to_s } if to_s.is_infinite() => {
                format!("no `ok` from {from_s} s on")
            }
            Must::NoOk { from_s, to_s } => format!("no `ok` in {from_s}–{to_s} s"),
            Must::Settle {
                at_s: 0.0,
                within_s,
                tol,
            } => format!(
                "every reading ok within {} % of the truth from {within_s} s until the first event",
                100.0 * tol
            ),
            Must::Settle {
                at_s,
                within_s,
                tol,
            } => format!(
                "every reading ok within {} % of the new truth from {within_s} s after {at_s} s",
                100.0 * tol
            ),
            Must::Code { from_s, code } => format!("`{code}` from {from_s} s on"),
            Must::Rate {
                min_ok_per_s,
                max_rms,
                max_err,
            } => format!(
                "≥ {min_ok_per_s} ok readings/s after {STREAM_SETTLE_S} s, RMS ≤ {} %, none off by > {} %",
                100.0 * max_rms,
                100.0 * max_err
            ),
        }
    }

    /// Whether stream `s` does it, and the figure measured: `NoOk` the number of ok readings in
    /// the span, `Settle` the time from the event until every reading is within the tolerance
    /// (s; infinite: never), `Code` the number of readings from `from_s` on with another
    /// status, `Rate` ok readings per second (the RMS and the worst error are
    /// [`crate::stream::Summary`]'s).
    pub fn check(&self, s: &Streamed) -> (bool, f64) {
        let t = |r: &StreamReading| r.t_s.0 as f64;
        let ok = |r: &StreamReading| r.reading.status == Status::Ok;
        match *self {
            Must::NoOk { from_s, to_s } => {
                let n = s
                    .readings
                    .iter()
                    .filter(|r| (from_s..to_s).contains(&t(r)) && ok(r))
                    .count();
                (n == 0, n as f64)
            }
            Must::Settle {
                at_s,
                within_s,
                tol,
            } => {
                let d = settled_after(&s.readings, &s.truth, at_s, tol)
                    .map_or(f64::INFINITY, |x| x - at_s);
                (d <= within_s, d)
            }
            Must::Code { from_s, code } => {
                let n = s
                    .readings
                    .iter()
                    .filter(|r| t(r) >= from_s && r.reading.status.code() != code)
                    .count();
                (n == 0, n as f64)
            }
            Must::Rate {
                min_ok_per_s,
                max_rms,
                max_err,
            } => {
                let m = summarize(&s.readings, &s.truth, STREAM_SETTLE_S);
                let met = m.ok_per_s >= min_ok_per_s
                    && m.rms_rel.is_some_and(|x| x <= max_rms)
                    && m.worst_rel.is_some_and(|x| x <= max_err);
                (met, m.ok_per_s)
            }
        }
    }
}

/// One scene of the continuous mode: a stream with events on the way and what it must do.
#[derive(Clone, Debug)]
pub struct StreamCase {
    /// Short name.
    pub name: &'static str,
    /// The scene and its events.
    pub scene: StreamScene,
    /// Probe time streamed, s.
    pub seconds: f64,
    /// What the stream must do.
    pub must: Vec<Must>,
    /// Failure codes that are correct answers in `[accept_from_s, accept_to_s)`, s (before
    /// [`STREAM_SETTLE_S`] any code is; elsewhere a failure is a lost reading, except within
    /// the time a [`Must::Settle`] allows after its event).
    pub accept: &'static [&'static str],
    /// Start of the span where `accept` applies, s.
    pub accept_from_s: f64,
    /// Its end, s.
    pub accept_to_s: f64,
}

impl StreamCase {
    /// The `probe-bench stream` options that run it (with `--seed`).
    pub fn args(&self) -> Vec<String> {
        let mut v = self.scene.args();
        v.extend(["--seconds".to_owned(), format!("{}", self.seconds)]);
        v
    }

    /// Stream it with the default tracker, unit `unit`, noise seed `seed` (through
    /// [`crate::stream::run`], as `probe-bench stream` does).
    pub fn run(&self, unit: &UnitProfile, seed: u64) -> anyhow::Result<Streamed> {
        crate::stream::run(
            &self.scene,
            &TrackerConfig::DEFAULT,
            unit,
            seed,
            self.seconds,
            |_| {},
        )
    }

    /// The outcome of reading `r` of stream `s`, as the single-reading map classes a reading:
    /// an `ok` within 3 of its combined standard uncertainties of the truth under the probe at
    /// the start or the end of the reading's probe time is correct, any other `ok` (beyond
    /// 3 σ, or with no tissue under the probe) a silent wrong number; a failure code is correct
    /// during the acquisition, where the case accepts it, or while a [`Must::Settle`] allows
    /// the stream to find the new truth — a lost reading elsewhere.
    pub fn classify(&self, s: &Streamed, r: &StreamReading) -> Outcome {
        let end = r.t_s.0 as f64;
        let start = end - r.reading.probe_time.0 as f64;
        match r.reading.status {
            Status::Ok => {
                let within = |truth: Option<f64>| match (
                    truth,
                    r.reading.modulus,
                    r.reading.modulus_sigma,
                ) {
                    (Some(t), Some(e), Some(sg)) => (e.0 as f64 - t).abs() <= 3.0 * sg.0 as f64,
                    _ => false,
                };
                if within(s.truth.at(start)) || within(s.truth.at(end)) {
                    Outcome::Correct
                } else {
                    Outcome::SilentWrong
                }
            }
            Status::Failed(f) => {
                let settling = self.must.iter().any(|m| match *m {
                    Must::Settle { at_s, within_s, .. } => (at_s..at_s + within_s).contains(&end),
                    _ => false,
                });
                let accepted = (self.accept_from_s..self.accept_to_s).contains(&end)
                    && self.accept.contains(&f.code());
                if end <= STREAM_SETTLE_S || settling || accepted {
                    Outcome::CorrectFailure
                } else {
                    Outcome::WrongFailure
                }
            }
        }
    }

    /// Stream `s` judged: its readings counted by outcome, and each [`Must`] with whether it
    /// was met and its figure ([`Must::check`]).
    pub fn judge(&self, s: &Streamed) -> StreamVerdict {
        let mut counts = [0usize; 4];
        for r in &s.readings {
            counts[self.classify(s, r) as usize] += 1;
        }
        StreamVerdict {
            counts,
            checks: self.must.iter().map(|m| m.check(s)).collect(),
        }
    }
}

/// How one stream of a [`StreamCase`] turned out.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamVerdict {
    /// Its readings by [`Outcome`] (indexed by `Outcome as usize`).
    pub counts: [usize; 4],
    /// Each of the case's [`Must`]s: met, and its figure.
    pub checks: Vec<(bool, f64)>,
}

impl StreamVerdict {
    /// True when the stream did everything the case asks.
    pub fn met(&self) -> bool {
        self.checks.iter().all(|c| c.0)
    }
}

/// The continuous-mode scenes (issue 14): phantom C streamed steadily, lifted off (at once and
/// with the preload falling over 50 ms), lifted off and put down again, a step from B to D,
/// the tip slipping down an edge, a creeping press, knocks — each with what the stream must do
/// (the figures: no `ok` later than 0.1 s after the tip leaves the tissue, within 3 %
/// of the new truth 0.25 s after a step or a new contact, ≥ 20 ok readings/s within 1 % RMS).
pub fn stream_catalogue(noise: NoiseScene) -> Vec<StreamCase> {
    let ph = |n: &str| phantoms::by_name(n).expect("a phantom or a named tissue");
    let c = StreamScene::on(Target::Phantom(ph("C")), noise);
    let lossy = StreamScene::on(Target::Phantom(ph("carcinoma-like")), noise);
    // Lifted off at 1.5 s at once.
    let lifted = |s: StreamScene| StreamScene {
        lift_off: Some(LiftOff {
            at_s: 1.5,
            ramp_s: 0.0,
        }),
        ..s
    };
    let steady = Must::Rate {
        min_ok_per_s: 20.0,
        max_rms: 0.01,
        max_err: 0.03,
    };
    const LIFTED: &[&str] = &[
        "no_contact",
        "contact_lost",
        "bad_contact",
        "force_unstable",
        "too_light",
        "not_locked",
    ];
    const PRESS_MOVES: &[&str] = &[
        "force_unstable",
        "unstable",
        "contact_lost",
        "bad_contact",
        "not_locked",
    ];
    const SLIPPED: &[&str] = &[
        "force_unstable",
        "too_light",
        "unstable",
        "contact_lost",
        "bad_contact",
        "not_locked",
    ];
    let inf = f64::INFINITY;
    // Streamed 3 s with nothing happening: the steady rate and accuracy, no failure accepted.
    let held_steady = |name, scene| StreamCase {
        name,
        scene,
        seconds: 3.0,
        must: vec![steady],
        accept: &[],
        accept_from_s: 0.0,
        accept_to_s: 0.0,
    };
    vec![
        held_steady("steady", c),
        StreamCase {
            name: "lift-off",
            scene: lifted(c),
            seconds: 2.5,
            must: vec![
                Must::NoOk {
                    from_s: 1.6,
                    to_s: inf,
                },
                Must::Settle {
                    at_s: 0.0,
                    within_s: STREAM_SETTLE_S,
                    tol: 0.03,
                },
            ],
            accept: LIFTED,
            accept_from_s: 1.5,
            accept_to_s: inf,
        },
        StreamCase {
            name: "lift-off-ramp",
            scene: StreamScene {
                lift_off: Some(LiftOff {
                    at_s: 1.5,
                    ramp_s: 0.05,
                }),
                ..c
            },
            seconds: 2.5,
            must: vec![Must::NoOk {
                from_s: 1.65,
                to_s: inf,
            }],
            accept: LIFTED,
            accept_from_s: 1.5,
            accept_to_s: inf,
        },
        StreamCase {
            name: "new-contact",
            scene: StreamScene {
                lift_off: Some(LiftOff {
                    at_s: 1.0,
                    ramp_s: 0.0,
                }),
                touch_at_s: Some(2.0),
                ..c
            },
            seconds: 3.0,
            must: vec![
                Must::NoOk {
                    from_s: 1.1,
                    to_s: 2.0,
                },
                Must::Settle {
                    at_s: 2.0,
                    within_s: 0.25,
                    tol: 0.03,
                },
            ],
            accept: LIFTED,
            accept_from_s: 1.0,
            accept_to_s: 2.0,
        },
        StreamCase {
            name: "step-b-d",
            scene: StreamScene {
                step: Some((ph("D"), 1.5)),
                ..StreamScene::on(Target::Phantom(ph("B")), noise)
            },
            seconds: 3.0,
            must: vec![
                Must::Settle {
                    at_s: 0.0,
                    within_s: STREAM_SETTLE_S,
                    tol: 0.03,
                },
                Must::Settle {
                    at_s: 1.5,
                    within_s: 0.25,
                    tol: 0.03,
                },
            ],
            accept: &[],
            accept_from_s: 0.0,
            accept_to_s: 0.0,
        },
        StreamCase {
            name: "slip-off-edge",
            scene: StreamScene {
                press: Some(ForceChange {
                    at_s: 1.0,
                    ramp_s: crate::stream::DEFAULT_PRESS_RAMP_S,
                    to_fraction: 0.3,
                }),
                ..c
            },
            seconds: 2.0,
            must: vec![
                // A reading that ends before the load cell's first conversion after the slip
                // began (12.5 ms at 80 SPS) has nothing that could tell it from a steady press
                // (its estimate is of the press before: 7.5 ms of a 38 ms segment measured);
                // from then on, no ok.
                Must::NoOk {
                    from_s: 1.0 + 1.0 / hal_sim::loadcell::LoadCell::default().rate_hz,
                    to_s: inf,
                },
                Must::Code {
                    from_s: 1.2,
                    code: "too_light",
                },
            ],
            accept: SLIPPED,
            accept_from_s: 1.0,
            accept_to_s: inf,
        },
        StreamCase {
            name: "creeping-press",
            scene: StreamScene {
                press: Some(ForceChange {
                    at_s: 1.0,
                    ramp_s: 0.5,
                    to_fraction: 1.5,
                }),
                ..c
            },
            seconds: 2.0,
            must: vec![
                Must::NoOk {
                    from_s: 1.15,
                    to_s: 1.45,
                },
                Must::Settle {
                    at_s: 1.5,
                    within_s: 0.1,
                    tol: 0.03,
                },
            ],
            accept: PRESS_MOVES,
            accept_from_s: 1.0,
            accept_to_s: 1.6,
        },
        StreamCase {
            name: "knocks",
            scene: StreamScene {
                knocks_hz: Some(2.0),
                ..c
            },
            seconds: 3.0,
            must: vec![steady],
            // As the single-reading `knocks` scene.
            accept: &["interference", "low_snr"],
            accept_from_s: 0.0,
            accept_to_s: inf,
        },
        // Lossy tissue (a tumour-like inclusion, docs/physics.md): followed as steadily, and
        // left as promptly, as the lossless phantom.
        held_steady("lossy-steady", lossy),
        StreamCase {
            name: "lossy-lift-off",
            scene: lifted(lossy),
            seconds: 2.5,
            must: vec![Must::NoOk {
                from_s: 1.6,
                to_s: inf,
            }],
            accept: LIFTED,
            accept_from_s: 1.5,
            accept_to_s: inf,
        },
        // Tissue softer than the band: its resonance lies below the tracker's band, where a hold
        // whose bursts lie in the band hears too little to tell it from noise. Every reading
        // names the cause, as a single reading does.
        StreamCase {
            name: "below-band",
            scene: StreamScene::on(Target::Phantom(ph(BELOW_BAND)), noise),
            seconds: 2.0,
            must: vec![Must::Code {
                from_s: 0.0,
                code: "out_of_band",
            }],
            accept: &["out_of_band"],
            accept_from_s: 0.0,
            accept_to_s: inf,
        },
    ]
}

/// The tissue of the `below-band` stream scene: Krouskop's breast fat, whose resonance at 30 mN
/// lies below the tracker's band (`bench/tests/stream.rs` checks it against the simulator).
pub const BELOW_BAND: &str = "fat-like";
