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
    assert_eq!(cases.len(), 11);
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

/// On tissue whose resonance lies below the tracker's band (by the simulator's own physics) the
/// stream names the cause, `out_of_band`, in every reading, as the single reading does; a hold
/// alone would hear too little and say `low_snr` ("raise the drive"), which misleads.
#[test]
fn below_the_band_the_stream_says_out_of_band() {
    use pzt_probe::instrument::continuous::TrackerConfig;
    let tissue = probe_bench::stability::BELOW_BAND;
    let scene = hal_sim::scenes::Scene::on_phantom(&hal_sim::phantoms::by_name(tissue).unwrap());
    let band = TrackerConfig::DEFAULT.band_start.0 as f64;
    assert!(scene.resonance_hz() < band, "{} Hz", scene.resonance_hz());
    let v = stream(&["--phantom", tissue, "--seconds", "2", "--seed", "3"]);
    assert!(v.len() >= 2, "{} readings", v.len());
    for r in &v {
        assert_eq!(r["status"], "out_of_band", "{r}");
        assert_eq!(r["locked"], false, "{r}");
        assert!(r["modulus_kpa"].is_null(), "{r}");
    }
    let one = run_ok(bin().args(["measure", "--phantom", tissue, "--json"]));
    let one: Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(one["status"], "out_of_band", "{one}");
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
    // A tracker setting outside its range is refused before the stream runs, in the settings
    // error's words.
    for (knob, value) in [
        ("--plan-segments", "9"),
        ("--segment-s", "1000"),
        ("--q-prior", "0"),
    ] {
        let e = run_fails_one_line(
            bin()
                .args(["stream", "--phantom", "C", "--seconds", "0.5", "--json"])
                .args([knob, value]),
        );
        assert!(e.contains("a method setting is outside its range"), "{e}");
    }
}

