//! `probe-bench stream` as a user runs it (issue 14's "done when"): phantom C streams at least
//! 20 ok readings per second after the first 0.5 s within 1 % RMS of its modulus, numbered
//! without gaps; after a step from B to D every reading from 0.25 s on is within 3 % of D;
//! after a lift-off no ok reading later than 0.1 s; on a new contact the stream finds the
//! tissue again without a command. Probe time is the simulator's (deterministic); the
//! tolerances are the issue's, the measured worst cases over the seeds are in
//! docs/methods.md.

mod common;

use common::{bin, run_fails_one_line, run_ok};
use serde_json::Value;

fn stream(args: &[&str]) -> Vec<Value> {
    let out = run_ok(bin().arg("stream").args(args).arg("--json"));
    let v: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // Numbered from 0 without gaps, stamped in increasing probe time.
    for (k, r) in v.iter().enumerate() {
        assert_eq!(r["seq"].as_u64(), Some(k as u64), "{r}");
        for key in [
            "status",
            "t_s",
            "locked",
            "resonance_hz",
            "modulus_kpa",
            "modulus_sigma_kpa",
        ] {
            assert!(r.get(key).is_some(), "{key} missing: {r}");
        }
    }
    for w in v.windows(2) {
        assert!(t(&w[1]) > t(&w[0]), "{} then {}", w[0], w[1]);
    }
    v
}

fn t(r: &Value) -> f64 {
    r["t_s"].as_f64().unwrap()
}

fn ok(r: &Value) -> bool {
    r["status"] == "ok"
}

fn modulus(r: &Value) -> f64 {
    r["modulus_kpa"].as_f64().unwrap()
}

#[test]
fn phantom_c_streams_20_readings_per_second_within_1_percent() {
    for seed in ["0", "1", "2"] {
        let v = stream(&["--phantom", "C", "--seconds", "3", "--seed", seed]);
        let end = t(v.last().unwrap());
        assert!(end >= 3.0, "{end}");
        let after: Vec<&Value> = v.iter().filter(|r| t(r) > 0.5).collect();
        let good: Vec<f64> = after.iter().filter(|r| ok(r)).map(|r| modulus(r)).collect();
        let rate = good.len() as f64 / (end - 0.5);
        let rms = (good.iter().map(|e| (e / 414.0 - 1.0).powi(2)).sum::<f64>() / good.len() as f64)
            .sqrt();
        eprintln!(
            "seed {seed}: {rate:.1} ok readings/s, RMS {:.3} %",
            100.0 * rms
        );
        assert!(rate >= 20.0, "seed {seed}: {rate} ok readings/s");
        assert!(rms <= 0.01, "seed {seed}: RMS {rms}");
        assert!(after.iter().all(|r| r["locked"] == true), "seed {seed}");
    }
}

#[test]
fn a_step_from_b_to_d_is_followed_within_a_quarter_second() {
    for seed in ["0", "1", "2"] {
        let v = stream(&[
            "--phantom",
            "B",
            "--step-to",
            "D",
            "--step-at-s",
            "1.5",
            "--seconds",
            "3",
            "--seed",
            seed,
        ]);
        for r in &v {
            let (time, e) = (t(r), r["modulus_kpa"].as_f64());
            if time < 1.5 && time > 0.5 {
                assert!(ok(r) && (e.unwrap() / 279.0 - 1.0).abs() <= 0.03, "{r}");
            }
            if time >= 1.75 {
                assert!(ok(r), "seed {seed}: {r}");
                assert!(
                    (e.unwrap() / 1146.0 - 1.0).abs() <= 0.03,
                    "seed {seed}: {r}"
                );
            }
        }
        assert!(v.iter().filter(|r| t(r) >= 1.75).count() >= 25);
    }
}

