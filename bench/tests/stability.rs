//! The stability catalogue: the default strategy (`auto`: hold, falling back to fit, then sweep-G) reports
//! a modulus within 3 of its stated standard uncertainties in at least 99 % of its ok readings
//! over every scene, and never a number where none is due; fit never reports a silent wrong
//! number, sweep-G only under within-reading drift (its 6 s sweep). Where they fail with a code
//! the scene does not list (a lost reading, not a wrong one), the count is bounded.

use hal_sim::catalogue::catalogue;
use hal_sim::{NoiseScene, Scene};
use probe_bench::stability::{
    calibrated, classify, run_case, statement, tally, Outcome, FIRST_SEED,
};
use pzt_probe::{Failure, Method, Status};

/// The statement for the firmware's default strategy, over the whole catalogue: 40
/// seeds per scene give about 300 ok readings, so 99 % allows at most 3 beyond 3 σ.
#[test]
fn the_default_strategy_is_within_three_sigma_in_99_percent_of_its_readings() {
    let unit = calibrated(Method::Auto, 10).expect("calibration");
    let cases = catalogue(NoiseScene::Bench);
    let seeds = 40;
    let t = tally(&cases, Method::Auto, &unit, seeds);
    println!("{}", statement(Method::Auto, &t, cases.len(), seeds));
    assert_eq!(t.readings, cases.len() * seeds as usize);
    assert!(t.ok >= 100, "{t:?}");
    assert!(t.within_fraction() >= 0.99, "{t:?}");
    assert_eq!(t.ok_without_truth, 0, "{t:?}");
    // No lost reading: mains hum, which pulled hold's Q off the Q(E) curve (bad_contact) or
    // towards the free Q (no_contact) in 15 of the 80 mains readings, is now seen turning in the
    // hold fit's residuals (`interference::hum`), and a press that moved during the reading is
    // reported as such (`force_unstable`) whatever the estimator made of it.
    assert_eq!(t.wrong_failures, 0, "{t:?}");
}

#[test]
fn sweep_g_and_fit_never_report_a_silent_wrong_number_but_sweep_g_under_drift() {
    for m in [Method::SweepG, Method::Fit] {
        let unit = calibrated(m, 10).expect("calibration");
        // The free probe: 232.3 Hz and Q 40 in hal-sim.
        let air = unit.profile.air.expect("air reference");
        assert!(
            (air.free_resonance.0 - 232.3).abs() < 0.5 && (air.free_q / 40.0 - 1.0).abs() < 0.1
        );
        let mut wrong_codes = 0;
        let mut readings = 0;
        for case in catalogue(NoiseScene::Bench) {
            for seed in FIRST_SEED..FIRST_SEED + 3 {
                let r = run_case(&case, m, &unit, seed).expect("reading");
                readings += 1;
                let o = classify(&case, &r);
                // A wrong failure code is a lost reading, not a wrong one; count it.
                if o == Outcome::WrongFailure {
                    wrong_codes += 1;
                }
                // sweep-G's 6 s sweep passes the resonance 3 s in: 0.9 Hz of drift at 0.3 Hz/s,
                // 3–4 of its stated σ (docs/methods.md).
                let drift = case.name.starts_with("drift-");
                if m == Method::SweepG && drift {
                    continue;
                }
                // fit under mains hum: a known limitation, bounded in
                // `fit_under_mains_hum_is_a_bounded_known_limitation`.
                if m == Method::Fit && case.name.starts_with("mains-") {
                    continue;
                }
                assert_ne!(
                    o,
                    Outcome::SilentWrong,
                    "{} on {}: {:?}",
                    m.name(),
                    case.name,
                    r
                );
            }
        }
        // 24 scenes × 3 seeds: at most the dielectric-leakage and mains scenes lose readings.
        println!(
            "{}: {wrong_codes} wrong failure codes of {readings} readings",
            m.name()
        );
        assert!(
            wrong_codes <= 9,
            "{}: {wrong_codes} wrong failure codes",
            m.name()
        );
    }
}

