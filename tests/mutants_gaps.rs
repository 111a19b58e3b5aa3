//! Checks that the mutation-testing pass (`docs/testing.md`) found missing: each test here fails
//! for at least one surviving mutant of `src/reading/pipeline.rs`, `src/unit/profile.rs` or
//! `src/unit/calibration.rs` that the other tests let through.
//!
//! References are worked by hand from closed forms, not taken from the crate: paper 003's
//! experimental curve `f = 266.6 − 2305 E^−0.7243` (E in kPa) and its slope
//! `df/dE = b c E^(c−1)`, evaluated here with `f64::powf`; the Q model `Q = q0 + q1 ln E` through
//! two hand-picked points; the stable names the calibration file and the log print.

use pzt_probe::estimate::Estimate;
use pzt_probe::estimate::Resonance;
use pzt_probe::reading::pipeline::conclude;
use pzt_probe::unit::calibration::{RefPoint, Source};
use pzt_probe::unit::q_model::QModel;
use pzt_probe::UnitProfile;
use pzt_probe::{AirReference, Failure, Farads, Hz, Method, PowerLaw, Seconds, Siemens, Status};

/// Paper 003 eq. 5.
const A: f64 = 266.6;
const B: f64 = -2305.0;
const C: f64 = -0.7243;

/// Resonance of the paper's curve at `e` kPa.
fn f_of(e: f64) -> f64 {
    A + B * e.powf(C)
}

/// Its slope `df/dE` (Hz/kPa) at `e` kPa.
fn slope_of(e: f64) -> f64 {
    B * C * e.powf(C - 1.0)
}

/// Q model through (100 kPa, Q 10) and (1000 kPa, Q 20): `q1 = 10 / ln 10`,
/// `q0 = 10 − q1 ln 100 = 10 − 20 = −10`.
fn q_model() -> QModel {
    QModel {
        q0: -10.0,
        q1: 10.0 / std::f64::consts::LN_10,
        q2: 0.0,
        sigma_rel: 0.0,
        damping: None,
    }
}

/// A calibrated unit on the paper's curve, with an air reference at 230 Hz / Q 40 (well away
/// from the 251 Hz a 1000 kPa tissue reads).
fn unit() -> UnitProfile {
    UnitProfile {
        calibration: PowerLaw::paper_experiment(),
        resonance: Resonance::Motional,
        q_model: Some(q_model()),
        air: Some(AirReference {
            free_resonance: Hz(230.0),
            free_q: 40.0,
            static_capacitance: Farads(200e-12),
            static_conductance: Siemens(0.0),
        }),
        contact: None,
        load_cell: None,
        force_window: pzt_probe::loadcell::ForceWindow::DEFAULT,
    }
}

fn estimate(f: f64, sigma: f64, q: Option<f32>) -> Estimate {
    Estimate {
        resonance: Hz(f as f32),
        sigma: Hz(sigma as f32),
        q,
        q_sigma: None,
        points_used: 10,
    }
}

fn status(est: Estimate, unit: &UnitProfile) -> Status {
    conclude(Method::SweepG, Ok(est), unit, Seconds(1.0), 10, None).status
}

/// The verdict on resonance `f` (Hz) with uncertainty `sigma` and quality `q` for [`unit`].
fn verdict(f: f64, sigma: f64, q: Option<f32>) -> Status {
    status(estimate(f, sigma, q), &unit())
}

/// 1000 kPa reads `266.6 − 2305 · 1000^−0.7243 = 251.12 Hz`; the model expects Q 20 there.
#[test]
fn a_good_reading_on_the_curve_gives_its_modulus() {
    let f = f_of(1000.0);
    assert!((f - 251.12).abs() < 0.01, "{f}");
    let r = conclude(
        Method::SweepG,
        Ok(estimate(f, 0.1, Some(20.0))),
        &unit(),
        Seconds(1.0),
        10,
        None,
    );
    assert_eq!(r.status, Status::Ok);
    let m = r.modulus.expect("a modulus").0 as f64;
    assert!((m / 1000.0 - 1.0).abs() < 1e-4, "{m}");
}

