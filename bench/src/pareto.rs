//! The speed–accuracy study: methods × knob settings × moduli × noise scenes on the simulated
//! probe, each method calibrated on the same unit, charted against the Cramér–Rao bound.

use hal_sim::{NoiseScene, Scene};
use pzt_probe::board::sim::read;
use pzt_probe::engine::sweep::SweepSettings;
use pzt_probe::estimate::hold::HoldSettings;
use pzt_probe::estimate::staged::StagedSettings;
use pzt_probe::reading::{Method, Settings};
use pzt_probe::unit::calibration::PowerLaw;
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::{Hz, Seconds};
use std::f64::consts::PI;

/// One method with one set of knobs.
#[derive(Clone, Debug)]
pub struct Config {
    /// Method.
    pub method: Method,
    /// Short description of the knobs.
    pub label: String,
    /// Its settings.
    pub settings: Settings,
}

impl Config {
    /// `method` with `settings`, described by `label`.
    pub fn new(method: Method, label: String, settings: impl Into<Settings>) -> Self {
        Self {
            method,
            label,
            settings: settings.into(),
        }
    }

    /// True when these are the method's default settings.
    pub fn is_default(&self) -> bool {
        self.settings == self.method.default_settings()
    }
}

/// The knob settings the study runs.
pub fn configs() -> Vec<Config> {
    let mut v = Vec::new();
    let ms = |x: f32| Seconds(x / 1000.0);
    // The stepped sweeps: paper at its own 1 Hz step, sweep-G coarser.
    for (method, step, settle, int) in [
        (Method::Paper, 1.0, 10.0, 10.0),
        (Method::Paper, 1.0, 25.0, 25.0),
        (Method::Paper, 1.0, 50.0, 50.0),
        (Method::Paper, 1.0, 100.0, 100.0),
        (Method::SweepG, 4.0, 15.0, 10.0),
        (Method::SweepG, 2.0, 30.0, 20.0),
        (Method::SweepG, 2.0, 50.0, 40.0),
        (Method::SweepG, 2.0, 100.0, 100.0),
    ] {
        let s = SweepSettings {
            step: Hz(step),
            settle: ms(settle),
            integrate: ms(int),
            ..method.default_sweep()
        };
        v.push(Config::new(
            method,
            format!("{step} Hz, {settle}+{int} ms"),
            &s,
        ));
    }
    for int in [10.0, 20.0, 40.0, 80.0] {
        let s = StagedSettings {
            integrate: ms(int),
            ..StagedSettings::DEFAULT
        };
        v.push(Config::new(Method::Fit, format!("{int} ms"), &s));
    }
    // hold subtracts the unit's static admittance: the profile's air reference supplies it.
    let air = HoldSettings::DEFAULT;
    // The fast hold: auto's first stage (docs/methods.md).
    let fast = HoldSettings::FAST;
    v.push(Config {
        method: Method::Hold,
        label: format!(
            "no seed, {:.0}+{:.0} ms",
            1e3 * fast.refine.0,
            1e3 * (fast.hold.0 - fast.refine.0)
        ),
        settings: Settings::Hold(fast),
    });
    for (burst, refine, hold) in [
        (20.0, 50.0, 150.0),
        (20.0, 80.0, 300.0),
        (20.0, 100.0, 500.0),
        (20.0, 150.0, 800.0),
        (20.0, 200.0, 1300.0),
    ] {
        let s = HoldSettings {
            seed_burst: ms(burst),
            // auto's row: the shortest ring-down (three windows).
            seed_ring: if burst < 5.0 { ms(0.0) } else { air.seed_ring },
            refine: ms(refine),
            hold: ms(hold),
            ..air
        };
        let label = if refine > 0.0 {
            format!("{burst} ms seed, {refine}+{} ms", hold - refine)
        } else {
            format!("{burst} ms seed, {hold} ms")
        };
        v.push(Config {
            method: Method::Hold,
            label,
            settings: Settings::Hold(s),
        });
    }
    v
}

/// The unit `c` reads with, made as the product is calibrated: its air reference, then phantoms
/// A–E × `repeats` readings under `noise` (a unit is calibrated with its own front end, as the
/// paper calibrated its prototype) and the robust fit.
pub fn calibrate(c: &Config, repeats: usize, noise: NoiseScene) -> Option<UnitProfile> {
    crate::unit::simulated(c.method, &c.settings, noise, repeats, 900_000).ok()
}