/// `stream --qemu`: the firmware image's `stream` command in QEMU, the same JSON. Lifted off
/// and put down again on phantom C: ok within 1 % before, none 0.1 s after the lift-off,
/// within 3 % again 0.25 s after the new contact (the scene's events count from its start,
/// 10 ms before the stream's). Host-only options the image does not take (the tracker's
/// settings but the segment and the segments a plan, a ramped lift-off) are refused.
#[test]
fn qemu_streams_the_same_json_and_follows_lift_off_and_new_contact() {
    let _image = common::image_lock();
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
    run_fails_one_line(bin().args(["stream", "--phantom", "C", "--qemu", "--dither", "0.5"]));
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

/// The ok readings of a stream after `from_s`: (their count, the mean modulus, the RMS error
/// against `truth_kpa` relative to it, the mean of their own stated σ).
fn ok_after(v: &[Value], from_s: f64, truth_kpa: f64) -> (usize, f64, f64, f64) {
    let ok: Vec<&Value> = v.iter().filter(|r| ok(r) && t(r) > from_s).collect();
    let n = ok.len() as f64;
    let mean = ok.iter().map(|r| modulus(r)).sum::<f64>() / n;
    let rms = (ok
        .iter()
        .map(|r| (modulus(r) / truth_kpa - 1.0).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let sigma = ok
        .iter()
        .map(|r| r["modulus_sigma_kpa"].as_f64().unwrap())
        .sum::<f64>()
        / n;
    (ok.len(), mean, rms, sigma)
}

/// `stream --stm32` (issue 26): the STM32 image's `stream` command on the emulated board, after
/// its user's path (air, weigh, calibration on A–E), on phantom C for 3 s: at least 20 ok
/// readings per second after the first 0.5 s within 1 % RMS of C's 414 kPa (issue 14's
/// figures); the readings missing from the JSON are the ones the firmware counts as dropped;
/// the mean modulus agrees with the host's stream of the same scene within 4 σ of the
/// difference of the two means (each reading's own stated σ, the readings independent).
#[test]
fn stm32_streams_phantom_c_as_the_host_does() {
    let _image = common::image_lock();
    let args = ["--phantom", "C", "--seconds", "3"];
    let v = stream(&[&args[..], &["--stm32"]].concat());
    let (n, mean, rms, sigma) = ok_after(&v, 0.5, 414.0);
    let span = t(v.last().unwrap()) - 0.5;
    let per_s = n as f64 / span;
    eprintln!(
        "stm32: {n} ok after 0.5 s ({per_s:.1}/s), mean {mean:.2} kPa, RMS {:.3} %, σ {sigma:.2} kPa",
        rms * 100.0
    );
    assert!(per_s >= 20.0, "{per_s} ok readings/s");
    assert!(rms <= 0.01, "RMS {rms}");
    // The firmware's own count of dropped readings (the text output's `the firmware:` line)
    // against the gaps in seq.
    let out = run_ok(bin().arg("stream").args(args).arg("--stm32"));
    let text = String::from_utf8(out.stdout).unwrap();
    let line = text
        .lines()
        .find(|l| l.contains("the firmware:"))
        .unwrap_or_else(|| panic!("no firmware line: {text}"));
    let dropped: u64 = line
        .split(" dropped")
        .next()
        .and_then(|h| h.rsplit(' ').next())
        .and_then(|d| d.parse().ok())
        .unwrap_or_else(|| panic!("no dropped count in {line}"));
    let last_seq = v.last().unwrap()["seq"].as_u64().unwrap();
    assert_eq!(last_seq + 1 - v.len() as u64, dropped, "{line}");
    // The host's stream of the same scene.
    let h = stream(&args);
    let (hn, hmean, hrms, hsigma) = ok_after(&h, 0.5, 414.0);
    eprintln!(
        "host: {hn} ok after 0.5 s, mean {hmean:.2} kPa, RMS {:.3} %, σ {hsigma:.2} kPa",
        hrms * 100.0
    );
    let tol = 4.0 * (sigma.powi(2) / n as f64 + hsigma.powi(2) / hn as f64).sqrt();
    assert!(
        (mean - hmean).abs() <= tol,
        "stm32 {mean} kPa vs host {hmean} kPa ± {tol}"
    );
}

/// `stream --stm32` with issue 28's fast setting (`pareto::FAST_STREAM`, passed to the image's
/// `stream` command): on phantom C for 3 s at least 50 ok readings per second after the first
/// 0.5 s within 0.5 % RMS of C's 414 kPa, as on the host.
#[test]
fn stm32_streams_phantom_c_with_the_fast_setting() {
    let _image = common::image_lock();
    let (seg, per) = probe_bench::pareto::FAST_STREAM;
    let (seg, per) = (seg.to_string(), per.to_string());
    let v = stream(&[
        "--phantom",
        "C",
        "--seconds",
        "3",
        "--segment-s",
        &seg,
        "--plan-segments",
        &per,
        "--stm32",
    ]);
    let (n, mean, rms, sigma) = ok_after(&v, 0.5, 414.0);
    let per_s = n as f64 / (t(v.last().unwrap()) - 0.5);
    eprintln!(
        "stm32 fast: {n} ok after 0.5 s ({per_s:.1}/s), mean {mean:.2} kPa, RMS {:.3} %, σ {sigma:.2} kPa",
        rms * 100.0
    );
    assert!(per_s >= 50.0, "{per_s} ok readings/s");
    assert!(rms <= 0.005, "RMS {rms}");
}

/// One speed–accuracy point's figures, on stderr.
fn print_point(name: &str, s: &probe_bench::pareto::StreamCell) {
    let x = &s.cell;
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
        print_point(&name, &s);
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
/// phantoms A and E and 2000 kPa (other seeds). Its error from noise is within 0.85× one
/// segment's steady-state bound on C and within 1.2× on every scene (measured 0.6× and, on A,
/// 1.01×). The tracker pools a plan's later segments through the difference of their fits'
/// information: a fit stopped short of its optimum moves that difference, and a difference that
/// fails the filter's gate must restart it from the plan's whole fit, not from itself (on A,
/// seeds 20–24, a restart from the difference read 4×).
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
        print_point(&name, &s);
        assert!(s.ok_per_s >= 50.0, "{name}: {} ok/s", s.ok_per_s);
        assert!(x.rms_pct() <= 0.5, "{name}: RMS {} %", x.rms_pct());
        let most = if seed0 == 0 { 0.85 } else { 1.2 };
        assert!(s.ratio() <= most, "{name}: {} × its bound", s.ratio());
    }
}

/// Issue 28: the reading's σ covers the truth as a single reading's does under the stated drift
/// (docs/accuracy.md: the probe's free resonance drifting at a rate drawn from N(0, 0.3 Hz/s),
/// `profile::FREE_RESONANCE_DRIFT_HZ_S`), at the default setting on phantom C and at the fast
/// setting (`pareto::FAST_STREAM`, whose later segments update the plan's first fit: its σ is
/// that update's) on C and on the lossy carcinoma-like phantom. 20 streams of 3 s each, each with
/// its own rate (`probe_rng`, seed 28) and noise seed; every ok reading after 0.5 s against the
/// scene's closed-form resonance at the reading's time, less the tracker's constant offset from
/// it (the mean error of five streams without drift on other seeds, which the calibration
/// absorbs): within 1σ 60–80 % and within 2σ 90–99 % (measured 76.0 / 97.8 % of 1340 at the
/// default, 66.4 / 92.5 % of 4008 and 68.0 / 92.5 % of 4046 at the fast setting; successive
/// readings are correlated, so the tolerance is a few times a binomial σ). Without drift the σ
/// over-covers (more than 90 % within 1σ), as a single reading's does without its drift.
#[test]
fn the_trackers_sigma_covers_the_truth_under_the_stated_drift() {
    use hal_sim::{phantoms, Drift, Scene};
    use pzt_probe::instrument::continuous::TrackerConfig;
    use pzt_probe::units::Seconds;
    let unit = default_for(METHOD).unwrap();
    let (seg, per) = probe_bench::pareto::FAST_STREAM;
    let fast = TrackerConfig {
        segment: Seconds(seg as f32),
        plan_segments: per,
        ..TrackerConfig::DEFAULT
    };
    for (phantom, setting, cfg) in [
        ("C", "default", TrackerConfig::DEFAULT),
        ("C", "fast", fast),
        ("carcinoma-like", "fast", fast),
    ] {
        let base =
            Scene::on_phantom(&phantoms::by_name(phantom).unwrap()).with_noise(NoiseScene::Bench);
        let errors = |scene: &Scene, seed: u64| {
            let mut v = Vec::new();
            pzt_probe::board::sim::stream(scene, seed, &cfg, &unit, 3.0, |r| v.push(*r)).unwrap();
            v.iter()
                .filter(|r| r.t_s.0 > 0.5 && r.reading.status.is_ok())
                .filter_map(|r| {
                    let f = r.reading.resonance?.0 as f64;
                    let s = r.reading.resonance_sigma?.0 as f64;
                    Some((f - scene.at(r.t_s.0 as f64).resonance_hz(), s))
                })
                .collect::<Vec<_>>()
        };
        let still: Vec<(f64, f64)> = (100..105).flat_map(|seed| errors(&base, seed)).collect();
        let offset = still.iter().map(|e| e.0).sum::<f64>() / still.len() as f64;
        let within = |v: &[(f64, f64)], k: f64| {
            v.iter()
                .filter(|(e, s)| (e - offset).abs() <= k * s)
                .count() as f64
                / v.len() as f64
        };
        let mut rates = probe_rng::Rng::new(28);
        let drifting: Vec<(f64, f64)> = (0..20)
            .flat_map(|seed| {
                let rate_hz_s = 0.3 * rates.normal();
                errors(&base.with_drift(Drift { rate_hz_s }), seed)
            })
            .collect();
        let (one, two) = (within(&drifting, 1.0), within(&drifting, 2.0));
        let case = format!("{phantom} {setting}");
        eprintln!(
            "{case}: offset {offset:+.4} Hz; under drift {} readings: {:.1} % within 1σ, {:.1} % within 2σ; without: {:.1} %",
            drifting.len(),
            100.0 * one,
            100.0 * two,
            100.0 * within(&still, 1.0)
        );
        assert!(drifting.len() >= 1000, "{case}: {}", drifting.len());
        assert!((0.60..=0.80).contains(&one), "{case}: {one}");
        assert!((0.90..=0.99).contains(&two), "{case}: {two}");
        assert!(within(&still, 1.0) > 0.9, "{case}: {}", within(&still, 1.0));
    }
}

/// Issue 28's diagnosis (docs/methods.md, "Why the tracker carries `Q`, and then `f0`"): with
/// nothing carried between segments (`drift` and `q_drift` at 100, the filter forgets at once),
/// a segment's `f0` error follows its `Q` error times the offset drive's sign (correlation above
/// 0.7: measured 0.85), and successive readings' errors are uncorrelated (|ρ| < 0.2: −0.05); the
/// default tracker, which carries both, reads `f0` with less than half that error (measured
/// 0.009 against 0.037 Hz). Phantom C, noise seeds 0–4, the readings after 0.5 s, errors against
/// the scene's closed-form resonance and `Q` (each less its mean).
#[test]
fn a_segment_alone_ties_its_f0_to_its_q_through_the_offset_drive() {
    use hal_sim::{phantoms, Scene};
    use pzt_probe::instrument::continuous::TrackerConfig;
    let unit = default_for(METHOD).unwrap();
    let scene = Scene::on_phantom(&phantoms::by_name("C").unwrap()).with_noise(NoiseScene::Bench);
    let (f_true, q_true) = (scene.resonance_hz(), scene.q());
    // (f0 error Hz, Q error relative × the offset's sign, previous reading's f0 error).
    let errors = |cfg: &TrackerConfig| {
        let mut out = Vec::new();
        for seed in 0..5 {
            let mut v = Vec::new();
            pzt_probe::board::sim::stream(&scene, seed, cfg, &unit, 3.0, |r| v.push(*r)).unwrap();
            let mut prev = None;
            for r in v.iter().filter(|r| r.t_s.0 > 0.5) {
                let (Some(f), Some(q)) = (r.reading.resonance, r.reading.q) else {
                    prev = None;
                    continue;
                };
                // The first tracking segment (seq 1) drives above the estimate, then alternately.
                let side = if r.seq % 2 == 1 { 1.0 } else { -1.0 };
                let df = f.0 as f64 - f_true;
                out.push((df, side * (q as f64 / q_true - 1.0), prev));
                prev = Some(df);
            }
        }
        out
    };
    fn corr(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let c: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        c / (va * vb).sqrt()
    }
    fn sd(a: &[f64]) -> f64 {
        let n = a.len() as f64;
        let m = a.iter().sum::<f64>() / n;
        (a.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
    }
    let alone = errors(&TrackerConfig {
        drift: 100.0,
        q_drift: 100.0,
        ..TrackerConfig::DEFAULT
    });
    let df: Vec<f64> = alone.iter().map(|e| e.0).collect();
    let dq: Vec<f64> = alone.iter().map(|e| e.1).collect();
    let (now, before): (Vec<f64>, Vec<f64>) =
        alone.iter().filter_map(|e| Some((e.0, e.2?))).unzip();
    let carried: Vec<f64> = errors(&TrackerConfig::DEFAULT)
        .iter()
        .map(|e| e.0)
        .collect();
    let (rho, lag) = (corr(&df, &dq), corr(&now, &before));
    eprintln!(
        "alone: f0 sd {:.4} Hz, ρ(f0, ±Q) {rho:.2}, ρ(successive) {lag:.2}; carried: f0 sd {:.4} Hz",
        sd(&df),
        sd(&carried)
    );
    assert!(df.len() >= 250, "{}", df.len());
    assert!(rho > 0.7, "{rho}");
    assert!(lag.abs() < 0.2, "{lag}");
    assert!(
        sd(&carried) < 0.5 * sd(&df),
        "{} vs {}",
        sd(&carried),
        sd(&df)
    );
}