/// The repeatability gate: the modulus' own scatter `σ_f / (df/dE)` must stay within 10 % of
/// the modulus. At 1000 kPa the slope is `2305 · 0.7243 · 1000^−1.7243 = 0.011213 Hz/kPa`, so
/// the gate lies at `σ_f = 0.1 · 1000 · 0.011213 = 1.1213 Hz`.
#[test]
fn repeatability_gate_at_ten_percent() {
    let f = f_of(1000.0);
    let s = slope_of(1000.0);
    assert!((s - 0.011213).abs() < 2e-6, "{s}");
    // 1.05 Hz: 93.6 kPa, 9.4 % -> a reading.
    assert_eq!(verdict(f, 1.05, Some(20.0)), Status::Ok);
    // 1.2 Hz: 107 kPa, 10.7 % -> too scattered to place tissue.
    assert_eq!(verdict(f, 1.2, Some(20.0)), Status::Failed(Failure::LowSnr));
    // 20 Hz: 1784 kPa, 178 % of the value.
    assert_eq!(
        verdict(f, 20.0, Some(20.0)),
        Status::Failed(Failure::LowSnr)
    );
}

/// A Q that is not a positive finite number is "Q not resolved" (`low_snr`), never a contact
/// verdict (`bad_contact`) drawn from a meaningless Q.
#[test]
fn unresolved_q_is_low_snr() {
    let f = f_of(1000.0);
    for q in [
        None,
        Some(0.0),
        Some(-20.0),
        Some(f32::INFINITY),
        Some(f32::NAN),
    ] {
        assert_eq!(
            verdict(f, 0.1, q),
            Status::Failed(Failure::LowSnr),
            "q = {q:?}"
        );
    }
}

/// The contact condition: Q within 20 % of the model's `q0 + q1 ln E`. At 1000 kPa the model
/// expects `−10 + (10 / ln 10) · ln 1000 = −10 + 30 = 20`; at 100 kPa, 10.
#[test]
fn contact_condition_holds_within_twenty_percent() {
    let m = q_model();
    assert!((m.q_at(1000.0, None, None) - 20.0).abs() < 1e-12);
    assert!((m.q_at(100.0, None, None) - 10.0).abs() < 1e-12);
    assert!(m.deviation(1000.0, None, 20.0, None).holds());
    assert!(m.deviation(1000.0, None, 23.9, None).holds()); // +19.5 %
    assert!(m.deviation(1000.0, None, 16.1, None).holds()); // −19.5 %
    assert!(!m.deviation(1000.0, None, 24.1, None).holds()); // +20.5 %
    assert!(!m.deviation(1000.0, None, 15.9, None).holds()); // −20.5 %
                                                             // Where the model expects no positive Q (E below e^1 = 2.7 kPa here), nothing holds.
    assert!(m.q_at(2.0, None, None) < 0.0);
    assert!(!m
        .deviation(2.0, None, m.q_at(2.0, None, None), None)
        .holds());

    // Through the pipeline: off-condition contact is `bad_contact`, not a modulus.
    let f = f_of(1000.0);
    assert_eq!(verdict(f, 0.1, Some(23.9)), Status::Ok);
    assert_eq!(
        verdict(f, 0.1, Some(26.0)),
        Status::Failed(Failure::BadContact)
    );
    assert_eq!(
        verdict(f, 0.1, Some(14.0)),
        Status::Failed(Failure::BadContact)
    );
}

/// `QModel::fit` uses only positive `(E, Q)` pairs: through (100, 10) and (1000, 20) it is
/// `q0 = −10`, `q1 = 10 / ln 10`, whatever non-positive pairs come along.
#[test]
fn q_model_fit_ignores_non_positive_pairs() {
    let check = |data: &[(f64, f64)]| {
        let m = QModel::fit(data.iter().map(|&(e, q)| (e, 0.0, q))).expect("two distinct moduli");
        assert!((m.q0 + 10.0).abs() < 1e-9, "{data:?}: q0 {}", m.q0);
        assert!(
            (m.q1 - 10.0 / std::f64::consts::LN_10).abs() < 1e-9,
            "{data:?}: q1 {}",
            m.q1
        );
    };
    check(&[(100.0, 10.0), (1000.0, 20.0)]);
    check(&[(100.0, 10.0), (1000.0, 20.0), (0.0, 15.0)]);
    check(&[(100.0, 10.0), (1000.0, 20.0), (500.0, 0.0)]);
    check(&[(100.0, 10.0), (1000.0, 20.0), (500.0, -3.0)]);
    check(&[(100.0, 10.0), (1000.0, 20.0), (-500.0, 15.0)]);
}

