//! `probe-bench stream` as a user runs it (issue 14's "done when") and the continuous-mode scenes
//! of the stability map (`probe_bench::stability::stream_catalogue`, the definitions the map
//! uses): phantom C streams at least 20 ok readings per second after the first 0.5 s within 1 %
//! RMS of its modulus, numbered without gaps; after a step from B to D every reading from
//! 0.25 s on is within 3 % of D; after a lift-off no ok reading later than 0.1 s; on a new
//! contact the stream finds the tissue again without a command; the tip slipping off an edge, a
//! creeping press and knocks as docs/stability.md states. Probe time is the simulator's
//! (deterministic); the tolerances are the issue's, the measured figures in docs/stability.md.

mod common;

use common::{bin, run_fails_one_line, run_ok, Scratch};
use hal_sim::NoiseScene;
use probe_bench::stability::{calibrated, stream_catalogue, Must, Outcome, StreamCase, FIRST_SEED};
use probe_bench::unit::default_for;
use pzt_probe::instrument::continuous::METHOD;
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

/// The command line streams each catalogue scene as the library does: `probe-bench stream` with
/// the scene's own options (`StreamCase::args`) gives the same readings — seq, time, status,
/// modulus — as `StreamCase::run` with the command's unit, numbered without gaps; on phantom C
/// every reading after the first 0.5 s is locked.
#[test]
fn the_command_streams_the_catalogue_scenes_as_the_library_does() {
    let unit = default_for(METHOD).unwrap();
    for case in stream_catalogue(NoiseScene::Bench) {
        let seed = 1u64;
        let mut args = case.args();
        args.extend(["--seed".to_owned(), seed.to_string()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let cli = stream(&args);
        let lib = case.run(&unit, seed).unwrap().readings;
        assert_eq!(cli.len(), lib.len(), "{}", case.name);
        for (c, l) in cli.iter().zip(&lib) {
            assert_eq!(c["seq"].as_u64(), Some(l.seq as u64), "{}", case.name);
            assert!((t(c) - l.t_s.0 as f64).abs() < 1e-6, "{}: {c}", case.name);
            assert_eq!(c["status"], l.reading.status.code(), "{}: {c}", case.name);
            assert_eq!(
                c["modulus_kpa"].as_f64().map(|x| x as f32),
                l.reading.modulus.map(|m| m.0),
                "{}: {c}",
                case.name
            );
        }
        if case.name == "steady" {
            assert!(t(cli.last().unwrap()) >= 3.0);
            assert!(cli
                .iter()
                .filter(|r| t(r) > 0.5)
                .all(|r| r["locked"] == true));
        }
    }
}

/// Every continuous scene does what it must (`stability::Must`) in every stream, and no reading
/// is a silent wrong number: seeds 0–2 with the command's unit, and the stability map's seeds
/// with the map's unit (hold's column); among them the lossy tumour-like tissue, steady and
/// lifted off.
#[test]
fn the_continuous_scenes_do_what_they_must() {
    let command_unit = default_for(METHOD).unwrap();
    let map_unit = calibrated(METHOD, 10).unwrap().profile;
    let cases = stream_catalogue(NoiseScene::Bench);
    assert_eq!(cases.len(), 10);
    for (unit, seeds) in [
        (&command_unit, 0..3),
        (&map_unit, FIRST_SEED..FIRST_SEED + 5),
    ] {
        for case in &cases {
            let (mut silent, mut missed) = (0, 0);
            for seed in seeds.clone() {
                let s = case.run(unit, seed).unwrap();
                let v = case.judge(&s);
                eprintln!("{} seed {seed}: {v:?}", case.name);
                silent += v.counts[Outcome::SilentWrong as usize];
                missed += (!v.met()) as usize;
                assert_eq!(
                    v.counts.iter().sum::<usize>(),
                    s.readings.len(),
                    "{}",
                    case.name
                );
            }
            assert_eq!((silent, missed), (0, 0), "{}", case.name);
        }
    }
}

/// After a lift-off the free probe is told apart by the pipeline's contact check: no modulus, and
/// all but two readings `no_contact` (the catalogue's `lift-off` scene, seeds 0–2).
#[test]
fn after_a_lift_off_the_stream_says_no_contact() {
    let unit = default_for(METHOD).unwrap();
    let case = stream_catalogue(NoiseScene::Bench)
        .into_iter()
        .find(|c| c.name == "lift-off")
        .unwrap();
    for seed in 0..3 {
        let s = case.run(&unit, seed).unwrap();
        let after: Vec<_> = s.readings.iter().filter(|r| r.t_s.0 > 1.6).collect();
        assert!(after.len() >= 15);
        assert!(after.iter().all(|r| r.reading.modulus.is_none()), "{seed}");
        let free = after
            .iter()
            .filter(|r| r.reading.status.code() == "no_contact")
            .count();
        assert!(
            free + 2 >= after.len(),
            "seed {seed}: {free} of {}",
            after.len()
        );
    }
}

/// A criterion that is not met is reported: the step scene judged against a tolerance of 0.1 %
/// (the tracker's scatter is 0.2–0.5 %) never settles, and a lift-off scene whose stream is
/// judged as if the probe stayed on the tissue has silent wrong numbers.
#[test]
fn the_judge_can_say_no() {
    let unit = default_for(METHOD).unwrap();
    let cases = stream_catalogue(NoiseScene::Bench);
    let step = cases.iter().find(|c| c.name == "step-b-d").unwrap();
    let strict = StreamCase {
        must: vec![Must::Settle {
            at_s: 1.5,
            within_s: 0.25,
            tol: 0.001,
        }],
        ..step.clone()
    };
    let s = strict.run(&unit, 0).unwrap();
    let v = strict.judge(&s);
    assert!(!v.met() && v.checks[0].1 > 0.25, "{v:?}");
    let steady = cases.iter().find(|c| c.name == "steady").unwrap();
    let lift = cases.iter().find(|c| c.name == "lift-off").unwrap();
    // The steady scene's stream judged against the lift-off's truth: ok readings with no tissue.
    let mut s = steady.run(&unit, 0).unwrap();
    s.truth = lift.scene.build().unwrap().1;
    let v = lift.judge(&s);
    assert!(
        !v.met() && v.counts[Outcome::SilentWrong as usize] >= 10,
        "{v:?}"
    );
}

#[test]
fn the_bench_log_and_the_plot() {
    let dir = Scratch::new("stream");
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

/// Issue 28, from the library (`pareto::evaluate_stream`, the study's function), five 3 s
/// streams a scene (at least 250 readings after the first 0.5 s): at the default setting the
/// tracker gives ≥ 25 ok readings per second whose error from noise is within 1.5× of the
/// steady-state Cramér–Rao bound for one reading's probe time (`pareto::steady_crb_pct`), on
/// phantom C (noise seeds 0–4) and on 1000 kPa and phantom A (other seeds); RMS within 1 % of
/// the truth. The bound is one segment's; a reading that pools segments may go below it, so
/// only its ceiling is asserted (docs/methods.md, "Continuous reading").
#[test]
fn the_trackers_speed_accuracy_point_on_phantom_c() {
    use hal_sim::{phantoms, NoiseScene};
    use probe_bench::pareto::{evaluate_stream, stream_unit};
    use probe_bench::scene::Target;
    use pzt_probe::instrument::continuous::TrackerConfig;
    let unit = stream_unit(NoiseScene::Bench).unwrap();
    let d = TrackerConfig::DEFAULT;
    for (target, seed0) in [
        (Target::Phantom(phantoms::by_name("C").unwrap()), 0),
        (Target::Modulus(1000.0), 40),
        (Target::Phantom(phantoms::by_name("A").unwrap()), 80),
    ] {
        let seg = d.segment.0 as f64;
        let s = evaluate_stream(
            target,
            NoiseScene::Bench,
            seg,
            d.plan_segments,
            &unit,
            5,
            seed0,
        )
        .unwrap();
        let x = &s.cell;
        let name = target.describe();
        eprintln!(
            "{name}: {} ms: {:.1} ok/s ({} of {} ok), {:.1} ms a reading, RMS {:.3} % vs truth, {:.3} % from noise, CRB {:.4} %, ratio {:.2}",
            s.setting(),
            s.ok_per_s,
            x.ok,
            x.n,
            x.time_ms,
            x.rms_pct(),
            x.noise_rms_pct(),
            s.crb_pct,
            s.ratio()
        );
        assert!(s.ok_per_s >= 25.0, "{name}: {} ok/s", s.ok_per_s);
        assert!(x.ok >= 250, "{name}: {} ok readings", x.ok);
        assert!(x.rms_pct() <= 1.0, "{name}: RMS {} %", x.rms_pct());
        assert!(s.crb_pct.is_finite() && s.crb_pct > 0.0, "{}", s.crb_pct);
        assert!(
            s.ratio().is_finite() && s.ratio() <= 1.5,
            "{name}: {}",
            s.ratio()
        );
    }
}

/// Issue 28's fast setting (`pareto::FAST_STREAM`: segments of 12 ms, four a plan): at least
/// 50 ok readings per second within 0.5 % RMS of the truth, on phantom C (noise seeds 0–4),
/// phantoms A and E and 2000 kPa (other seeds).
#[test]
fn the_fast_setting_reads_fifty_a_second_within_half_a_percent() {
    use hal_sim::{phantoms, NoiseScene};
    use probe_bench::pareto::{evaluate_stream, stream_unit, FAST_STREAM};
    use probe_bench::scene::Target;
    let unit = stream_unit(NoiseScene::Bench).unwrap();
    let (seg, per) = FAST_STREAM;
    for (target, seed0) in [
        (Target::Phantom(phantoms::by_name("C").unwrap()), 0),
        (Target::Phantom(phantoms::by_name("A").unwrap()), 20),
        (Target::Phantom(phantoms::by_name("E").unwrap()), 60),
        (Target::Modulus(2000.0), 100),
    ] {
        let s = evaluate_stream(target, NoiseScene::Bench, seg, per, &unit, 5, seed0).unwrap();
        let x = &s.cell;
        let name = target.describe();
        eprintln!(
            "{name}: {} ms: {:.1} ok/s ({} of {} ok), {:.1} ms a reading, RMS {:.3} % vs truth, {:.3} % from noise, CRB {:.4} %, ratio {:.2}",
            s.setting(),
            s.ok_per_s,
            x.ok,
            x.n,
            x.time_ms,
            x.rms_pct(),
            x.noise_rms_pct(),
            s.crb_pct,
            s.ratio()
        );
        assert!(s.ok_per_s >= 50.0, "{name}: {} ok/s", s.ok_per_s);
        assert!(x.rms_pct() <= 0.5, "{name}: RMS {} %", x.rms_pct());
    }
}
