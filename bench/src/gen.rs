//! Generators of bench captures with a known answer, for the golden files in `tests/data/` and
//! the tests: the simulated probe (the firmware's own sweep on `hal-sim`, and raw DAQ-like
//! samples from `SimProbe::exchange`), and the closed-form Butterworth–Van Dyke admittance of a
//! scene, which involves no estimator at all.
//!
//! `probe-bench generate-captures --out-dir tests/data` (a hidden subcommand) rewrites the golden
//! files.

use crate::capture::{write_admittance_csv, write_impedance_csv};
use anyhow::{anyhow, Result};
use hal_sim::{NoiseScene, Phantom, Scene, SimProbe};
use probe_rng::Rng;
use pzt_probe::board::sim as simboard;
use pzt_probe::engine::sweep::SweepSettings;
use pzt_probe::Method;
use std::f64::consts::PI;
use std::path::Path;

/// Admittance `(f, G, B)` of a full simulated reading of `scene` with `method`.
pub fn sim_sweep(
    scene: &Scene,
    seed: u64,
    method: Method,
    settings: &SweepSettings,
) -> Result<Vec<(f64, f64, f64)>> {
    let mut pts = Vec::new();
    simboard::read(
        scene,
        seed,
        method,
        settings,
        &pzt_probe::unit::profile::UnitProfile::fallback(),
        |p| pts.push((p.freq.0 as f64, p.g_s as f64, p.b_s as f64)),
    )
    .map_err(|e| anyhow!("simulated reading failed: {e}"))?;
    Ok(pts)
}

/// Closed-form admittance of `scene` at `f0, f0 + step, ..., f1`, plus white Gaussian noise of
/// `noise_s` per component (seeded).
pub fn closed_form(
    scene: &Scene,
    f0: f64,
    f1: f64,
    step: f64,
    noise_s: f64,
    seed: u64,
) -> Vec<(f64, f64, f64)> {
    let mut rng = Rng::new(seed);
    let n = ((f1 - f0) / step + 1e-9).floor() as usize + 1;
    (0..n)
        .map(|k| {
            let f = f0 + k as f64 * step;
            let y = scene.admittance(f);
            (
                f,
                y.re + noise_s * rng.normal(),
                y.im + noise_s * rng.normal(),
            )
        })
        .collect()
}

/// Drive of a time-domain capture.
#[derive(Clone, Debug, PartialEq)]
pub enum Drive {
    /// Frequencies held for `settle_s + dwell_s` each.
    Stepped {
        /// Step frequencies, Hz.
        freqs: Vec<f64>,
        /// Time per step, s.
        step_s: f64,
    },
    /// A linear chirp from `f0` to `f1` Hz over `duration_s`, after `lead_s` at `f0`.
    Chirp {
        /// Start, Hz.
        f0: f64,
        /// End, Hz.
        f1: f64,
        /// Sweep time, s.
        duration_s: f64,
        /// Time at `f0` before the sweep (lets the resonator reach steady state), s.
        lead_s: f64,
    },
}

/// A DAQ-like recording of the simulated probe: the DAC plays a sine of amplitude `drive_v`
/// (at the PZT) following `drive`; the ADC codes are converted to volts and amperes with the
/// front end's scale (`monitor_volts_per_code`, `amps_per_code`). Returns the CSV text
/// (`t_s,drive_hz,v_drive_v,i_sense_a`) with `comments` first.
pub fn time_capture(
    scene: &Scene,
    seed: u64,
    drive: &Drive,
    drive_v: f64,
    comments: &[String],
) -> String {
    let fe = scene.front_end;
    let fs = fe.sample_rate_hz;
    let volts_per_dac = fe.drive_gain * fe.vref_v / hal_sim::frontend::CODES;
    let amp = drive_v / volts_per_dac;
    let mut probe = SimProbe::new(*scene, seed);
    let (av, ai) = (fe.monitor_volts_per_code(), fe.amps_per_code());
    let mid = hal_sim::frontend::MID_CODE as f64;
    let mut out = String::new();
    for c in comments {
        out += &format!("# {c}\n");
    }
    out += "t_s,drive_hz,v_drive_v,i_sense_a\n";
    let total = match drive {
        Drive::Stepped { freqs, step_s } => (freqs.len() as f64 * step_s * fs).round() as usize,
        Drive::Chirp {
            duration_s, lead_s, ..
        } => ((duration_s + lead_s) * fs).round() as usize,
    };
    let mut phase = 0.0f64;
    let mut pair = [hal_sim::AdcPair::default()];
    for k in 0..total {
        let t = k as f64 / fs;
        let (f, label) = match drive {
            Drive::Stepped { freqs, step_s } => {
                let i = ((t / step_s) as usize).min(freqs.len() - 1);
                (freqs[i], format!("{}", freqs[i]))
            }
            Drive::Chirp {
                f0,
                f1,
                duration_s,
                lead_s,
            } => {
                let u = ((t - lead_s) / duration_s).clamp(0.0, 1.0);
                let f = f0 + (f1 - f0) * u;
                (f, format!("{f:.4}"))
            }
        };
        let code = (mid + amp * phase.sin()).round().clamp(0.0, 4095.0) as u16;
        probe.exchange(&[code], &mut pair);
        let v = (pair[0].monitor as f64 - mid) * av;
        let i = (pair[0].current as f64 - mid) * ai;
        out += &format!("{t:.6},{label},{v:.5},{i:.4e}\n");
        phase = (phase + 2.0 * PI * f / fs) % (2.0 * PI);
    }
    out
}

