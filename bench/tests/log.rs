//! `probe-bench log`: the parser's templates are the firmware's format strings, lines formatted
//! through them parse back to the same values, and a real decoded QEMU log reconstructs the
//! reading the firmware made.

mod common;
use common::{bin, run_fails_one_line, run_ok, run_ok_containing, Scratch};

use probe_bench::defmt_log::{self, compile, parse_line, render, Piece, Ty, Value, TEMPLATES};
use pzt_probe::engine::sweep::SweepPoint;
use pzt_probe::{Hz, Method};
use std::collections::BTreeSet;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every format string passed to `defmt::{trace,debug,info,warn,error}!` in the firmware, and
/// to the log module's `reading_line!` (which hands its format to `defmt::info!`).
fn firmware_formats() -> BTreeSet<String> {
    // The RTIC application and the instrument layer (its log module, its folders) log; the boards' own
    // lines (the QEMU board's watchdog) and the cost image's are not the instrument's log.
    let mut files = vec![root().join("src/bin/probe.rs")];
    let mut dirs = vec![root().join("src/instrument")];
    while let Some(dir) = dirs.pop() {
        for e in std::fs::read_dir(&dir).expect("src/instrument") {
            let path = e.expect("entry").path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                files.push(path);
            }
        }
    }
    let src = files
        .iter()
        .map(|f| std::fs::read_to_string(f).expect("read"))
        .collect::<Vec<_>>()
        .join("\n");
    let mut out = BTreeSet::new();
    let macros = ["trace!(", "debug!(", "info!(", "warn!(", "error!("]
        .map(|m| format!("defmt::{m}"))
        .into_iter()
        .chain(["reading_line!(".to_owned()]);
    for pat in macros {
        let mut rest = src.as_str();
        while let Some(i) = rest.find(&pat) {
            rest = &rest[i + pat.len()..];
            let t = rest.trim_start();
            if let Some(body) = t.strip_prefix('"') {
                if let Some(end) = body.find('"') {
                    out.insert(body[..end].to_owned());
                }
            }
        }
    }
    out
}

#[test]
fn templates_are_the_firmwares_format_strings() {
    let fw = firmware_formats();
    // Structured messages only: the panic handler's `{}` is free text.
    let structured: BTreeSet<String> = fw.into_iter().filter(|f| !f.contains("{}")).collect();
    let ours: BTreeSet<String> = TEMPLATES.iter().map(|s| s.to_string()).collect();
    let missing: Vec<_> = structured.difference(&ours).collect();
    let stale: Vec<_> = ours.difference(&structured).collect();
    assert!(
        missing.is_empty() && stale.is_empty(),
        "firmware formats unknown to the parser: {missing:?}; parser templates the firmware no longer logs: {stale:?}"
    );
    for t in TEMPLATES {
        assert!(compile(t).is_some(), "{t}");
    }
}

/// Sample values for a template: distinct per field, with awkward floats.
fn sample(template: &str, salt: u32) -> Vec<Value> {
    let floats = [
        227.9683f32,
        1.9323245e-8,
        -3.5e-7,
        0.040545568,
        f32::NAN,
        1e10,
        0.0,
    ];
    let mut k = salt as usize;
    compile(template)
        .unwrap()
        .into_iter()
        .filter_map(|p| match p {
            Piece::Field(key, ty) => {
                k += 1;
                Some(match ty {
                    Ty::F32 => Value::F32(floats[k % floats.len()] * (1.0 + salt as f32)),
                    Ty::Uint => Value::Uint(k as u32 * 7 + salt),
                    Ty::Bool => Value::Bool(k.is_multiple_of(2)),
                    Ty::Str if key == "error" => {
                        Value::Str("stop frequency must be above start frequency".into())
                    }
                    Ty::Str => Value::Str(format!("{key}-{salt}")),
                })
            }
            Piece::Literal(_) => None,
        })
        .collect()
}

fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::F32(x), Value::F32(y)) => x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
        _ => a == b,
    }
}