#[test]
fn no_ok_reading_after_a_lift_off_and_the_next_contact_is_found() {
    for seed in ["0", "1", "2"] {
        let v = stream(&[
            "--phantom",
            "C",
            "--lift-off-at-s",
            "1.5",
            "--seconds",
            "2.5",
            "--seed",
            seed,
        ]);
        let after: Vec<&Value> = v.iter().filter(|r| t(r) > 1.6).collect();
        assert!(after.len() >= 15);
        assert!(
            after.iter().all(|r| !ok(r) && r["modulus_kpa"].is_null()),
            "seed {seed}"
        );
        // The free probe is told apart by the pipeline's contact check.
        assert!(after.iter().filter(|r| r["status"] == "no_contact").count() >= after.len() - 2);
        // Lifted off at 1.0 s, put down on the same tissue at 2.0 s: read again within 0.25 s.
        let v = stream(&[
            "--phantom",
            "C",
            "--lift-off-at-s",
            "1.0",
            "--touch-at-s",
            "2.0",
            "--seconds",
            "3",
            "--seed",
            seed,
        ]);
        for r in &v {
            let time = t(r);
            if time > 1.1 && time < 2.0 {
                assert!(!ok(r), "{r}");
            }
            if time >= 2.25 {
                assert!(
                    ok(r) && (modulus(r) / 414.0 - 1.0).abs() <= 0.03,
                    "seed {seed}: {r}"
                );
            }
        }
    }
}