/// Statistics of one config at one modulus and noise scene.
#[derive(Clone, Debug, Default)]
pub struct Cell {
    /// Readings taken.
    pub n: usize,
    /// Readings that were ok.
    pub ok: usize,
    /// Mean probe time per reading, ms.
    pub time_ms: f64,
    /// Sum of squared relative errors of ok readings.
    pub sum_err2: f64,
    /// Sum of relative errors of ok readings.
    pub sum_err: f64,
    /// Sum of squared reported (combined) relative sigmas.
    pub sum_sig2: f64,
    /// Sum of squared reported repeatability relative sigmas.
    pub sum_rep2: f64,
    /// Ok readings within ±5 % of the truth.
    pub within5: usize,
    /// Ok readings within ±10 %.
    pub within10: usize,
    /// Ok readings whose error is within 3 reported sigmas.
    pub within3sigma: usize,
    /// Sum of squared relative deviations from the noise-free reading of the same method (from
    /// the readings' own mean when the method refuses the noise-free data).
    pub sum_dev2: f64,
    /// Relative error of the noise-free reading (the calibration misfit plus the method's
    /// deterministic bias left after calibration), if that reading was ok.
    pub quiet_err: Option<f64>,
    /// Ok readings that reported a loss tangent.
    pub loss_ok: usize,
    /// Sum of the loss tangents' errors against the tissue's.
    pub sum_loss_err: f64,
    /// Sum of their squares.
    pub sum_loss_err2: f64,
    /// Sum of the squared reported σ of the loss tangent.
    pub sum_loss_sig2: f64,
}

impl Cell {
    /// RMS relative error of ok readings, %.
    pub fn rms_pct(&self) -> f64 {
        100.0 * (self.sum_err2 / self.ok.max(1) as f64).sqrt()
    }
    /// Mean relative error (bias), %.
    pub fn bias_pct(&self) -> f64 {
        100.0 * self.sum_err / self.ok.max(1) as f64
    }
    /// Standard deviation of the relative error, %.
    pub fn sd_pct(&self) -> f64 {
        let k = self.ok.max(2) as f64;
        let m = self.sum_err / k;
        100.0 * ((self.sum_err2 - k * m * m).max(0.0) / (k - 1.0)).sqrt()
    }
    /// RMS deviation from the noise-free reading (the error noise causes), %.
    pub fn noise_rms_pct(&self) -> f64 {
        100.0 * (self.sum_dev2 / self.ok.max(1) as f64).sqrt()
    }
    /// RMS reported combined sigma, %.
    pub fn sigma_pct(&self) -> f64 {
        100.0 * (self.sum_sig2 / self.ok.max(1) as f64).sqrt()
    }
    /// RMS reported repeatability sigma, %.
    pub fn repeat_pct(&self) -> f64 {
        100.0 * (self.sum_rep2 / self.ok.max(1) as f64).sqrt()
    }
    /// RMS error of the loss tangents read (`None` without any).
    pub fn loss_rms(&self) -> Option<f64> {
        (self.loss_ok > 0).then(|| (self.sum_loss_err2 / self.loss_ok as f64).sqrt())
    }
    /// Mean error of the loss tangents read.
    pub fn loss_bias(&self) -> Option<f64> {
        (self.loss_ok > 0).then(|| self.sum_loss_err / self.loss_ok as f64)
    }
    /// RMS reported σ of the loss tangent.
    pub fn loss_sigma_rms(&self) -> Option<f64> {
        (self.loss_ok > 0).then(|| (self.sum_loss_sig2 / self.loss_ok as f64).sqrt())
    }
}

/// Run `seeds` readings of config `c` (with the unit's profile `unit`) at modulus `e` under
/// `noise`.
pub fn evaluate(
    c: &Config,
    unit: &UnitProfile,
    e: f64,
    noise: NoiseScene,
    seeds: usize,
    seed0: u64,
) -> Cell {
    evaluate_on(c, unit, &Scene::on_modulus_kpa(e), e, noise, seeds, seed0)
}

/// [`evaluate`] on `quiet_scene` (noise-free; the readings take it with `noise`), whose true
/// storage modulus is `e` kPa: the loss tangents read are counted against its tissue's.
pub fn evaluate_on(
    c: &Config,
    unit: &UnitProfile,
    quiet_scene: &Scene,
    e: f64,
    noise: NoiseScene,
    seeds: usize,
    seed0: u64,
) -> Cell {
    let scene = quiet_scene.with_noise(noise);
    let loss_truth = quiet_scene.tissue.map_or(0.0, |t| t.loss_tangent);
    // The same method, same calibration, noise-free: what the reading would be without noise.
    let quiet = read(quiet_scene, seed0, c.method, c.settings, unit, |_| {})
        .ok()
        .and_then(|r| r.modulus)
        .map(|m| m.0 as f64);
    let mut cell = Cell {
        n: seeds,
        quiet_err: quiet.map(|q| (q - e) / e),
        ..Cell::default()
    };
    let mut t = 0.0;
    for k in 0..seeds {
        let Ok(r) = read(&scene, seed0 + k as u64, c.method, c.settings, unit, |_| {}) else {
            continue;
        };
        t += r.probe_time.0 as f64 * 1e3;
        cell.add(&r, e, quiet);
        cell.add_loss(&r, loss_truth);
    }
    cell.time_ms = t / seeds.max(1) as f64;
    cell.finish(quiet.is_some());
    cell
}

impl Cell {
    /// Count the loss tangent of reading `r` (if ok and it reported one) against the tissue's
    /// `truth`.
    pub fn add_loss(&mut self, r: &pzt_probe::Reading, truth: f64) {
        let (true, Some(l), Some(s)) = (r.status.is_ok(), r.loss_tangent, r.loss_tangent_sigma)
        else {
            return;
        };
        let err = l as f64 - truth;
        self.loss_ok += 1;
        self.sum_loss_err += err;
        self.sum_loss_err2 += err * err;
        self.sum_loss_sig2 += (s as f64) * (s as f64);
    }