#[test]
fn firmware_lines_round_trip_through_the_parser() {
    // Frames of the decoders: scripts/qemu-run (`{L} {s}`), defmt-print with time and location,
    // probe-rs style, colour codes.
    let frames: [(&str, &str, Option<f64>); 5] = [
        ("INFO  ", "", None),
        (
            "0.001234 [INFO ] ",
            " (src/bin/probe.rs:771 )",
            Some(0.001234),
        ),
        ("<time> [WARN ] ", " (src/bin/probe.rs:12)", None),
        ("12.500000 ERROR ", "", Some(12.5)),
        ("\u{1b}[32mINFO \u{1b}[0m ", "", None),
    ];
    for (salt, t) in TEMPLATES.iter().enumerate() {
        let values = sample(t, salt as u32);
        let msg = render(t, &values).expect("values fit");
        for (pre, post, time) in frames {
            let line = format!("{pre}{msg}{post}");
            let m = parse_line(7, &line)
                .unwrap_or_else(|e| panic!("{line}: {e}"))
                .unwrap_or_else(|| panic!("not recognised: {line}"));
            assert_eq!(TEMPLATES[m.template], *t, "{line}");
            assert_eq!(m.at.line, 7);
            assert_eq!(m.at.time_s, time, "{line}");
            assert_eq!(m.fields.len(), values.len());
            for ((_, got), want) in m.fields.iter().zip(&values) {
                assert!(same(got, want), "{line}: {got:?} vs {want:?}");
            }
        }
    }
    // Not messages: location lines, other output.
    assert_eq!(
        parse_line(1, "└─ probe::app::report @ src/bin/probe.rs:771").unwrap(),
        None
    );
    assert_eq!(parse_line(1, "(HOST) INFO  flashing done").unwrap(), None);
    // A recognised message with a broken value is an error naming its line.
    let e = parse_line(9, "INFO  point tag=x f_hz=1.0 g_s=1.0 b_s=1.0 sigma_s=1.0").unwrap_err();
    assert_eq!(e.line, 9);
    assert!(e.to_string().contains("tag=x"), "{e}");
}

#[test]
fn qemu_log_reconstructs_the_firmwares_reading() {
    let text = std::fs::read_to_string(root().join("tests/data/log/qemu_session.log")).unwrap();
    let located =
        std::fs::read_to_string(root().join("tests/data/log/qemu_session_located.log")).unwrap();
    let s = defmt_log::parse_log(&text);
    assert_eq!(s, {
        let mut l = defmt_log::parse_log(&located);
        // Same run, different frames: identical but for the header comment line's text.
        l.other_lines = s.other_lines;
        l
    });
    assert!(s.errors.is_empty(), "{:?}", s.errors);
    // The built-in script: a reading by the default method (auto, whose first stage, hold,
    // read it: no admittance points), then one by sweep-G over a sweep of the script's own.
    assert_eq!(s.readings.len(), 2);
    assert_eq!(s.sweeps.len(), 1);
    assert_eq!(s.readings[0].msg.method, "hold");
    let r = &s.readings[1];
    let w = &s.sweeps[0];
    assert_eq!(r.msg.status, "ok");
    assert_eq!(r.msg.method, "sweep-g");
    assert_eq!(w.reading, Some(1));
    assert_eq!(r.msg.points as usize, w.points.len());
    assert!(w
        .points
        .iter()
        .enumerate()
        .all(|(k, p)| p.tag as usize == k + 1));
    // The settings in force were the second `settings` line (200–260 Hz).
    let set = w.settings.as_ref().unwrap();
    assert_eq!(
        (set.f32("start_hz"), set.f32("stop_hz")),
        (Some(200.0), Some(260.0))
    );
    // The firmware's estimator on the logged points gives the logged resonance again.
    let pts: Vec<SweepPoint> = w
        .points
        .iter()
        .map(|p| SweepPoint {
            freq: Hz(p.f_hz),
            g_s: p.g_s,
            b_s: p.b_s,
            sigma_s: p.sigma_s,
            // The log carries admittance, not current: the current at the logged 5 V drive.
            current_a: p.g_s.hypot(p.b_s) * 5.0,
            drive_v: 5.0,
            clip_fraction: 0.0,
            residual_a: 0.0,
        })
        .collect();
    let est = Method::SweepG.estimate(&pts).unwrap();
    let f = r.msg.f_hz.unwrap();
    assert!(
        (est.resonance.0 - f).abs() < 1e-3,
        "{} vs {f}",
        est.resonance.0
    );
    assert!((est.sigma.0 / r.msg.f_sigma_hz.unwrap() - 1.0).abs() < 1e-3);
    // And the image's calibration (its factory profile: its curve at the logged contact
    // force) maps it to the logged modulus.
    let unit = pzt_probe::board::sim_factory::profile().expect("factory record");
    let force = r.to_reading().and_then(|x| x.force);
    assert!(force.is_some(), "the reading logs its contact force");
    let t = pzt_probe::Seconds(r.msg.probe_time_s);
    assert!(t.0.is_finite(), "no probe time logged");
    let m = unit.invert(Hz(f), Hz(0.0), force.as_ref(), t).unwrap();
    assert!(
        (m.value.0 / r.msg.e_kpa.unwrap() - 1.0).abs() < 1e-4,
        "{} vs {:?}",
        m.value.0,
        r.msg.e_kpa
    );
}