/// The detectors end to end: knocks end fit's readings as `interference` (or leave them
/// within 3 σ), mains hum most of them, a lift-off between its stages as `contact_lost`.
#[test]
fn fit_names_interference_and_lost_contact() {
    let unit = calibrated(Method::Fit, 10).expect("calibration");
    let cases = catalogue(NoiseScene::Bench);
    let case = |n: &str| cases.iter().find(|c| c.name == n).expect(n);
    for seed in FIRST_SEED..FIRST_SEED + 5 {
        let r = run_case(case("knocks"), Method::Fit, &unit, seed).unwrap();
        if r.status != Status::Failed(Failure::Interference) {
            assert_eq!(classify(case("knocks"), &r), Outcome::Correct, "{r:?}");
        }
    }
    // mains-60 puts 240 Hz within a linewidth of the resonance: most readings see it (9 of these
    // 10; the rest: `fit_under_mains_hum_is_a_bounded_known_limitation`).
    let interference = (FIRST_SEED..FIRST_SEED + 10)
        .filter(|&seed| {
            let r = run_case(case("mains-60"), Method::Fit, &unit, seed).unwrap();
            r.status == Status::Failed(Failure::Interference)
        })
        .count();
    println!("fit on mains-60: {interference} of 10 interference");
    assert!(interference >= 7, "{interference}");
    for seed in FIRST_SEED..FIRST_SEED + 5 {
        let r = run_case(case("lift-off-0.4s"), Method::Fit, &unit, seed).unwrap();
        assert_eq!(r.status, Status::Failed(Failure::ContactLost), "{r:?}");
    }
}

/// fit under mains hum, a known limitation: a harmonic within a linewidth of the resonance
/// biases some of its readings by 3–5 of their stated σ. Its misfit test asks the χ² that white
/// residuals exceed once in ten thousand (`interference::chi2_limit_per_dof`): over 40 seeds
/// mains-50 0 and mains-60 1 silent wrong numbers. The one left scatters at 2.9 its stated σ² per degree of freedom (limit 4.3)
/// but 0.9 % of the admittance: the hum also inflates each point's own σ. Bounded here at 2 a
/// scene so that it cannot grow unseen; the default strategy reads both scenes without one
/// (`the_default_strategy_…`).
#[test]
fn fit_under_mains_hum_is_a_bounded_known_limitation() {
    let unit = calibrated(Method::Fit, 10).expect("calibration");
    let cases = catalogue(NoiseScene::Bench);
    for name in ["mains-50", "mains-60"] {
        let case = cases.iter().find(|c| c.name == name).expect(name);
        let silent = (FIRST_SEED..FIRST_SEED + 40)
            .filter(|&seed| {
                let r = run_case(case, Method::Fit, &unit, seed).unwrap();
                classify(case, &r) == Outcome::SilentWrong
            })
            .count();
        println!("fit on {name}: {silent} silent wrong numbers of 40");
        assert!(silent <= 2, "fit on {name}: {silent} of 40");
    }
}

#[test]
fn contact_is_told_by_q_not_by_frequency() {
    let unit = calibrated(Method::SweepG, 10).expect("calibration");
    let air = unit.profile.air.expect("air reference");
    let (s, profile) = (unit.settings, unit.profile);
    // Tissue whose loaded resonance equals the free one (about 330 kPa in hal-sim).
    let mut e = 300.0;
    while Scene::on_modulus_kpa(e).resonance_hz() < air.free_resonance.0 as f64 {
        e += 1.0;
    }
    let scene = Scene::on_modulus_kpa(e).with_noise(NoiseScene::Bench);
    assert!((scene.resonance_hz() - air.free_resonance.0 as f64).abs() < 0.2);
    let r = pzt_probe::board::sim::read(&scene, 9, Method::SweepG, s, &profile, |_| {}).unwrap();
    assert_eq!(r.status, Status::Ok, "{e} kPa in contact: {r:?}");
    let free = pzt_probe::board::sim::read(
        &Scene::free_air().with_noise(NoiseScene::Bench),
        9,
        Method::SweepG,
        s,
        &profile,
        |_| {},
    )
    .unwrap();
    assert_eq!(free.status, Status::Failed(Failure::NoContact));
    assert!(free.modulus.is_none());
}
