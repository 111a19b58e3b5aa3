//! On-target cost of every estimation method: build the QEMU-only cost image
//! (`src/bin/cost.rs`), run it on `mps2-an386` with instruction counting, and check every
//! method's per-sample and per-reading work against the budget — 1 % per sample (the sample
//! engine's worst batch) and 2 % per reading of a 170 MHz core at the
//! firmware's 10 kHz sample rate — and that every reading ended as it should.
//!
//! Prints the figures as the markdown tables of `docs/firmware.md`
//! (`cargo test --test qemu_cost -- --nocapture`).
//!
//! Needs `qemu-system-arm`, `defmt-print` and the `thumbv7em-none-eabihf` target. Without them
//! the test fails with the command that installs each (it never passes by skipping).

mod qemu_support;

use pzt_probe::Method;
use qemu_support::build_and_run;
use qemu_support::log_fields::{all, fields, last, num};
use std::collections::{BTreeSet, HashMap};
use std::time::Duration;

/// A run takes about 4.5 min of wall time (260 s measured, the `calibrate fit` cases included).
const TIMEOUT: Duration = Duration::from_secs(900);
/// The budget: this share of the core (percent) ...
const BUDGET_PCT: f64 = 2.0;
/// ... and the sample engine's, in its worst batch (issue #28: the sample interrupt within 1 %).
const SAMPLE_BUDGET_PCT: f64 = 1.0;
/// ... of the STM32G474's core at 170 MHz, counting one cycle per instruction ...
const CORE_HZ: f64 = 170e6;
/// ... at the firmware's sample rate (`SAMPLE_RATE_HZ` of `src/board/stm32g474/mod.rs`; the
/// simulated front end of the QEMU image runs at the same rate).
const FIRMWARE_FS_HZ: f64 = 10_000.0;
/// Samples per batch.
const BATCH: f64 = pzt_probe::engine::BATCH as f64;
/// The largest single measurement call must leave the measurement task free to feed the
/// watchdog at its interval, µs (the STM32's independent watchdog bites after 500 ms).
const CALL_MAX_US: f64 = pzt_probe::instrument::watchdog::FEED.0 as f64 * 1e3;
/// Fewest moduli every method must have been measured at.
const MIN_MODULI: usize = 3;

/// A method known to exceed the per-reading budget or the call latency bound: why, and the
/// ceilings it must still stay under (stated tolerances, about 1.2–1.3 times the worst figure
/// measured when it was listed). Once a listed method is within budget everywhere, the entry is
/// stale and the test fails until it is struck from [`KNOWN_OVER_BUDGET`].
struct Known {
    method: &'static str,
    why: &'static str,
    /// Ceiling of the per-reading work, percent of the core.
    reading_pct: f64,
    /// Ceiling of the largest single call, µs at 170 MHz.
    call_us: f64,
}

/// The methods over budget (see `docs/firmware.md`): none.
const KNOWN_OVER_BUDGET: &[Known] = &[];

/// A `cost` line with its `split` line.
struct Case {
    cost: HashMap<String, String>,
    split: HashMap<String, String>,
}

impl Case {
    fn str(&self, k: &str) -> &str {
        self.cost
            .get(k)
            .unwrap_or_else(|| panic!("missing {k}"))
            .as_str()
    }
    fn num(&self, k: &str) -> f64 {
        num(&self.cost, k)
    }
    fn method(&self) -> &str {
        self.str("method")
    }
}

/// Relative agreement of a logged `f32` figure with its recomputation.
fn agrees(logged: f64, computed: f64) -> bool {
    (logged - computed).abs() <= 1e-4 * computed.abs().max(1e-9)
}

