//! The stability study: every method through every scene of `hal_sim::catalogue`, each reading
//! classified as a correct reading, a correct failure code, a wrong failure code, or a silent
//! wrong number.

use hal_sim::catalogue::Case;
use hal_sim::{NoiseScene, Scene};
use pzt_probe::board::sim::{calibrate_unit, read};
use pzt_probe::calibration::{PowerLaw, QModel};
use pzt_probe::measure::{AirReference, Method, Reading, Settings};
use pzt_probe::sweep::SweepSettings;
use pzt_probe::{Hz, Seconds, Status, Volts};

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

/// The free-air reference the firmware stores: a fine sweep-G of the free probe (0.5 Hz steps
/// over 220–245 Hz, 250 ms settling, 2 V drive) at bench noise.
pub fn air_reference() -> Option<AirReference> {
    let s = SweepSettings {
        start: Hz(220.0),
        stop: Hz(245.0),
        step: Hz(0.5),
        settle: Seconds(0.25),
        integrate: Seconds(0.1),
        drive: Volts(2.0),
    };
    let scene = Scene::free_air().with_noise(NoiseScene::Bench);
    let r = read(
        &scene,
        77,
        Method::SweepG,
        &s,
        &PowerLaw::paper_experiment(),
        |_| {},
    )
    .ok()?;
    Some(AirReference {
        free_resonance: r.resonance?,
        free_q: r.q?,
    })
}

/// A unit calibrated for one method: settings, power law, Q(E) curve.
pub struct Unit {
    /// The method's settings.
    pub settings: Settings,
    /// Its calibration.
    pub cal: PowerLaw,
    /// The contact condition of the calibration (methods that measure Q).
    pub q_model: Option<QModel>,
}

/// A method calibrated on A–E × `repeats` at bench noise with its default settings.
pub fn calibrated(method: Method, repeats: usize) -> Option<Unit> {
    let settings = method.default_settings();
    let (cal, q_model) =
        calibrate_unit(method, settings, NoiseScene::Bench, repeats, 700_000).ok()?;
    Some(Unit {
        settings,
        cal,
        q_model,
    })
}

/// One reading of `case` with the contact and condition checks applied, as the firmware would.
pub fn run_case(
    case: &Case,
    method: Method,
    unit: &Unit,
    air: Option<&AirReference>,
    seed: u64,
) -> Option<Reading> {
    read(&case.scene, seed, method, unit.settings, &unit.cal, |_| {})
        .ok()
        .map(|r| r.check_contact(air).check_condition(unit.q_model.as_ref()))
}