    /// Count reading `r` of true modulus `e` (kPa) whose noise-free counterpart read `quiet`
    /// (kPa; None: it did not read): its error, its stated σ, its deviation from `quiet`.
    pub fn add(&mut self, r: &pzt_probe::Reading, e: f64, quiet: Option<f64>) {
        let (true, Some(m), Some(s), Some(rep)) = (
            r.status.is_ok(),
            r.modulus,
            r.modulus_sigma,
            r.modulus_sigma_repeat,
        ) else {
            return;
        };
        let err = (m.0 as f64 - e) / e;
        if let Some(q) = quiet {
            let dev = (m.0 as f64 - q) / e;
            self.sum_dev2 += dev * dev;
        }
        self.ok += 1;
        self.sum_err += err;
        self.sum_err2 += err * err;
        let sr = s.0 as f64 / e;
        self.sum_sig2 += sr * sr;
        let rr = rep.0 as f64 / e;
        self.sum_rep2 += rr * rr;
        self.within5 += (err.abs() <= 0.05) as usize;
        self.within10 += (err.abs() <= 0.10) as usize;
        self.within3sigma += (err.abs() <= 3.0 * sr) as usize;
    }

    /// After the last [`Cell::add`]: without noise-free readings to compare with (`had_quiet`
    /// false; a method may refuse perfectly clean data, e.g. a decay check whose χ² has no noise
    /// to divide by) the deviation from the readings' own mean, i.e. the scatter, stands in —
    /// never the error against the truth.
    pub fn finish(&mut self, had_quiet: bool) {
        if !had_quiet && self.ok > 1 {
            let k = self.ok as f64;
            let mean = self.sum_err / k;
            self.sum_dev2 = (self.sum_err2 - k * mean * mean).max(0.0);
        }
    }
}

/// Settings of the continuous tracker's curve: (segment length s, segments a plan): the fast
/// setting (12 ms segments, four a plan: more than 50 readings a second), single-segment plans
/// from 25 ms, the default (30 ms) and longer ones.
pub const STREAM_SETTINGS: [(f64, u8); 8] = [
    (0.012, 4),
    (0.025, 1),
    (0.03, 1),
    (0.035, 1),
    (0.045, 1),
    (0.06, 1),
    (0.09, 1),
    (0.15, 1),
];

/// The fast setting of [`STREAM_SETTINGS`]: segments of 12 ms, four a plan.
pub const FAST_STREAM: (f64, u8) = STREAM_SETTINGS[0];

/// Probe time of each of the tracker's streams, s.
pub const STREAM_SECONDS: f64 = 3.0;

pub use crate::stream::SETTLE_S as STREAM_SETTLE_S;

/// The continuous tracker (`pzt_probe::instrument::continuous`) at one segment length on one scene, streamed as
/// `probe-bench stream` streams ([`crate::stream::run`]).
#[derive(Clone, Debug, Default)]
pub struct StreamCell {
    /// Length of a tracking segment (one reading each), s.
    pub segment_s: f64,
    /// Segments a plan holds (`TrackerConfig::plan_segments`).
    pub plan_segments: u8,
    /// The readings after [`STREAM_SETTLE_S`] as a single-reading cell: `n` readings, `ok` of
    /// them ok, `time_ms` the mean probe time of one (a segment from the previous reading's end
    /// to its own), errors against the truth and against the same stream in the quiet scene.
    pub cell: Cell,
    /// Ok readings per second of probe time after [`STREAM_SETTLE_S`], over all streams.
    pub ok_per_s: f64,
    /// The steady-state Cramér–Rao bound ([`steady_crb_pct`]) for one reading's probe time, %.
    pub crb_pct: f64,
    /// Ok readings compared with the quiet stream's reading of the same `seq` (the others with
    /// its mean).
    pub matched: usize,
}

impl StreamCell {
    /// The setting as the tables write it: the segment in ms, and `× n` for plans of `n`
    /// segments.
    pub fn setting(&self) -> String {
        let ms = self.segment_s * 1e3;
        if self.plan_segments > 1 {
            format!("{ms:.0} × {}", self.plan_segments)
        } else {
            format!("{ms:.0}")
        }
    }

    /// Probe time per ok reading, ms (1000 / ok readings per second).
    pub fn ms_per_ok(&self) -> f64 {
        1e3 / self.ok_per_s.max(1e-9)
    }

    /// RMS error caused by noise over the bound (how far the tracker sits above it).
    pub fn ratio(&self) -> f64 {
        self.cell.noise_rms_pct() / self.crb_pct
    }
}

/// The unit the tracker reads with under `noise`: calibrated with the stream's method at its
/// default settings on A–E × 20 (noise seeds from 1000) — at bench noise the unit
/// `probe-bench stream` reads with (`crate::unit::default_for`).
pub fn stream_unit(noise: NoiseScene) -> Option<UnitProfile> {
    let m = pzt_probe::instrument::continuous::METHOD;
    crate::unit::simulated(m, &m.default_settings(), noise, 20, 1000).ok()
}