#[test]
fn every_method_fits_its_budget_on_target() {
    let (exited_ok, lines) = build_and_run("cost", TIMEOUT);
    let parsed: Vec<_> = lines.iter().filter_map(|l| fields(l)).collect();

    // The figures are stated for the budget of the issue.
    let budget = last(&parsed, "budget");
    assert_eq!(num(&budget, "core_hz"), CORE_HZ);
    assert_eq!(num(&budget, "fs_hz"), FIRMWARE_FS_HZ);
    assert_eq!(num(&budget, "batch"), BATCH);
    assert_eq!(num(&budget, "budget_pct"), BUDGET_PCT);
    assert_eq!(budget["unit"], "instructions");

    let costs: Vec<_> = parsed.iter().filter(|(n, _)| n == "cost").collect();
    let splits: Vec<_> = parsed.iter().filter(|(n, _)| n == "split").collect();
    assert_eq!(costs.len(), splits.len(), "one split line per cost line");
    let cases: Vec<Case> = costs
        .iter()
        .zip(&splits)
        .map(|((_, c), (_, s))| {
            assert_eq!(c["method"], s["method"]);
            assert_eq!(c["e_kpa"], s["e_kpa"]);
            Case {
                cost: c.clone(),
                split: s.clone(),
            }
        })
        .collect();

    // Every method of the firmware, at every modulus, each reading ok by the method itself
    // (auto: by one of its stages, hold, fit or sweep-G) — but paper, whose |Z| dip the
    // image's factory profile (calibrated on the motional resonance) does not map: its
    // readings end `uncalibrated`, after the same work.
    let nominal: Vec<&Case> = cases
        .iter()
        .filter(|c| c.str("expect") == "ok" || c.method() == "paper")
        .collect();
    let moduli: BTreeSet<u64> = nominal.iter().map(|c| c.num("e_kpa") as u64).collect();
    assert!(moduli.len() >= MIN_MODULI, "moduli {moduli:?}");
    for m in Method::ALL {
        for e in &moduli {
            let c = nominal
                .iter()
                .find(|c| c.method() == m.name() && c.num("e_kpa") as u64 == *e)
                .unwrap_or_else(|| panic!("{} at {e} kPa not measured", m.name()));
            let expect = if m == Method::Paper {
                "uncalibrated"
            } else {
                "ok"
            };
            assert_eq!(c.str("status"), expect, "{} at {e} kPa", m.name());
            let used = c.str("used");
            match m {
                Method::Auto => assert!(
                    ["hold", "fit", "sweep-g"].contains(&used),
                    "auto used {used}"
                ),
                _ => assert_eq!(used, m.name()),
            }
            assert!(c.num("points") > 0.0);
            assert_eq!(c.num("e_read_kpa") > 0.0, m != Method::Paper);
        }
    }
    // auto's fallback: hold and fit find nothing in the band, sweep-G runs and says so.
    let fallback: Vec<&Case> = cases
        .iter()
        .filter(|c| c.str("expect") != "ok" && c.method() != "paper")
        .collect();
    assert_eq!(fallback.len(), 1, "one fallback case");
    let fb = fallback[0];
    assert_eq!(fb.method(), "auto");
    assert_eq!(fb.str("used"), "sweep-g", "auto fell back to sweep-G");
    assert_eq!(fb.str("status"), fb.str("expect"));

    // Every figure, recomputed from the counts, against the budget.
    let mut over = Vec::new();
    for c in &cases {
        let who = format!("{} at {} kPa", c.method(), c.str("e_kpa"));
        let (mean, max) = (c.num("engine_mean"), c.num("engine_max"));
        assert!(c.num("batches") > 0.0 && mean > 0.0 && max >= mean, "{who}");
        let sample_pct = |per_batch: f64| per_batch / BATCH * FIRMWARE_FS_HZ / CORE_HZ * 100.0;
        let probe_time = c.num("probe_time_s");
        assert!(probe_time > 0.0, "{who}: probe time");
        let reading = c.num("reading");
        let reading_pct = reading / (probe_time * CORE_HZ) * 100.0;
        let call_max_us = c.num("call_max") / (CORE_HZ / 1e6);
        for (k, v) in [
            ("sample_mean_pct", sample_pct(mean)),
            ("sample_max_pct", sample_pct(max)),
            ("reading_pct", reading_pct),
            ("call_max_us", call_max_us),
        ] {
            assert!(agrees(c.num(k), v), "{who}: {k} {} ≠ {v}", c.num(k));
        }
        // The split by call adds up to the reading's total; the largest call is within it.
        let split: f64 = ["new", "next_plan", "accept", "is_complete", "finish"]
            .iter()
            .map(|k| num(&c.split, k))
            .sum();
        assert!(
            (split - reading).abs() < 1.0,
            "{who}: split {split} ≠ {reading}"
        );
        assert!(
            c.num("call_max") <= reading && c.num("calls") >= 3.0,
            "{who}"
        );

        // Per sample: the sample engine's worst batch (and so its mean).
        assert!(
            sample_pct(max) < SAMPLE_BUDGET_PCT,
            "{who}: per-sample max {:.2} %",
            sample_pct(max)
        );
        // Per reading: the measurement task's work over the reading's probe time; and the
        // largest single call, the latency of the priority-1 measurement task.
        let call = c.str("call_max_in");
        match KNOWN_OVER_BUDGET.iter().find(|k| k.method == c.method()) {
            None => {
                assert!(
                    reading_pct < BUDGET_PCT,
                    "{who}: per-reading work {reading_pct:.2} % of the core"
                );
                assert!(
                    call_max_us < CALL_MAX_US,
                    "{who}: a single {call} call takes {call_max_us:.0} µs at 170 MHz"
                );
            }
            Some(k) => {
                assert!(
                    reading_pct < k.reading_pct,
                    "{who}: {reading_pct:.2} % ≥ its ceiling {} %",
                    k.reading_pct
                );
                assert!(
                    call_max_us < k.call_us,
                    "{who}: a single {call} call of {call_max_us:.0} µs ≥ its ceiling {} µs",
                    k.call_us
                );
                if reading_pct >= BUDGET_PCT || call_max_us >= CALL_MAX_US {
                    over.push(format!(
                        "{who}: {reading_pct:.2} % of the core, {call} {call_max_us:.0} µs ({})",
                        k.why
                    ));
                }
            }
        }
    }
    for k in KNOWN_OVER_BUDGET {
        assert!(
            over.iter()
                .any(|o| o.starts_with(&format!("{} at ", k.method))),
            "{} is within budget now: strike it from KNOWN_OVER_BUDGET",
            k.method
        );
    }
    for o in &over {
        println!("KNOWN OVER BUDGET: {o}");
    }

    print_tables(&cases);
    check_fits(&parsed);
    check_streams(&parsed);
    assert_eq!(last(&parsed, "exit")["ok"], "true");
    assert!(exited_ok, "QEMU exit status");
}