#[test]
fn readings_sweeps_and_events_of_a_longer_log() {
    let pt = |t: f64, tag: u32, f: f32, g: f32| {
        let v = [
            Value::Uint(tag),
            Value::F32(f),
            Value::F32(g),
            Value::F32(3e-7),
            Value::F32(1e-10),
        ];
        format!("{t:.6} [INFO ] {}", render(TEMPLATES[6], &v).unwrap())
    };
    let reading = |t: f64, status: &str, f: f32, n: u32| {
        let v = [
            Value::Str(status.into()),
            Value::F32(f),
            Value::F32(if f.is_nan() { f32::NAN } else { 0.05 }),
            Value::F32(if status == "ok" { 280.0 } else { f32::NAN }),
            Value::F32(if status == "ok" { 5.0 } else { f32::NAN }),
            Value::F32(if status == "ok" { 0.5 } else { f32::NAN }),
            Value::F32(10.0),
            Value::F32(1.2),
            Value::Uint(n),
            Value::Str("sweep-g".into()),
            Value::F32(0.030),
            Value::F32(1e-5),
            Value::F32(if status == "ok" { 0.12 } else { f32::NAN }),
            Value::F32(if status == "ok" { 0.05 } else { f32::NAN }),
        ];
        format!("{t:.6} [INFO ] {}", render(TEMPLATES[7], &v).unwrap())
    };
    let mut lines = vec![
        "0.000010 [INFO ] boot board=stm32 fs_hz=10000.0 batch=50".to_owned(),
        "└─ probe::app::init @ src/bin/probe.rs:285".to_owned(),
    ];
    for k in 0..3 {
        lines.push(pt(1.0, k + 1, 220.0 + k as f32, 1e-7));
    }
    lines.push(reading(1.5, "ok", 227.5, 3));
    lines.push(
        "2.000000 [WARN ] rejected error=stop frequency must be above start frequency".into(),
    );
    lines.push(pt(3.0, 1, 220.0, 1e-7));
    lines.push("3.100000 [ERROR] stalled tag=2".into());
    lines.push(reading(4.0, "no_contact", f32::NAN, 0));
    lines.push(pt(5.0, 1, 180.0, 2e-8));
    lines.push(pt(5.1, 2, 182.0, 2e-8));
    lines.push(reading(5.5, "out_of_band", 170.0, 2));
    let s = defmt_log::parse_log(&lines.join("\n"));
    assert!(s.errors.is_empty());
    assert_eq!(s.readings.len(), 3);
    assert_eq!(
        s.readings
            .iter()
            .map(|r| r.msg.status.as_str())
            .collect::<Vec<_>>(),
        ["ok", "no_contact", "out_of_band"]
    );
    assert_eq!(s.readings[0].at.time_s, Some(1.5));
    assert_eq!(s.readings[0].msg.e_kpa, Some(280.0));
    assert_eq!(s.readings[1].msg.f_hz, None);
    assert_eq!(s.readings[1].msg.e_kpa, None);
    assert_eq!(s.readings[1].sweep, None);
    // Sweeps: 3 points (reading 1), 1 abandoned by the stall, 2 points (reading 3).
    assert_eq!(s.sweeps.len(), 3);
    assert_eq!(s.sweeps[0].points.len(), 3);
    assert_eq!(s.sweeps[0].reading, Some(0));
    assert_eq!(s.sweeps[1].reading, None);
    assert_eq!(s.sweeps[2].reading, Some(2));
    assert_eq!(s.readings[2].sweep, Some(2));
    // Events: boot, rejected (its message with spaces), stalled.
    let ev: Vec<String> = s.events.iter().map(|e| e.text()).collect();
    assert_eq!(ev.len(), 3, "{ev:?}");
    assert!(ev[1].ends_with("error=stop frequency must be above start frequency"));
    assert_eq!(s.other_lines, 1);
}