/// The stable names the calibration file (`probe-bench`) and the firmware log print.
#[test]
fn source_names_are_stable() {
    assert_eq!(Source::PaperSimulation.name(), "paper-simulation");
    assert_eq!(Source::PaperExperiment.name(), "paper-experiment");
    assert_eq!(Source::Fitted.name(), "fitted");
}

/// A calibration with more distinct moduli than the fit's distinct-moduli count keeps (64):
/// 70 readings on the paper's curve from 150 to 2450 kPa, exact to `f64`, give back the curve
/// (the count stops at 64 instead of running past its buffer).
#[test]
fn fit_with_more_than_64_distinct_moduli() {
    let data: Vec<RefPoint> = (0..70)
        .map(|k| {
            let e = 150.0 * (2450.0f64 / 150.0).powf(k as f64 / 69.0);
            RefPoint {
                modulus_kpa: e,
                resonance_hz: f_of(e),
                sigma_hz: 0.05,
                force_n: 0.0,
            }
        })
        .collect();
    let fit = PowerLaw::fit(&data).expect("a curve");
    assert!((fit.a - A).abs() < 1e-3, "a {}", fit.a);
    assert!((fit.b / B - 1.0).abs() < 1e-4, "b {}", fit.b);
    assert!((fit.c - C).abs() < 1e-5, "c {}", fit.c);
    // The span is the references' ±10 %: 135 to 2695 kPa.
    assert!((fit.min_kpa - 135.0).abs() < 1e-6, "{}", fit.min_kpa);
    assert!((fit.max_kpa - 2695.0).abs() < 1e-6, "{}", fit.max_kpa);
}

/// A usable curve saturates (`b < 0`, `c < 0`) over a real span (`0 < min < max`): each limit
/// itself is refused, as the store and `invert` rely on.
#[test]
fn curve_validity_limits_are_strict() {
    let good = PowerLaw::paper_experiment();
    assert!(good.is_valid());
    let with = |f: &dyn Fn(&mut PowerLaw)| {
        let mut p = good;
        f(&mut p);
        p.is_valid()
    };
    assert!(!with(&|p| p.b = 0.0));
    assert!(!with(&|p| p.c = 0.0));
    assert!(!with(&|p| p.min_kpa = 0.0));
    assert!(!with(&|p| p.max_kpa = p.min_kpa));
    // A flat curve is bad settings, not a range verdict.
    let mut flat = good;
    flat.b = 0.0;
    assert_eq!(flat.invert(Hz(250.0), Hz(0.1)), Err(Failure::BadSettings));
}

/// The span's ends are vouched for (inclusive). With `f = 256 − 1024 / E` (`c = −1`) every
/// number is a power of two: 240 Hz is `E = 1024 / 16 = 64 kPa` and 192 Hz is `1024 / 64 =
/// 16 kPa`, exactly; with the span set to 16–64 kPa both ends read, their neighbours do not.
#[test]
fn span_ends_are_inclusive() {
    let p = PowerLaw {
        a: 256.0,
        b: -1024.0,
        c: -1.0,
        cov: [[0.0; 3]; 3],
        model_sigma_hz: 0.0,
        min_kpa: 16.0,
        max_kpa: 64.0,
        source: Source::Fitted,
    };
    assert_eq!(p.invert(Hz(240.0), Hz(0.0)).map(|m| m.value.0), Ok(64.0));
    assert_eq!(p.invert(Hz(192.0), Hz(0.0)).map(|m| m.value.0), Ok(16.0));
    // One f32 step beyond: 240.00002 Hz is 64.0001 kPa, 191.99998 Hz 15.99999 kPa.
    assert_eq!(
        p.invert(Hz(f32::from_bits(240.0f32.to_bits() + 1)), Hz(0.0)),
        Err(Failure::AboveRange)
    );
    assert_eq!(
        p.invert(Hz(f32::from_bits(192.0f32.to_bits() - 1)), Hz(0.0)),
        Err(Failure::BelowRange)
    );
}

