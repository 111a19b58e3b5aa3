//! The error budget of a reading (issue #13): what a reading is off by, by source, and how well
//! the combined standard uncertainty it reports covers the truth.
//!
//! Every figure is measured through the main job's path: the simulated unit's profile as a user
//! gets it ([`crate::unit::default_for`]) and `pzt_probe::board::sim::read` on the scenes
//! `probe-bench measure` builds (`Scene::on_modulus_kpa(e).with_noise(..).with_preload_n(..)`),
//! concluded by the one pipeline. The reported σ's parts are taken apart through the same
//! `UnitProfile::invert` the pipeline calls, with the calibration's parameter covariance or its
//! misfit set to zero in a copy of the profile.

use crate::pareto::{evaluate, Config};
use anyhow::{anyhow, Result};
use hal_sim::{NoiseScene, Scene};
use pzt_probe::board::sim::read;
use pzt_probe::reading::{Method, Reading};
use pzt_probe::unit::profile::{
    drift_allowance, UnitProfile, FREE_RESONANCE_ALLOWANCE, FREE_RESONANCE_DRIFT_HZ_S,
};
use pzt_probe::{Hz, KPa, Newtons};

/// What the budget measures, and on how many readings.
#[derive(Clone, Debug)]
pub struct Options {
    /// Methods whose noise is measured (each with its own default settings and unit profile).
    pub noise_methods: Vec<Method>,
    /// Moduli of the noise rows, kPa.
    pub noise_moduli: Vec<f64>,
    /// Readings per noise cell.
    pub noise_seeds: usize,
    /// Moduli between the calibration phantoms for the calibration bias, kPa (at 30 mN).
    pub bias_moduli: Vec<f64>,
    /// Readings averaged per bias, preload, force-noise and drift cell.
    pub seeds: usize,
    /// Moduli of the preload rows, kPa.
    pub preload_moduli: Vec<f64>,
    /// Contact forces of the preload rows and of the coverage set, N.
    pub forces: Vec<f64>,
    /// Shifts of the probe's free resonance since the air reference, Hz.
    pub drifts_hz: Vec<f64>,
    /// Moduli of the coverage set, kPa.
    pub coverage_moduli: Vec<f64>,
    /// Readings (noise seeds) per modulus and force of the coverage set.
    pub coverage_seeds: usize,
    /// Moduli of the lossy-tissue set, kPa (at 30 mN).
    pub loss_moduli: Vec<f64>,
    /// Loss tangents of the lossy-tissue set.
    pub loss_tangents: Vec<f64>,
    /// Readings (noise seeds) per modulus and loss tangent of the lossy-tissue set.
    pub loss_seeds: usize,
    /// First noise seed (the unit was calibrated on seeds from 1000).
    pub seed0: u64,
}

impl Options {
    /// The generator's set (`probe-bench accuracy`).
    pub fn full() -> Self {
        Self {
            noise_methods: vec![Method::Auto, Method::Hold, Method::Fit],
            noise_moduli: vec![200.0, 500.0, 1500.0],
            noise_seeds: 20,
            bias_moduli: vec![200.0, 350.0, 500.0, 700.0, 1000.0, 1500.0, 2000.0],
            seeds: 8,
            preload_moduli: vec![157.5, 279.0, 414.0, 1146.0],
            forces: vec![0.015, 0.020, 0.030, 0.040, 0.045, 0.050],
            drifts_hz: vec![-0.5, 0.5],
            coverage_moduli: vec![
                180.0, 230.0, 350.0, 500.0, 700.0, 900.0, 1300.0, 1800.0, 2300.0,
            ],
            coverage_seeds: 8,
            loss_moduli: vec![180.0, 350.0, 700.0, 1300.0, 2300.0],
            loss_tangents: vec![0.0, 0.1, 0.2, 0.3, 0.4, 0.5],
            loss_seeds: 6,
            seed0: 50_000,
        }
    }

    /// A small set for the tests.
    pub fn small() -> Self {
        Self {
            noise_methods: vec![Method::Auto],
            noise_moduli: vec![500.0],
            noise_seeds: 8,
            bias_moduli: vec![350.0, 700.0],
            seeds: 8,
            preload_moduli: vec![279.0],
            forces: vec![0.015, 0.030, 0.050],
            drifts_hz: vec![0.5],
            coverage_moduli: vec![230.0, 500.0, 900.0, 1800.0],
            coverage_seeds: 6,
            loss_moduli: vec![350.0, 1300.0],
            loss_tangents: vec![0.0, 0.3, 0.5],
            loss_seeds: 3,
            seed0: 60_000,
        }
    }
}