/// Stream `target` under `noise` with the default tracker but segments of `segment_s` seconds,
/// `plan_segments` a plan,
/// `seeds` streams of [`STREAM_SECONDS`] (noise seeds from `seed0`) with the unit `unit`, and
/// once in the quiet scene: each reading after [`STREAM_SETTLE_S`] counted against the truth
/// and against the quiet stream's reading of the same `seq` (ending within a millisecond of
/// it; else the quiet stream's mean). None when the stream fails to run or the target has no
/// modulus.
pub fn evaluate_stream(
    target: crate::scene::Target,
    noise: NoiseScene,
    segment_s: f64,
    plan_segments: u8,
    unit: &UnitProfile,
    seeds: usize,
    seed0: u64,
) -> Option<StreamCell> {
    use crate::stream::{run, summarize, StreamScene};
    use pzt_probe::instrument::continuous::TrackerConfig;
    let e = target.modulus_kpa()?;
    let config = TrackerConfig {
        segment: Seconds(segment_s as f32),
        plan_segments,
        ..TrackerConfig::DEFAULT
    };
    let after =
        |r: &&pzt_probe::instrument::continuous::StreamReading| r.t_s.0 as f64 > STREAM_SETTLE_S;
    let quiet = run(
        &StreamScene::on(target, NoiseScene::Quiet),
        &config,
        unit,
        seed0,
        STREAM_SECONDS,
        |_| {},
    )
    .ok()?
    .readings;
    let quiet_ok: Vec<(u32, f64, f64)> = quiet
        .iter()
        .filter(after)
        .filter(|r| r.reading.status.is_ok())
        .filter_map(|r| Some((r.seq, r.t_s.0 as f64, r.reading.modulus?.0 as f64)))
        .collect();
    let quiet_mean = (!quiet_ok.is_empty())
        .then(|| quiet_ok.iter().map(|q| q.2).sum::<f64>() / quiet_ok.len() as f64);
    let scene = StreamScene::on(target, noise);
    let mut cell = Cell::default();
    let (mut t_ms, mut ok, mut span, mut matched) = (0.0, 0.0, 0.0, 0);
    for k in 0..seeds {
        let s = run(
            &scene,
            &config,
            unit,
            seed0 + k as u64,
            STREAM_SECONDS,
            |_| {},
        )
        .ok()?;
        let sum = summarize(&s.readings, &s.truth, STREAM_SETTLE_S);
        let end = s.readings.last().map_or(0.0, |r| r.t_s.0 as f64);
        ok += sum.ok_per_s * (end - STREAM_SETTLE_S);
        span += end - STREAM_SETTLE_S;
        for r in s.readings.iter().filter(after) {
            cell.n += 1;
            t_ms += r.reading.probe_time.0 as f64 * 1e3;
            let same = quiet_ok
                .iter()
                .find(|q| q.0 == r.seq && (q.1 - r.t_s.0 as f64).abs() < 1e-3)
                .map(|q| q.2);
            matched += (same.is_some() && r.reading.status.is_ok()) as usize;
            let q = same.or(quiet_mean);
            cell.add(&r.reading, e, q);
        }
    }
    cell.time_ms = t_ms / cell.n.max(1) as f64;
    cell.finish(quiet_mean.is_some());
    let (sim, _) = scene.build().ok()?;
    let crb_pct = steady_crb_pct(
        &unit.calibration,
        &sim,
        e,
        config.drive.0 as f64,
        cell.time_ms * 1e-3,
    );
    Some(StreamCell {
        segment_s,
        plan_segments,
        cell,
        ok_per_s: ok / span.max(1e-9),
        crb_pct,
        matched,
    })
}

/// The Cramér–Rao bound on the resonance frequency (Hz) of the scene's resonator driven at its
/// resonance from rest for `t_s` seconds at drive amplitude `drive_v` (asked of the DAC), its
/// current observed in white noise, `f0`, `Q` and the motional conductance `g` unknown, the
/// static branch known.
///
/// Steady state (Rife–Boorstyn phase bound turned into frequency through the resonance's phase
/// slope `dφ/df = 2πτ`): `σ_f = 1 / (2π τ sqrt(2 (C/N0) T))`, with carrier power at the ADC
/// `C = (G_peak V k)² / 2` (`k` the front end's filters, [`front_end_gain`]: until 2026-11-24 the
/// bound left them out and was 12 % too low at 500 kPa), noise density `N0` (A²/Hz, one-sided),
/// `τ = Q / (π f0)`.
///
/// Switched on from rest the motional admittance in the drive's rotating frame is
/// `Y(t) = Y_m (1 − e^{λt})`, `Y_m = g/(1 + jQu)`, `λ = −1/τ + j2π(f_d − f_h)`. At `f_h = f0`
/// its derivative with respect to `f0` is `j 2π g τ [1 − (1 + t/τ) e^{−t/τ}]`: the steady
/// state's phase turns by `2πτ δf` but the free ring-up, which rotates at `δf`, has had no time
/// to turn at the start — the response begins in phase with the drive whatever the detuning.
/// (`∂Y/∂Q` and `∂Y/∂g` are in phase with the drive there, so the unknown `Q` and `g` cost
/// nothing.) The information therefore builds up with
/// `T_eff = ∫₀ᵀ (1 − (1 + t/τ) e^{−t/τ})² dt
///        = τ [x − 11/4 + 2 (2 + x) e^{−x} − (5/4 + 3x/2 + x²/2) e^{−2x}]`, `x = T/τ`,
/// which is `T − 2.75 τ` after a few τ and `≈ T⁵/(20 τ⁴)` for `T ≪ τ`. (Until 2026-11 the
/// bound used the amplitude's build-up `∫(1 − e^{−t/τ})²` = `T − 1.5 τ`, which forgets that
/// the early response carries no phase information: at 10.8 τ it was 7.5 % too optimistic.)
/// [`fisher_crb_hz`] computes the same bound numerically from the resonator's equation of motion;
/// the test `crb_matches_the_numerical_fisher_information` holds the two together.
pub fn crb_hz(scene: &Scene, drive_v: f64, t_s: f64) -> f64 {
    let (c, n0, tau) = carrier_noise_tau(scene, drive_v);
    let t_eff = tau * build_up(t_s / tau);
    1.0 / (2.0 * PI * tau * (2.0 * (c / n0) * t_eff.max(1e-30)).sqrt())
}

