//! `probe-bench analyze`: golden captures against their known resonance, captures that must not
//! read ok, the time-domain demodulator, and one malformed file per error kind.

mod common;
use common::{bin, run_fails_one_line, run_json, run_ok, Scratch};

use hal_sim::{phantoms, Scene};
use probe_bench::capture::{self, CaptureError, DemodOptions, Layout, SweepShape};
use probe_bench::cmd::analyze::{analysis_json, analyze, offline_method, Analysis, Unit};
use probe_bench::gen;
use pzt_probe::unit::profile::NOMINAL_FORCE;
use pzt_probe::{Failure, Method, Status};
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data")
        .join(name)
}

fn read(name: &str) -> String {
    std::fs::read_to_string(data(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Paper 003's curve alone (`--calibration paper-experiment` without `--profile`: a modulus,
/// no Q model, no air reference).
/// The papers' curve maps the motional resonance; paper's |Z| dip is read with the simulated
/// unit's own paper calibration (a curve maps only the resonance it was calibrated on).
fn unit(method: Method) -> Unit {
    let curve = if method == Method::Paper {
        "unit"
    } else {
        "paper-experiment"
    };
    probe_bench::cmd::analyze::profile(None, Some(curve), method).expect("unit profile")
}

fn run(name: &str, method: Method) -> Analysis {
    analyze(
        &read(name),
        method,
        &unit(method),
        &DemodOptions::default(),
        NOMINAL_FORCE,
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// `run`, and the reading must be the failure `f` without a modulus.
fn refused(name: &str, method: Method, f: Failure) -> Analysis {
    let a = run(name, method);
    assert_eq!(a.reading.status, Status::Failed(f), "{name}, {method:?}");
    assert!(a.reading.modulus.is_none(), "{name}, {method:?}");
    a
}

/// Inverse of paper 003 eq. 5, written out independently of `PowerLaw::invert`.
fn f_e_inverse(f: f64) -> f64 {
    ((266.6 - f) / 2305.0).powf(1.0 / -0.7243)
}

/// The sweep-G estimate of each golden capture lies within 4 of its own standard uncertainties
/// of the scene's true resonance (the undamped natural frequency of the loaded mode, where the
/// BVD conductance peaks), and that uncertainty is small.
#[test]
fn golden_captures_read_their_true_resonance() {
    let cases: [(&str, Scene, Layout, f64); 5] = [
        (
            "sim_sweep_g_phantom_b.csv",
            Scene::on_phantom(&phantoms::B),
            Layout::Admittance,
            0.05,
        ),
        (
            "sim_paper_phantom_c_z.csv",
            Scene::on_phantom(&phantoms::C),
            Layout::Impedance,
            0.05,
        ),
        (
            "bvd_300kpa_y.csv",
            Scene::on_modulus_kpa(300.0),
            Layout::Admittance,
            0.05,
        ),
        (
            "bvd_1000kpa_z.csv",
            Scene::on_modulus_kpa(1000.0),
            Layout::Impedance,
            0.05,
        ),
        (
            "sim_time_stepped_phantom_b.csv",
            gen::daq_scene(&phantoms::B),
            Layout::TimeDomain,
            0.1,
        ),
    ];
    for (name, scene, layout, max_sigma) in cases
        .iter()
        .flat_map(|c| {
            // sweep-G and the BVD fit both estimate the motional resonance.
            [Method::SweepG, Method::Fit].map(|m| (c.0, c.1, c.2, c.3, m))
        })
        .map(|(n, s, l, ms, m)| ((n, m), s, l, ms))
    {
        let (name, method) = name;
        let a = run(name, method);
        let name = format!("{name} [{}]", method.name());
        assert_eq!(a.capture.layout, layout, "{name}");
        let r = a.reading;
        eprintln!(
            "{name}: {:?} ± {:?} Hz, true {:.4} Hz",
            r.resonance,
            r.resonance_sigma,
            scene.resonance_hz()
        );
        assert_eq!(r.status, Status::Ok, "{name}");
        let f = r.resonance.unwrap().0 as f64;
        let s = r.resonance_sigma.unwrap().0 as f64;
        let truth = scene.resonance_hz();
        assert!(s > 0.0 && s < max_sigma, "{name}: sigma {s}");
        assert!(
            (f - truth).abs() <= 4.0 * s + 1e-3,
            "{name}: {f} ± {s} Hz against true {truth} Hz"
        );
        // Q from the fit against the model's Q (loose: settling bias of the time-domain steps).
        let q = r.q.unwrap() as f64;
        assert!(
            (q / scene.q() - 1.0).abs() < 0.1,
            "{name}: Q {q} vs {}",
            scene.q()
        );
        // The modulus is paper eq. 5 inverted at the estimate.
        let e = r.modulus.unwrap().0 as f64;
        let e_ref = f_e_inverse(f);
        assert!((e / e_ref - 1.0).abs() < 1e-3, "{name}: {e} vs {e_ref} kPa");
        assert!(r.modulus_sigma.unwrap().0 > 0.0);
    }
}

/// Independent reference of the paper method: the maximum of `|Y|` above the straight line
/// through the band's end points, found on a 1 mHz grid of the closed form.
fn paper_dip_reference(scene: &Scene, f0: f64, f1: f64) -> f64 {
    let y0 = scene.admittance(f0).norm();
    let y1 = scene.admittance(f1).norm();
    let n = ((f1 - f0) * 1000.0) as usize;
    let mut best = (f0, f64::NEG_INFINITY);
    for k in 0..=n {
        let f = f0 + k as f64 * 1e-3;
        let d = scene.admittance(f).norm() - (y0 + (f - f0) / (f1 - f0) * (y1 - y0));
        if d > best.1 {
            best = (f, d);
        }
    }
    best.0
}

#[test]
fn paper_method_finds_the_closed_form_impedance_dip() {
    for (name, scene, f0, f1, tol) in [
        (
            "bvd_300kpa_y.csv",
            Scene::on_modulus_kpa(300.0),
            180.0,
            280.0,
            0.3,
        ),
        (
            "bvd_1000kpa_z.csv",
            Scene::on_modulus_kpa(1000.0),
            200.0,
            300.0,
            0.3,
        ),
    ] {
        let r = run(name, Method::Paper).reading;
        assert_eq!(r.status, Status::Ok, "{name}");
        let f = r.resonance.unwrap().0 as f64;
        let s = r.resonance_sigma.unwrap().0 as f64;
        let reference = paper_dip_reference(&scene, f0, f1);
        eprintln!("{name}: paper {f:.4} ± {s:.4} Hz, closed-form dip {reference:.4} Hz");
        assert!(
            (f - reference).abs() <= 3.0 * s + tol,
            "{name}: {f} ± {s} against the dip at {reference}"
        );
        // The dip is not the resonance: C0 pulls it below (the reason for sweep-G).
        assert!(reference < scene.resonance_hz() - 5.0);
    }
}

#[test]
fn estimated_noise_matches_the_noise_added() {
    // bvd_300kpa_y.csv carries white noise of 0.5 nS per component.
    let a = run("bvd_300kpa_y.csv", Method::SweepG);
    let s = a.capture.domain.noise_sigma_s().unwrap();
    assert!((s / 0.5e-9 - 1.0).abs() < 0.15, "estimated {s:e} S");
    assert!(a
        .capture
        .points
        .iter()
        .all(|p| p.sigma_s as f64 == s as f32 as f64));
}

#[test]
fn out_of_band_capture_is_not_ok() {
    for m in [Method::SweepG, Method::Paper] {
        let a = refused("bvd_1000kpa_below_band_y.csv", m, Failure::OutOfBand);
        // The estimators themselves say so (not only the bench's band guard).
        assert_eq!(m.estimate(&a.capture.points), Err(Failure::OutOfBand));
        let j = analysis_json(&a, "x");
        assert_eq!(j["status"], "out_of_band");
        assert!(j["modulus_kpa"].is_null());
    }
    // And with the resonance below the band.
    let scene = Scene::on_modulus_kpa(300.0);
    let pts = gen::closed_form(&scene, 236.0, 290.0, 1.0, 0.0, 0);
    let text = capture::write_admittance_csv(&[], &pts);
    for m in [Method::SweepG, Method::Paper] {
        let a = analyze(&text, m, &unit(m), &DemodOptions::default(), NOMINAL_FORCE).unwrap();
        assert_ne!(a.reading.status, Status::Ok, "{m:?}");
        assert!(a.reading.modulus.is_none());
    }
}

#[test]
fn fit_method_does_not_read_ok_without_a_resonance_in_band() {
    for name in ["bvd_capacitor_only_y.csv", "bvd_1000kpa_below_band_y.csv"] {
        let r = run(name, Method::Fit).reading;
        assert_ne!(r.status, Status::Ok, "{name}");
        assert!(r.modulus.is_none(), "{name}");
    }
}

#[test]
fn capture_without_resonance_is_not_ok() {
    for m in [Method::SweepG, Method::Paper] {
        let a = refused("bvd_capacitor_only_y.csv", m, Failure::NoResonance);
        assert!(a.reading.resonance.is_none());
        assert_eq!(m.estimate(&a.capture.points), Err(Failure::NoResonance));
    }
}

#[test]
fn json_has_the_documented_fields() {
    let a = run("sim_sweep_g_phantom_b.csv", Method::SweepG);
    let j = analysis_json(&a, "sim_sweep_g_phantom_b.csv");
    for k in [
        "status",
        "resonance_hz",
        "resonance_sigma_hz",
        "modulus_kpa",
        "modulus_sigma_kpa",
        "q_factor",
        "method",
        "points",
        "layout",
        "band_hz",
    ] {
        assert!(j.get(k).is_some(), "missing {k}");
    }
    assert_eq!(j["status"], "ok");
    assert_eq!(j["method"], "sweep-g");
    assert_eq!(j["points"], 61);
    assert_eq!(j["layout"], "admittance");
    let f = j["resonance_hz"].as_f64().unwrap();
    assert!((f - Scene::on_phantom(&phantoms::B).resonance_hz()).abs() < 0.1);
}

/// The demodulator divides the current phasor by the phasor of the *recorded* drive: a drive
/// with an arbitrary amplitude, phase and offset, and a slowly drifting amplitude, still gives
/// the admittance that links them.
#[test]
fn demodulation_uses_the_recorded_drive() {
    let fs = 5000.0;
    let (g, b) = (1.3e-7, 2.9e-7);
    let mut text = String::from("t_s,drive_hz,v_drive_v,i_sense_a\n");
    let freqs = [200.0, 210.0, 220.0, 230.0];
    let per = 500; // 0.1 s a step
    for (si, f) in freqs.iter().enumerate() {
        for k in 0..per {
            let t = (si * per + k) as f64 / fs;
            let w = 2.0 * std::f64::consts::PI * f;
            // V = A e^{j phi}; v(t) = Re(V e^{jwt}) + offset.
            let (amp, phi) = (3.7 * (1.0 + 0.001 * si as f64), 0.4 + si as f64);
            let v = amp * (w * t + phi).cos() + 0.25;
            // I = Y V.
            let i = amp * (g * (w * t + phi).cos() - b * (w * t + phi).sin());
            text += &format!("{t:.6},{f},{v:.9},{i:.9e}\n");
        }
    }
    let c = capture::parse(&text, 3, &DemodOptions::default()).unwrap();
    let t = c.domain.time().unwrap();
    assert_eq!(t.shape, SweepShape::Stepped);
    assert_eq!(c.points.len(), 4);
    assert!((t.sample_rate_hz - fs).abs() < 1e-6);
    for (p, f) in c.points.iter().zip(freqs) {
        assert!((p.freq.0 as f64 - f).abs() < 1e-9);
        assert!((p.g_s as f64 / g - 1.0).abs() < 1e-5, "G {}", p.g_s);
        assert!((p.b_s as f64 / b - 1.0).abs() < 1e-5, "B {}", p.b_s);
        assert!((p.sigma_s as f64) < 1e-12);
    }
}

/// A continuous (chirped) DAQ recording of the simulated probe: windows of whole cycles, phase
/// integrated from the recorded frequency. Up and down chirps lag in opposite directions; each
/// is within 0.6 Hz of the truth and their mean within 0.15 Hz.
#[test]
fn continuous_sweep_reads_the_resonance() {
    let scene = gen::daq_scene(&phantoms::B);
    let truth = scene.resonance_hz();
    let mut fr = Vec::new();
    for (f0, f1) in [(196.0, 260.0), (260.0, 196.0)] {
        let text = gen::time_capture(
            &scene,
            11,
            &gen::Drive::Chirp {
                f0,
                f1,
                duration_s: 4.0,
                lead_s: 0.1,
            },
            5.0,
            &[],
        );
        let a = analyze(
            &text,
            Method::SweepG,
            &unit(Method::SweepG),
            &DemodOptions::default(),
            NOMINAL_FORCE,
        )
        .unwrap();
        assert_eq!(
            a.capture.domain.time().map(|t| t.shape),
            Some(SweepShape::Continuous)
        );
        // Windows must come out in increasing frequency for the estimators: a down chirp reads
        // as a capture whose frequency decreases.
        let f = match a.reading.status {
            Status::Ok => a.reading.resonance.unwrap().0 as f64,
            s => panic!("{f0}->{f1}: {s:?}"),
        };
        eprintln!("chirp {f0}->{f1}: {f:.4} Hz, truth {truth:.4} Hz");
        assert!((f - truth).abs() < 0.6, "{f0}->{f1}: {f} vs {truth}");
        fr.push(f);
    }
    let mean = 0.5 * (fr[0] + fr[1]);
    assert!((mean - truth).abs() < 0.15, "mean {mean} vs {truth}");
}

fn err(name: &str) -> CaptureError {
    capture::parse(
        &read(&format!("malformed/{name}")),
        3,
        &DemodOptions::default(),
    )
    .expect_err(name)
}

#[test]
fn malformed_no_header() {
    assert_eq!(err("no_header.csv"), CaptureError::NoHeader { line: 3 });
}

#[test]
fn malformed_missing_column() {
    assert_eq!(
        err("missing_column.csv"),
        CaptureError::MissingColumn {
            line: 2,
            column: "z_phase_deg",
            layout: Layout::Impedance
        }
    );
}

#[test]
fn malformed_unknown_column() {
    assert_eq!(
        err("unknown_column.csv"),
        CaptureError::UnknownColumn {
            line: 1,
            column: "temp_c".into()
        }
    );
}

#[test]
fn malformed_duplicate_column() {
    assert_eq!(
        err("duplicate_column.csv"),
        CaptureError::DuplicateColumn {
            line: 1,
            column: "y_re_s".into()
        }
    );
}

#[test]
fn malformed_cell_count() {
    assert_eq!(
        err("cell_count.csv"),
        CaptureError::CellCount {
            line: 4,
            expected: 3,
            found: 2
        }
    );
}

#[test]
fn malformed_not_numeric() {
    assert_eq!(
        err("not_numeric.csv"),
        CaptureError::NotNumeric {
            line: 5,
            column: "y_im_s".into(),
            cell: "abc".into()
        }
    );
}

#[test]
fn malformed_not_finite() {
    assert_eq!(
        err("not_finite.csv"),
        CaptureError::NotFinite {
            line: 3,
            column: "z_mag_ohm".into()
        }
    );
    // NaN spelled as analysers do.
    let e = capture::parse(
        "freq_hz,y_re_s,y_im_s\n200,1e-7,NaN\n",
        3,
        &DemodOptions::default(),
    )
    .unwrap_err();
    assert_eq!(e.kind(), "not_finite");
    assert_eq!(e.line(), 2);
}

#[test]
fn malformed_not_positive() {
    assert_eq!(
        err("not_positive.csv"),
        CaptureError::NotPositive {
            line: 3,
            column: "z_mag_ohm"
        }
    );
}

#[test]
fn malformed_frequency_not_increasing() {
    assert_eq!(
        err("not_increasing_freq.csv"),
        CaptureError::NotIncreasing {
            line: 7,
            column: "freq_hz",
            value: 203.0,
            previous: 204.0
        }
    );
}

#[test]
fn malformed_time_not_increasing() {
    assert_eq!(
        err("not_increasing_time.csv"),
        CaptureError::NotIncreasing {
            line: 8,
            column: "t_s",
            value: 0.005,
            previous: 0.005
        }
    );
}

#[test]
fn malformed_too_few_points() {
    assert_eq!(
        err("too_few_points.csv"),
        CaptureError::TooFewPoints {
            line: 7,
            found: 5,
            needed: 7
        }
    );
}

#[test]
fn malformed_non_uniform_sampling() {
    let e = err("non_uniform.csv");
    assert_eq!(e.kind(), "non_uniform_sampling");
    assert_eq!(e.line(), 10);
}

#[test]
fn malformed_too_coarse() {
    let e = err("too_coarse.csv");
    assert_eq!(e.kind(), "too_coarse");
    assert_eq!(e.line(), 12);
}

#[test]
fn malformed_no_drive() {
    assert_eq!(err("no_drive.csv"), CaptureError::NoDrive { line: 103 });
}

#[test]
fn every_error_message_names_its_line() {
    for f in std::fs::read_dir(data("malformed")).unwrap() {
        let name = f.unwrap().file_name().into_string().unwrap();
        let e = err(&name);
        let msg = e.to_string();
        assert!(msg.starts_with(&format!("line {}: ", e.line())), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
    }
}

/// `auto` reads every layout with the BVD fit (a DAQ capture after demodulation) and falls back
/// to sweep-G on the same points when the fit finds no resonance, as the firmware's `auto`
/// does; the reading names the estimator that made it.
#[test]
fn auto_fits_every_layout_and_falls_back_to_sweep_g() {
    for (name, layout) in [
        ("bvd_300kpa_y.csv", Layout::Admittance),
        ("bvd_1000kpa_z.csv", Layout::Impedance),
        ("sim_time_stepped_phantom_b.csv", Layout::TimeDomain),
    ] {
        let a = run(name, Method::Auto);
        assert_eq!(a.capture.layout, layout, "{name}");
        assert_eq!(a.reading.method, Method::Fit, "{name}");
        assert_eq!(a.reading.status, Status::Ok, "{name}");
        // The same estimate as asking for the fit.
        assert_eq!(
            a.reading.resonance,
            run(name, Method::Fit).reading.resonance
        );
    }
    // No resonance: the fit fails, sweep-G on the same points says why.
    let a = run("bvd_capacitor_only_y.csv", Method::Auto);
    assert_eq!(a.reading.method, Method::SweepG);
    assert_eq!(a.reading.status, Status::Failed(Failure::NoResonance));
    let a = run("bvd_1000kpa_below_band_y.csv", Method::Auto);
    assert_ne!(a.reading.status, Status::Ok);
    assert!(a.reading.modulus.is_none());
}

#[test]
fn methods_for_captures() {
    for m in Method::ALL {
        let r = offline_method(m.name());
        assert_eq!(
            r.is_ok(),
            m.works_on_points() || m == Method::Auto,
            "{}",
            m.name()
        );
        if let Err(e) = r {
            assert!(e.to_string().contains("steers the drive"), "{e}");
        }
    }
    assert_eq!(offline_method("auto").unwrap(), Method::Auto);
    assert!(offline_method("sweep-g").is_ok());
    assert!(offline_method("paper").is_ok());
    let e = offline_method("nonsense").unwrap_err().to_string();
    assert!(e.contains("unknown method") && e.contains("sweep-g"), "{e}");
}

#[test]
fn cli_json_plot_and_errors() {
    let dir = Scratch::new("analyze");
    let svg = dir.join("a.svg");
    let png = dir.join("a.png");
    let j = run_json(
        bin()
            .args(["analyze", "--json", "--plot"])
            .arg(&svg)
            .arg(data("bvd_300kpa_y.csv")),
    );
    assert_eq!(j["status"], "ok");
    // The default is auto, which reads an analyser sweep with the BVD fit.
    assert_eq!(j["method"], "fit");
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // Every estimator stays selectable.
    for m in ["paper", "sweep-g", "fit", "auto"] {
        let j = run_json(
            bin()
                .args(["analyze", "--json", "--method", m])
                .arg(heavy_c0_path("hc0_300kpa_r10_y.csv")),
        );
        assert_eq!(j["method"], if m == "auto" { "fit" } else { m }, "{m}");
        assert!(j["resonance_hz"].as_f64().is_some(), "{m}");
    }
    run_ok(
        bin()
            .args(["analyze", "--method", "paper", "--plot"])
            .arg(&png)
            .arg(data("sim_time_stepped_phantom_b.csv")),
    );
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    // A malformed file: non-zero exit, one line naming the line.
    let e = run_fails_one_line(bin().arg("analyze").arg(data("malformed/cell_count.csv")));
    assert!(e.contains("line 4"), "{e}");
    // A failed reading is still a successful analysis (exit 0), with the failure code.
    let j = run_json(
        bin()
            .args(["analyze", "--json"])
            .arg(data("bvd_capacitor_only_y.csv")),
    );
    assert_eq!(j["status"], "no_resonance");
    assert!(j["modulus_kpa"].is_null());
}

// ---------------------------------------------------------------------------------------------
// Heavy-C0 analyser sweeps against an independent least-squares BVD fit (scipy).
//
// The sweeps are made here, not by `probe_bench::gen` or the core: the closed-form admittance
// of a Butterworth–Van Dyke circuit in its physical parameters (R0 ‖ C0 beside R1–L1–C1 in
// series), in f64, plus seeded Gaussian noise from this file's own generator. C0 is 10–30 times
// the motional peak conductance at the resonance (the motional current a tenth to a thirtieth of
// the capacitive one), and a parallel conductance G0 of 0.3–1 times it. The committed files in
// `tests/data/heavy_c0/` are this generator's output (checked byte for byte; rewrite them with
// `HEAVY_C0_WRITE=1 cargo test -p probe-bench --test analyze heavy_c0`), and
// `tests/data/heavy_c0/scipy_bvd_fit.csv` is the scipy fit of each
// (`python3 bench/tests/bvd_reference.py tests/data/heavy_c0 > tests/data/heavy_c0/scipy_bvd_fit.csv`).

/// One heavy-C0 sweep: true resonance `f0` (Hz), quality `q`, motional peak conductance `g`
/// (S), `ratio` = ω0 C0 / g, `g0_rel` = G0 / g, white noise per component `noise_rel` × ω0 C0,
/// band and step (Hz), impedance or admittance layout, noise seed.
struct HeavyC0 {
    name: &'static str,
    f0: f64,
    q: f64,
    g: f64,
    ratio: f64,
    g0_rel: f64,
    noise_rel: f64,
    band: (f64, f64, f64),
    impedance: bool,
    seed: u64,
}

/// Resonances and Q of the simulated unit on 150–1000 kPa (so that the readings pass the unit's
/// contact and Q checks), written out as numbers.
const HEAVY_C0: [HeavyC0; 5] = [
    HeavyC0 {
        name: "hc0_300kpa_r10_y.csv",
        f0: 230.0195,
        q: 10.016,
        g: 1.53e-7,
        ratio: 10.0,
        g0_rel: 0.3,
        noise_rel: 3e-4,
        band: (180.0, 280.0, 1.0),
        impedance: false,
        seed: 1,
    },
    HeavyC0 {
        name: "hc0_200kpa_r20_z.csv",
        f0: 216.1712,
        q: 9.924,
        g: 1.45e-7,
        ratio: 20.0,
        g0_rel: 1.0,
        noise_rel: 2e-4,
        band: (170.0, 270.0, 1.0),
        impedance: true,
        seed: 2,
    },
    HeavyC0 {
        name: "hc0_500kpa_r30_y.csv",
        f0: 241.9419,
        q: 10.414,
        g: 1.63e-7,
        ratio: 30.0,
        g0_rel: 0.5,
        noise_rel: 2e-4,
        band: (190.0, 290.0, 1.0),
        impedance: false,
        seed: 3,
    },
    HeavyC0 {
        name: "hc0_1000kpa_r25_z.csv",
        f0: 251.4022,
        q: 11.282,
        g: 1.78e-7,
        ratio: 25.0,
        g0_rel: 0.7,
        noise_rel: 1e-4,
        band: (220.0, 285.0, 0.5),
        impedance: true,
        seed: 4,
    },
    HeavyC0 {
        name: "hc0_150kpa_r15_y.csv",
        f0: 203.7121,
        q: 10.013,
        g: 1.40e-7,
        ratio: 15.0,
        g0_rel: 0.5,
        noise_rel: 5e-4,
        band: (170.0, 290.0, 2.0),
        impedance: false,
        seed: 5,
    },
];

/// SplitMix64 with Box–Muller normals: this file's own noise.
struct Normal(u64);

impl Normal {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform on (0, 1].
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }
    fn pair(&mut self) -> (f64, f64) {
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * self.uniform();
        (r * t.cos(), r * t.sin())
    }
}

/// The motional branch's admittance `1 / (R1 + jωL1 + 1/(jωC1))` at `f` (G, B), in f64: the
/// series resonator of resonance `f0`, quality factor `q` and peak conductance `g`.
fn motional(f0: f64, q: f64, g: f64, f: f64) -> (f64, f64) {
    let w0 = 2.0 * std::f64::consts::PI * f0;
    let r1 = 1.0 / g;
    let l1 = q * r1 / w0;
    let c1 = 1.0 / (w0 * w0 * l1);
    let w = 2.0 * std::f64::consts::PI * f;
    // 1 / (a + jb) = (a - jb) / (a² + b²)
    let (a, b) = (r1, w * l1 - 1.0 / (w * c1));
    let d = a * a + b * b;
    (a / d, -b / d)
}

impl HeavyC0 {
    /// `Y = G0 + jωC0 + 1 / (R1 + jωL1 + 1/(jωC1))` in f64.
    fn admittance(&self, f: f64) -> (f64, f64) {
        let w0 = 2.0 * std::f64::consts::PI * self.f0;
        let c0 = self.ratio * self.g / w0;
        let g0 = self.g0_rel * self.g;
        let w = 2.0 * std::f64::consts::PI * f;
        let (gm, bm) = motional(self.f0, self.q, self.g, f);
        (g0 + gm, w * c0 + bm)
    }

    fn csv(&self) -> String {
        let w0 = 2.0 * std::f64::consts::PI * self.f0;
        let sigma = self.noise_rel * self.ratio * self.g;
        let mut rng = Normal(self.seed);
        let (f_lo, f_hi, step) = self.band;
        let n = ((f_hi - f_lo) / step).round() as usize + 1;
        let mut s = format!(
            "# heavy-C0 BVD sweep (bench/tests/analyze.rs): f0 {} Hz, Q {}, g {:e} S, C0 {:e} F \
             (w0 C0 / g = {}), G0 {:e} S, white noise {:e} S per component, seed {}\n",
            self.f0,
            self.q,
            self.g,
            self.ratio * self.g / w0,
            self.ratio,
            self.g0_rel * self.g,
            sigma,
            self.seed
        );
        s += if self.impedance {
            "freq_hz,z_mag_ohm,z_phase_deg\n"
        } else {
            "freq_hz,y_re_s,y_im_s\n"
        };
        for k in 0..n {
            let f = f_lo + k as f64 * step;
            let (g, b) = self.admittance(f);
            let (ng, nb) = rng.pair();
            let (g, b) = (g + sigma * ng, b + sigma * nb);
            if self.impedance {
                let d = g * g + b * b;
                // Z = 1/Y = (G - jB) / |Y|²
                let (zr, zi) = (g / d, -b / d);
                s += &format!(
                    "{f},{:.10e},{:.10}\n",
                    zr.hypot(zi),
                    zi.atan2(zr).to_degrees()
                );
            } else {
                s += &format!("{f},{g:.10e},{b:.10e}\n");
            }
        }
        s
    }
}

fn heavy_c0_path(name: &str) -> PathBuf {
    data(&format!("heavy_c0/{name}"))
}

/// The committed heavy-C0 captures are exactly this file's generator output.
#[test]
fn heavy_c0_fixtures_are_the_generator_output() {
    let write = std::env::var_os("HEAVY_C0_WRITE").is_some();
    for c in &HEAVY_C0 {
        let text = c.csv();
        let path = heavy_c0_path(c.name);
        if write {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &text).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
        assert_eq!(committed, text, "{}", c.name);
    }
}

/// `probe-bench analyze`'s default (`auto`: the BVD fit for analyser sweeps) reads every
/// heavy-C0 sweep's resonance within twice the error of scipy's least-squares BVD fit of the
/// same file, as a valid reading (the unit profile's checks pass); sweep-G, whose `1/G` model
/// has no `G0`, is printed beside it.
#[test]
fn heavy_c0_auto_is_within_twice_the_scipy_fit() {
    let fixture = std::fs::read_to_string(heavy_c0_path("scipy_bvd_fit.csv")).unwrap();
    let rows: Vec<Vec<&str>> = fixture
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("file,"))
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), HEAVY_C0.len(), "one scipy fit per capture");
    let unit = unit(Method::Auto);
    for c in &HEAVY_C0 {
        let row = rows
            .iter()
            .find(|r| r[0] == c.name)
            .unwrap_or_else(|| panic!("{}: no scipy fit in the fixture", c.name));
        let truth: f64 = row[1].parse().unwrap();
        let f_scipy: f64 = row[2].parse().unwrap();
        assert_eq!(truth, c.f0, "{}", c.name);
        let text = std::fs::read_to_string(heavy_c0_path(c.name)).unwrap();
        let a = analyze(
            &text,
            Method::Auto,
            &unit,
            &DemodOptions::default(),
            NOMINAL_FORCE,
        )
        .unwrap();
        let r = a.reading;
        assert_eq!(r.method, Method::Fit, "{}", c.name);
        assert_eq!(r.status, Status::Ok, "{}", c.name);
        let f = r.resonance.unwrap().0 as f64;
        let err = (f - truth).abs();
        let err_scipy = (f_scipy - truth).abs();
        let sweep_g = Method::SweepG
            .estimate(&a.capture.points)
            .map(|e| e.resonance.0 as f64 - truth);
        eprintln!(
            "{}: auto (fit) {f:.5} Hz, error {:+.5} Hz; scipy {f_scipy:.5} Hz, error {:+.5} Hz; \
             |auto - scipy| {:.6} Hz; sweep-G error {sweep_g:+.4?} Hz; σ {:.4} Hz",
            c.name,
            f - truth,
            f_scipy - truth,
            (f - f_scipy).abs(),
            r.resonance_sigma.unwrap().0
        );
        assert!(
            err <= 2.0 * err_scipy,
            "{}: error {err} Hz against scipy's {err_scipy} Hz",
            c.name
        );
        // The same least-squares minimum: measured within 8 µHz (half an f32 step at 250 Hz).
        assert!(
            (f - f_scipy).abs() < 2e-5,
            "{}: {f} vs scipy {f_scipy}",
            c.name
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Analysers' own exports: the HP/Agilent 4294A ASCII data file and the Keysight E4990A trace
// CSV, written here from the closed-form admittance of a Butterworth–Van Dyke resonator with
// known f0, Q and C0 (`Resonator::admittance`, f64, independent of the code under test), in the
// layouts the manuals document (bench/src/capture/export.rs names the sections).

/// A resonator: `Y = G0 + jωC0 + 1/(R1 + jωL1 + 1/(jωC1))` with resonance `f0`, quality `q`,
/// motional peak conductance `g = 1/R1`, static capacitance `c0`.
struct Resonator {
    f0: f64,
    q: f64,
    g: f64,
    c0: f64,
    g0: f64,
    /// White noise per component of Y, S.
    noise: f64,
}

/// Another probe than the simulated unit: a 4 kHz plate with Q 40 and C0 = 2 nF.
const OTHER_PROBE: Resonator = Resonator {
    f0: 4000.0,
    q: 40.0,
    g: 1.0e-4,
    c0: 2.0e-9,
    g0: 2.0e-6,
    noise: 2.0e-8,
};

impl Resonator {
    fn admittance(&self, f: f64) -> (f64, f64) {
        let w = 2.0 * std::f64::consts::PI * f;
        let (gm, bm) = motional(self.f0, self.q, self.g, f);
        (self.g0 + gm, w * self.c0 + bm)
    }
    /// `(f, G, B)` from `f_lo` to `f_hi` in `n` points, with seeded noise.
    fn sweep(&self, f_lo: f64, f_hi: f64, n: usize, seed: u64) -> Vec<(f64, f64, f64)> {
        let mut rng = Normal(seed);
        (0..n)
            .map(|k| {
                let f = f_lo + (f_hi - f_lo) * k as f64 / (n - 1) as f64;
                let (g, b) = self.admittance(f);
                let (ng, nb) = rng.pair();
                (f, g + self.noise * ng, b + self.noise * nb)
            })
            .collect()
    }
}

/// `Z = 1/Y` as (R, X), (|Z|, θ deg).
fn z_of(g: f64, b: f64) -> ((f64, f64), (f64, f64)) {
    let d = g * g + b * b;
    let (r, x) = (g / d, -b / d);
    ((r, x), (r.hypot(x), x.atan2(r).to_degrees()))
}

/// The 4294A's export parameter.
#[derive(Clone, Copy)]
enum Hp {
    /// `IMPEDANCE MAG PHASE (DEG)`: trace A |Z|, trace B θ (+ an offset, degrees).
    ZTheta(f64),
    /// `RESISTANCE REACTANCE`: trace A R, trace B X.
    Rx,
    /// The data array (R, X) beside the data trace (|Z|), one trace.
    DataArray,
}

/// A 4294A ASCII data file: setup lines, then per trace `"TRACE: x"`, `"FORMAT: …"`, a quoted
/// tab-separated column row and tab-separated rows.
fn export_4294a(sweep: &[(f64, f64, f64)], p: Hp) -> String {
    let param = match p {
        Hp::ZTheta(_) | Hp::DataArray => "IMPEDANCE MAG PHASE (DEG)",
        Hp::Rx => "RESISTANCE REACTANCE",
    };
    let mut s = format!(
        "4294A REV1.11\n\"DATE: Jan 25 2018\"\n\n\n\"MEASURE PARAMETER: {param}\"\n\"ADAPTER: NONE\"\n\"SWEEP TYPE: LIN FREQ\"\n\"NUMBER of POINTS: {}\"\n\"OSC LEVEL:  500 mVolt\"\n\"DC BIAS: OFF\"\n\"BW: 5\"\n\n\n",
        sweep.len()
    );
    let traces: &[(&str, usize)] = match p {
        Hp::DataArray => &[("A", 0)],
        _ => &[("A", 0), ("B", 1)],
    };
    for (k, (name, which)) in traces.iter().enumerate() {
        if k > 0 {
            s += "\n\n";
        }
        s += &format!("\"TRACE: {name}\"\n\"FORMAT: LOG\"\n\n");
        match p {
            Hp::DataArray => {
                s += "\"Frequency\"\t\"Data Real\"\t\"Data Imag\"\t\"Data Trace Real\"\t\"Data Trace Imag\"\n"
            }
            _ => s += "\"Frequency\"\t\"Data Trace Real\"\t\"Data Trace Imag\"\n",
        }
        for &(f, g, b) in sweep {
            let ((r, x), (m, th)) = z_of(g, b);
            match p {
                Hp::DataArray => {
                    s += &format!("{f:.11e}\t{r:.6e}\t{x:.6e}\t{m:.6e}\t0.000000e+00\n")
                }
                Hp::ZTheta(off) => {
                    let v = if *which == 0 { m } else { th + off };
                    s += &format!("{f:.11e}\t{v:.6e}\t0.000000e+00\n");
                }
                Hp::Rx => {
                    let v = if *which == 0 { r } else { x };
                    s += &format!("{f:.11e}\t{v:.6e}\t0.000000e+00\n");
                }
            }
        }
    }
    s
}

/// An E4990A trace CSV: `!` lines, then (with `blocks`) `BEGIN CH1_DATA`, title and DC monitor
/// lines, `Frequency(Hz), …-data, …-mem`, rows, `END`; `polar`: |Z| and theta-z, else
/// Z-Real and Z-Imag.
fn export_e4990a(sweep: &[(f64, f64, f64)], polar: bool, blocks: bool) -> String {
    let mut s = String::from(
        "!Agilent Technologies,E4990A,MY521012345,A.02.10\n!Date: Fri Apr 03 13:41:16 2015\n",
    );
    if blocks {
        s += "BEGIN CH1_DATA\nTitle label, TEST DATA\nDCV(V), +5.230e-005, DCI(A), +2.335e-005\n";
    }
    s += if polar {
        "Frequency(Hz), |Z|(Ohm)-data, theta-z(deg)-data, theta-z(deg)-mem\n"
    } else {
        "Frequency(Hz), Z-Real(Ohm)-data, Z-Imag(Ohm)-data, Y-Real(S)-mem, Y-Imag(S)-mem\n"
    };
    for &(f, g, b) in sweep {
        let ((r, x), (m, th)) = z_of(g, b);
        if polar {
            s += &format!("{f:+.11e}, {m:+.11e}, {th:+.11e}, {:+.11e}\n", 0.0);
        } else {
            s += &format!("{f:+.11e}, {r:+.11e}, {x:+.11e}, {g:+.11e}, {b:+.11e}\n");
        }
    }
    if blocks {
        s += "END\n";
    }
    s
}

fn bare(text: &str) -> Analysis {
    analyze(
        text,
        Method::Auto,
        &Unit::Bare,
        &DemodOptions::default(),
        NOMINAL_FORCE,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The reading is `ok` with the known f0 within 4σ (+ 1e-5 relative) and Q within 3 %, and no
/// modulus (no profile, no curve).
fn reads_the_resonator(name: &str, a: &Analysis, r: &Resonator) {
    let rd = &a.reading;
    assert_eq!(rd.status, Status::Ok, "{name}: {:?}", a.warnings);
    let f = rd.resonance.unwrap().0 as f64;
    let s = rd.resonance_sigma.unwrap().0 as f64;
    let q = rd.q.unwrap() as f64;
    eprintln!(
        "{name}: f0 {f:.4} ± {s:.4} Hz (true {}), Q {q:.3} (true {}), chi2/dof {:?}",
        r.f0, r.q, a.reduced_chi2
    );
    assert!(
        (f - r.f0).abs() <= 4.0 * s + 1e-5 * r.f0,
        "{name}: {f} ± {s} vs {}",
        r.f0
    );
    assert!(s > 0.0 && s < r.f0 / r.q / 20.0, "{name}: sigma {s}");
    assert!((q / r.q - 1.0).abs() < 0.03, "{name}: Q {q} vs {}", r.q);
    assert!(rd.modulus.is_none(), "{name}");
    assert_eq!(a.unit, "none");
}

#[test]
fn instrument_exports_read_the_known_resonance() {
    let r = &OTHER_PROBE;
    let sweep = r.sweep(3700.0, 4300.0, 201, 11);
    let cases: [(&str, String, Layout); 6] = [
        (
            "4294A |Z|-θ",
            export_4294a(&sweep, Hp::ZTheta(0.0)),
            Layout::Hp4294a,
        ),
        ("4294A R-X", export_4294a(&sweep, Hp::Rx), Layout::Hp4294a),
        (
            "4294A data array",
            export_4294a(&sweep, Hp::DataArray),
            Layout::Hp4294a,
        ),
        (
            "E4990A |Z|-θ",
            export_e4990a(&sweep, true, true),
            Layout::E4990a,
        ),
        (
            "E4990A Z-Real/Imag",
            export_e4990a(&sweep, false, true),
            Layout::E4990a,
        ),
        (
            "E4990A without BEGIN/END",
            export_e4990a(&sweep, true, false),
            Layout::E4990a,
        ),
    ];
    for (name, text, layout) in &cases {
        let a = bare(text);
        assert_eq!(a.capture.layout, *layout, "{name}");
        assert_eq!(a.capture.points.len(), 201, "{name}");
        assert!(
            !a.magnitude_only && a.warnings.is_empty(),
            "{name}: {:?}",
            a.warnings
        );
        assert_eq!(a.reading.method, Method::Fit, "{name}");
        reads_the_resonator(name, &a, r);
        let j = analysis_json(&a, name);
        assert_eq!(j["layout"], layout.name());
        assert_eq!(j["unit"], "none");
        assert!(j["source"].as_str().is_some(), "{name}");
    }
}

/// A phase column offset by 180° (Re Z < 0 throughout): never read as if passive; the
/// magnitude fit finds f0 and Q and says so — in the 4294A file and in the bench's impedance
/// CSV converted by hand.
#[test]
fn phase_offset_by_180_degrees_falls_back_to_the_magnitude() {
    let r = &OTHER_PROBE;
    let sweep = r.sweep(3700.0, 4300.0, 201, 12);
    let mut own = String::from("freq_hz,z_mag_ohm,z_phase_deg\n");
    for &(f, g, b) in &sweep {
        let (_, (m, th)) = z_of(g, b);
        own += &format!("{f},{m:.10e},{:.10}\n", th + 180.0);
    }
    for (name, text) in [
        ("4294A θ + 180°", export_4294a(&sweep, Hp::ZTheta(180.0))),
        ("impedance CSV θ + 180°", own),
    ] {
        let a = bare(&text);
        assert!(a.magnitude_only, "{name}");
        assert!(a.warnings.iter().any(|w| w.contains("passive")), "{name}");
        reads_the_resonator(name, &a, r);
        let j = analysis_json(&a, name);
        assert_eq!(j["magnitude_only"], true);
        assert!(j["warnings"].as_array().is_some_and(|w| !w.is_empty()));
        // sweep-G asked for: still the magnitude fit, and said so.
        let s = analyze(
            &text,
            Method::SweepG,
            &Unit::Bare,
            &DemodOptions::default(),
            NOMINAL_FORCE,
        )
        .unwrap();
        assert!(s.magnitude_only);
        assert!(
            s.warnings.iter().any(|w| w.contains("not sweep-g")),
            "{:?}",
            s.warnings
        );
    }
    // On the simulated unit's golden capture the magnitude fit agrees with the complex one.
    let scene = Scene::on_modulus_kpa(1000.0);
    let text = read("bvd_1000kpa_z.csv");
    let flipped: String = text
        .lines()
        .map(|l| match l.split(',').collect::<Vec<_>>()[..] {
            [f, m, p] if f.parse::<f64>().is_ok() => {
                format!("{f},{m},{}\n", p.parse::<f64>().unwrap() - 180.0)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let a = bare(&flipped);
    assert!(a.magnitude_only);
    let f = a.reading.resonance.unwrap().0 as f64;
    assert!(
        (f - scene.resonance_hz()).abs() < 0.05,
        "{f} vs {}",
        scene.resonance_hz()
    );
}

/// The BVD fit's σ grows by sqrt(χ²/dof) when the residuals exceed the noise: a weak second
/// mode the model lacks, with little noise.
#[test]
fn fit_sigma_grows_with_the_misfit() {
    let r = &OTHER_PROBE;
    let quiet = Resonator {
        noise: 2e-9,
        ..OTHER_PROBE
    };
    let second = Resonator {
        f0: 4150.0,
        q: 60.0,
        g: 3.5e-8,
        c0: 0.0,
        g0: 0.0,
        noise: 0.0,
    };
    let sweep: Vec<(f64, f64, f64)> = quiet
        .sweep(3700.0, 4300.0, 201, 13)
        .into_iter()
        .map(|(f, g, b)| {
            let (g2, b2) = second.admittance(f);
            (f, g + g2, b + b2)
        })
        .collect();
    let text = capture::write_admittance_csv(&[], &sweep);
    let a = bare(&text);
    let red = a.reduced_chi2.expect("the fit's chi2");
    // Above the noise, below the firmware's own gross-misfit scaling (16): there the firmware
    // leaves σ alone and `analyze` scales it.
    assert!(red > 1.5 && red < 16.0, "chi2/dof {red}");
    let plain = Method::Fit.estimate(&a.capture.points).unwrap();
    let ratio = a.reading.resonance_sigma.unwrap().0 as f64 / plain.sigma.0 as f64;
    let expect = red.sqrt() / pzt_probe::estimate::gross_scale(red).sqrt();
    eprintln!("chi2/dof {red:.2}: sigma x {ratio:.3} (expected {expect:.3})");
    assert!((ratio / expect - 1.0).abs() < 0.02, "{ratio} vs {expect}");
    let _ = r;
}

/// Without `--profile` a capture of another probe reads ok (its resonance and Q), never
/// `bad_contact` against the simulated unit's Q model; a modulus comes only with a profile or a
/// chosen curve.
#[test]
fn no_profile_reads_resonance_and_q_only() {
    let dir = Scratch::new("exports");
    let other = dir.join("other.txt");
    std::fs::write(
        &other,
        export_4294a(&OTHER_PROBE.sweep(3700.0, 4300.0, 201, 14), Hp::ZTheta(0.0)),
    )
    .unwrap();
    let j = run_json(bin().args(["analyze", "--json"]).arg(&other));
    assert_eq!(j["status"], "ok", "{j}");
    assert_eq!(j["unit"], "none");
    assert!(j["modulus_kpa"].is_null());
    assert!((j["resonance_hz"].as_f64().unwrap() - 4000.0).abs() < 0.5);
    // The simulated unit's own capture with paper 003's curve: a modulus.
    let j = run_json(
        bin()
            .args(["analyze", "--json", "--calibration", "paper-experiment"])
            .arg(data("bvd_300kpa_y.csv")),
    );
    assert_eq!(j["status"], "ok");
    assert_eq!(j["unit"], "curve");
    assert!(j["modulus_kpa"].as_f64().is_some());
    // The text report says what was read and that no unit was applied.
    let out = run_ok(bin().arg("analyze").arg(&other));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("4294a-ascii") && text.contains("calibration none"),
        "{text}"
    );
    // The 180°-offset file: a warning line.
    let off = dir.join("offset.txt");
    std::fs::write(
        &off,
        export_4294a(
            &OTHER_PROBE.sweep(3700.0, 4300.0, 201, 15),
            Hp::ZTheta(180.0),
        ),
    )
    .unwrap();
    let out = run_ok(bin().arg("analyze").arg(&off));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("warning: phase inconsistent"), "{text}");
}

/// Truncated exports and garbage: a one-line error naming its line (never a panic, never a
/// silent number from a partial file).
#[test]
fn truncated_and_garbage_exports_are_one_line_errors() {
    let sweep = OTHER_PROBE.sweep(3700.0, 4300.0, 41, 16);
    let check = |text: &str| -> Option<CaptureError> {
        match capture::parse(text, 3, &DemodOptions::default()) {
            Ok(_) => None,
            Err(e) => {
                let m = e.to_string();
                assert!(m.starts_with(&format!("line {}: ", e.line())), "{m}");
                assert!(!m.contains('\n'), "{m}");
                Some(e)
            }
        }
    };
    for (name, full) in [
        ("4294A", export_4294a(&sweep, Hp::ZTheta(0.0))),
        ("4294A R-X", export_4294a(&sweep, Hp::Rx)),
        ("E4990A", export_e4990a(&sweep, true, true)),
        ("E4990A rect", export_e4990a(&sweep, false, true)),
    ] {
        assert!(check(&full).is_none(), "{name}");
        // Cut anywhere before the last data row: always an error.
        let last_row = full.trim_end().rfind('\n').unwrap();
        let last_row = if name.starts_with("E4990A") {
            full.len() - 1 // the END line makes every cut detectable
        } else {
            full[..last_row].rfind('\n').unwrap()
        };
        for cut in (1..last_row).filter(|c| full.is_char_boundary(*c)) {
            let e = check(&full[..cut]);
            assert!(e.is_some(), "{name} cut at {cut} read as a capture");
        }
        // Lines dropped from the middle of trace/channel blocks.
        let lines: Vec<&str> = full.lines().collect();
        for drop in 0..lines.len() {
            let t: String = lines
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != drop)
                .map(|(_, l)| format!("{l}\n"))
                .collect();
            let _ = check(&t);
        }
    }
    // Garbage: random bytes, random text from the exports' own characters.
    const CHARS: &[u8] = b" \t\n,\"!0123456789.e+-TRACE:ABFrequency()|Z";
    let mut rng = Normal(99);
    for n in [0usize, 1, 7, 100, 5000] {
        let bytes: Vec<u8> = (0..n).map(|_| (rng.next_u64() & 0xff) as u8).collect();
        let _ = check(&String::from_utf8_lossy(&bytes));
        let text: String = (0..n)
            .map(|_| CHARS[(rng.next_u64() % CHARS.len() as u64) as usize] as char)
            .collect();
        let _ = check(&text);
        let _ = check(&format!("4294A REV1.11\n{text}"));
        let _ = check(&format!("!E4990A\nBEGIN CH1_DATA\n{text}"));
    }
    let e = check("4294A REV1.11\n\"DATE: x\"\n").expect("no trace");
    assert_eq!(e.kind(), "bad_export");
    let e = check("!Agilent Technologies,E4990A,MY1,A.02.10\nBEGIN CH1_DATA\nFrequency(Hz), |Z|(Ohm)-data, theta-z(deg)-data\n1e6, 2, nan\nEND\n")
        .expect("NaN");
    assert!(e.to_string().contains("not finite"), "{e}");
    // On the command line: exit non-zero, one line.
    let dir = Scratch::new("garbage");
    let full = export_4294a(&sweep, Hp::ZTheta(0.0));
    let path = dir.join("truncated.txt");
    std::fs::write(&path, &full[..full.len() * 3 / 4]).unwrap();
    let e = run_fails_one_line(bin().arg("analyze").arg(&path));
    assert!(e.contains("4294a-ascii export"), "{e}");
    let path = dir.join("garbage.bin");
    std::fs::write(&path, [0u8, 159, 146, 150, 255, 0, 1, 2]).unwrap();
    run_fails_one_line(bin().arg("analyze").arg(&path));
}