/// The reported standard uncertainty of a reading and its parts (kPa): `combined² =
/// repeat² + cov² + misfit² + drift²` (GUM, first order, `Modulus::propagated`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Terms {
    /// The resonance's own scatter and the contact force's, through the curve.
    pub repeat: f64,
    /// The calibration's parameter covariance.
    pub cov: f64,
    /// The curve's own misfit (the calibration's held-out misfit).
    pub misfit: f64,
    /// The free resonance's allowance since the air reference and over the reading
    /// (`profile::drift_allowance` of its probe time), through the curve.
    pub drift: f64,
    /// What the reading reports.
    pub combined: f64,
}

impl Terms {
    /// The parts of the σ `r` reports, through `unit`'s own inversion.
    pub fn of(unit: &UnitProfile, r: &Reading) -> Option<Terms> {
        let (f, s) = (r.resonance?, r.resonance_sigma?);
        let force = r.force;
        let sigma = |u: &UnitProfile, allowance: Hz| {
            u.invert_with(f, s, force.as_ref(), allowance)
                .ok()
                .map(|m| m.sigma.0 as f64)
        };
        let full = sigma(unit, drift_allowance(r.probe_time))?;
        let curve = sigma(unit, Hz(0.0))?;
        let mut no_misfit = *unit;
        no_misfit.calibration.model_sigma_hz = 0.0;
        if let Some(c) = no_misfit.contact.as_mut() {
            c.model_sigma_hz = 0.0;
        }
        let mut bare = no_misfit;
        bare.calibration.cov = [[0.0; 3]; 3];
        if let Some(c) = bare.contact.as_mut() {
            c.cov = [[0.0; 3]; 3];
        }
        let with_cov = sigma(&no_misfit, Hz(0.0))?;
        let repeat = sigma(&bare, Hz(0.0))?;
        let q = |a: f64, b: f64| (a * a - b * b).max(0.0).sqrt();
        Some(Terms {
            repeat,
            cov: q(with_cov, repeat),
            misfit: q(curve, with_cov),
            drift: q(full, curve),
            combined: r.modulus_sigma.map(|m| m.0 as f64).unwrap_or(full),
        })
    }

    /// `sqrt(repeat² + cov² + misfit² + drift²)`.
    pub fn quadrature(&self) -> f64 {
        (self.repeat.powi(2) + self.cov.powi(2) + self.misfit.powi(2) + self.drift.powi(2)).sqrt()
    }

    /// The reported σ without the free resonance's allowance.
    pub fn statistical(&self) -> f64 {
        (self.repeat.powi(2) + self.cov.powi(2) + self.misfit.powi(2)).sqrt()
    }
}

/// Noise of one method at one modulus (bench noise, 30 mN, default settings).
#[derive(Clone, Debug)]
pub struct NoiseRow {
    pub method: Method,
    pub e_kpa: f64,
    pub probe_time_ms: f64,
    pub ok: usize,
    pub n: usize,
    /// RMS deviation from the noise-free reading, % of the truth.
    pub scatter_pct: f64,
    /// RMS repeatability σ the readings report, %.
    pub reported_repeat_pct: f64,
}

/// One cell of readings on a scene: the mean error and the mean reported parts.
#[derive(Clone, Debug, Default)]
pub struct Cell {
    pub e_kpa: f64,
    pub force_n: f64,
    pub n: usize,
    pub ok: usize,
    /// Mean relative error of the ok readings, %.
    pub mean_err_pct: f64,
    /// Standard deviation of the relative error, %.
    pub sd_pct: f64,
    /// RMS of the reported parts, % of the truth.
    pub terms_pct: Terms,
    /// Mean contact force reported, N, and its RMS σ.
    pub force_mean_n: f64,
    pub force_sigma_n: f64,
}

/// The force sensor's noise at one modulus.
#[derive(Clone, Debug)]
pub struct ForceRow {
    pub e_kpa: f64,
    /// `∂E/∂F` through the unit's inversion at the reading's resonance, % per mN.
    pub de_df_pct_per_mn: f64,
    /// RMS σ of the force the readings report, mN.
    pub sigma_f_mn: f64,
    /// `|∂E/∂F| σ_F`, %.
    pub predicted_pct: f64,
    /// RMS of the paired difference of readings with and without the cell's noise (same
    /// front-end noise seeds), %.
    pub measured_pct: f64,
}