/// The tables of `docs/firmware.md`: per method the worst case over the moduli, then every
/// reading with the split of its measurement work by call.
fn print_tables(cases: &[Case]) {
    let pct = |v: f64| format!("{v:.2} %");
    println!("\n| method | per sample: mean / max instructions | % of core | per reading: instructions / probe time | % of core | largest call | µs at 170 MHz |");
    println!("|---|---|---|---|---|---|---|");
    let mut methods: Vec<&str> = Vec::new();
    for c in cases.iter().filter(|c| c.str("expect") == "ok") {
        if !methods.contains(&c.method()) {
            methods.push(c.method());
        }
    }
    let rows = methods.into_iter().map(|m| (m.to_owned(), m, true)).chain(
        cases.iter().filter(|c| c.str("expect") != "ok").map(|c| {
            let label = format!(
                "{} at {} kPa ({}: {})",
                c.method(),
                c.str("e_kpa"),
                c.str("used"),
                c.str("status")
            );
            (label, c.method(), false)
        }),
    );
    for (label, m, nominal) in rows {
        let of = || {
            cases
                .iter()
                .filter(move |c| c.method() == m && (c.str("expect") == "ok") == nominal)
        };
        let worst = |k: &str| of().map(|c| c.num(k)).fold(0.0, f64::max);
        let heavy = of()
            .max_by(|a, b| a.num("reading_pct").total_cmp(&b.num("reading_pct")))
            .expect("a case");
        let slow = of()
            .max_by(|a, b| a.num("call_max").total_cmp(&b.num("call_max")))
            .expect("a case");
        println!(
            "| {label} | {:.0} / {:.0} | {} / {} | {:.2} M / {:.2} s | {} | {} ({:.2} M) | {:.0} |",
            worst("engine_mean") / BATCH,
            worst("engine_max") / BATCH,
            pct(worst("sample_mean_pct")),
            pct(worst("sample_max_pct")),
            heavy.num("reading") / 1e6,
            heavy.num("probe_time_s"),
            pct(heavy.num("reading_pct")),
            slow.str("call_max_in"),
            slow.num("call_max") / 1e6,
            slow.num("call_max_us"),
        );
    }
    println!("\n| method | E (kPa) | status (by) | probe time (s) | batches | engine mean / max per batch | new | next_plan | accept | is_complete | finish | total | % |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for c in cases {
        let k = |key: &str| format!("{:.0}", num(&c.split, key));
        println!(
            "| {} | {} | {} ({}) | {:.2} | {} | {} / {} | {} | {} | {} | {} | {} | {} | {} |",
            c.method(),
            c.str("e_kpa"),
            c.str("status"),
            c.str("used"),
            c.num("probe_time_s"),
            c.str("batches"),
            c.str("engine_mean"),
            c.str("engine_max"),
            k("new"),
            k("next_plan"),
            k("accept"),
            k("is_complete"),
            k("finish"),
            c.str("reading"),
            pct(c.num("reading_pct")),
        );
    }
}