fn air() -> AirReference {
    AirReference {
        free_resonance: Hz(230.0),
        free_q: 40.0,
        static_capacitance: Farads(200e-12),
        static_conductance: Siemens(0.0),
    }
}

/// An air reference needs a positive finite resonance and Q.
#[test]
fn air_reference_validity() {
    assert!(air().is_valid());
    for (f, q) in [
        (f32::INFINITY, 40.0),
        (0.0, 40.0),
        (-230.0, 40.0),
        (230.0, 0.0),
    ] {
        let a = AirReference {
            free_resonance: Hz(f),
            free_q: q,
            ..air()
        };
        assert!(!a.is_valid(), "f {f} q {q}");
    }
}

/// "Looks free" = Q above 0.6 of the free Q (40 -> 24) *and* resonance within 5 Hz of the free
/// 230 Hz, both strict.
#[test]
fn looks_free_thresholds() {
    let a = air();
    assert!(a.looks_free(Hz(231.0), 30.0)); // Q 30 > 24, 1 Hz off
    assert!(a.looks_free(Hz(225.5), 38.0)); // 4.5 Hz below
    assert!(!a.looks_free(Hz(231.0), 20.0)); // damped: contact
    assert!(!a.looks_free(Hz(250.0), 35.0)); // rings, but 20 Hz above: rigid contact
    assert!(!a.looks_free(Hz(235.0), 35.0)); // exactly 5 Hz: not within
    let q_edge = pzt_probe::unit::profile::NO_CONTACT_Q_FRACTION * a.free_q;
    assert!(!a.looks_free(Hz(230.0), q_edge)); // exactly at the Q fraction: not above
}

/// A profile with a non-finite Q model is not stored.
#[test]
fn profile_with_non_finite_q_model_is_invalid() {
    let mut p = unit();
    assert!(p.is_valid());
    p.q_model = Some(QModel {
        q0: f64::NAN,
        q1: 1.0,
        q2: 0.0,
        sigma_rel: 0.0,
        damping: None,
    });
    assert!(!p.is_valid());
    p.q_model = Some(QModel {
        q0: 1.0,
        q1: f64::INFINITY,
        q2: 0.0,
        sigma_rel: 0.0,
        damping: None,
    });
    assert!(!p.is_valid());
}

/// A reading makes a calibration reference only with a finite resonance and uncertainty and a
/// positive Q; otherwise it is left out (not passed on to fail the whole fit).
#[test]
fn reference_of_a_reading_needs_finite_values_and_positive_q() {
    let reading = |f: f32, s: f32, q: f32| {
        conclude(
            Method::SweepG,
            Ok(Estimate {
                resonance: Hz(f),
                sigma: Hz(s),
                q: Some(q),
                q_sigma: None,
                points_used: 10,
            }),
            &UnitProfile::fallback(),
            Seconds(1.0),
            10,
            None,
        )
    };
    let e = pzt_probe::KPa(1000.0);
    let r = reading(251.1, 0.1, 20.0).reference(e).expect("a reference");
    assert_eq!((r.modulus_kpa, r.q), (1000.0, 20.0));
    for (f, s, q) in [
        (f32::NAN, 0.1, 20.0),
        (f32::INFINITY, 0.1, 20.0),
        (251.1, f32::INFINITY, 20.0),
        (251.1, f32::NAN, 20.0),
        (251.1, 0.1, 0.0),
        (251.1, 0.1, -20.0),
    ] {
        assert_eq!(reading(f, s, q).reference(e), None, "f {f} s {s} q {q}");
    }
}