/// The air reference's age at one modulus.
#[derive(Clone, Debug)]
pub struct DriftRow {
    pub e_kpa: f64,
    /// The mean (paired) change of the reading per hertz of free-resonance shift since the air
    /// reference, % per Hz, at each shift of [`Options::drifts_hz`].
    pub pct_per_hz: Vec<f64>,
}

/// Coverage of the reported σ over a scene set.
#[derive(Clone, Debug, Default)]
pub struct Coverage {
    pub readings: usize,
    pub ok: usize,
    pub within1: usize,
    pub within2: usize,
    pub within3: usize,
    /// RMS of error / reported σ.
    pub rms_z: f64,
    /// Within 1σ and 2σ of the σ without the free resonance's allowance.
    pub within1_stat: usize,
    pub within2_stat: usize,
    /// RMS relative error, % and RMS reported σ, %.
    pub rms_err_pct: f64,
    pub rms_sigma_pct: f64,
    /// Per modulus: (modulus, ok, within 1σ, within 2σ).
    pub per_modulus: Vec<(f64, usize, usize, usize)>,
    /// Per force: (force N, ok, within 1σ, within 2σ).
    pub per_force: Vec<(f64, usize, usize, usize)>,
    /// Every ok reading: (modulus, force N, error %, σ %).
    pub points: Vec<(f64, f64, f64, f64)>,
}

impl Coverage {
    pub fn frac1(&self) -> f64 {
        self.within1 as f64 / self.ok.max(1) as f64
    }
    pub fn frac2(&self) -> f64 {
        self.within2 as f64 / self.ok.max(1) as f64
    }
}

/// Readings on lossy tissue at one loss tangent, over the set's moduli and seeds.
#[derive(Clone, Debug, Default)]
pub struct LossRow {
    /// The tissue's loss tangent.
    pub tan_d: f64,
    /// Readings taken, ok, and refused as `broad_resonance`.
    pub readings: usize,
    pub ok: usize,
    pub broad: usize,
    /// RMS relative error of the modulus, %, and its worst, %.
    pub rms_modulus_pct: f64,
    pub worst_modulus_pct: f64,
    /// Ok readings with the modulus within 3 of its σ.
    pub modulus_within3: usize,
    /// RMS error of the loss tangent, RMS of its reported σ.
    pub rms_loss: f64,
    pub rms_loss_sigma: f64,
    /// Ok readings with the loss tangent within 1, 2 and 3 of its σ.
    pub loss_within: [usize; 3],
}

/// What a reading is off by, source by source: the front end's noise, the calibration's bias
/// between its phantoms, the preload, the load cell's noise and the air reference's age.
#[derive(Clone, Debug)]
pub struct Sources {
    pub noise: Vec<NoiseRow>,
    pub bias: Vec<Cell>,
    pub preload: Vec<Cell>,
    pub force: Vec<ForceRow>,
    pub drift: Vec<DriftRow>,
}

/// The whole budget.
#[derive(Clone, Debug)]
pub struct Budget {
    pub options: Options,
    /// What a reading is off by, source by source.
    pub sources: Sources,
    /// Under the stated conditions: the free resonance off the air reference's by a normal
    /// draw of standard deviation `FREE_RESONANCE_ALLOWANCE` per reading.
    pub coverage: Coverage,
    /// Without drift: the free resonance the air reference's.
    pub clean: Coverage,
    /// Lossy tissue: modulus and loss tangent against the loss tangent.
    pub loss: Vec<LossRow>,
}

/// The scene `probe-bench measure --modulus-kpa e --preload-n f --noise ..` reads.
pub fn scene(e_kpa: f64, force_n: f64, noise: NoiseScene) -> Scene {
    Scene::on_modulus_kpa(e_kpa)
        .with_noise(noise)
        .with_preload_n(force_n)
}

/// The modulus of a reading that is `ok`.
fn ok_modulus(r: &Reading) -> Option<KPa> {
    r.modulus.filter(|_| r.status.is_ok())
}

/// One reading by the default strategy with the unit's profile.
fn read_auto(unit: &UnitProfile, s: &Scene, seed: u64) -> Option<Reading> {
    let m = Method::Auto;
    read(s, seed, m, m.default_settings(), unit, |_| {}).ok()
}

