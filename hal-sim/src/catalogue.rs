//! The stability catalogue: scenes where resonance methods break, each with what a correct
//! probe must answer there — a modulus (within its stated uncertainty) or one of a few failure
//! codes. Each scene switches on only the physics it needs (see [`Scene::layers`]).
//!
//! Failure codes are the firmware's snake_case codes (`no_contact`, `below_range`, ...), kept as
//! strings here so that the simulator does not depend on the firmware crate.

use crate::events::{Drift, ForceChange, Knocks, LiftOff};
use crate::frontend::Mains;
use crate::phantoms;
use crate::scenes::{Fault, NoiseScene, Scene};
use crate::tissue::{SecondMode, Tissue};

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
/// modulus `e_kpa` and Poisson ratio `nu`. The contact stiffness follows the contact modulus, but
/// the tissue's damping and co-moving mass do not (they also depend on `nu` and the density), so
/// this is only the first approximation of what the probe reads; see
/// [`resonance_equivalent_kpa`].
pub fn equivalent_kpa(e_kpa: f64, nu: f64) -> f64 {
    e_kpa * (1.0 - 0.49 * 0.49) / (1.0 - nu * nu)
}

/// Modulus (kPa) of calibration-type tissue (`nu = 0.49`, 1000 kg/m³, 30 mN) whose loaded
/// resonance equals that of `scene`: what a probe calibrated on such tissue reads at best, since
/// the resonance is all it measures. Bisection on the closed-form resonance (monotonic in the
/// modulus) over 1 kPa – 10 MPa; `None` outside that span or without contact.
pub fn resonance_equivalent_kpa(scene: &Scene) -> Option<f64> {
    scene.tissue?;
    let f = scene.resonance_hz();
    let at = |e: f64| Scene::on_modulus_kpa(e).resonance_hz();
    let (mut lo, mut hi) = (1.0f64, 1e4f64);
    if !(f >= at(lo) && f <= at(hi)) {
        return None;
    }
    // Geometric bisection: 60 halvings of a factor of 1e4 leave 1e-14 relative.
    for _ in 0..60 {
        let mid = libm::sqrt(lo * hi);
        if at(mid) < f {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

fn at(e: f64, noise: NoiseScene) -> Scene {
    Scene::on_modulus_kpa(e).with_noise(noise)
}

/// Number of scenes in the catalogue.
pub const SCENES: usize = 31;

/// Rate of the thermal drift scenes: the free resonance moves by 3 Hz in 10 s (about one reading
/// of the paper method, 10.9 s).
pub const DRIFT_HZ_S: f64 = 0.3;

/// The knocks of the `knocks` scene, twice a second: a mechanical knock steps the mode's velocity
/// by about 15 mm/s (twice what the drive gives it at resonance on 300 kPa), an electrical one
/// puts 0.8 nC into the sense input (a 1.8 uA-peak pulse through the anti-alias filter). Both
/// stay below the converter's rails on top of the driven current.
pub const KNOCKS: Knocks = Knocks {
    rate_hz: 2.0,
    velocity_m_s: 15e-3,
    charge_c: 8e-10,
};

/// The catalogue under `noise`.
pub fn catalogue(noise: NoiseScene) -> [Case; SCENES] {
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
    // Lossy tissue: a tumour-like inclusion (docs/physics.md, "Named tissues"), stiff and lossy
    // tissue at the edge of what reads, and lossy tissue with mains hum and with a lift-off.
    let lossy = |e: f64, tan_d: f64| at(e, noise).with_loss_tangent(tan_d);
    let tumour = phantoms::by_name("carcinoma-like").map_or(lossy(490.0, 0.3), |p| {
        Scene::on_phantom(&p).with_noise(noise)
    });
    let mut clipping = nominal;
    clipping.front_end.tia_ohm *= 5.0;
    let open = Fault::OpenPzt.apply(nominal);
    let short = Fault::ShortedPzt.apply(nominal);
    let stuck = Fault::StuckDac.apply(nominal);
    let adc_rail = Fault::AdcRail.apply(nominal);
    // Mains pick-up of 0.1 uA per harmonic (about a tenth of the motional current).
    let mut h50 = [0.0; 8];
    h50[3] = 1e-7; // 200 Hz
    h50[4] = 1e-7; // 250 Hz
    h50[5] = 1e-7; // 300 Hz
    let mut h60 = [0.0; 8];
    h60[3] = 1e-7; // 240 Hz
    h60[4] = 1e-7; // 300 Hz
    let s = phantoms::silicones();
    // Lift-off: the preload falls to nothing in 50 ms (a hand lifting the probe).
    let lift = |at_s: f64| LiftOff { at_s, ramp_s: 0.05 };
    let mains = |fundamental_hz: f64, harmonic_amplitude_a: [f64; 8]| {
        nominal.with_mains(Mains {
            fundamental_hz,
            harmonic_amplitude_a,
        })
    };
    let drift = |rate_hz_s: f64| nominal.with_drift(Drift { rate_hz_s });
    // The paper's second mode (326 Hz) pulled down to 295 Hz, Q 40 (the tissue does not load
    // it), its peak motional conductance half of the first mode's on 300 kPa.
    let mode2 = SecondMode::with_peak_conductance(295.0, 40.0, 0.5 * g_peak);
    const RANGE_LOW: &[&str] = &["below_range", "out_of_band", "no_resonance", "low_snr"];
    const RANGE_HIGH: &[&str] = &["above_range", "out_of_band"];
    // Tissue much lossier than the references reads, or its resonance is too broad to read: a
    // press inside the force window is never `bad_contact` for a low Q.
    const OK_OR_WEAK: &[&str] = &["low_snr", "no_resonance", "broad_resonance"];
    const LIFT_OFF: &[&str] = &["contact_lost", "no_contact", "force_unstable", "too_light"];
    // A press outside the force window, or one that changes during the reading: the load cell
    // says so before the resonance is read as a modulus (a unit without one: the Q model).
    const TOO_LIGHT: &[&str] = &["too_light", "no_contact", "bad_contact"];
    const TOO_HARD: &[&str] = &["too_hard", "bad_contact"];
    const FORCE_MOVES: &[&str] = &["force_unstable", "unstable", "contact_lost", "bad_contact"];
    // A tracker that keeps following a moving resonance says so.
    const DRIFTING: &[&str] = &["not_locked", "unstable"];
    // A second mode ringing with the first makes a ring-down beat as a tone or a knock does.
    const SECOND_MODE: &[&str] = &["interference"];
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
        // Calibrated on nu = 0.49, 1000 kg/m³ tissue, the probe reports the modulus of such
        // tissue with the same resonance: 180.8 kPa (the same contact modulus would be 182.2 kPa,
        // but this silicone's lower nu and higher density also change its damping and mass).
        Case {
            name: "dragon-skin-20",
            what: "190 kPa silicone (nu 0.456, 1080 kg/m³)",
            scene: Scene::on_phantom(&s[2]).with_noise(noise),
            truth_kpa: resonance_equivalent_kpa(&Scene::on_phantom(&s[2])),
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
            what: "300 kPa with loss tangent 0.3",
            scene: Scene::on_tissue(damped_t).with_noise(noise),
            truth_kpa: Some(NOMINAL_KPA),
            accept: OK_OR_WEAK,
        },
        Case {
            name: "lossy-tumour",
            what: "carcinoma-like tissue: 490 kPa, loss tangent 0.3",
            scene: tumour,
            truth_kpa: Some(tumour.tissue.map_or(490.0, |t| t.modulus_pa * 1e-3)),
            accept: OK_OR_WEAK,
        },
        Case {
            name: "lossy-stiff",
            what: "2000 kPa with loss tangent 0.5",
            scene: lossy(2000.0, 0.5),
            truth_kpa: Some(2000.0),
            accept: OK_OR_WEAK,
        },
        Case {
            name: "lossy-mains-50",
            what: "300 kPa with loss tangent 0.3 under the 50 Hz harmonics of mains-50",
            scene: lossy(NOMINAL_KPA, 0.3).with_mains(Mains {
                fundamental_hz: 50.0,
                harmonic_amplitude_a: h50,
            }),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["interference", "low_snr", "broad_resonance"],
        },
        Case {
            name: "lossy-lift-off-0.4s",
            what: "300 kPa with loss tangent 0.3, lifted off at 0.4 s",
            scene: lossy(NOMINAL_KPA, 0.3).with_lift_off(lift(0.4)),
            truth_kpa: Some(NOMINAL_KPA),
            accept: LIFT_OFF,
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
            scene: mains(50.0, h50),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["interference", "low_snr"],
        },
        Case {
            name: "mains-60",
            what: "60 Hz harmonics at 240, 300 Hz, 0.1 uA each",
            scene: mains(60.0, h60),
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
        // Every sample of the sense channel at the rail: what a reading sees is a clipped
        // channel (the power-on self-test names it: `adc_rail_current`).
        Case {
            name: "adc-rail",
            what: "sense ADC stuck at its upper rail",
            scene: adc_rail,
            truth_kpa: None,
            accept: &["clipped"],
        },
        Case {
            name: "preload-60mN",
            what: "300 kPa pressed at 60 mN instead of 30 mN",
            scene: nominal.with_preload_n(0.060),
            truth_kpa: Some(NOMINAL_KPA),
            accept: TOO_HARD,
        },
        Case {
            name: "touch-5mN",
            what: "300 kPa touched at 5 mN, below the force window",
            scene: nominal.with_preload_n(0.005),
            truth_kpa: Some(NOMINAL_KPA),
            accept: TOO_LIGHT,
        },
        Case {
            name: "press-ramp",
            what: "300 kPa, the press rising from 30 to 48 mN over 1 s from 50 ms",
            scene: nominal.with_force_change(ForceChange {
                at_s: 0.05,
                ramp_s: 1.0,
                to_fraction: 1.6,
            }),
            truth_kpa: Some(NOMINAL_KPA),
            accept: FORCE_MOVES,
        },
        Case {
            name: "slip-off-edge",
            what: "300 kPa, the tip sliding down the phantom's edge at 0.1 s: 30 to 9 mN in 30 ms",
            scene: nominal.with_force_change(ForceChange {
                at_s: 0.1,
                ramp_s: 0.03,
                to_fraction: 0.3,
            }),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &[
                "force_unstable",
                "too_light",
                "unstable",
                "contact_lost",
                "bad_contact",
            ],
        },
        // A reading that ends before the lift-off is a valid reading; one that spans it must say
        // the probe is off the tissue (`contact_lost`, or `no_contact` when what it saw was
        // mostly the free probe): never a number.
        Case {
            name: "lift-off-0.4s",
            what: "300 kPa, lifted off at 0.4 s (preload to zero in 50 ms)",
            scene: nominal.with_lift_off(lift(0.4)),
            truth_kpa: Some(NOMINAL_KPA),
            accept: LIFT_OFF,
        },
        Case {
            name: "lift-off-2.5s",
            what: "300 kPa, lifted off at 2.5 s (preload to zero in 50 ms)",
            scene: nominal.with_lift_off(lift(2.5)),
            truth_kpa: Some(NOMINAL_KPA),
            accept: LIFT_OFF,
        },
        Case {
            name: "knocks",
            what: "300 kPa, random knocks twice a second (mechanical 15 mm/s, electrical 0.8 nC)",
            scene: nominal.with_knocks(KNOCKS),
            truth_kpa: Some(NOMINAL_KPA),
            accept: &["interference", "low_snr"],
        },
        // The calibration and the air reference hold at the temperature the reading starts at;
        // the probe's own resonance then drifts. The truth is the tissue's modulus, not what the
        // calibration maps the drifted resonance to: the probe does not know the drift, so it
        // must stay within its stated uncertainty of the truth or fail.
        Case {
            name: "drift-up",
            what: "300 kPa, free resonance drifting +0.3 Hz/s (+3 Hz in 10 s)",
            scene: drift(DRIFT_HZ_S),
            truth_kpa: Some(NOMINAL_KPA),
            accept: DRIFTING,
        },
        Case {
            name: "drift-down",
            what: "300 kPa, free resonance drifting -0.3 Hz/s (-3 Hz in 10 s)",
            scene: drift(-DRIFT_HZ_S),
            truth_kpa: Some(NOMINAL_KPA),
            accept: DRIFTING,
        },
        Case {
            name: "second-mode",
            what: "300 kPa, second mode at 295 Hz (Q 40, half the first mode's peak conductance)",
            scene: nominal.with_second_mode(mode2),
            truth_kpa: Some(NOMINAL_KPA),
            accept: SECOND_MODE,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resonance_equivalent_modulus() {
        // Calibration-type tissue is its own equivalent.
        for e in [50.0, 300.0, 3000.0] {
            let got = resonance_equivalent_kpa(&Scene::on_modulus_kpa(e)).unwrap();
            assert!((got / e - 1.0).abs() < 1e-9, "{e}: {got}");
        }
        // Dragon Skin 20: same resonance, and near (not at) the contact-modulus equivalent.
        let s = phantoms::silicones();
        let d = Scene::on_phantom(&s[2]);
        let e = resonance_equivalent_kpa(&d).unwrap();
        assert!((Scene::on_modulus_kpa(e).resonance_hz() - d.resonance_hz()).abs() < 1e-9);
        let contact = equivalent_kpa(s[2].modulus_kpa, s[2].poisson);
        assert!((e / contact - 1.0).abs() < 0.02, "{e} vs {contact}");
        assert_eq!(resonance_equivalent_kpa(&Scene::free_air()), None);
    }

    /// Every scene has an answer; the scenes of issue 4 switch on exactly their own layer on
    /// top of the nominal scene's.
    #[test]
    fn every_scene_has_an_answer_and_its_own_layers() {
        use crate::Layer;
        let layers = |c: &Case| {
            let mut l = [Layer::Kelvin; Layer::COUNT];
            let n = c.scene.layers(&mut l);
            l[..n].to_vec()
        };
        let cases = catalogue(NoiseScene::Bench);
        let nominal = layers(&cases[0]);
        for c in &cases {
            assert!(c.truth_kpa.is_some() || !c.accept.is_empty(), "{}", c.name);
            let extra = match c.name {
                "lift-off-0.4s" | "lift-off-2.5s" => Some(Layer::LiftOff),
                "press-ramp" | "slip-off-edge" => Some(Layer::ForceChange),
                "knocks" => Some(Layer::Knocks),
                "drift-up" | "drift-down" => Some(Layer::Drift),
                "second-mode" => Some(Layer::SecondMode),
                _ => None,
            };
            if let Some(x) = extra {
                let mut expect = nominal.clone();
                expect.push(x);
                assert_eq!(layers(c), expect, "{}", c.name);
            }
        }
    }
}