/// The scene of the time-domain golden captures: phantom B, bench noise, and a DAQ sampling at
/// 2 kHz (the simulated front end's converters and filters otherwise unchanged).
pub fn daq_scene(phantom: &hal_sim::Phantom) -> Scene {
    let mut s = Scene::on_phantom(phantom).with_noise(NoiseScene::Bench);
    s.front_end.sample_rate_hz = 2000.0;
    s
}

/// Write every golden capture into `dir` (the committed `tests/data/`). Returns the files
/// written.
pub fn write_golden(dir: &Path) -> Result<Vec<String>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> Result<()> {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| anyhow!("cannot write {}: {e}", p.display()))?;
        written.push(name.to_owned());
        Ok(())
    };
    let regen = "regenerate: probe-bench generate-captures --out-dir tests/data".to_owned();

    // The comments of a capture of `scene`: what it is and how it was taken, its true
    // resonance, how to regenerate it.
    let about = |what: &str, how: &str, scene: &Scene| -> Vec<String> {
        vec![
            what.to_owned(),
            how.to_owned(),
            format!("true resonance {:.4} Hz", scene.resonance_hz()),
            regen.clone(),
        ]
    };

    // (a) The simulated probe's own sweeps: the firmware's reading of a phantom at 30 mN and
    // bench noise with the method's default sweep; the comments and the points.
    let sim = |p: &Phantom, seed: u64, method: Method, how: &str| -> Result<_> {
        let scene = Scene::on_phantom(p).with_noise(NoiseScene::Bench);
        let pts = sim_sweep(&scene, seed, method, &method.default_sweep())?;
        let what = format!(
            "simulated probe (hal-sim), phantom {} ({:.0} kPa), 30 mN, bench noise, seed {seed}",
            p.name, p.modulus_kpa
        );
        Ok((about(&what, how, &scene), pts))
    };
    let b = hal_sim::phantoms::B;
    let (comments, pts) = sim(
        &b,
        1,
        Method::SweepG,
        "firmware sweep-G sweep 170-290 Hz step 2 Hz; points as the firmware measured them",
    )?;
    put(
        "sim_sweep_g_phantom_b.csv",
        write_admittance_csv(&comments, &pts),
    )?;
    let (comments, pts) = sim(
        &hal_sim::phantoms::C,
        2,
        Method::Paper,
        "firmware paper sweep 200-300 Hz step 1 Hz, exported as impedance",
    )?;
    put(
        "sim_paper_phantom_c_z.csv",
        write_impedance_csv(&comments, &pts),
    )?;

    // (b) Closed-form Butterworth-Van Dyke admittance, no estimator involved.
    let scene = Scene::on_modulus_kpa(300.0);
    put(
        "bvd_300kpa_y.csv",
        write_admittance_csv(
            &about(
                "closed-form BVD admittance of the probe on 300 kPa tissue (Scene::admittance)",
                "180-280 Hz step 1 Hz, white noise 0.5 nS per component (seed 7)",
                &scene,
            ),
            &closed_form(&scene, 180.0, 280.0, 1.0, 0.5e-9, 7),
        ),
    )?;
    let scene = Scene::on_modulus_kpa(1000.0);
    put(
        "bvd_1000kpa_z.csv",
        write_impedance_csv(
            &about(
                "closed-form BVD admittance of the probe on 1000 kPa tissue, as impedance",
                "200-300 Hz step 2 Hz, noise-free",
                &scene,
            ),
            &closed_form(&scene, 200.0, 300.0, 2.0, 0.0, 0),
        ),
    )?;
    // The resonance (about 251 Hz) lies above this band: an out-of-band capture.
    put(
        "bvd_1000kpa_below_band_y.csv",
        write_admittance_csv(
            &[
                "closed-form BVD admittance on 1000 kPa tissue, swept 180-235 Hz only".into(),
                format!(
                    "true resonance {:.4} Hz lies above the band: must not read ok",
                    scene.resonance_hz()
                ),
                regen.clone(),
            ],
            &closed_form(&scene, 180.0, 235.0, 1.0, 0.0, 0),
        ),
    )?;
    // No resonance: the PZT's static capacitance alone (free of any motional branch).
    let mut bare = Scene::on_modulus_kpa(300.0);
    bare.pzt.force_factor_n_v = 0.0;
    put(
        "bvd_capacitor_only_y.csv",
        write_admittance_csv(
            &[
                "closed-form admittance of the bare 210 pF capacitance (force factor 0)".into(),
                "180-280 Hz step 2 Hz, white noise 0.5 nS (seed 3): no resonance".into(),
                regen.clone(),
            ],
            &closed_form(&bare, 180.0, 280.0, 2.0, 0.5e-9, 3),
        ),
    )?;

    // (a') A DAQ-like stepped time-domain recording of the simulated probe.
    let scene = daq_scene(&b);
    let freqs: Vec<f64> = (0..12).map(|k| 206.0 + 4.0 * k as f64).collect();
    put(
        "sim_time_stepped_phantom_b.csv",
        time_capture(
            &scene,
            5,
            &Drive::Stepped { freqs, step_s: 0.1 },
            5.0,
            &about(
                "simulated probe (hal-sim SimProbe::exchange) on phantom B, bench noise, seed 5",
                "DAQ at 2 kHz; stepped drive 206-250 Hz step 4 Hz, 100 ms a step, 5 V",
                &scene,
            ),
        ),
    )?;
    Ok(written)
}