/// `seeds` readings on `s` (truth `e`): the mean error, its scatter, the reported parts.
fn cell(unit: &UnitProfile, s: &Scene, e: f64, seeds: usize, seed0: u64) -> Cell {
    let mut c = Cell {
        e_kpa: e,
        force_n: s.contact.preload_n,
        n: seeds,
        ..Cell::default()
    };
    let (mut sum, mut sum2) = (0.0, 0.0);
    let mut t2 = [0.0f64; 5];
    let (mut fsum, mut fs2) = (0.0, 0.0);
    for k in 0..seeds {
        let Some(r) = read_auto(unit, s, seed0 + k as u64) else {
            continue;
        };
        let Some(m) = ok_modulus(&r) else {
            continue;
        };
        let err = (m.0 as f64 - e) / e;
        c.ok += 1;
        sum += err;
        sum2 += err * err;
        if let Some(t) = Terms::of(unit, &r) {
            for (a, v) in t2
                .iter_mut()
                .zip([t.repeat, t.cov, t.misfit, t.drift, t.combined])
            {
                *a += (v / e).powi(2);
            }
        }
        if let Some(f) = r.force {
            fsum += f.mean.0 as f64;
            fs2 += (f.sigma.0 as f64).powi(2);
        }
    }
    let k = c.ok.max(1) as f64;
    c.mean_err_pct = 100.0 * sum / k;
    c.sd_pct = 100.0 * ((sum2 - k * (sum / k).powi(2)).max(0.0) / (k - 1.0).max(1.0)).sqrt();
    let r = |x: f64| 100.0 * (x / k).sqrt();
    c.terms_pct = Terms {
        repeat: r(t2[0]),
        cov: r(t2[1]),
        misfit: r(t2[2]),
        drift: r(t2[3]),
        combined: r(t2[4]),
    };
    c.force_mean_n = fsum / k;
    c.force_sigma_n = (fs2 / k).sqrt();
    c
}

