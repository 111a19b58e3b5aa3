//! Unit tests of the continuous mode's tracker.

use super::*;
use crate::dsp::lockin::LockInSums;
use crate::unit::profile::AirReference;
use crate::units::{Farads, Siemens};

include!("../../../tests/support/arbitrary_window.rs");

fn unit() -> UnitProfile {
    UnitProfile {
        air: Some(AirReference {
            free_resonance: Hz(232.3),
            free_q: 40.0,
            static_capacitance: Farads(210e-12),
            static_conductance: Siemens(1e-9),
        }),
        ..UnitProfile::fallback()
    }
}

/// What a fit of more windows adds to one of fewer is what the new windows measure: two
/// independent measurements `A`, `B` fused in covariance form (`x = x_A + K (x_B − x_A)`,
/// `K = C_A (C_A + C_B)⁻¹`, `C = (I − K) C_A`) are the fit of all; the difference with `A`
/// gives back `B`.
#[test]
fn added_information_is_the_new_windows_measurement() {
    let a = Measurement {
        f0: 238.10,
        q: 10.4,
        cov: Sym2 {
            a: 4e-3,
            b: 0.02,
            c: 0.25,
        },
        t: 1.0,
    };
    let b = Measurement {
        f0: 238.16,
        q: 10.1,
        cov: Sym2 {
            a: 9e-4,
            b: -0.004,
            c: 0.36,
        },
        t: 1.0,
    };
    let m = |s: &Sym2| [[s.a as f64, s.b as f64], [s.b as f64, s.c as f64]];
    let (ca, cb) = (m(&a.cov), m(&b.cov));
    let s = [
        [ca[0][0] + cb[0][0], ca[0][1] + cb[0][1]],
        [ca[1][0] + cb[1][0], ca[1][1] + cb[1][1]],
    ];
    let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
    let si = [
        [s[1][1] / det, -s[0][1] / det],
        [-s[1][0] / det, s[0][0] / det],
    ];
    let k: [[f64; 2]; 2] = core::array::from_fn(|i| {
        core::array::from_fn(|j| ca[i][0] * si[0][j] + ca[i][1] * si[1][j])
    });
    let d = [b.f0 - a.f0, b.q - a.q];
    let x = [
        a.f0 + k[0][0] * d[0] + k[0][1] * d[1],
        a.q + k[1][0] * d[0] + k[1][1] * d[1],
    ];
    let c: [[f64; 2]; 2] = core::array::from_fn(|i| {
        core::array::from_fn(|j| ca[i][j] - (k[i][0] * ca[0][j] + k[i][1] * ca[1][j]))
    });
    let all = Measurement {
        f0: x[0],
        q: x[1],
        cov: Sym2 {
            a: c[0][0] as f32,
            b: (0.5 * (c[0][1] + c[1][0])) as f32,
            c: c[1][1] as f32,
        },
        t: 1.0,
    };
    let got = added_information(&all, &a).unwrap();
    // To 1e-6 of the σ and of the covariance (`f32`: the worst case measured is 2e-7; the f32
    // rounding of `all`'s covariance alone is 6e-8).
    let (sf, sq) = ((b.cov.a as f64).sqrt(), (b.cov.c as f64).sqrt());
    assert!(
        (got.f0 - b.f0).abs() < 1e-6 * sf && (got.q - b.q).abs() < 1e-6 * sq,
        "{got:?}"
    );
    assert!((got.cov.a / b.cov.a - 1.0).abs() < 2e-6, "{got:?}");
    assert!((got.cov.b / b.cov.b - 1.0).abs() < 2e-6, "{got:?}");
    assert!((got.cov.c / b.cov.c - 1.0).abs() < 2e-6, "{got:?}");
    // Nothing added (the same fit twice): no measurement.
    assert!(added_information(&a, &a).is_none());
}

#[test]
fn knobs_out_of_range_are_refused() {
    let scale = FrontEndScale::PROBE;
    let d = TrackerConfig::DEFAULT;
    assert!(d.validate(&scale, &unit()).is_ok());
    for bad in [
        TrackerConfig {
            segment: Seconds(f32::NAN),
            ..d
        },
        TrackerConfig {
            segment: Seconds(0.005),
            ..d
        },
        TrackerConfig {
            plan_segments: 0,
            ..d
        },
        TrackerConfig {
            plan_segments: 9,
            ..d
        },
        TrackerConfig { drift: 0.0, ..d },
        TrackerConfig {
            q_drift: f32::INFINITY,
            ..d
        },
        TrackerConfig { dither: 2.5, ..d },
        TrackerConfig { q_prior: 0.0, ..d },
        TrackerConfig { lost_after: 0, ..d },
        TrackerConfig {
            acquire_hold: Seconds(0.05),
            ..d
        },
        TrackerConfig {
            drive: Volts(1e3),
            ..d
        },
    ] {
        assert!(bad.validate(&scale, &unit()).is_err(), "{bad:?}");
    }
}

/// Arbitrary demodulator sums (a small xorshift generator): whatever the windows hold, the
/// tracker never panics, asks for a plan after every reading, and numbers its readings
/// from 0 without gaps, each concluded (a failure or a reading with a resonance).
#[test]
fn arbitrary_windows_never_panic_and_readings_have_no_gaps() {
    for cfg in [
        TrackerConfig::DEFAULT,
        TrackerConfig {
            segment: Seconds(0.012),
            plan_segments: 4,
            ..TrackerConfig::DEFAULT
        },
    ] {
        arbitrary_windows(cfg);
    }
}

fn arbitrary_windows(cfg: TrackerConfig) {
    let scale = FrontEndScale::PROBE;
    let unit = unit();
    let mut t = cfg.validate(&scale, &unit).unwrap();
    let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
    let mut sample = 0u64;
    let mut expect = 0u32;
    for _ in 0..400 {
        let plan = t.next_plan().expect("a plan after every reading or plan");
        for w in 0..plan.windows.max(1) {
            sample += 100;
            let raw = arbitrary_window(&mut next, plan, w, sample, true);
            if let Some(r) = t.accept(&raw, &scale, &unit, |_, _| None) {
                assert_eq!(r.seq, expect);
                expect += 1;
                assert!(r.t_s.0 >= 0.0);
                assert!(r.reading.status != Status::Ok || r.reading.modulus.is_some());
                if !t.plan_running() {
                    break;
                }
            }
        }
    }
    assert_eq!(t.emitted(), expect);
    std::eprintln!("{expect} readings");
    assert!(expect >= 100, "{expect} readings of 400 plans");
}