/// The Cramér–Rao bound on the resonance frequency (Hz) of the scene's resonator observed for
/// `t_s` seconds while it is driven at its resonance **in steady state** (driven long before the
/// observation starts, as the continuous tracker's segments are: the drive never stops, a
/// segment begins where the previous one left the resonator), `f0` and `g` unknown, `Q` known to
/// the tracker's prior, the static branch known: `σ_f = 1 / (2π τ sqrt(2 (C/N0) T))` —
/// [`crb_hz`] without the switch-on's build-up (`T_eff = T`). In steady state on the resonance
/// the current carries almost no information on `Q` (`∂Y/∂Q = 0` at `f_h = f0`): without a prior
/// the little that is left correlates with `f0` over a short window and the numerical bound
/// with `Q` free is 11.5 % higher at 2.5 τ; the tracker fits with a prior on `Q` (±50 %, a
/// thousand times the data's information) and so does this bound. [`fisher_crb_hz_after`]
/// with a long warm-up and that prior computes it numerically (test
/// `the_steady_state_bound_matches_the_numerical_fisher_information`).
pub fn steady_crb_hz(scene: &Scene, drive_v: f64, t_s: f64) -> f64 {
    let (c, n0, tau) = carrier_noise_tau(scene, drive_v);
    1.0 / (2.0 * PI * tau * (2.0 * (c / n0) * t_s.max(1e-30)).sqrt())
}

/// `T_eff / τ` of [`crb_hz`] at `x = T/τ`.
fn build_up(x: f64) -> f64 {
    if x < 0.05 {
        return x.powi(5) / 20.0;
    }
    let (e1, e2) = ((-x).exp(), (-2.0 * x).exp());
    x - 2.75 + 2.0 * (2.0 + x) * e1 - (1.25 + 1.5 * x + 0.5 * x * x) * e2
}

/// Magnitude of the front end's two filters at `f_hz`: the reconstruction filter between the
/// DAC and the PZT (the drive the PZT sees is `drive_v` times its gain) and the anti-alias
/// filter between the sense current and the ADC, whose noise enters after it — each two real
/// poles, `1/(1 + (f/f_c)²)`. At 242 Hz with both corners at 1 kHz it is 0.892: the carrier at
/// the ADC is 11 % below `g drive_v` and the bound 12 % above what an ideal front end's would be.
pub fn front_end_gain(scene: &Scene, f_hz: f64) -> f64 {
    let fe = &scene.front_end;
    let pole2 = |fc: f64| 1.0 / (1.0 + (f_hz / fc).powi(2));
    pole2(fe.reconstruction_hz) * pole2(fe.antialias_hz)
}

/// Carrier power `C` (A², at the ADC, through [`front_end_gain`]), noise density `N0` (A²/Hz,
/// one-sided, with the ADC's quantisation) and `τ` (s) of `scene` driven at `drive_v` (asked of
/// the DAC) on resonance.
fn carrier_noise_tau(scene: &Scene, drive_v: f64) -> (f64, f64, f64) {
    let k = scene.kelvin();
    let g = scene.pzt.motional_peak_s(&k) * front_end_gain(scene, k.natural_frequency_hz());
    let c = 0.5 * (g * drive_v) * (g * drive_v);
    let n0 = scene.front_end.current_noise_a_rthz.powi(2)
        + scene.front_end.amps_per_code().powi(2) / 12.0 / (scene.front_end.sample_rate_hz / 2.0);
    let tau = k.q() / (PI * k.natural_frequency_hz());
    (c, n0, tau)
}