#[test]
fn the_bench_log_and_the_plot() {
    let dir = std::env::temp_dir().join(format!("probe-bench-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let svg = dir.join("stream.svg");
    let out = run_ok(
        bin()
            .args([
                "stream",
                "--phantom",
                "B",
                "--step-to",
                "D",
                "--step-at-s",
                "0.8",
                "--seconds",
                "1.5",
                "--plot",
            ])
            .arg(&svg),
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("0 dropped"), "{text}");
    assert!(
        text.contains("step at 0.800 s: within 3 % of the truth from"),
        "{text}"
    );
    let plot = std::fs::read_to_string(&svg).unwrap();
    assert!(plot.contains("<svg") && plot.contains("modulus"), "{plot}");
    std::fs::remove_dir_all(&dir).ok();
    run_fails_one_line(bin().args(["stream", "--phantom", "B", "--step-to", "D"]));
    run_fails_one_line(bin().args(["stream", "--phantom", "C", "--touch-at-s", "1"]));
}

/// `stream --qemu`: the firmware image's `stream` command in QEMU, the same JSON. Lifted off
/// and put down again on phantom C: ok within 1 % before, none 0.1 s after the lift-off,
/// within 3 % again 0.25 s after the new contact (the scene's events count from its start,
/// 10 ms before the stream's). Host-only options the image does not take are refused.
#[test]
fn qemu_streams_the_same_json_and_follows_lift_off_and_new_contact() {
    let v = stream(&[
        "--phantom",
        "C",
        "--seconds",
        "2.5",
        "--lift-off-at-s",
        "1.0",
        "--touch-at-s",
        "1.6",
        "--qemu",
    ]);
    assert!(t(v.last().unwrap()) >= 2.5);
    let before: Vec<&Value> = v.iter().filter(|r| t(r) > 0.3 && t(r) < 0.95).collect();
    assert!(
        before.len() >= 12 && before.iter().all(|r| ok(r)),
        "{before:?}"
    );
    for r in &v {
        let time = t(r);
        if time > 1.1 && time < 1.6 {
            assert!(!ok(r), "{r}");
        }
        if time >= 1.85 {
            assert!(ok(r) && (modulus(r) / 414.0 - 1.0).abs() <= 0.03, "{r}");
        }
        if ok(r) && time < 0.95 {
            assert!((modulus(r) / 414.0 - 1.0).abs() <= 0.01, "{r}");
        }
    }
    run_fails_one_line(bin().args(["stream", "--phantom", "C", "--qemu", "--segment-s", "0.05"]));
    run_fails_one_line(bin().args([
        "stream",
        "--phantom",
        "C",
        "--qemu",
        "--lift-off-at-s",
        "1",
        "--lift-off-ramp-s",
        "0.05",
    ]));
}

/// The continuous-mode scenes of the stability catalogue (docs/methods.md): beside the step
/// and the lift-off above, the tip slipping down an edge (the press falls from 30 to 9 mN in
/// 30 ms: no ok reading from the slip on, `too_light` once it is over), a press that creeps
/// from 30 to 45 mN over 0.5 s (`force_unstable` while it moves, every reading ok within 3 %
/// at the new force after), and random knocks twice a second (no ok reading off by more than 3 %, RMS
/// within 1 %, at least 20 ok readings per second still).
#[test]
fn continuous_mode_scenes_slip_press_and_knocks() {
    for seed in ["0", "1", "2"] {
        let base = ["--phantom", "C", "--seconds", "2", "--seed", seed];
        // Slip off the edge at 1.0 s.
        let v = stream(&[&base[..], &["--press-to", "0.3", "--press-at-s", "1.0"]].concat());
        assert!(v.iter().filter(|r| t(r) > 0.5 && t(r) < 1.0).all(ok));
        assert!(
            v.iter().filter(|r| t(r) > 1.0).all(|r| !ok(r)),
            "seed {seed}"
        );
        assert!(v
            .iter()
            .filter(|r| t(r) > 1.2)
            .all(|r| r["status"] == "too_light"));
        // A press creeping from 30 to 45 mN from 1.0 s over 0.5 s.
        let v = stream(
            &[
                &base[..],
                &[
                    "--press-to",
                    "1.5",
                    "--press-at-s",
                    "1.0",
                    "--press-ramp-s",
                    "0.5",
                ],
            ]
            .concat(),
        );
        for r in &v {
            let time = t(r);
            if (1.15..1.45).contains(&time) {
                assert!(!ok(r), "seed {seed}: {r}");
            }
            if time > 1.6 {
                assert!(
                    ok(r) && (modulus(r) / 414.0 - 1.0).abs() <= 0.03,
                    "seed {seed}: {r}"
                );
            }
        }
        // Knocks twice a second for 3 s.
        let v = stream(&[
            "--phantom",
            "C",
            "--seconds",
            "3",
            "--seed",
            seed,
            "--knocks-hz",
            "2",
        ]);
        let good: Vec<f64> = v
            .iter()
            .filter(|r| t(r) > 0.5 && ok(r))
            .map(modulus)
            .collect();
        let rate = good.len() as f64 / (t(v.last().unwrap()) - 0.5);
        let rms = (good.iter().map(|e| (e / 414.0 - 1.0).powi(2)).sum::<f64>() / good.len() as f64)
            .sqrt();
        eprintln!(
            "knocks, seed {seed}: {rate:.1} ok/s, RMS {:.3} %",
            100.0 * rms
        );
        assert!(rate >= 20.0 && rms <= 0.01, "seed {seed}: {rate} /s, {rms}");
        assert!(good.iter().all(|e| (e / 414.0 - 1.0).abs() <= 0.03));
    }
}

/// Issue 14 point 6, from the library (`pareto::evaluate_stream`, the study's function): at the
/// default segment length the tracker gives ≥ 20 ok readings per second after the first 0.5 s
/// within 1 % RMS of phantom C, and its error from noise sits above the steady-state Cramér–Rao
/// bound for one reading's probe time — finite, never below it (a bound cannot be beaten), and
/// no more than 8× (measured 5.9× on these seeds, 39.4 ms a reading; the single-shot hold is
/// within 2×).
#[test]
fn the_trackers_speed_accuracy_point_on_phantom_c() {
    use hal_sim::{phantoms, NoiseScene};
    use probe_bench::pareto::{evaluate_stream, stream_unit};
    use probe_bench::scene::Target;
    use pzt_probe::stream::TrackerConfig;
    let unit = stream_unit(NoiseScene::Bench).unwrap();
    let c = Target::Phantom(phantoms::by_name("C").unwrap());
    let seg = TrackerConfig::DEFAULT.segment.0 as f64;
    let s = evaluate_stream(c, NoiseScene::Bench, seg, &unit, 5, 0).unwrap();
    let x = &s.cell;
    eprintln!(
        "{:.0} ms: {:.1} ok/s ({} of {} ok), {:.1} ms a reading, RMS {:.3} % vs truth, {:.3} % from noise, CRB {:.4} %, ratio {:.2}",
        seg * 1e3,
        s.ok_per_s,
        x.ok,
        x.n,
        x.time_ms,
        x.rms_pct(),
        x.noise_rms_pct(),
        s.crb_pct,
        s.ratio()
    );
    assert!(s.ok_per_s >= 20.0, "{} ok/s", s.ok_per_s);
    assert!(x.ok >= 300, "{} ok readings", x.ok);
    assert!(x.rms_pct() <= 1.0, "RMS {} %", x.rms_pct());
    assert!(s.crb_pct.is_finite() && s.crb_pct > 0.0, "{}", s.crb_pct);
    assert!(s.ratio().is_finite() && s.ratio() >= 1.0, "{}", s.ratio());
    assert!(s.ratio() <= 8.0, "{}", s.ratio());
}
