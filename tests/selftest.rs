//! The power-on self-test (src/instrument/selftest.rs) on the simulated probe: every contact the probe can
//! be in at power-on passes against the unit's air reference, every fault scene of `hal-sim`
//! ends in its own typed fault, and the measured capacitance agrees with the closed-form
//! admittance of the scene.
//!
//! References: `hal_sim::Scene::admittance` (the plate's closed-form Butterworth–Van Dyke
//! admittance, independent of the converters, the engine and the demodulation) and the
//! simulated unit's factory profile (its air reference, taken by the firmware's own `air`
//! procedure).

use hal_sim::{phantoms, AdcChannel, Fault, NoiseScene, Scene, SimProbe, StuckAdc};
use pzt_probe::board::sim::SimBoard;
use pzt_probe::engine::SampleEngine;
use pzt_probe::instrument::selftest::{
    self, Channel, SelfTestFault, SelfTestReport, MOTIONAL_BOUND, NOMINAL_TOLERANCE, TEST_HZ,
};
use pzt_probe::reading::driver::{block_on, SyncSource};
use pzt_probe::UnitProfile;
use std::f64::consts::PI;

fn factory() -> UnitProfile {
    pzt_probe::board::sim_factory::profile().expect("factory record")
}

fn run(scene: Scene, unit: &UnitProfile, seed: u64) -> SelfTestReport {
    let mut board = SimBoard::new(SimProbe::new(scene, seed));
    let mut engine = SampleEngine::new();
    let mut src = SyncSource::new(&mut board, &mut engine);
    block_on(selftest::run(&mut src, unit, |_| {}))
}

/// Every contact at power-on, from free air to rigid, light to hard presses.
fn contacts() -> Vec<(String, Scene)> {
    let mut v = vec![("free air".to_string(), Scene::free_air())];
    for e in [1.0, 8.0, 30.0, 100.0, 300.0, 1000.0, 5000.0, 1e6, 1e9] {
        for preload in [0.03, 0.1, 1.0] {
            v.push((
                format!("{e} kPa at {preload} N"),
                Scene::on_modulus_kpa(e).with_preload_n(preload),
            ));
        }
    }
    v
}

/// The bound on the motional branch's share of the susceptance at the test frequency holds
/// over every contact, and is within 10 % of the worst case (a bound, not a round number).
#[test]
fn motional_bound_from_the_closed_form() {
    let f = TEST_HZ as f64;
    let w = 2.0 * PI * f;
    let mut worst: f64 = 0.0;
    for (name, s) in contacts() {
        let y = s.admittance(f);
        let share = (y.im / (w * s.pzt.c0_f) - 1.0).abs();
        assert!(share <= MOTIONAL_BOUND as f64, "{name}: {share}");
        worst = worst.max(share);
        // Far from every resonance: the highest loaded one is under a quarter of TEST_HZ.
        assert!(s.resonance_hz() < f / 3.7, "{name}: {}", s.resonance_hz());
    }
    println!("worst motional share at {TEST_HZ} Hz: {worst:.5}");
    assert!(MOTIONAL_BOUND as f64 <= 1.1 * worst, "{worst}");
}

/// Every contact passes against the factory air reference, and the measured capacitance is the
/// scene's closed-form `Im(Y(f)) / (2 pi f)` within five of its own standard uncertainties
/// plus 0.2 %: a systematic of the simulated converters (sampling and hold of the discretised
/// chain) that the noise does not explain, at most −0.16 % over these contacts, −0.11/−0.13 % under QEMU
/// (printed below) — an allowance from measurement, 27 times below the self-test's own 5.35 %.
#[test]
fn every_contact_passes_and_measures_the_closed_form_capacitance() {
    let unit = factory();
    let air = unit.air.expect("factory air reference");
    let mut worst: f64 = 0.0;
    for (i, (name, s)) in contacts().into_iter().enumerate() {
        let r = run(s.with_noise(NoiseScene::Bench), &unit, 100 + i as u64);
        assert_eq!(r.outcome, Ok(()), "{name}: {r:?}");
        let f = r.freq.0 as f64;
        assert!((f - TEST_HZ as f64).abs() < 1e-3, "{f}");
        let truth = s.admittance(f).im / (2.0 * PI * f);
        let c = r.capacitance.0 as f64;
        let tol = 5.0 * r.capacitance_sigma.0 as f64 + 2e-3 * truth;
        assert!(
            (c - truth).abs() <= tol,
            "{name}: {c:e} F, closed form {truth:e} F ± {tol:e}"
        );
        if (c / truth - 1.0).abs() > worst.abs() {
            worst = c / truth - 1.0;
        }
        if i == 0 {
            println!(
                "free air: C {:.2} pF (sigma {:.3} pF), closed form {:.2} pF, air reference C0 {:.2} pF, G {:.3e} S, i {:.3e} A, v {:.3} V, {:.2} s",
                c * 1e12,
                r.capacitance_sigma.0 * 1e12,
                truth * 1e12,
                air.static_capacitance.0 * 1e12,
                r.conductance.0,
                r.current_a,
                r.drive_v,
                r.probe_time.0
            );
        }
    }
    println!(
        "largest deviation from the closed form: {:+.3} %",
        100.0 * worst
    );
}

