//! The firmware's continuous mode in QEMU (#14): `stream <seconds>` on the simulated probe,
//! through the same session, tracker and pipeline as on the host, its defmt log decoded.
//!
//! One image run, five streams (`sim` lines put the probe on each scene, whose events count
//! from the scene's start, 10 ms before the stream's command); every stream's `seq` runs from 0
//! without gaps (or gaps exactly the dropped count of the `stream end` line):
//! - phantom C for 3 s: at least 25 `ok` readings per second after the first 0.5 s, RMS
//!   error within 1.5× the steady-state bound of a 30 ms segment (issue 28);
//! - phantom C lifted off 1.5 s into the scene: no `ok` reading later than 0.1 s after;
//! - phantom B stepping to D 1 s in: within 3 % of D within 0.25 s;
//! - phantom C pressed at 30 % of the preload 1 s in: no `ok` reading later than 0.1 s after
//!   (the force window says `too_light`);
//! - phantom C for 3 s with the fast setting (`stream 3 0.012 4`: segments of 12 ms, four a
//!   plan): at least 50 `ok` readings per second after the first 0.5 s, RMS error at most
//!   0.5 % of the truth.
//!
//! The image exits with success only when no sample-interrupt overrun happened: the stream
//! never held the sample interrupt up.

#[allow(dead_code)] // build_and_run, last: not used here
mod qemu_support;

use qemu_support::log_fields::{fields, num, Fields};
use qemu_support::{build_image, require_tools, run_script};
use std::collections::HashMap;
use std::time::Duration;

const SCRIPT: &str = "sim phantom C;stream 3;\
sim phantom C;sim lift-off 1.5;stream 2.5;\
sim phantom B;sim step D 1;stream 2;\
sim phantom C;sim press 0.3 1;stream 2;\
sim phantom C;stream 3 0.012 4";

/// One stream: its readings and its end line.
struct Stream {
    readings: Vec<HashMap<String, String>>,
    end: HashMap<String, String>,
}

impl Stream {
    fn start(&self) -> f64 {
        num(&self.end, "start_s")
    }
    fn ok(&self) -> Vec<(f64, f64)> {
        self.readings
            .iter()
            .filter(|r| r["status"] == "ok")
            .map(|r| (num(r, "t_s"), num(r, "e_kpa")))
            .collect()
    }
    /// `seq` from 0, gaps exactly the dropped count, the end's counts those of the lines.
    fn check_numbering(&self, who: &str) {
        let readings = num(&self.end, "readings") as usize;
        let dropped = num(&self.end, "dropped") as usize;
        let mut expect = 0usize;
        let mut gaps = 0usize;
        for r in &self.readings {
            let seq = num(r, "seq") as usize;
            assert!(seq >= expect, "{who}: seq {seq} after {expect}");
            gaps += seq - expect;
            expect = seq + 1;
        }
        gaps += readings - expect;
        assert_eq!(gaps, dropped, "{who}: gaps in seq vs dropped");
        assert_eq!(self.readings.len() + dropped, readings, "{who}");
        let ok = self.readings.iter().filter(|r| r["status"] == "ok").count();
        if dropped == 0 {
            assert_eq!(ok, num(&self.end, "ok") as usize, "{who}");
        }
    }
}

fn streams(parsed: &[Fields]) -> Vec<Stream> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for (name, m) in parsed {
        if name != "stream" {
            continue;
        }
        if m.contains_key("seq") {
            cur.push(m.clone());
        } else {
            out.push(Stream {
                readings: std::mem::take(&mut cur),
                end: m.clone(),
            });
        }
    }
    out
}

/// No `ok` reading ends later than `after` s of probe time.
fn no_ok_after(s: &Stream, after: f64, who: &str) {
    let late: Vec<_> = s.ok().into_iter().filter(|(t, _)| *t > after).collect();
    assert!(
        late.is_empty(),
        "{who}: ok readings after {after:.3} s: {late:?}"
    );
    assert!(!s.ok().is_empty(), "{who}: no ok reading before the event");
}