/// The Cramér–Rao bound (Hz) on `f0` computed numerically: the motional branch (series `RLC`
/// with `R = 1/g`, `L = Q R / ω0`, `C = 1/(ω0² L)`) driven from rest by `drive_v sin(2π f_h t)`
/// through the reconstruction filter, its current through the anti-alias filter (each two real
/// poles at the scene's corners), `f_h = f0 + detune_hz`, integrated (RK4, 16 steps a sample)
/// and sampled at the front end's rate for `t_s`; the current's derivatives with respect to `f0`, `Q`, `g` by central
/// differences; white noise of the scene's density per sample; the `f0` element of the inverse
/// 3 × 3 Fisher matrix (the unknown `Q` and `g` accounted for). Independent of [`crb_hz`]'s
/// closed form. The samples themselves are observed here; the firmware's whole-cycle windows of
/// a sine fit lose essentially nothing of an envelope that changes little within a window.
pub fn fisher_crb_hz(scene: &Scene, drive_v: f64, t_s: f64, detune_hz: f64) -> f64 {
    fisher_crb_schedule_hz(scene, drive_v, &[(t_s, detune_hz)], 0.0, f64::INFINITY)
}

/// [`fisher_crb_hz`] with the resonator driven from rest for `warmup_s` seconds before the
/// `t_s` seconds observed (a long warm-up: the steady-state bound, [`steady_crb_hz`]) and a
/// prior on `Q` of relative standard uncertainty `q_prior_rel` (infinite: none).
pub fn fisher_crb_hz_after(
    scene: &Scene,
    drive_v: f64,
    warmup_s: f64,
    t_s: f64,
    detune_hz: f64,
    q_prior_rel: f64,
) -> f64 {
    let schedule = [(warmup_s + t_s, detune_hz)];
    fisher_crb_schedule_hz(scene, drive_v, &schedule, warmup_s, q_prior_rel)
}

/// The numerical bound of [`fisher_crb_hz`] for a drive that moves phase-continuously through
/// `schedule` — (duration s, detune from `f0` Hz) in turn, from rest — observed from
/// `observe_from_s` on, with a prior on `Q` of relative standard uncertainty `q_prior_rel`
/// (infinite: none): the bound of a reading that holds first at a seed and then on the
/// resonance, or of a stream's segment long after the drive came on.
pub fn fisher_crb_schedule_hz(
    scene: &Scene,
    drive_v: f64,
    schedule: &[(f64, f64)],
    observe_from_s: f64,
    q_prior_rel: f64,
) -> f64 {
    let k = scene.kelvin();
    let (f0, q, g) = (
        k.natural_frequency_hz(),
        k.q(),
        scene.pzt.motional_peak_s(&k),
    );
    let (_, n0, _) = carrier_noise_tau(scene, drive_v);
    let fs = scene.front_end.sample_rate_hz;
    let t_s: f64 = schedule.iter().map(|s| s.0).sum();
    let n = (t_s * fs).round() as usize;
    let skip = (observe_from_s * fs).round() as usize;
    // The drive's frequency at time t, and its phase (continuous across the switches).
    let f_at = |t: f64| {
        let mut end = 0.0;
        for &(d, det) in schedule {
            end += d;
            if t < end {
                return f0 + det;
            }
        }
        f0 + schedule.last().map_or(0.0, |s| s.1)
    };
    let substeps = 16;
    let h0 = 1.0 / (fs * substeps as f64);
    let mut phases = Vec::with_capacity(2 * n * substeps + 2);
    let mut ph = 0.0;
    for i in 0..=2 * n * substeps {
        phases.push(ph);
        ph += 2.0 * PI * f_at(i as f64 * 0.5 * h0) * 0.5 * h0;
    }
    // The front end's filters (two real poles each): the drive through the reconstruction
    // filter to the PZT, the motional current through the anti-alias filter to the ADC.
    let wr = 2.0 * PI * scene.front_end.reconstruction_hz;
    let wa = 2.0 * PI * scene.front_end.antialias_hz;
    let current = |f0: f64, q: f64, g: f64| -> Vec<f64> {
        let w0 = 2.0 * PI * f0;
        let r = 1.0 / g;
        let l = q * r / w0;
        let cap = 1.0 / (w0 * w0 * l);
        let sub = substeps;
        let h = h0;
        // State: reconstruction filter (2), charge and current of the motional branch (2),
        // anti-alias filter (2); the drive at half-step k (phases tabulated at every half step).
        let deriv = |k: usize, x: &[f64; 6]| -> [f64; 6] {
            [
                wr * (drive_v * phases[k].sin() - x[0]),
                wr * (x[0] - x[1]),
                x[3],
                (x[1] - r * x[3] - x[2] / cap) / l,
                wa * (x[3] - x[4]),
                wa * (x[4] - x[5]),
            ]
        };
        let add = |x: &[f64; 6], d: &[f64; 6], s: f64| -> [f64; 6] {
            core::array::from_fn(|i| x[i] + s * d[i])
        };
        let mut x = [0.0f64; 6];
        let mut out = Vec::with_capacity(n.saturating_sub(skip));
        for i in 0..n {
            for j in 0..sub {
                let k = 2 * (i * sub + j);
                let k1 = deriv(k, &x);
                let k2 = deriv(k + 1, &add(&x, &k1, 0.5 * h));
                let k3 = deriv(k + 1, &add(&x, &k2, 0.5 * h));
                let k4 = deriv(k + 2, &add(&x, &k3, h));
                for (m, v) in x.iter_mut().enumerate() {
                    *v += h / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m]);
                }
            }
            if i >= skip {
                out.push(x[5]);
            }
        }
        out
    };
    let steps = [1e-3, 1e-4 * q, 1e-4 * g];
    let cols: Vec<Vec<f64>> = (0..3)
        .map(|p| {
            let mut a = [f0, q, g];
            let mut b = a;
            a[p] += steps[p];
            b[p] -= steps[p];
            let (ya, yb) = (current(a[0], a[1], a[2]), current(b[0], b[1], b[2]));
            ya.iter()
                .zip(&yb)
                .map(|(u, v)| (u - v) / (2.0 * steps[p]))
                .collect()
        })
        .collect();
    let var = n0 * fs / 2.0;
    let mut fi = [[0.0f64; 3]; 3];
    for (i, row) in fi.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = cols[i]
                .iter()
                .zip(&cols[j])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / var;
        }
    }
    // f0 element of the inverse: 1 / (F00 − F0r Frr⁻¹ Fr0) over the nuisance block r = (Q, g).
    // A prior on Q: its information adds to the Q element.
    fi[1][1] += 1.0 / (q_prior_rel * q).powi(2);
    let det = fi[1][1] * fi[2][2] - fi[1][2] * fi[2][1];
    let inv = [
        [fi[2][2] / det, -fi[1][2] / det],
        [-fi[2][1] / det, fi[1][1] / det],
    ];
    let b = [fi[0][1], fi[0][2]];
    let schur = fi[0][0]
        - (b[0] * (inv[0][0] * b[0] + inv[0][1] * b[1])
            + b[1] * (inv[1][0] * b[0] + inv[1][1] * b[1]));
    1.0 / schur.max(1e-300).sqrt()
}