/// Each fault scene of `hal-sim` ends in its own fault, on tissue and in free air, with the
/// air reference and without (a fresh unit: the nominal plate).
#[test]
fn each_fault_scene_ends_in_its_typed_fault() {
    let units = [factory(), UnitProfile::fallback()];
    let expect = |f: Fault| match f {
        Fault::OpenPzt => SelfTestFault::OpenPzt,
        Fault::ShortedPzt => SelfTestFault::ShortedPzt,
        Fault::StuckDac => SelfTestFault::NoDrive,
        Fault::AdcRail => SelfTestFault::AdcRail(Channel::Current),
    };
    for unit in &units {
        for base in [
            Scene::on_phantom(&phantoms::B),
            Scene::free_air(),
            Scene::on_modulus_kpa(1e9),
        ] {
            for f in Fault::ALL {
                let r = run(f.apply(base).with_noise(NoiseScene::Paper), unit, 5);
                assert_eq!(r.outcome, Err(expect(f)), "{}: {r:?}", f.name());
                println!(
                    "{} (air reference {}): {}",
                    f.name(),
                    unit.air.is_some(),
                    r.outcome.unwrap_err().code()
                );
            }
        }
    }
}

/// The other channel and the other rail: a drive monitor stuck at its lower rail is a stuck
/// ADC, not a missing drive; a sense channel stuck low is one too.
#[test]
fn a_stuck_monitor_or_a_low_rail_is_a_stuck_adc() {
    for (channel, code, want) in [
        (AdcChannel::Monitor, 0, Channel::Monitor),
        (AdcChannel::Monitor, 4095, Channel::Monitor),
        (AdcChannel::Current, 0, Channel::Current),
    ] {
        let mut s = Scene::on_phantom(&phantoms::B).with_noise(NoiseScene::Bench);
        s.stuck_adc = Some(StuckAdc { channel, code });
        let r = run(s, &factory(), 3);
        assert_eq!(
            r.outcome,
            Err(SelfTestFault::AdcRail(want)),
            "{channel:?} {code}"
        );
    }
}

/// The capacitance check against the air reference: a plate 8 % off (beyond the 5.35 %
/// tolerance: temperature allowance and motional bound) fails, 3 % off passes; a fresh unit is
/// checked against the nominal plate with its wider manufacturing tolerance (23 %).
#[test]
fn capacitance_tolerance_against_air_and_nominal() {
    let with = |k: f64| {
        let mut s = Scene::on_phantom(&phantoms::B).with_noise(NoiseScene::Bench);
        s.pzt.c0_f *= k;
        s
    };
    let unit = factory();
    for (k, ok) in [(0.92, false), (0.97, true), (1.03, true), (1.08, false)] {
        let r = run(with(k), &unit, 9);
        let want = if ok {
            Ok(())
        } else {
            Err(SelfTestFault::Capacitance)
        };
        assert_eq!(r.outcome, want, "C0 x {k}: {r:?}");
    }
    let fresh = UnitProfile::fallback();
    let t = NOMINAL_TOLERANCE as f64;
    for (k, ok) in [
        (1.0 - t - 0.03, false),
        (0.85, true),
        (1.15, true),
        (1.0 + t + 0.03, false),
    ] {
        let r = run(with(k), &fresh, 9);
        assert!(!r.expected.from_air);
        let want = if ok {
            Ok(())
        } else {
            Err(SelfTestFault::Capacitance)
        };
        assert_eq!(r.outcome, want, "fresh unit, C0 x {k}: {r:?}");
    }
}

/// The catalogue's scenes pass the self-test unless their plate or wiring is at fault: leakage
/// of 0.3 of the motional peak, mains hum, a second mode, knocks, drift and lift-off are for
/// the readings to judge; the `clipping` scene's five-fold transimpedance gain clips the
/// readings' 5 V at resonance, not the self-test's 0.64 uA (0.48 V of its 1.65 V range).
#[test]
fn catalogue_scenes_pass_unless_the_plate_is_at_fault() {
    let unit = factory();
    for c in hal_sim::catalogue::catalogue(NoiseScene::Bench) {
        let r = run(c.scene, &unit, 21);
        match c.name {
            "open-pzt" => assert_eq!(r.outcome, Err(SelfTestFault::OpenPzt)),
            "shorted-pzt" => assert_eq!(r.outcome, Err(SelfTestFault::ShortedPzt)),
            "dac-stuck" => assert_eq!(r.outcome, Err(SelfTestFault::NoDrive)),
            "adc-rail" => assert_eq!(r.outcome, Err(SelfTestFault::AdcRail(Channel::Current))),
            // C0 ten times the motional conductance's susceptance: a probe of another make.
            "c0-dominant" => assert!(r.outcome.is_err(), "{r:?}"),
            "knocks" => assert!(
                matches!(r.outcome, Ok(()) | Err(SelfTestFault::Interference)),
                "{r:?}"
            ),
            name => assert_eq!(r.outcome, Ok(()), "{name}: {r:?}"),
        }
        println!("{}: {}", c.name, selftest::outcome_code(Some(r.outcome)));
    }
}

/// A plate twenty times the nominal capacitance drives the sense channel into its rails while
/// its current stays capacitive: clipped, not shorted.
#[test]
fn a_huge_plate_clips() {
    let mut s = Scene::on_phantom(&phantoms::B).with_noise(NoiseScene::Bench);
    s.pzt.c0_f *= 20.0;
    let r = run(s, &factory(), 4);
    assert_eq!(r.outcome, Err(SelfTestFault::Clipped), "{r:?}");
}