#[test]
fn cli_table_stdin_plot_and_errors() {
    use std::io::Write;
    let log = root().join("tests/data/log/qemu_session.log");
    let dir = Scratch::new("log");
    let svg = dir.join("log.svg");
    run_ok_containing(
        bin().arg("log").arg(&log).arg("--plot").arg(&svg),
        &["227.976 ± 0.043", "280.3 ± 3.6", "29.96 ± 0.01"],
    );
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // stdin, JSON.
    let mut child = bin()
        .args(["log", "-", "--json"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(&std::fs::read(&log).unwrap())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["readings"][0]["status"], "ok");
    assert_eq!(j["sweeps"][0]["points"].as_array().unwrap().len(), 31);
    // Not a firmware log: one line, non-zero exit.
    run_fails_one_line(
        bin()
            .arg("log")
            .arg(root().join("tests/data/bvd_300kpa_y.csv")),
    );
}

/// A captured QEMU log of two streams (`tests/data/log/qemu_stream.log`, command in its first
/// line): phantom C for 1.5 s, then C lifted off 0.5 s into its scene. The streams, their
/// numbering, ok rate and the firmware's own counts are reconstructed.
#[test]
fn qemu_stream_log_gives_streams_their_rate_and_no_missing_readings() {
    let text = std::fs::read_to_string(root().join("tests/data/log/qemu_stream.log")).unwrap();
    let s = defmt_log::parse_log(&text);
    assert!(s.errors.is_empty(), "{:?}", s.errors);
    assert!(s.readings.is_empty());
    assert_eq!(s.streams.len(), 2);
    let c = &s.streams[0];
    let end = c.end.as_ref().expect("stream end");
    assert_eq!(c.missing(), 0);
    assert_eq!(end.dropped, 0);
    assert_eq!(end.readings as usize, c.readings.len());
    assert_eq!(end.ok as usize, c.ok());
    assert!(c
        .readings
        .iter()
        .enumerate()
        .all(|(k, r)| r.seq as usize == k));
    assert!(c.ok_per_s(0.5).unwrap() >= 20.0, "{:?}", c.ok_per_s(0.5));
    for r in &c.readings {
        let e = r.reading.msg.e_kpa.unwrap() as f64;
        assert!((e / 414.0 - 1.0).abs() < 0.03, "{r:?}");
        assert!(r.locked && r.reading.msg.method == "hold");
        assert!(r.reading.to_reading().is_some());
    }
    // The lift-off 0.5 s into the scene (which starts before the stream): nothing ok after.
    let l = &s.streams[1];
    let lift = l.start_s().unwrap() + 0.5;
    assert!(l.ok() > 0);
    assert!(l
        .readings
        .iter()
        .all(|r| r.reading.msg.status != "ok" || r.t_s <= lift + 0.1));
}

/// Readings lost on the link (lines cut out of the log) are counted from the gaps in `seq`,
/// also the last ones before the end line; without the end line a new stream starts where
/// the numbering starts again.
#[test]
fn missing_stream_readings_are_counted_from_seq_gaps() {
    let text = std::fs::read_to_string(root().join("tests/data/log/qemu_stream.log")).unwrap();
    let cut: String = text
        .lines()
        .filter(|l| {
            ![
                "stream seq=3 ",
                "stream seq=4 ",
                "stream seq=10 ",
                "stream seq=35 ",
            ]
            .iter()
            .any(|p| l.contains(p))
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let s = defmt_log::parse_log(&cut);
    assert_eq!(s.streams.len(), 2);
    // Stream 1 loses 3, 4, 10 and its last reading (35 of 36); stream 2 loses 3, 4, 10.
    assert_eq!(s.streams[0].missing(), 4);
    assert_eq!(s.streams[1].missing(), 3);
    // No end lines: the streams split where seq starts again from 0.
    let no_end: String = text
        .lines()
        .filter(|l| !l.contains("stream end"))
        .map(|l| format!("{l}\n"))
        .collect();
    let s = defmt_log::parse_log(&no_end);
    assert_eq!(s.streams.len(), 2);
    assert!(s
        .streams
        .iter()
        .all(|x| x.end.is_none() && x.missing() == 0));
    // The CLI says so.
    let dir = Scratch::new("stream-log");
    let f = dir.join("cut.log");
    std::fs::write(&f, &cut).unwrap();
    run_ok_containing(
        bin().arg("log").arg(&f),
        &[
            "2 streams",
            "32 readings logged, 4 missing",
            "firmware: 36 readings, 0 dropped",
        ],
    );
    let out = run_ok(bin().arg("log").arg(&f).arg("--json"));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["streams"][0]["missing"], 4);
    assert_eq!(j["streams"][0]["end"]["dropped"], 0);
    assert_eq!(j["streams"][1]["readings"][0]["seq"], 0);
}
