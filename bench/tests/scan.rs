//! `probe-bench scan`: paper 003's coin sample reads the paper's two frequencies, and the lump's
//! centre is found within one grid step, for paper 003's coin and paper 002's ball.

mod common;
use common::scan::{bench_scene, centre_error, scan_json};
use common::{bin, run_fails_one_line, Scratch};

use hal_sim::lump::Inclusion;
use probe_bench::cmd::scan::{
    away_radius_mm, locate, mean_resonance, over_radius_mm, scan, slide_line, slide_over,
    ScanScene, ScanSpec,
};
use pzt_probe::{PowerLaw, Status};

/// Paper 003, section 4.2: 206.3 Hz away from the lump, 223.5 Hz over it.
const PAPER_AWAY_HZ: f64 = 206.3;
const PAPER_OVER_HZ: f64 = 223.5;

#[test]
fn coin_scan_reads_the_papers_frequencies_and_finds_the_coin() {
    let spec = ScanSpec::coin(1.5, -1.0, 2.0, bench_scene()).unwrap();
    let res = scan(&spec, || {}).unwrap();
    assert!(res.points.len() > 100);
    assert!(res.points.iter().all(|p| p.reading.status == Status::Ok));
    let inc = spec.phantom.inclusion;
    let over = mean_resonance(&res.points, &inc, |d| d <= over_radius_mm(&inc)).unwrap();
    let away = mean_resonance(&res.points, &inc, |d| d >= away_radius_mm(&inc)).unwrap();
    let (over, n_over, away, n_away) = (over.hz, over.points, away.hz, away.points);
    eprintln!("over the coin {over:.2} Hz ({n_over} points), away {away:.2} Hz ({n_away} points)");
    assert!(n_over >= 20 && n_away >= 10);
    assert!(
        (over - PAPER_OVER_HZ).abs() <= 3.0,
        "over the coin {over} Hz"
    );
    assert!(
        (away - PAPER_AWAY_HZ).abs() <= 3.0,
        "away from the coin {away} Hz"
    );
    // In modulus by paper eq. 5: 246.3 and 151.8 kPa in the paper.
    let cal = PowerLaw::paper_experiment();
    let e = |f: f64| {
        cal.invert(pzt_probe::Hz(f as f32), pzt_probe::Hz(0.0))
            .unwrap()
            .value
            .0 as f64
    };
    assert!((e(over) / 246.3 - 1.0).abs() < 0.10, "{}", e(over));
    assert!((e(away) / 151.8 - 1.0).abs() < 0.05, "{}", e(away));
    let l = res.lump.expect("the coin is found");
    let err = centre_error(&spec, l.x_mm, l.y_mm);
    eprintln!(
        "lump at ({:.2}, {:.2}) mm, {:.1} mm across; centre error {err:.2} mm",
        l.x_mm, l.y_mm, l.diameter_mm
    );
    assert!(err <= spec.step_mm, "centre off by {err} mm");
    // Its size: the coin's 19 mm within one grid step.
    assert!(
        (l.diameter_mm - 19.0).abs() <= spec.step_mm,
        "{} mm",
        l.diameter_mm
    );
}

#[test]
fn coin_elsewhere_is_found_where_it_is() {
    let spec = ScanSpec::coin(-3.3, 2.6, 2.0, bench_scene()).unwrap();
    let res = scan(&spec, || {}).unwrap();
    let l = res.lump.expect("the coin is found");
    let err = centre_error(&spec, l.x_mm, l.y_mm);
    assert!(
        err <= spec.step_mm,
        "centre off by {err} mm at ({}, {})",
        l.x_mm,
        l.y_mm
    );
}

#[test]
fn ball_is_found_along_the_path() {
    for d in [0.0, 12.5, 20.0] {
        let spec = ScanSpec::ball(d, 1.0, bench_scene()).unwrap();
        let res = scan(&spec, || {}).unwrap();
        let l = res
            .lump
            .unwrap_or_else(|| panic!("ball at {d} mm not found"));
        let err = centre_error(&spec, l.x_mm, l.y_mm);
        eprintln!("ball at {d} mm: found at ({:.2}, {:.2}) mm", l.x_mm, l.y_mm);
        assert!(
            err <= spec.step_mm,
            "ball at {d} mm: centre off by {err} mm"
        );
        // The ball stiffens the reading by several hertz over it.
        assert!(l.peak_hz - l.background_hz > 3.0);
    }
}

#[test]
fn no_lump_where_there_is_none() {
    // The coin sunk to 14 mm, on the table: the probe cannot feel it.
    let mut spec = ScanSpec::coin(0.0, 0.0, 2.0, bench_scene()).unwrap();
    spec.phantom.inclusion = Inclusion::Disc {
        x_m: 0.0,
        y_m: 0.0,
        radius_m: 9.5e-3,
        depth_m: 14e-3,
    };
    let res = scan(&spec, || {}).unwrap();
    assert!(res.lump.is_none(), "{:?}", res.lump);
    // And the locator on a flat map with one noisy point: a rise under 1 Hz is no lump.
    let mut pts = res.points.clone();
    if let Some(f) = pts[0].reading.resonance.as_mut() {
        f.0 += 0.5;
    }
    assert!(locate(&pts, spec.xs_mm.len(), spec.ys_mm.len(), 2.0).is_none());
}

#[test]
fn cli_writes_the_map() {
    let dir = Scratch::new("scan");
    let png = dir.join("scan.png");
    let j = scan_json(&[], &png);
    assert_eq!(j["scene"], "coin");
    let over = j["over_mean_hz"].as_f64().unwrap();
    assert!((over - PAPER_OVER_HZ).abs() <= 3.0);
    assert!(j["lump"]["x_mm"].as_f64().is_some());
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    // Negative coordinates are numbers, not options.
    let j = scan_json(
        &["--step-mm", "3", "--coin-at-mm", "-3", "2"],
        &dir.join("neg.svg"),
    );
    assert_eq!(j["true_centre_mm"][0].as_f64(), Some(-3.0));
    // Bad input: one line, non-zero exit.
    run_fails_one_line(bin().args(["scan", "--scene", "ball", "--ball-d-mm", "25"]));
}

/// `scan --continuous` (issue #14): sliding across the coin at 1–20 mm/s the stream finds the
/// coin's centre within 0.5 mm of where the same rule puts it on the closed-form apparent
/// modulus (measured: 0.00–0.18 mm, the tracker's lag of a segment or two at the edges) and its
/// contrast within 1 % (measured 0.1 %), with at least 15 ok readings a second on the path;
/// the coin moved to the other side is found there.
#[test]
fn a_sliding_scan_finds_the_coin() {
    for (k, (v, coin_x)) in [(1.0, 1.5), (5.0, 1.5), (20.0, 1.5), (5.0, -3.0)]
        .into_iter()
        .enumerate()
    {
        let phantom = hal_sim::lump::paper003_coin(coin_x, -1.0);
        let line = slide_line(ScanScene::Coin, -1.0);
        let r = slide_over(phantom, bench_scene(), line, v, 40 + k as u64).expect("a slide");
        let (found, truth) = (r.found.expect("found"), r.truth.expect("closed form"));
        assert!((truth.centre_mm - coin_x).abs() < 0.1, "{truth:?}");
        assert!(
            (found.centre_mm - truth.centre_mm).abs() <= 0.5,
            "{v} mm/s: {found:?} vs {truth:?}"
        );
        assert!((found.contrast / truth.contrast - 1.0).abs() <= 0.01);
        assert!(r.ok_rate() >= 15.0, "{v} mm/s: {} ok/s", r.ok_rate());
    }
}