/// Measure the budget with `opts`; `tick` is called once per unit of work (see
/// [`work_units`]).
pub fn measure(opts: &Options, mut tick: impl FnMut()) -> Result<Budget> {
    let noise = NoiseScene::Bench;
    let unit = crate::unit::default_for(Method::Auto)?;
    let s0 = opts.seed0;
    // (a) noise per method and probe time: pareto's evaluate with each method's own unit.
    let mut noise_rows = Vec::new();
    for &m in &opts.noise_methods {
        let u = crate::unit::default_for(m)?;
        let c = Config::new(m, "default".into(), m.default_settings());
        for &e in &opts.noise_moduli {
            let cell = evaluate(&c, &u, e, noise, opts.noise_seeds, s0);
            noise_rows.push(NoiseRow {
                method: m,
                e_kpa: e,
                probe_time_ms: cell.time_ms,
                ok: cell.ok,
                n: cell.n,
                scatter_pct: cell.noise_rms_pct(),
                reported_repeat_pct: cell.repeat_pct(),
            });
            tick();
        }
    }
    // (b) calibration bias between the phantoms, at the nominal 30 mN.
    let mut bias = Vec::new();
    for &e in &opts.bias_moduli {
        bias.push(cell(&unit, &scene(e, 0.030, noise), e, opts.seeds, s0));
        tick();
    }
    // (c) preload: the residual error over the force window after compensation.
    let mut preload = Vec::new();
    for &e in &opts.preload_moduli {
        for &f in &opts.forces {
            preload.push(cell(&unit, &scene(e, f, noise), e, opts.seeds, s0));
            tick();
        }
    }
    // (d) the force sensor's noise: predicted through the inversion, and measured by turning
    // the cell's noise off with the same front-end noise seeds.
    let mut force = Vec::new();
    for &e in &opts.bias_moduli {
        let on = scene(e, 0.030, noise);
        let mut off = on;
        if let Some(c) = off.load_cell.as_mut() {
            c.noise_n = 0.0;
        }
        let (mut d2, mut slope, mut sf2, mut k) = (0.0, 0.0, 0.0, 0usize);
        for j in 0..opts.seeds {
            let seed = s0 + j as u64;
            let (Some(a), Some(b)) = (read_auto(&unit, &on, seed), read_auto(&unit, &off, seed))
            else {
                continue;
            };
            let (Some(ma), Some(mb), Some(f), Some(fs), Some(w)) = (
                ok_modulus(&a),
                ok_modulus(&b),
                a.resonance,
                a.resonance_sigma,
                a.force,
            ) else {
                continue;
            };
            let at = |df: f32| {
                let mut w2 = w;
                w2.mean = Newtons(w.mean.0 + df);
                unit.invert(f, fs, Some(&w2), a.probe_time)
                    .ok()
                    .map(|m| m.value.0 as f64)
            };
            let (Some(hi), Some(lo)) = (at(1e-3), at(-1e-3)) else {
                continue;
            };
            slope += (hi - lo) / 2.0 / e; // per mN
            sf2 += (w.sigma.0 as f64 * 1e3).powi(2);
            d2 += ((ma.0 - mb.0) as f64 / e).powi(2);
            k += 1;
        }
        let k = k.max(1) as f64;
        let (slope, sf) = (slope / k, (sf2 / k).sqrt());
        force.push(ForceRow {
            e_kpa: e,
            de_df_pct_per_mn: 100.0 * slope,
            sigma_f_mn: sf,
            predicted_pct: 100.0 * (slope * sf).abs(),
            measured_pct: 100.0 * (d2 / k).sqrt(),
        });
        tick();
    }
    // (e) the air reference's age: the probe's free resonance shifted since the air reference
    // (the unit's profile is the same; the scene's probe is not), paired seeds.
    let mut drift = Vec::new();
    for &e in &opts.bias_moduli {
        let base = scene(e, 0.030, noise);
        let mut row = DriftRow {
            e_kpa: e,
            pct_per_hz: Vec::new(),
        };
        for &dh in &opts.drifts_hz {
            let mut moved = base;
            moved.mech.free_resonance_hz += dh;
            let (mut sum, mut k) = (0.0, 0usize);
            for j in 0..opts.seeds {
                let seed = s0 + j as u64;
                let m = |s: &Scene| {
                    read_auto(&unit, s, seed)
                        .and_then(|r| ok_modulus(&r))
                        .map(|m| m.0 as f64)
                };
                if let (Some(a), Some(b)) = (m(&moved), m(&base)) {
                    sum += (a - b) / e;
                    k += 1;
                }
            }
            row.pct_per_hz.push(100.0 * sum / k.max(1) as f64 / dh);
        }
        drift.push(row);
        tick();
    }
    // (f) coverage of the combined σ: moduli × forces × seeds, under the conditions of use the
    // allowance states (the free resonance off its air reference's by N(0, allowance)), and
    // without any drift.
    let coverage = coverage_of(&unit, opts, true, &mut tick)?;
    let clean = coverage_of(&unit, opts, false, &mut || {})?;
    // (g) lossy tissue: the modulus and the loss tangent a reading reports against the truth.
    let mut loss = Vec::new();
    for &t in &opts.loss_tangents {
        let mut row = LossRow {
            tan_d: t,
            ..LossRow::default()
        };
        let (mut e2, mut l2, mut s2) = (0.0, 0.0, 0.0);
        for &e in &opts.loss_moduli {
            for j in 0..opts.loss_seeds {
                let seed = opts.seed0 + 20_000 + j as u64;
                let s = scene(e, 0.030, noise).with_loss_tangent(t);
                row.readings += 1;
                let Some(r) = read_auto(&unit, &s, seed) else {
                    continue;
                };
                if r.status == pzt_probe::Status::Failed(pzt_probe::Failure::BroadResonance) {
                    row.broad += 1;
                }
                let (Some(m), Some(sm), Some(l), Some(sl)) = (
                    ok_modulus(&r),
                    r.modulus_sigma,
                    r.loss_tangent,
                    r.loss_tangent_sigma,
                ) else {
                    continue;
                };
                row.ok += 1;
                let err = m.0 as f64 / e - 1.0;
                e2 += err * err;
                row.worst_modulus_pct = row.worst_modulus_pct.max(100.0 * err.abs());
                row.modulus_within3 += usize::from((m.0 as f64 - e).abs() <= 3.0 * sm.0 as f64);
                let (dl, sl) = (l as f64 - t, sl as f64);
                l2 += dl * dl;
                s2 += sl * sl;
                for (k, w) in row.loss_within.iter_mut().enumerate() {
                    *w += usize::from(dl.abs() <= (k + 1) as f64 * sl);
                }
            }
        }
        let k = row.ok.max(1) as f64;
        row.rms_modulus_pct = 100.0 * (e2 / k).sqrt();
        row.rms_loss = (l2 / k).sqrt();
        row.rms_loss_sigma = (s2 / k).sqrt();
        loss.push(row);
        tick();
    }
    Ok(Budget {
        options: opts.clone(),
        sources: Sources {
            noise: noise_rows,
            bias,
            preload,
            force,
            drift,
        },
        coverage,
        clean,
        loss,
    })
}