/// A stream of phantom C (414 kPa) for 3 s: at least `min_rate` ok readings/s after the first
/// 0.5 s, their RMS relative error at most `max_rms`.
fn phantom_c(c: &Stream, min_rate: f64, max_rms: f64, who: &str) {
    let t0 = c.start() + 0.5;
    let last = c.readings.iter().map(|r| num(r, "t_s")).fold(0.0, f64::max);
    assert!(last >= c.start() + 3.0, "{who}: the stream ran {last} s");
    let ok: Vec<_> = c.ok().into_iter().filter(|(t, _)| *t > t0).collect();
    let rate = ok.len() as f64 / (last - t0);
    let rms = (ok
        .iter()
        .map(|(_, e)| (e / 414.0 - 1.0).powi(2))
        .sum::<f64>()
        / ok.len() as f64)
        .sqrt();
    println!(
        "{who}: {} readings, {} ok after 0.5 s: {rate:.1} ok/s, RMS error {:.3} %, dropped {}, plan work max {}",
        c.readings.len(),
        ok.len(),
        100.0 * rms,
        c.end["dropped"],
        c.end["plan_work"]
    );
    assert!(rate >= min_rate, "{who}: {rate:.1} ok readings/s");
    assert!(rms <= max_rms, "{who}: RMS error {:.3} %", 100.0 * rms);
}

#[test]
fn qemu_streams_phantom_c_and_follows_lift_off_step_and_press() {
    require_tools();
    let elf = build_image("probe");
    let (exited_ok, lines) = run_script(&elf, Duration::from_secs(600), Some(SCRIPT));
    for l in lines.iter().filter(|l| !l.contains("stream seq=")) {
        println!("{l}");
    }
    let parsed: Vec<Fields> = lines.iter().filter_map(|l| fields(l)).collect();
    assert!(
        !lines.iter().any(|l| l.contains("overrun")),
        "the sample interrupt overran"
    );
    assert!(exited_ok, "the image's script failed");
    let s = streams(&parsed);
    assert_eq!(s.len(), 5, "five streams");
    for (k, x) in s.iter().enumerate() {
        x.check_numbering(&format!("stream {k}"));
    }

    // Issue 28 on the image as on the host: the default setting at least 25 ok readings a
    // second within 1.5× the steady-state bound of its 30 ms segment on C (0.0455 %, `probe-bench
    // pareto`, docs/speed-accuracy.md: one stream of 3 s, so a few tens of percent of seed
    // noise on its RMS); a setting at least 50 a second within 0.5 %.
    phantom_c(&s[0], 25.0, 1.5 * 0.000455, "phantom C");
    phantom_c(&s[4], 50.0, 0.005, "phantom C, 12 ms segments, four a plan");

    // Lift-off 1.5 s into the scene, which starts at most 15 ms before the stream: the tip is
    // off by start + 1.5 s.
    let lift = s[1].start() + 1.5;
    no_ok_after(&s[1], lift + 0.1, "lift-off");
    println!(
        "lift-off at ≤ {lift:.3} s: last ok at {:.3} s",
        s[1].ok().last().map_or(f64::NAN, |x| x.0)
    );

    // B → D 1 s in: within 3 % of D (1146 kPa) from step + 0.25 s on, every ok reading.
    let step = s[2].start() + 1.0;
    let before: Vec<_> = s[2]
        .ok()
        .into_iter()
        .filter(|(t, _)| *t < step - 0.02)
        .collect();
    assert!(
        before.iter().all(|(_, e)| (e / 279.0 - 1.0).abs() < 0.03),
        "{before:?}"
    );
    let after: Vec<_> = s[2]
        .ok()
        .into_iter()
        .filter(|(t, _)| *t > step + 0.25)
        .collect();
    assert!(after.len() >= 10, "{after:?}");
    assert!(
        after.iter().all(|(_, e)| (e / 1146.0 - 1.0).abs() < 0.03),
        "{after:?}"
    );
    let first = s[2]
        .ok()
        .into_iter()
        .find(|(t, e)| *t > step && (e / 1146.0 - 1.0).abs() < 0.03)
        .map_or(f64::NAN, |x| x.0);
    println!("step B→D at ≤ {step:.3} s: within 3 % of D from {first:.3} s");

    // The press falls to 9 mN 1 s in: too light, no ok reading after.
    let press = s[3].start() + 1.0;
    no_ok_after(&s[3], press + 0.1, "press 30 %");
    assert!(s[3].readings.iter().any(|r| r["status"] == "too_light"));
}
