//! The contact law against the simulated probe's closed-form resonance (hal-sim's Kelvin
//! mechanics of the scene, not the law's code): fitted on phantoms A–E at 30 mN with the free
//! resonance held, it reads the moduli between them within 0.05 % — where the paper's power law,
//! fitted on the same five, is off by up to 1.3 %.

use hal_sim::{phantoms, Scene};
use pzt_probe::unit::calibration::{PowerLaw, RefPoint};
use pzt_probe::unit::contact_law::ContactLaw;
use pzt_probe::Hz;

fn reference(e_kpa: f64) -> RefPoint {
    RefPoint {
        modulus_kpa: e_kpa,
        resonance_hz: Scene::on_modulus_kpa(e_kpa).resonance_hz(),
        sigma_hz: 0.01,
        force_n: 0.0,
    }
}

#[test]
fn the_contact_law_reads_between_the_phantoms() {
    let refs: Vec<RefPoint> = ["A", "B", "C", "D", "E"]
        .iter()
        .map(|n| {
            let p = phantoms::by_name(n).expect("paper 003's phantoms");
            RefPoint {
                modulus_kpa: p.modulus_kpa,
                resonance_hz: Scene::on_phantom(&p).resonance_hz(),
                sigma_hz: 0.01,
                force_n: 0.0,
            }
        })
        .collect();
    let free = Scene::free_air().resonance_hz();
    let law = ContactLaw::fit(&refs, free, 0.0).expect("a contact law");
    let power = PowerLaw::fit(&refs).expect("a power law");
    let (mut worst_law, mut worst_power) = (0.0f64, 0.0f64);
    for e in [200.0, 350.0, 500.0, 700.0, 1000.0, 1500.0, 2000.0] {
        let f = Hz(reference(e).resonance_hz as f32);
        let m = law
            .invert(f, Hz(0.0), None)
            .expect("inside the span")
            .value
            .0 as f64;
        let p = power.invert(f, Hz(0.0)).expect("inside the span").value.0 as f64;
        worst_law = worst_law.max((m / e - 1.0).abs());
        worst_power = worst_power.max((p / e - 1.0).abs());
    }
    println!("worst between the phantoms: contact law {worst_law:e}, power law {worst_power:e}");
    assert!(worst_law < 5e-4, "contact law {worst_law}");
    assert!(
        worst_power > 5e-3,
        "the power law's bias this law removes: {worst_power}"
    );
}

/// The reading's uncertainty through the contact law against an f64 reference of its own: the
/// modulus by bisection of the law's resonance (and of the law with each constant nudged), the
/// slopes by central differences, combined as GUM does — the repeatability part `|dE/df| σ_f`
/// and the combined one with the misfit and the constants' covariance. Within 1e-3 (the f32
/// the reading carries, its slopes found in f32, and the differences' truncation).
#[test]
fn the_contact_laws_uncertainty_is_gums() {
    let free = Scene::free_air().resonance_hz();
    let refs: Vec<RefPoint> = [150.0, 279.0, 414.0, 1146.0, 2465.0]
        .iter()
        .map(|&e| reference(e))
        .collect();
    let fitted = ContactLaw::fit(&refs, free, 0.0).expect("a contact law");
    // A covariance and a misfit of the size a noisy calibration gives, correlated.
    let law = ContactLaw {
        cov: [
            [4e-6, -2e-6, 1e-6],
            [-2e-6, 9e-6, 3e-6],
            [1e-6, 3e-6, 16e-6],
        ],
        model_sigma_hz: 0.05,
        ..fitted
    };
    let modulus_at = |l: &ContactLaw, f: f64| {
        let (mut lo, mut hi) = (10.0f64, 1e5f64);
        for _ in 0..200 {
            let mid = (lo * hi).sqrt();
            if l.frequency(mid) < f {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (lo * hi).sqrt()
    };
    for e in [200.0, 700.0, 2000.0] {
        let f = law.frequency(e) as f32 as f64;
        let sf = 0.02;
        let m = law
            .invert(Hz(f as f32), Hz(sf as f32), None)
            .expect("in span");
        let h = 1e-4;
        let de_df = (modulus_at(&law, f + h) - modulus_at(&law, f - h)) / (2.0 * h);
        let mut g = [0.0; 3];
        for (i, gi) in g.iter_mut().enumerate() {
            let (mut up, mut dn) = (law, law);
            up.p[i] += 1e-5;
            dn.p[i] -= 1e-5;
            *gi = (modulus_at(&up, f) - modulus_at(&dn, f)) / 2e-5;
        }
        let repeat = de_df.abs() * sf;
        let mut var = repeat * repeat + (de_df * law.model_sigma_hz).powi(2);
        for i in 0..3 {
            for j in 0..3 {
                var += g[i] * law.cov[i][j] * g[j];
            }
        }
        let combined = var.sqrt();
        let close = |a: f32, b: f64| (a as f64 / b - 1.0).abs() < 1e-3;
        assert!(
            close(m.sigma_repeat.0, repeat),
            "{e}: {m:?} vs repeat {repeat}"
        );
        assert!(
            close(m.sigma.0, combined),
            "{e}: {m:?} vs combined {combined}"
        );
        // The root is found in `f32` (a reading's inversion runs on the M4F's FPU): the
        // modulus solves the law to within 8 ulps of the resonance (2.4e-4 Hz at 256 Hz).
        let ulp = (f32::from_bits((f as f32).to_bits() + 1) - f as f32) as f64;
        let residual = (law.frequency(m.value.0 as f64) - f).abs();
        assert!(residual <= 8.0 * ulp, "{e}: {residual} Hz off the law");
    }
}
