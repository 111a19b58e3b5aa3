//! The main job as a user runs it (`probe-bench measure --json`): scenes where no number is due
//! end in a failure code, never in `ok`; the paper's phantoms at the nominal 30 mN read within
//! 3 % of their modulus; the help lists every method and the firmware's default.

mod common;

use common::{bin, run_json, run_ok};
use pzt_probe::reading::DEFAULT_METHOD;
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
    // A user's sweep over the paper's band on a silicone whose resonance lies far below it: the
    // conductance still falls from the band's low edge, and a noise bump beside the edge is no
    // peak (a check of the edge point alone lets it through as about 143 kPa).
    for seed in ["0", "1", "2", "3"] {
        let r = measure(&[
            "--phantom",
            "ecoflex-00-10",
            "--method",
            "sweep-g",
            "--start-hz",
            "200",
            "--stop-hz",
            "300",
            "--step-hz",
            "1",
            "--seed",
            seed,
        ]);
        assert_ne!(r["status"], "ok", "seed {seed}: {r}");
    }
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
/// agrees on status and method, and on the modulus within 1 %, and on lossy tissue both loss
/// tangents cover the scene's within 3 σ (the image reads with its factory
/// profile, which is the host's auto profile: tests/factory_profile.rs). Needs QEMU's tools
/// (tests/qemu.rs says which are missing).
#[test]
fn the_firmware_in_qemu_agrees_with_the_host() {
    let _image = common::image_lock();
    let cases: &[&[&str]] = &[
        &["--phantom", "B"],
        &["--phantom", "D", "--seed", "3"],
        &["--free-air"],
        &["--phantom", "B", "--preload-n", "0.002"],
        &["--modulus-kpa", "6000"],
        // Lossy tissue (issue #25): the image's reading carries the loss tangent too.
        &[
            "--modulus-kpa",
            "950",
            "--loss-tangent",
            "0.41",
            "--seed",
            "7",
        ],
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
        // Where the scene is lossy, each reading's loss tangent covers the scene's within 3 of
        // its σ.
        if let Some(i) = c.iter().position(|a| *a == "--loss-tangent") {
            let truth: f64 = c[i + 1].parse().expect("a loss tangent");
            for r in [&host, &fw] {
                let l = r["loss_tangent"].as_f64().expect("a loss tangent");
                let s = r["loss_tangent_sigma"].as_f64().expect("its σ");
                assert!((l - truth).abs() <= 3.0 * s, "{c:?}: {r}");
            }
        }
    }
}

/// The release binary run directly, as a newcomer does after `cargo build --release` (no `cargo
/// run` around it: no `CARGO`, no rustup toolchain in its environment), builds the QEMU image in a
/// target directory of its own and reads from it as under `cargo run`. A dependency of the image
/// (fugit) carries its own `rust-toolchain.toml`: built without the workspace's toolchain, its
/// compiler would be that file's, which a fresh machine does not have.
#[test]
fn the_binary_run_directly_builds_the_image_with_the_workspaces_toolchain() {
    let _image = common::image_lock();
    let scratch = common::Scratch::new("direct");
    let out = run_ok(
        bin()
            .args(["measure", "--phantom", "B", "--qemu", "--json"])
            .env_remove("CARGO")
            .env_remove("RUSTUP_TOOLCHAIN")
            .env("CARGO_TARGET_DIR", scratch.join("target")),
    );
    let fw: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(fw["status"], "ok", "{fw}");
    assert!(scratch
        .join("target/thumbv7em-none-eabihf/fw/probe")
        .is_file());
}

/// The contact force (issue #13), through the main job's own path (the unit profile
/// `probe-bench measure` makes, `board::sim::read` on the scene its options build): phantoms
/// A–D pressed at 15–50 mN read `ok` within 0.5 % of the truth (measured worst 0.29 %, A at
/// 15 mN; the issue asks 2 %), the truth within 3 reported σ, and the contact force reported
/// within 1 % of the scene's (measured −0.36 % at 15 mN: the tare's drift; the issue asks 5 %).
/// 5 mN is `too_light`, 100 mN `too_hard`.
#[test]
fn every_press_inside_the_force_window_reads_its_phantom() {
    use hal_sim::{phantoms, NoiseScene, Scene};
    let unit = probe_bench::unit::default_for(Method::Auto).expect("the simulated unit");
    let settings = Method::Auto.default_settings();
    for p in [phantoms::A, phantoms::B, phantoms::C, phantoms::D] {
        let truth = p.modulus_kpa;
        let read = |force: f64, seed: u64| {
            let scene = Scene::on_phantom(&p)
                .with_noise(NoiseScene::Bench)
                .with_preload_n(force);
            pzt_probe::board::sim::read(&scene, seed, Method::Auto, settings, &unit, |_| {})
                .expect("a reading")
        };
        for force in [0.015, 0.020, 0.030, 0.040, 0.045, 0.050] {
            for seed in 1..=2 {
                let r = read(force, seed);
                let at = format!("{} at {} mN, seed {seed}", p.name, force * 1e3);
                assert_eq!(r.status, pzt_probe::Status::Ok, "{at}: {r:?}");
                let e = r.modulus.expect("a modulus").0 as f64;
                let s = r.modulus_sigma.expect("its sigma").0 as f64;
                assert!((e / truth - 1.0).abs() <= 0.005, "{at}: {e} kPa");
                assert!((e - truth).abs() <= 3.0 * s, "{at}: {e} ± {s} kPa");
                let f = r.force.expect("the contact force").mean.0 as f64;
                assert!((f / force - 1.0).abs() <= 0.01, "{at}: {f} N");
            }
        }
        let refused = |force: f64, code: &str| {
            let r = read(force, 1);
            assert_eq!(r.status.code(), code, "{} at {force} N: {r:?}", p.name);
            assert!(r.modulus.is_none());
        };
        refused(0.005, "too_light");
        refused(0.100, "too_hard");
    }
}

