//! The stability study: every method through every scene of `hal_sim::catalogue`, each reading
//! classified as a correct reading, a correct failure code, a wrong failure code, or a silent
//! wrong number.

use hal_sim::catalogue::Case;
use hal_sim::NoiseScene;
use pzt_probe::board::sim::read;
use pzt_probe::measure::{Method, Reading, Settings};
use pzt_probe::profile::UnitProfile;
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
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
    format!(
        "{}: {} readings ({} scenes × seeds {}–{}); {} reported a modulus, {} of them ({:.1} %) \
         within 3 combined standard uncertainties of the truth, {} a number where none is due; \
         {} correct failure codes, {} wrong failure codes (lost readings)",
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
    )
}
