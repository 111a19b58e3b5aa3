//! The stability catalogue: scenes where resonance methods break, each with what a correct
//! probe must answer there — a modulus (within its stated uncertainty) or one of a few failure
//! codes. Each scene switches on only the physics it needs (see [`Scene::layers`]).
//!
//! Failure codes are the firmware's snake_case codes (`no_contact`, `below_range`, ...), kept as
//! strings here so that the simulator does not depend on the firmware crate.

use crate::frontend::Mains;
use crate::phantoms;
use crate::scenes::{NoiseScene, Scene};
use crate::tissue::Tissue;

/// One scene of the catalogue.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    /// Short name.
    pub name: &'static str,
    /// What is simulated.
    pub what: &'static str,
    /// The scene.
    pub scene: Scene,
    /// The modulus (kPa) a correct reading reports, if any.
    pub truth_kpa: Option<f64>,
    /// Failure codes that are correct answers here.
    pub accept: &'static [&'static str],
}

const NOMINAL_KPA: f64 = 300.0;

/// Modulus (kPa) of `nu = 0.49` tissue with the same contact modulus `E / (1 - nu^2)` as tissue of
/// modulus `e_kpa` and Poisson ratio `nu`: what a probe calibrated on `nu = 0.49` tissue reads.
pub fn equivalent_kpa(e_kpa: f64, nu: f64) -> f64 {
    e_kpa * (1.0 - 0.49 * 0.49) / (1.0 - nu * nu)
}

fn at(e: f64, noise: NoiseScene) -> Scene {
    Scene::on_modulus_kpa(e).with_noise(noise)
}

/// The catalogue under `noise`.
pub fn catalogue(noise: NoiseScene) -> [Case; 17] {
    let nominal = at(NOMINAL_KPA, noise);
    let k = nominal.kelvin();
    let g_peak = nominal.pzt.motional_peak_s(&k);
    let w0 = 2.0 * core::f64::consts::PI * nominal.resonance_hz();
    let mut c0_dominant = nominal;
    c0_dominant.pzt.c0_f = 10.0 * g_peak / w0;
    let mut leaky = nominal;
    leaky.pzt.leakage_s = 0.3 * g_peak;
    let mut damped_t = Tissue::with_modulus_kpa(NOMINAL_KPA);
    damped_t.loss_tangent = 0.3;
    let mut clipping = nominal;
    clipping.front_end.tia_ohm *= 5.0;
    let mut open = nominal;
    open.pzt.c0_f = 0.0;
    open.pzt.force_factor_n_v = 0.0;
    let mut short = nominal;
    short.pzt.leakage_s = 1e-3;
    let mut stuck = nominal;
    stuck.stuck_dac = Some(crate::frontend::MID_CODE);
    // Mains pick-up of 0.1 uA per harmonic (about a tenth of the motional current).
    let mut h50 = [0.0; 8];
    h50[3] = 1e-7; // 200 Hz
    h50[4] = 1e-7; // 250 Hz
    h50[5] = 1e-7; // 300 Hz
    let mut h60 = [0.0; 8];
    h60[3] = 1e-7; // 240 Hz
    h60[4] = 1e-7; // 300 Hz
    let s = phantoms::silicones();
    const RANGE_LOW: &[&str] = &["below_range", "out_of_band", "no_resonance", "low_snr"];
    const RANGE_HIGH: &[&str] = &["above_range", "out_of_band"];
    // A much lossier tissue than the references is outside the calibrated contact condition.
    const OK_OR_WEAK: &[&str] = &["low_snr", "no_resonance", "bad_contact"];
    [
        Case {
            name: "nominal",
            what: "300 kPa tissue, 30 mN",
            scene: nominal,
            truth_kpa: Some(NOMINAL_KPA),
            accept: &[],
        },
        Case {
            name: "free-air",
            what: "no contact",
            scene: Scene::free_air().with_noise(noise),
            truth_kpa: None,
            accept: &["no_contact"],
        },
        Case {
            name: "ecoflex-00-10",
            what: "8.2 kPa (paper 001/002), below the calibrated span",
            scene: Scene::on_phantom(&s[0]).with_noise(noise),
            truth_kpa: None,
            accept: RANGE_LOW,
        },
        Case {
            name: "ecoflex-00-30",
            what: "28.6 kPa, below the calibrated span",
            scene: Scene::on_phantom(&s[1]).with_noise(noise),
            truth_kpa: None,
            accept: RANGE_LOW,
        },
        // The probe senses the contact modulus E / (1 - nu^2); calibrated on nu = 0.49 tissue it
        // reports the modulus of nu = 0.49 tissue of the same contact modulus.
        Case {
            name: "dragon-skin-20",
            what: "190 kPa silicone (nu 0.456)",
            scene: Scene::on_phantom(&s[2]).with_noise(noise),
            truth_kpa: Some(equivalent_kpa(s[2].modulus_kpa, s[2].poisson)),
            accept: &[],
        },
        Case {
            name: "hard-5mpa",
            what: "5 MPa, above the calibrated span",
            scene: at(5000.0, noise),
            truth_kpa: None,
            accept: RANGE_HIGH,
        },
        Case {
            name: "rigid",
            what: "rigid contact",
            scene: at(1e9, noise),
            truth_kpa: None,
            accept: RANGE_HIGH,
        },
        Case {
            name: "heavy-damping",
            what: "300 kPa with loss tangent 0.3 (Q about 3)",
            scene: Scene::on_tissue(damped_t).with_noise(noise),
            truth_kpa: Some(NOMINAL_KPA),
            accept: OK_OR_WEAK,
        },
        Case {
            name: "c0-dominant",
            what: "motional current a tenth of the capacitive",
            scene: c0_dominant,
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["clipped"],
        },
        Case {
            name: "dielectric-loss",
            what: "leakage 0.3 of the motional peak conductance",
            scene: leaky,
            truth_kpa: Some(NOMINAL_KPA),
            accept: &[],
        },
        Case {
            name: "mains-50",
            what: "50 Hz harmonics at 200, 250, 300 Hz, 0.1 uA each",
            scene: nominal.with_mains(Mains {
                fundamental_hz: 50.0,
                harmonic_amplitude_a: h50,
            }),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["interference", "low_snr"],
        },
        Case {
            name: "mains-60",
            what: "60 Hz harmonics at 240, 300 Hz, 0.1 uA each",
            scene: nominal.with_mains(Mains {
                fundamental_hz: 60.0,
                harmonic_amplitude_a: h60,
            }),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["interference", "low_snr"],
        },
        Case {
            name: "clipping",
            what: "transimpedance gain 5x: the ADC clips",
            scene: clipping,
            truth_kpa: None,
            accept: &["clipped"],
        },
        Case {
            name: "open-pzt",
            what: "PZT disconnected",
            scene: open,
            truth_kpa: None,
            accept: &["open_circuit"],
        },
        Case {
            name: "shorted-pzt",
            what: "PZT shorted through 1 kOhm",
            scene: short,
            truth_kpa: None,
            accept: &["short_circuit", "clipped", "drive_fault"],
        },
        Case {
            name: "dac-stuck",
            what: "DAC stuck at mid-scale",
            scene: stuck,
            truth_kpa: None,
            accept: &["drive_fault"],
        },
        Case {
            name: "preload-60mN",
            what: "300 kPa pressed at 60 mN instead of 30 mN",
            scene: nominal.with_preload_n(0.060),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["bad_contact"],
        },
    ]
}