/// The same through the command line: B pressed at 15 mN (where the reading was 20 % off
/// before the load cell) reads within 0.5 % and reports its force in the JSON.
#[test]
fn the_json_reports_the_contact_force() {
    let r = measure(&["--phantom", "B", "--preload-n", "0.015"]);
    assert_eq!(r["status"], "ok", "{r}");
    let e = r["modulus_kpa"].as_f64().unwrap();
    assert!((e / 279.0 - 1.0).abs() <= 0.005, "{e} kPa");
    let f = r["contact_force_n"].as_f64().expect("contact_force_n");
    let sf = r["contact_force_sigma_n"]
        .as_f64()
        .expect("contact_force_sigma_n");
    assert!((f / 0.015 - 1.0).abs() <= 0.01, "{f} N");
    assert!(sf > 0.0 && sf < 1e-3, "{sf} N");
    let r = measure(&["--phantom", "B", "--preload-n", "0.1"]);
    assert_eq!(r["status"], "too_hard", "{r}");
    assert!(r["modulus_kpa"].is_null());
}

/// `measure --stm32` (issue 26): the STM32 image on the emulated board, after its user's path
/// (air, `weigh 10`, calibration on A–E with the method asked for), reads as the host does. With
/// a method other than the default (`fit`, whose calibration and readings take their own time:
/// each step waits for the image's reply): B `ok` within 1 % of 279 kPa, and its contact force
/// the scene's 30 mN within the load cell's terms (0.5 % creep of the 10 g weighing and of the
/// force, 10 µN/s drift over the session's ~30 s, 4 σ; `hal_sim::loadcell::LoadCell`). The
/// force checks: B at 8 mN, B at 80 mN and free air get the host's verdicts (`too_light`,
/// `too_hard`, `no_contact`), with the host's force within 1 mN.
#[test]
fn stm32_reads_with_its_load_cell_and_any_method_as_the_host_does() {
    let _image = common::image_lock();
    let cell = hal_sim::loadcell::LoadCell::default();
    let weight_n = 0.010 * hal_sim::loadcell::STANDARD_GRAVITY_M_S2;
    let r = measure(&["--phantom", "B", "--method", "fit", "--stm32"]);
    eprintln!("stm32 fit: {r}");
    assert_eq!(r["status"], "ok", "{r}");
    assert_eq!(r["method"], "fit", "{r}");
    let e = r["modulus_kpa"].as_f64().unwrap();
    assert!((e / 279.0 - 1.0).abs() <= 0.01, "{e} kPa");
    let f = r["contact_force_n"].as_f64().unwrap();
    let sigma = r["contact_force_sigma_n"].as_f64().unwrap();
    let tol = cell.creep_fraction * (weight_n + 0.030) + cell.drift_n_per_s * 30.0 + 4.0 * sigma;
    assert!((f - 0.030).abs() <= tol, "force {f} N ± {tol}");
    for s in [
        &["--phantom", "B", "--preload-n", "0.008"][..],
        &["--phantom", "B", "--preload-n", "0.08"][..],
        &["--free-air"][..],
    ] {
        let host = measure(s);
        let stm32 = measure(&[s, &["--stm32"]].concat());
        eprintln!("{s:?}: host {} stm32 {}", host["status"], stm32["status"]);
        assert_eq!(stm32["status"], host["status"], "{s:?}: {stm32} vs {host}");
        let (hf, sf) = (
            host["contact_force_n"].as_f64().unwrap(),
            stm32["contact_force_n"].as_f64().unwrap(),
        );
        assert!(
            (hf - sf).abs() <= 1e-3,
            "{s:?}: force {sf} N vs host {hf} N"
        );
    }
}
