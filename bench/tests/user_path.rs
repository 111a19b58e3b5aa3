//! The main job as a user runs it (`probe-bench measure --json`): scenes where no number is due
//! end in a failure code, never in `ok`; the paper's phantoms at the nominal 30 mN read within
//! 3 % of their modulus; the help lists every method and the firmware's default.

mod common;

use common::{bin, run_json, run_ok};
use pzt_probe::measure::DEFAULT_METHOD;
use pzt_probe::Method;

fn measure(args: &[&str]) -> serde_json::Value {
    run_json(bin().arg("measure").args(args).arg("--json"))
}

#[test]
fn no_number_where_none_is_due() {
    // Free air, a 2 mN touch (the resonance rises toward the free one: 237.7 Hz, Q 26), a
    // 100 mN press (Q 5.6), silicones far below the calibrated range (8 and 29 kPa), and
    // stiffer than the range (6 MPa): for the default and the paper's baseline.
    let scenes: &[&[&str]] = &[
        &["--free-air"],
        &["--phantom", "B", "--preload-n", "0.002"],
        &["--phantom", "B", "--preload-n", "0.1"],
        &["--phantom", "ecoflex-00-10"],
        &["--phantom", "ecoflex-00-30"],
        &["--modulus-kpa", "6000"],
    ];
    for method in ["auto", "paper"] {
        for s in scenes {
            let mut args = s.to_vec();
            args.extend(["--method", method]);
            let r = measure(&args);
            assert_ne!(r["status"], "ok", "{method} {s:?}: {r}");
            assert!(r["modulus_kpa"].is_null(), "{method} {s:?}: {r}");
            assert!(r["message"].as_str().is_some_and(|m| m.len() > 10), "{r}");
        }
    }
    assert_eq!(measure(&["--free-air"])["status"], "no_contact");
}

#[test]
fn the_papers_phantoms_read_within_3_percent() {
    for (p, truth) in [("A", 157.5), ("B", 279.0), ("E", 2465.0)] {
        let r = measure(&["--phantom", p]);
        assert_eq!(r["status"], "ok", "{p}: {r}");
        let e = r["modulus_kpa"].as_f64().unwrap();
        assert!((e / truth - 1.0).abs() <= 0.03, "{p}: {e} kPa vs {truth}");
        assert_eq!(r["method"], "hold", "auto's first stage");
        // Read in well under a second of probe time (hold: 0.36–0.38 s).
        assert!(r["probe_time_ms"].as_f64().unwrap() < 500.0, "{r}");
    }
}

/// Between the reference phantoms at the nominal 30 mN, the mean of three readings of the
/// default method is within 0.5 % of the truth (issue #13; the contact law the calibration
/// chose, where the power law was off by up to 1.3 %), and the truth lies within 3 reported
/// standard uncertainties of each reading.
#[test]
fn between_the_phantoms_the_calibration_is_within_half_a_percent() {
    for truth in [200.0, 350.0, 700.0, 1500.0] {
        let e = truth.to_string();
        let out = common::run_ok(
            bin()
                .args(["measure", "--modulus-kpa", &e, "--repeat", "3", "--json"])
                .arg("--seed")
                .arg("40"),
        );
        let readings: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).expect("one JSON object per reading"))
            .collect();
        assert_eq!(readings.len(), 3);
        let mut sum = 0.0;
        for r in &readings {
            assert_eq!(r["status"], "ok", "{truth}: {r}");
            let m = r["modulus_kpa"].as_f64().unwrap();
            let s = r["modulus_sigma_kpa"].as_f64().unwrap();
            assert!((m - truth).abs() <= 3.0 * s, "{truth}: {m} ± {s} kPa");
            sum += m;
        }
        let mean = sum / 3.0;
        assert!(
            (mean / truth - 1.0).abs() <= 0.005,
            "{truth}: mean {mean} kPa"
        );
    }
}

#[test]
fn help_lists_every_method_and_the_firmwares_default() {
    let out = run_ok(bin().args(["measure", "--help"]));
    let help = String::from_utf8_lossy(&out.stdout);
    for m in Method::ALL {
        assert!(
            help.contains(&format!("`{}`", m.name())),
            "{} missing",
            m.name()
        );
    }
    assert!(
        help.contains(&format!("[default: {}]", DEFAULT_METHOD.name())),
        "{help}"
    );
}

/// The firmware image in QEMU on the same scene, seed, method and settings as the host reading
/// agrees on status and method, and on the modulus within 1 % (the image reads with its factory
/// profile, which is the host's auto profile: tests/factory_profile.rs). Needs QEMU's tools
/// (tests/qemu.rs says which are missing).
#[test]
fn the_firmware_in_qemu_agrees_with_the_host() {
    let cases: &[&[&str]] = &[
        &["--phantom", "B"],
        &["--phantom", "D", "--seed", "3"],
        &["--free-air"],
        &["--phantom", "B", "--preload-n", "0.002"],
        &["--modulus-kpa", "6000"],
    ];
    for c in cases {
        let host = measure(c);
        let mut q = c.to_vec();
        q.push("--qemu");
        let fw = measure(&q);
        println!("{c:?}: host {host}\n      qemu {fw}");
        assert_eq!(host["status"], fw["status"], "{c:?}");
        assert_eq!(host["method"], fw["method"], "{c:?}");
        if let (Some(h), Some(f)) = (host["modulus_kpa"].as_f64(), fw["modulus_kpa"].as_f64()) {
            assert!((f / h - 1.0).abs() <= 0.01, "{c:?}: {f} vs {h} kPa");
        }
    }
}