/// The calls of `tick` [`measure`] makes with `opts`.
pub fn work_units(o: &Options) -> u64 {
    (o.noise_methods.len() * o.noise_moduli.len()
        + o.bias_moduli.len() * 3
        + o.preload_moduli.len() * o.forces.len()
        + o.coverage_moduli.len() * o.forces.len()
        + o.loss_tangents.len()) as u64
}

/// The binomial standard deviation of a fraction `p` over `n` trials.
pub fn binomial_sd(p: f64, n: usize) -> f64 {
    (p * (1.0 - p) / n.max(1) as f64).sqrt()
}

/// The coverage of the reported σ on `opts`'s coverage set (with `drift`, each reading's free
/// resonance moved by a normal draw of standard deviation the allowance and drifting during
/// the reading at a rate drawn with standard deviation the allowance's rate, from its own
/// seed: the conditions `profile::drift_allowance` states).
fn coverage_of(
    unit: &UnitProfile,
    opts: &Options,
    drift: bool,
    tick: &mut dyn FnMut(),
) -> Result<Coverage> {
    let mut cov = Coverage::default();
    let (mut z2, mut e2, mut s2) = (0.0, 0.0, 0.0);
    let u = FREE_RESONANCE_ALLOWANCE.0 as f64;
    for &e in &opts.coverage_moduli {
        let mut pm = (e, 0, 0, 0);
        for (fi, &f) in opts.forces.iter().enumerate() {
            if cov.per_force.len() <= fi {
                cov.per_force.push((f, 0, 0, 0));
            }
            for j in 0..opts.coverage_seeds {
                let seed = opts.seed0 + 10_000 + j as u64;
                let mut s = scene(e, f, NoiseScene::Bench);
                if drift {
                    let mut rng = probe_rng::Rng::new(seed ^ (e.to_bits() >> 3) ^ f.to_bits());
                    s.mech.free_resonance_hz += u * rng.normal();
                    s = s.with_drift(hal_sim::Drift {
                        rate_hz_s: FREE_RESONANCE_DRIFT_HZ_S as f64 * rng.normal(),
                    });
                }
                cov.readings += 1;
                let Some(r) = read_auto(unit, &s, seed) else {
                    continue;
                };
                let (Some(m), Some(sg)) = (ok_modulus(&r), r.modulus_sigma) else {
                    continue;
                };
                let err = m.0 as f64 - e;
                let z = err.abs() / (sg.0 as f64).max(1e-12);
                cov.ok += 1;
                let (w1, w2) = ((z <= 1.0) as usize, (z <= 2.0) as usize);
                cov.within1 += w1;
                cov.within2 += w2;
                cov.within3 += (z <= 3.0) as usize;
                if let Some(t) = Terms::of(unit, &r) {
                    let zs = err.abs() / t.statistical().max(1e-12);
                    cov.within1_stat += (zs <= 1.0) as usize;
                    cov.within2_stat += (zs <= 2.0) as usize;
                }
                z2 += z * z;
                e2 += (err / e).powi(2);
                s2 += (sg.0 as f64 / e).powi(2);
                pm.1 += 1;
                pm.2 += w1;
                pm.3 += w2;
                let pf = &mut cov.per_force[fi];
                pf.1 += 1;
                pf.2 += w1;
                pf.3 += w2;
                cov.points
                    .push((e, f, 100.0 * err / e, 100.0 * sg.0 as f64 / e));
            }
            tick();
        }
        cov.per_modulus.push(pm);
    }
    if cov.ok == 0 {
        return Err(anyhow!("no ok reading in the coverage set"));
    }
    let k = cov.ok as f64;
    cov.rms_z = (z2 / k).sqrt();
    cov.rms_err_pct = 100.0 * (e2 / k).sqrt();
    cov.rms_sigma_pct = 100.0 * (s2 / k).sqrt();
    Ok(cov)
}