/// The bound of [`crb_hz`] as a relative modulus error (%) through `cal`'s slope, with the load
/// cell's own limit added in quadrature: a reading inverts at the force it measured, whose mean
/// over `t_s` scatters by the cell's conversion noise over the square root of its conversions
/// ([`force_floor_hz`]).
pub fn crb_pct(cal: &PowerLaw, e: f64, noise: NoiseScene, drive_v: f64, t_s: f64) -> f64 {
    scene_crb_pct(
        cal,
        &Scene::on_modulus_kpa(e).with_noise(noise),
        e,
        drive_v,
        t_s,
    )
}

/// [`crb_pct`] on `scene` (with its noise; true storage modulus `e` kPa): a lossy tissue's
/// bound is its own, through the scene's `τ` and carrier.
pub fn scene_crb_pct(cal: &PowerLaw, scene: &Scene, e: f64, drive_v: f64, t_s: f64) -> f64 {
    bound_pct(cal, scene, e, crb_hz(scene, drive_v, t_s), t_s)
}

/// The steady-state bound of [`steady_crb_hz`] for `t_s` seconds on `scene` (true modulus `e`,
/// kPa) as a relative modulus error (%) through `cal`'s slope, with the load cell's limit for
/// the force a stream reading inverts at (averaged over at least
/// `pzt_probe::instrument::continuous::FORCE_WINDOW_S`) added in quadrature.
pub fn steady_crb_pct(cal: &PowerLaw, scene: &Scene, e: f64, drive_v: f64, t_s: f64) -> f64 {
    let force_s = t_s.max(pzt_probe::instrument::continuous::FORCE_WINDOW_S);
    bound_pct(cal, scene, e, steady_crb_hz(scene, drive_v, t_s), force_s)
}

/// A resonance bound `f_hz` (Hz) on `scene` as a relative modulus error (%) at true modulus
/// `e` (kPa), the load cell's floor for a force averaged over `force_s` seconds added in
/// quadrature.
fn bound_pct(cal: &PowerLaw, scene: &Scene, e: f64, f_hz: f64, force_s: f64) -> f64 {
    let f = f_hz.hypot(force_floor_hz(scene, force_s));
    100.0 * f / cal.slope(e) / e
}

/// The resonance-equivalent (Hz) of the load cell's noise in a reading of `t_s` seconds on
/// `scene`: `|∂f/∂F| σ_cell / sqrt(rate t_s)`, the slope from the scene's closed-form resonance
/// at ±1 mN about its preload (0 without a load cell or its noise).
pub fn force_floor_hz(scene: &Scene, t_s: f64) -> f64 {
    let Some(cell) = scene.load_cell else {
        return 0.0;
    };
    let conversions = (cell.rate_hz * t_s).max(1.0);
    let f0 = scene.contact.preload_n;
    let at = |df: f64| scene.with_preload_n(f0 + df).resonance_hz();
    let slope = (at(1e-3) - at(-1e-3)) / 2e-3;
    (slope * cell.noise_n / conversions.sqrt()).abs()
}

/// Time constant τ = Q/(π f0) of the scene at modulus `e`, ms.
pub fn tau_ms(e: f64) -> f64 {
    scene_tau_ms(&Scene::on_modulus_kpa(e))
}

