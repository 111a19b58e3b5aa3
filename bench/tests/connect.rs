//! `probe-bench connect` against the firmware image in QEMU (issue #27): the host link carries
//! the same reading as the image's own script (`measure --qemu`), and a 3 s stream of phantom C
//! at ≥ 20 ok readings per second after the first 0.5 s, with the link's `seq` and the stream's
//! `stream_seq` both without gaps. Needs qemu-system-arm and the thumbv7em-none-eabihf target
//! (as `measure --qemu`); without them the tests fail naming what is missing.

mod common;

use common::{bin, run_ok};
use probe_bench::link::{Kind, Link, Received};
use serde_json::Value;
use std::time::Duration;

fn readings(stdout: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v.get("status").is_some())
        .collect()
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64()
        .unwrap_or_else(|| panic!("{k} missing in {v}"))
}

#[test]
fn connect_qemu_reads_phantom_b_as_measure_qemu_does() {
    let link = run_ok(bin().args([
        "connect",
        "qemu",
        "--phantom",
        "B",
        "--json",
        "-c",
        "sim seed 0",
        "-c",
        "measure",
    ]));
    let script = run_ok(bin().args(["measure", "--phantom", "B", "--qemu", "--json"]));
    let (a, b) = (readings(&link.stdout), readings(&script.stdout));
    assert_eq!((a.len(), b.len()), (1, 1), "one reading each");
    let (a, b) = (&a[0], &b[0]);
    // The same JSON fields from the same reporter.
    let keys = |v: &Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(a), keys(b));
    for k in ["status", "method", "message", "points"] {
        assert_eq!(a[k], b[k], "{k}");
    }
    assert_eq!(a["status"], "ok");
    // The same phantom through the same firmware: the two readings (noise realisations of the
    // same simulated probe, taken at different probe times) agree within their
    // repeatability, and each is phantom B (279 kPa) within its combined σ.
    for (k, sigma) in [
        ("modulus_kpa", "modulus_repeatability_kpa"),
        ("resonance_hz", "resonance_sigma_hz"),
    ] {
        let s = f(a, sigma).hypot(f(b, sigma));
        assert!(
            (f(a, k) - f(b, k)).abs() <= 4.0 * s,
            "{k}: {} vs {} (σ of the difference {s})",
            f(a, k),
            f(b, k)
        );
    }
    for r in [a, b] {
        assert!(
            (f(r, "modulus_kpa") - 279.0).abs() <= 3.0 * f(r, "modulus_sigma_kpa"),
            "{r}"
        );
    }
    eprintln!("connect: {a}\nmeasure --qemu: {b}");
}

#[test]
fn a_three_second_stream_of_phantom_c_over_the_link_has_no_gap() {
    let elf = probe_bench::qemu::build_image().unwrap();
    let scene = ["sim phantom C".to_owned(), "sim seed 0".to_owned()];
    let mut link = Link::qemu(&elf, &scene, None).unwrap();
    link.hello().unwrap();
    let id = link.command("stream 3").unwrap();
    let mut frames = Vec::new();
    loop {
        match link.recv(Duration::from_secs(300)) {
            Some(Received::Frame(f)) => {
                let end = matches!(f.kind, Kind::Reply { id: r, .. } if r == id);
                frames.push(f);
                if end {
                    break;
                }
            }
            other => panic!("the link gave {other:?}"),
        }
    }
    // The link: every message the probe made arrived (seq without gaps, nothing dropped).
    for w in frames.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1, "link seq gap");
    }
    assert!(frames.iter().all(|f| f.dropped == 0));
    let stream: Vec<_> = frames
        .iter()
        .filter_map(|f| match &f.kind {
            Kind::Stream(s) => Some(*s),
            _ => None,
        })
        .collect();
    let (start, made, dropped) = frames
        .iter()
        .find_map(|f| match f.kind {
            Kind::StreamEnd(e) => Some((e.start_s as f64, e.readings, e.dropped)),
            _ => None,
        })
        .expect("a stream end");
    // The stream: numbered from 0 without gaps, every reading the tracker made.
    for (k, s) in stream.iter().enumerate() {
        assert_eq!(s.seq, k as u32, "stream seq gap");
    }
    assert_eq!((stream.len() as u32, dropped), (made, 0));
    let after: Vec<_> = stream
        .iter()
        .filter(|s| s.t_s.0 as f64 - start >= 0.5)
        .collect();
    let span = after.last().unwrap().t_s.0 as f64 - start - 0.5;
    let ok = after.iter().filter(|s| s.reading.status.is_ok()).count();
    let rate = ok as f64 / span;
    eprintln!(
        "stream over the link: {} readings, {ok} ok in {span:.2} s after 0.5 s: {rate:.1} ok/s; {} frames, link seq {}..{}",
        stream.len(),
        frames.len(),
        frames[0].seq,
        frames.last().unwrap().seq
    );
    assert!(rate >= 20.0, "{rate:.1} ok readings/s");
}