/// `calibrate fit` on the M4 (`fit` lines): every case ended with a calibration, took at most
/// half the watchdog promise the firmware makes for its reference count
/// (`pzt_probe::instrument::watchdog::fit_bound`, recomputed here), and its milliseconds agree with its
/// instruction count at 170 MHz. Prints the table of `docs/firmware.md`.
fn check_fits(parsed: &[(String, HashMap<String, String>)]) {
    let fits = all(parsed, "fit");
    let names: Vec<&str> = fits.iter().map(|f| f["case"].as_str()).collect();
    assert_eq!(
        names,
        [
            "five-moduli",
            "sixteen-on-curve",
            "max-on-curve",
            "max-scattered",
            "factory-100",
            "factory-100-measured"
        ]
    );
    println!(
        "\n| case | references | instructions | ms at 170 MHz | promised (ms) | contact law kept |"
    );
    println!("|---|---|---|---|---|---|");
    for f in fits {
        let refs = num(f, "refs") as usize;
        let ms = num(f, "ms");
        let bound = pzt_probe::instrument::watchdog::fit_bound(refs).0 as f64;
        assert_eq!(f["ok"], "true", "{f:?}");
        assert_eq!(num(f, "bound_ms"), bound, "{f:?}");
        assert!(
            agrees(ms, num(f, "instructions") / (CORE_HZ / 1e3)),
            "{f:?}"
        );
        assert!(2.0 * ms <= bound, "the fit's promise is short: {f:?}");
        println!(
            "| {} | {refs} | {:.2} G | {ms:.0} | {bound:.0} | {} |",
            f["case"],
            num(f, "instructions") / 1e9,
            f["contact"]
        );
    }
}

/// The continuous tracker's known excess over the budget: (setting, ceiling of the measurement
/// side's work, % of the core, why). A reading every segment does a resonator fit of the plan's
/// windows so far (their solves, the tracker's filter and the pipeline besides): the default
/// setting, a reading every 37 ms, is within the budget; the fast one, a reading every 12.4 ms
/// (a plan's later segments update its first segment's fit), is not. Its ceiling is a tenth above the share
/// measured (docs/firmware.md), so that a change that costs more fails here; a setting that
/// comes within the budget fails here too until it is struck.
const STREAM_OVER_BUDGET: &[(&str, f64, &str)] = &[(
    "fast",
    3.5,
    "a reading every 12.4 ms, a plan's first segment fitted and each later one updating that fit: 0.067 M instructions a reading",
)];

/// The continuous tracker on the M4 (`stream` lines): the default setting and the fast one
/// (12 ms × 4) each streamed 1 s on 500 kPa, every tracking reading ok, and the measurement
/// side's work from the first tracking reading to the last (all but the sample engine's and the
/// plant's: the tracker, the pipeline and the plan loop) against the budget's 2 % of a 170 MHz
/// core over that probe time — a setting over it held to its ceiling in
/// [`STREAM_OVER_BUDGET`].
fn check_streams(parsed: &[(String, HashMap<String, String>)]) {
    let streams = all(parsed, "stream");
    let names: Vec<&str> = streams.iter().map(|f| f["setting"].as_str()).collect();
    assert_eq!(names, ["default", "fast"]);
    println!(
        "\n| tracker setting | readings | ok | probe time (s) | instructions | share of 170 MHz |"
    );
    println!("|---|---|---|---|---|---|");
    for f in streams {
        let (work, t) = (num(f, "work"), num(f, "probe_time_s"));
        assert!(num(f, "readings") >= 10.0, "{f:?}");
        assert_eq!(num(f, "ok"), num(f, "readings"), "{f:?}");
        assert!(
            agrees(num(f, "work_pct"), work / (t * CORE_HZ) * 100.0),
            "{f:?}"
        );
        let pct = num(f, "work_pct");
        match STREAM_OVER_BUDGET.iter().find(|k| k.0 == f["setting"]) {
            None => assert!(pct <= BUDGET_PCT, "over budget: {f:?}"),
            Some((setting, ceiling, why)) => {
                assert!(pct <= *ceiling, "above its ceiling {ceiling} %: {f:?}");
                assert!(
                    pct > BUDGET_PCT,
                    "{setting} is within budget now ({pct:.2} %): strike it from STREAM_OVER_BUDGET"
                );
                println!("known over budget ({pct:.2} % of the core): {why}");
            }
        }
        println!(
            "| {} | {} | {} | {t:.3} | {:.1} M | {:.2} % |",
            f["setting"],
            f["readings"],
            f["ok"],
            work / 1e6,
            num(f, "work_pct")
        );
    }
}