/// Time constant τ = Q/(π f0) of `scene`, ms.
pub fn scene_tau_ms(s: &Scene) -> f64 {
    1e3 * s.q() / (PI * s.resonance_hz())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form bound (switched on from rest, `T_eff` of the phase sensitivity's build-up)
    /// against the numerical Fisher information of the resonator's equation of motion, driven at
    /// its resonance, at 4–40 τ; the old amplitude build-up (`T − 1.5 τ`) misses by 7 % at 10 τ.
    #[test]
    fn crb_matches_the_numerical_fisher_information() {
        let scene = Scene::on_modulus_kpa(500.0).with_noise(NoiseScene::Bench);
        let tau = 1e-3 * tau_ms(500.0);
        for x in [4.0, 10.0, 40.0] {
            let (closed, numeric) = (
                crb_hz(&scene, 5.0, x * tau),
                fisher_crb_hz(&scene, 5.0, x * tau, 0.0),
            );
            let old = {
                let (c, n0, tau) = carrier_noise_tau(&scene, 5.0);
                let t_eff = tau * (x - 2.0 * (1.0 - (-x).exp()) + 0.5 * (1.0 - (-2.0 * x).exp()));
                1.0 / (2.0 * PI * tau * (2.0 * (c / n0) * t_eff).sqrt())
            };
            println!("{x} tau: closed {closed:.3e} Hz, numeric {numeric:.3e} Hz, old {old:.3e} Hz");
            assert!((closed / numeric - 1.0).abs() < 0.02, "{x} tau");
            if x == 10.0 {
                assert!(numeric / old > 1.05);
            }
        }
    }

    /// The steady-state bound (the tracker's: the drive never stops) against the numerical
    /// Fisher information of the resonator driven from rest for 15 τ before the observation, with
    /// the tracker's prior on `Q`, at 2.5 τ (a 35 ms segment) and 10 τ; and below the from-rest bound by the
    /// switch-on's build-up (`T` against `T − 2.75 τ`).
    #[test]
    fn the_steady_state_bound_matches_the_numerical_fisher_information() {
        let scene = Scene::on_modulus_kpa(500.0).with_noise(NoiseScene::Bench);
        let tau = 1e-3 * tau_ms(500.0);
        for x in [2.5, 10.0] {
            let closed = steady_crb_hz(&scene, 5.0, x * tau);
            let q_prior = pzt_probe::instrument::continuous::TrackerConfig::DEFAULT.q_prior as f64;
            let numeric = fisher_crb_hz_after(&scene, 5.0, 15.0 * tau, x * tau, 0.0, q_prior);
            let from_rest = crb_hz(&scene, 5.0, x * tau);
            println!(
                "{x} tau: steady closed {closed:.3e} Hz, numeric {numeric:.3e} Hz, from rest {from_rest:.3e} Hz"
            );
            assert!((closed / numeric - 1.0).abs() < 0.02, "{x} tau");
            let expect = (x / build_up(x)).sqrt();
            assert!((from_rest / closed / expect - 1.0).abs() < 1e-9, "{x} tau");
        }
    }

    /// On resonance is where the bound is lowest: with `Q` and `g` unknown, a tenth of a
    /// half-width off raises it by 10–20 % at 10 τ (docs/methods.md, hold).
    /// The schedule's bound: two pieces on resonance are one hold (the drive's phase is
    /// continuous), and 30 ms a half-width off before the hold costs about a fifth (measured
    /// 1.21× at 500 kPa, 9 τ in all; 20 ms: 1.08×) — what a hold that starts at a seed instead
    /// of the resonance can at best reach.
    #[test]
    fn a_seed_before_the_hold_costs_what_its_detuning_loses() {
        let scene = Scene::on_modulus_kpa(500.0).with_noise(NoiseScene::Bench);
        let half_width = scene.resonance_hz() / (2.0 * scene.q());
        let t = 0.125;
        let on = fisher_crb_hz(&scene, 5.0, t, 0.0);
        let split = fisher_crb_schedule_hz(
            &scene,
            5.0,
            &[(0.03, 0.0), (t - 0.03, 0.0)],
            0.0,
            f64::INFINITY,
        );
        assert!((split / on - 1.0).abs() < 1e-6, "{split} vs {on}");
        let seeded = fisher_crb_schedule_hz(
            &scene,
            5.0,
            &[(0.03, -half_width), (t - 0.03, 0.0)],
            0.0,
            f64::INFINITY,
        );
        println!("30 ms a half-width off: {:.3}x", seeded / on);
        assert!((1.15..1.27).contains(&(seeded / on)), "{}", seeded / on);
    }

    #[test]
    fn the_bound_is_lowest_on_resonance() {
        let scene = Scene::on_modulus_kpa(500.0).with_noise(NoiseScene::Bench);
        let t = 10.0 * 1e-3 * tau_ms(500.0);
        let half_width = scene.resonance_hz() / (2.0 * scene.q());
        let on = fisher_crb_hz(&scene, 5.0, t, 0.0);
        for d in [-0.1, 0.1] {
            let off = fisher_crb_hz(&scene, 5.0, t, d * half_width) / on;
            println!("{d} half-widths off: {off:.3}x");
            assert!((1.1..1.2).contains(&off), "{d}: {off}");
        }
    }
}
