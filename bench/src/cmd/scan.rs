//! `probe-bench scan`: scan a simulated phantom with a lump on a grid — press at the preload,
//! read, lift, move — and map its stiffness, marking where the lump was found.
//!
//! Each grid point is one full reading of the simulated probe (`board::sim::read`: the
//! firmware's sweep, estimator and calibration, the probe starting from rest as after a lift),
//! pressed onto the phantom's apparent modulus at that point (`hal_sim::lump`). The lump is
//! located on the resonance map: the background is the 10th percentile of the resonances, the lump is the
//! connected region around the highest reading that stands above half-way between background
//! and peak; its centre is the centroid of that region weighted by the rise above background and
//! its size the diameter of a disc of the region's area.
//!
//! On lossy tissue (`--loss-tangent`, and a lump of its own modulus and loss,
//! `--lump-modulus-kpa`, `--lump-loss-tangent`; the model is `hal_sim::lump`'s) each reading also
//! reports the tissue's loss tangent, and the scan maps it beside the stiffness. The loss lump is
//! located by the same rule on the loss map ([`locate_values`]), as a rise or as a dip (a lump
//! may be more or less lossy than its background): whichever stands out the more, if it rises
//! above the background by at least [`MIN_LOSS_CONTRAST`] and [`LOSS_CONTRAST_SIGMAS`] times
//! the map's median reported σ of the loss, beyond what a stiffness contrast alone does to the
//! loss read (see the constant).
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > y)` also rejects NaN, deliberately

use super::slide::{slide, Slide, SlideResult};
use super::{progress, CalibrationArgs};
use crate::calfile;
use crate::plot::{self, draw_legend, draw_to, err, padded_range, Area, Backend};
use crate::scene::{parse_noise, NoiseArgs};
use anyhow::{anyhow, bail, Result};
use clap::{Args, ValueEnum};
use hal_sim::lump::{self, Inclusion, LumpMaterial, LumpPhantom};
use hal_sim::Scene;
use plotters::prelude::*;
use pzt_probe::board::sim as simboard;
use pzt_probe::engine::sweep::SweepSettings;
use pzt_probe::reading::{Reading, Settings};
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::{Method, PowerLaw, Status};
use serde_json::{json, Value};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The phantoms that can be scanned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ScanScene {
    /// Paper 003: silicone disc 30 mm x 15 mm, a 19 mm coin 1 mm under the surface.
    Coin,
    /// Paper 002: a 6 mm steel ball 1 mm under the surface of Dragon Skin 20, at --ball-d-mm
    /// along the path.
    Ball,
}

#[derive(Args)]
pub struct ScanArgs {
    /// Phantom to scan.
    #[arg(long, value_enum, default_value = "coin")]
    pub scene: ScanScene,
    /// Slide the probe across the phantom reading continuously (the tracker, as
    /// `probe-bench stream`) instead of pressing on a grid: along a line through the lump
    /// (coin: at the coin's y from x = −13.5 to 13.5 mm; ball: along paper 002's path, −4 to
    /// 24 mm). With several `--speed-mm-s` the plot is the lump's centre error and contrast
    /// against speed.
    #[arg(long)]
    pub continuous: bool,
    /// Sliding speed(s), mm/s (`--continuous`).
    #[arg(long, num_args = 1.., default_values_t = [5.0])]
    pub speed_mm_s: Vec<f64>,
    /// Coin scene: where the coin's centre is, x and y in mm from the disc's centre.
    #[arg(long, num_args = 2, allow_negative_numbers = true, value_names = ["X_MM", "Y_MM"], default_values_t = [1.5, -1.0])]
    pub coin_at_mm: Vec<f64>,
    /// Ball scene: the ball's position along the probe path, mm (paper 002: 0–20 mm).
    #[arg(long, default_value_t = 5.0)]
    pub ball_d_mm: f64,
    /// Loss tangent tan δ of the phantom's soft material at the resonance (0–2; default 0, the
    /// papers' silicone). The scan then maps the loss beside the stiffness.
    #[arg(long)]
    pub loss_tangent: Option<f64>,
    /// Make the inclusion a tissue of this storage modulus, kPa (a tumour-like lump; default:
    /// rigid, the coin or the steel ball, which has no loss).
    #[arg(long)]
    pub lump_modulus_kpa: Option<f64>,
    /// Loss tangent of the inclusion (0–2; needs --lump-modulus-kpa; default: the soft
    /// material's).
    #[arg(long)]
    pub lump_loss_tangent: Option<f64>,
    /// Depth of the inclusion's top under the surface, mm (default: the scene's, 1 mm).
    #[arg(long)]
    pub lump_depth_mm: Option<f64>,
    /// Grid step, mm (default: 2 mm for the coin, 1 mm for the ball).
    #[arg(long)]
    pub step_mm: Option<f64>,
    /// Contact preload at every grid point, N.
    #[arg(long, default_value_t = 0.030)]
    pub preload_n: f64,
    /// Resonance method (one that sweeps: `sweep-g`, `paper`, ...).
    #[arg(long, default_value = "sweep-g")]
    pub method: String,
    /// The front end's noise and its seed (grid point k uses seed + k, the k-th slide of
    /// `--continuous` seed + k).
    #[command(flatten)]
    pub noise: NoiseArgs,
    /// The calibration and the unit profile.
    #[command(flatten)]
    pub cal: CalibrationArgs,
    /// Stiffness map to write (.svg or .png).
    #[arg(long, default_value = "scan.svg")]
    pub plot: PathBuf,
    /// Print one JSON object (every grid point and the lump found) instead of the report.
    #[arg(long)]
    pub json: bool,
}

/// What to scan and how.
#[derive(Clone, Debug)]
pub struct ScanSpec {
    /// The phantom.
    pub phantom: LumpPhantom,
    /// Grid columns, mm.
    pub xs_mm: Vec<f64>,
    /// Grid rows, mm.
    pub ys_mm: Vec<f64>,
    /// Grid step, mm.
    pub step_mm: f64,
    /// Grid points closer than this to the phantom's outline are skipped, mm.
    pub edge_margin_mm: f64,
    /// Probe, front end, noise and preload.
    pub base: Scene,
    /// Method.
    pub method: Method,
    /// Sweep.
    pub settings: SweepSettings,
    /// The unit's profile (calibration, Q model, air reference).
    pub unit: UnitProfile,
    /// Noise seed of the first grid point.
    pub seed: u64,
}

/// The scans' default profile: the simulated unit's (air reference, Q model) calibrated with
/// sweep-G under the scan's noise, with paper 003's experimental curve (eq. 5), by which the
/// paper mapped its coin sample.
fn default_unit(base: &Scene) -> Result<UnitProfile> {
    let m = Method::SweepG;
    let mut unit = crate::unit::simulated(
        m,
        &Settings::Sweep(m.default_sweep()),
        hal_sim::NoiseScene::Density(base.front_end.current_noise_a_rthz),
        20,
        1000,
    )?;
    unit.use_power_law(PowerLaw::paper_experiment(), m.resonance());
    Ok(unit)
}

/// The grid from `lo` to `hi` (inclusive) in steps of `step`.
fn axis(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step + 1e-9).floor() as usize + 1;
    (0..n).map(|k| lo + k as f64 * step).collect()
}

impl ScanSpec {
    /// The default scan of paper 003's coin sample with the coin at `(x, y)` mm: the disc on a
    /// grid of `step_mm`, 1.5 mm clear of its rim.
    pub fn coin(x_mm: f64, y_mm: f64, step_mm: f64, base: Scene) -> Result<Self> {
        let half = (14.0 / step_mm).floor() * step_mm;
        Ok(Self {
            phantom: lump::paper003_coin(x_mm, y_mm),
            xs_mm: axis(-half, half, step_mm),
            ys_mm: axis(-half, half, step_mm),
            step_mm,
            edge_margin_mm: 1.5,
            base,
            method: Method::SweepG,
            settings: Method::SweepG.default_sweep(),
            unit: default_unit(&base)?,
            seed: 0,
        })
    }
    /// The default scan of paper 002's ball at `d_mm` along the path: a strip 4 mm past either
    /// end of the 0–20 mm path and ±6 mm across it.
    pub fn ball(d_mm: f64, step_mm: f64, base: Scene) -> Result<Self> {
        let across = (6.0 / step_mm).floor() * step_mm;
        Ok(Self {
            phantom: lump::paper002_ball(d_mm),
            xs_mm: axis(-4.0, 24.0, step_mm),
            ys_mm: axis(-across, across, step_mm),
            step_mm,
            edge_margin_mm: 0.0,
            base,
            method: Method::SweepG,
            settings: Method::SweepG.default_sweep(),
            unit: default_unit(&base)?,
            seed: 0,
        })
    }
    /// Grid points on the phantom, row by row.
    pub fn grid(&self) -> Vec<(usize, usize)> {
        let mut g = Vec::new();
        for (j, &y) in self.ys_mm.iter().enumerate() {
            for (i, &x) in self.xs_mm.iter().enumerate() {
                if self
                    .phantom
                    .contains(x * 1e-3, y * 1e-3, self.edge_margin_mm * 1e-3)
                {
                    g.push((i, j));
                }
            }
        }
        g
    }
}

/// One grid point.
#[derive(Clone, Copy, Debug)]
pub struct ScanPoint {
    /// Column index.
    pub i: usize,
    /// Row index.
    pub j: usize,
    /// Position, mm.
    pub x_mm: f64,
    /// Position, mm.
    pub y_mm: f64,
    /// The model's apparent modulus there, kPa (ground truth of the simulation).
    pub apparent_kpa: f64,
    /// The model's apparent loss tangent there (ground truth of the simulation).
    pub apparent_loss_tangent: f64,
    /// The reading.
    pub reading: Reading,
}

/// Where the lump was found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumpEstimate {
    /// Centre, mm.
    pub x_mm: f64,
    /// Centre, mm.
    pub y_mm: f64,
    /// Diameter of a disc of the lump region's area, mm.
    pub diameter_mm: f64,
    /// Background: the 10th percentile of the scan's resonances, Hz.
    pub background_hz: f64,
    /// Highest resonance, Hz.
    pub peak_hz: f64,
    /// Half-way level that bounds the region, Hz.
    pub threshold_hz: f64,
    /// Grid points in the region.
    pub cells: usize,
}

/// Where a loss lump was found on the loss map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossLump {
    /// Centre, mm.
    pub x_mm: f64,
    /// Centre, mm.
    pub y_mm: f64,
    /// Diameter of a disc of the region's area, mm.
    pub diameter_mm: f64,
    /// The loss map's background (10th percentile of a rise, 90th of a dip), tan δ.
    pub background: f64,
    /// The lump's extreme loss tangent (highest of a rise, lowest of a dip).
    pub extreme: f64,
    /// Half-way level that bounds the region, tan δ.
    pub threshold: f64,
    /// Grid points in the region.
    pub cells: usize,
    /// The least |extreme − background| this map needed to call it a lump.
    pub min_contrast: f64,
}

/// A finished scan.
#[derive(Clone, Debug)]
pub struct ScanResult {
    /// Every grid point read.
    pub points: Vec<ScanPoint>,
    /// The lump, if one stands out.
    pub lump: Option<LumpEstimate>,
    /// The lump on the loss map, if one stands out there.
    pub loss_lump: Option<LossLump>,
}

/// Least rise of the peak over the background to call it a lump, Hz.
pub const MIN_CONTRAST_HZ: f64 = 1.0;

/// Least departure of the loss map's extreme from its background to call it a lump, tan δ.
pub const MIN_LOSS_CONTRAST: f64 = 0.03;

/// Least departure of the loss map's extreme from its background, in the map's median reported
/// σ of the loss. A reading's loss σ is its own σ(Q) and the uncertainty of the unit's lossless-Q
/// curve (`UnitProfile::tissue_loss`, `QModel::scatter`), and the curve follows the contact's
/// Q over the calibrated range: on lossless tissue the loss read's bias stays within that σ
/// (sweep-G, 152–2465 kPa: from −0.002 to +0.001, against a σ of 0.002; `docs/bench.md`, "Loss
/// map"), so a lump of its background's loss moves the loss read over it by no more than the
/// noise, and three σ is the bar against the noise. On the step scan's maps (median σ 0.002–0.003,
/// sweep-G) [`MIN_LOSS_CONTRAST`] is the larger and sets the bar.
pub const LOSS_CONTRAST_SIGMAS: f64 = 3.0;

/// Run the scan; `tick` is called after every grid point.
pub fn scan(spec: &ScanSpec, mut tick: impl FnMut()) -> Result<ScanResult> {
    let mut points = Vec::new();
    for (k, (i, j)) in spec.grid().into_iter().enumerate() {
        let (x, y) = (spec.xs_mm[i], spec.ys_mm[j]);
        let scene = spec.phantom.scene_at(&spec.base, x * 1e-3, y * 1e-3);
        let reading = simboard::read(
            &scene,
            spec.seed.wrapping_add(k as u64),
            spec.method,
            &spec.settings,
            &spec.unit,
            |_| {},
        )
        .map_err(|e| anyhow!("reading at ({x}, {y}) mm failed: {e}"))?;
        let app = spec
            .phantom
            .apparent(x * 1e-3, y * 1e-3, &spec.base.contact);
        points.push(ScanPoint {
            i,
            j,
            x_mm: x,
            y_mm: y,
            apparent_kpa: app.modulus_pa / 1e3,
            apparent_loss_tangent: app.loss_tangent,
            reading,
        });
        tick();
    }
    let (nx, ny) = (spec.xs_mm.len(), spec.ys_mm.len());
    let lump = locate(&points, nx, ny, spec.step_mm);
    let loss_lump = locate_loss(&points, nx, ny, spec.step_mm);
    Ok(ScanResult {
        points,
        lump,
        loss_lump,
    })
}

/// A region that stands out of a map, in the map's own unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anomaly {
    /// Centre, mm.
    pub x_mm: f64,
    /// Centre, mm.
    pub y_mm: f64,
    /// Diameter of a disc of the region's area, mm.
    pub diameter_mm: f64,
    /// Background: the 10th percentile of the map.
    pub background: f64,
    /// Highest value.
    pub peak: f64,
    /// Half-way level that bounds the region.
    pub threshold: f64,
    /// Grid points in the region.
    pub cells: usize,
}

/// One value of a map at grid cell `(i, j)`, placed at `(x, y)` mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapValue {
    /// Column index.
    pub i: usize,
    /// Row index.
    pub j: usize,
    /// Position, mm.
    pub x_mm: f64,
    /// Position, mm.
    pub y_mm: f64,
    /// The value.
    pub value: f64,
}

/// The map of `value` over the scanned points (points without one are left out).
pub fn map_of(points: &[ScanPoint], value: impl Fn(&ScanPoint) -> Option<f64>) -> Vec<MapValue> {
    points
        .iter()
        .filter_map(|p| {
            value(p).map(|v| MapValue {
                i: p.i,
                j: p.j,
                x_mm: p.x_mm,
                y_mm: p.y_mm,
                value: v,
            })
        })
        .collect()
}

/// Find the lump on a scanned grid of `nx` × `ny`: the stiffness map's rule (see the module
/// docs) on the resonances.
pub fn locate(points: &[ScanPoint], nx: usize, ny: usize, step_mm: f64) -> Option<LumpEstimate> {
    let map = map_of(points, |p| p.reading.resonance.map(|f| f.0 as f64));
    locate_values(&map, nx, ny, step_mm, MIN_CONTRAST_HZ).map(|a| LumpEstimate {
        x_mm: a.x_mm,
        y_mm: a.y_mm,
        diameter_mm: a.diameter_mm,
        background_hz: a.background,
        peak_hz: a.peak,
        threshold_hz: a.threshold,
        cells: a.cells,
    })
}

/// Find the loss lump on a scanned grid of `nx` × `ny` (see the module docs): the rule of
/// [`locate_values`] on the loss map and on its negative, the one that stands out the more.
pub fn locate_loss(points: &[ScanPoint], nx: usize, ny: usize, step_mm: f64) -> Option<LossLump> {
    let map = map_of(points, |p| p.reading.loss_tangent.map(f64::from));
    let min_contrast = loss_min_contrast(points)?;
    let dips: Vec<MapValue> = map
        .iter()
        .map(|v| MapValue {
            value: -v.value,
            ..*v
        })
        .collect();
    let rise = locate_values(&map, nx, ny, step_mm, min_contrast).map(|a| (a, 1.0));
    let dip = locate_values(&dips, nx, ny, step_mm, min_contrast).map(|a| (a, -1.0));
    let contrast = |a: &Option<(Anomaly, f64)>| a.map_or(0.0, |(a, _)| a.peak - a.background);
    let (a, sign) = if contrast(&dip) > contrast(&rise) {
        dip?
    } else {
        rise?
    };
    Some(LossLump {
        x_mm: a.x_mm,
        y_mm: a.y_mm,
        diameter_mm: a.diameter_mm,
        background: sign * a.background,
        extreme: sign * a.peak,
        threshold: sign * a.threshold,
        cells: a.cells,
        min_contrast,
    })
}

/// The region of `map` (a grid of `nx` × `ny`, step `step_mm`) around its highest value that
/// stands above half-way between the background (the 10th percentile) and that value, if the
/// value rises at least `min_contrast` above the background (see the module docs).
pub fn locate_values(
    map: &[MapValue],
    nx: usize,
    ny: usize,
    step_mm: f64,
    min_contrast: f64,
) -> Option<Anomaly> {
    let mut grid: Vec<Option<(f64, usize)>> = vec![None; nx * ny];
    let mut vals = Vec::new();
    for (k, p) in map.iter().enumerate() {
        let f = p.value;
        if f.is_finite() && p.i < nx && p.j < ny {
            grid[p.j * nx + p.i] = Some((f, k));
            vals.push(f);
        }
    }
    if vals.len() < 3 {
        return None;
    }
    vals.sort_by(f64::total_cmp);
    // A lump may cover most of the map (paper 003's coin fills much of its disc): the
    // background is the lowest tenth of the readings, not their median.
    let background = vals[vals.len() / 10];
    let peak = vals[vals.len() - 1];
    if !(peak - background >= min_contrast) {
        return None;
    }
    let threshold = 0.5 * (background + peak);
    let start = grid
        .iter()
        .position(|c| c.is_some_and(|(f, _)| f == peak))?;
    // Flood fill over 4-neighbours above the threshold.
    let mut seen = vec![false; nx * ny];
    let mut stack = vec![start];
    seen[start] = true;
    let (mut w, mut wx, mut wy, mut cells) = (0.0, 0.0, 0.0, 0usize);
    while let Some(c) = stack.pop() {
        let Some((f, k)) = grid[c] else { continue };
        let rise = f - background;
        w += rise;
        wx += rise * map[k].x_mm;
        wy += rise * map[k].y_mm;
        cells += 1;
        let (i, j) = (c % nx, c / nx);
        let mut push = |ii: usize, jj: usize| {
            let n = jj * nx + ii;
            if !seen[n] && grid[n].is_some_and(|(f, _)| f >= threshold) {
                seen[n] = true;
                stack.push(n);
            }
        };
        if i > 0 {
            push(i - 1, j);
        }
        if i + 1 < nx {
            push(i + 1, j);
        }
        if j > 0 {
            push(i, j - 1);
        }
        if j + 1 < ny {
            push(i, j + 1);
        }
    }
    if !(w > 0.0) {
        return None;
    }
    Some(Anomaly {
        x_mm: wx / w,
        y_mm: wy / w,
        diameter_mm: 2.0 * (cells as f64 * step_mm * step_mm / std::f64::consts::PI).sqrt(),
        background,
        peak,
        threshold,
        cells,
    })
}

/// Mean and count of the resonances read where `keep(distance from the inclusion's centre, mm)`.
pub fn mean_resonance(
    points: &[ScanPoint],
    inclusion: &Inclusion,
    keep: impl Fn(f64) -> bool,
) -> Option<MeanResonance> {
    let (cx, cy) = inclusion.centre_m();
    let v: Vec<f64> = points
        .iter()
        .filter(|p| keep((p.x_mm - cx * 1e3).hypot(p.y_mm - cy * 1e3)))
        .filter_map(|p| p.reading.resonance.map(|f| f.0 as f64))
        .collect();
    (!v.is_empty()).then(|| MeanResonance {
        hz: v.iter().sum::<f64>() / v.len() as f64,
        points: v.len(),
    })
}

/// The mean resonance of a region of a scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeanResonance {
    /// Mean, Hz.
    pub hz: f64,
    /// Points with a resonance in the region.
    pub points: usize,
}

/// Distance from the inclusion's centre (mm) within which a point counts as "over" the lump:
/// 1 mm inside its outline.
pub fn over_radius_mm(inc: &Inclusion) -> f64 {
    (inc.radius_m() * 1e3 - 1.0).max(0.5)
}

/// Distance beyond which a point counts as "away" from the lump: 3 mm outside its outline.
pub fn away_radius_mm(inc: &Inclusion) -> f64 {
    inc.radius_m() * 1e3 + 3.0
}

/// Run the subcommand.
pub fn run(a: ScanArgs) -> Result<()> {
    if a.continuous {
        return run_continuous(&a);
    }
    let spec = spec_of(&a)?;
    let n = spec.grid().len();
    let pb = (!a.json).then(|| progress(n as u64, "scanning"));
    let res = scan(&spec, || {
        if let Some(pb) = &pb {
            pb.inc(1)
        }
    })?;
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    write_map(&a.plot, &spec, &res)?;
    if a.json {
        println!("{}", scan_json(&spec, &res));
    } else {
        print_summary(&a, &spec, &res);
    }
    Ok(())
}

/// `scan --continuous`: one slide per speed through the stream's one driver, with the
/// simulated unit's profile for the tracker's method ([`super::slide`]).
fn run_continuous(a: &ScanArgs) -> Result<()> {
    let spec = spec_of(a)?;
    let line = slide_line(a.scene, a.coin_at_mm[1]);
    let mut results = Vec::new();
    for (k, &v) in a.speed_mm_s.iter().enumerate() {
        let r = slide_over(spec.phantom, spec.base, line, v, a.noise.seed + k as u64)?;
        let line = if a.json {
            super::slide::slide_json(&r).to_string()
        } else {
            super::slide::summary(&r)
        };
        writeln!(std::io::stdout(), "{line}")?;
        results.push(r);
    }
    super::slide::plot(&a.plot, &results)?;
    if !a.json {
        writeln!(std::io::stdout(), "plot written to {}", a.plot.display())?;
    }
    Ok(())
}

/// The line `--continuous` slides along through `scene`'s lump: its `y` and where the tip
/// starts and ends in `x`, mm. The coin: its row `coin_y_mm` across the disc, 1.5 mm clear of
/// the rim; the ball: paper 002's path, 4 mm past either end.
pub fn slide_line(scene: ScanScene, coin_y_mm: f64) -> (f64, (f64, f64)) {
    match scene {
        ScanScene::Coin => (coin_y_mm, (-13.5, 13.5)),
        ScanScene::Ball => (0.0, (-4.0, 24.0)),
    }
}

/// One slide of `--continuous` over `phantom` on `base` (probe, front end, noise, preload)
/// along `line` ([`slide_line`]) at `speed_mm_s`, noise stream `seed`: the continuous
/// tracker's default configuration and the simulated unit's profile for its method.
pub fn slide_over(
    phantom: LumpPhantom,
    base: Scene,
    (y_mm, x_mm): (f64, (f64, f64)),
    speed_mm_s: f64,
    seed: u64,
) -> Result<SlideResult> {
    let unit = crate::unit::default_for(pzt_probe::instrument::continuous::METHOD)?;
    let config = pzt_probe::instrument::continuous::TrackerConfig::DEFAULT;
    let s = Slide {
        phantom,
        y_mm,
        x_mm,
        speed_mm_s,
        base,
        seed,
    };
    slide(&s, &config, &unit)
}

/// The scan the arguments ask for: method, preload, noise, scene and the unit's profile.
fn spec_of(a: &ScanArgs) -> Result<ScanSpec> {
    let method = Method::from_name(&a.method)
        .filter(|m| matches!(m.default_settings(), pzt_probe::reading::Settings::Sweep(_)))
        .ok_or_else(|| {
            anyhow!(
                "scan needs a stepped-sweep method (sweep-g or paper), not `{}`",
                a.method
            )
        })?;
    if !(a.preload_n.is_finite() && a.preload_n > 0.0 && a.preload_n <= 1.0) {
        bail!("preload {} N is out of range (0 to 1 N)", a.preload_n);
    }
    let noise = parse_noise(&a.noise.noise)?;
    let base = Scene::free_air()
        .with_noise(noise)
        .with_preload_n(a.preload_n);
    let mut spec = match a.scene {
        ScanScene::Coin => {
            let step = a.step_mm.unwrap_or(2.0);
            check_step(step)?;
            let (x, y) = (a.coin_at_mm[0], a.coin_at_mm[1]);
            if !(x.is_finite() && y.is_finite() && x.hypot(y) <= 5.5) {
                bail!("the 19 mm coin must lie inside the 30 mm disc: its centre within 5.5 mm of the disc's");
            }
            ScanSpec::coin(x, y, step, base)?
        }
        ScanScene::Ball => {
            let step = a.step_mm.unwrap_or(1.0);
            check_step(step)?;
            if !(a.ball_d_mm.is_finite() && (0.0..=20.0).contains(&a.ball_d_mm)) {
                bail!("--ball-d-mm must be 0 to 20 mm (paper 002's path)");
            }
            ScanSpec::ball(a.ball_d_mm, step, base)?
        }
    };
    spec.phantom = lossy_phantom(a, spec.phantom)?;
    spec.method = method;
    spec.settings = method.default_sweep();
    let lossy = is_lossy(&spec);
    let calibration =
        a.cal
            .calibration
            .as_deref()
            .unwrap_or(if lossy { "unit" } else { "paper-experiment" });
    spec.unit = calfile::resolve(a.cal.profile.as_deref(), calibration, || {
        own_unit(method, noise)
    })?;
    if lossy && spec.unit.contact.is_none() {
        bail!(
            "the loss tangent is read through the unit's contact law, which `{calibration}` does \
             not have: scan lossy tissue with --calibration unit (its default) or a profile file"
        );
    }
    spec.seed = a.noise.seed;
    Ok(spec)
}

/// The simulated unit's own profile for a scan with `method` under `noise`: its air
/// reference, Q model and contact law, calibrated on A–E (20 repeats, seeds from 1000).
pub fn own_unit(method: Method, noise: hal_sim::NoiseScene) -> Result<UnitProfile> {
    crate::unit::simulated(
        method,
        &Settings::Sweep(method.default_sweep()),
        noise,
        20,
        1000,
    )
}

/// `phantom` with the soft material's loss, the inclusion's material and depth the arguments
/// ask for.
fn lossy_phantom(a: &ScanArgs, phantom: LumpPhantom) -> Result<LumpPhantom> {
    let tan_d = |name: &str, t: f64| -> Result<f64> {
        if !(t.is_finite() && (0.0..=2.0).contains(&t)) {
            bail!("{name} {t} is out of range (0 to 2)");
        }
        Ok(t)
    };
    let mut p = phantom;
    if let Some(t) = a.loss_tangent {
        p = p.with_matrix_loss(tan_d("--loss-tangent", t)?);
    }
    match (a.lump_modulus_kpa, a.lump_loss_tangent) {
        (None, Some(_)) => bail!(
            "a rigid inclusion (the coin, the steel ball) stores no strain energy and has no loss: \
             give the lump a modulus with --lump-modulus-kpa to give it a loss tangent"
        ),
        (None, None) => {}
        (Some(e), t) => {
            if !(e.is_finite() && (1.0..=1e6).contains(&e)) {
                bail!("--lump-modulus-kpa {e} is out of range (1 to 1e6 kPa)");
            }
            let loss_tangent = match t {
                Some(t) => tan_d("--lump-loss-tangent", t)?,
                None => p.matrix.loss_tangent,
            };
            p = p.with_material(LumpMaterial::Tissue {
                modulus_pa: e * 1e3,
                loss_tangent,
            });
        }
    }
    if let Some(d) = a.lump_depth_mm {
        let d_m = d * 1e-3;
        if !(d.is_finite() && d >= 0.1 && d_m < p.thickness_m) {
            bail!(
                "--lump-depth-mm {d} is out of range (0.1 mm to the phantom's {} mm)",
                p.thickness_m * 1e3
            );
        }
        p.inclusion = p.inclusion.with_depth_m(d_m);
    }
    Ok(p)
}

/// True when the scan's phantom has any loss (the scan then maps it).
pub fn is_lossy(spec: &ScanSpec) -> bool {
    spec.phantom.is_lossy()
}

/// Mean and count of the loss tangents read where `keep(distance from the inclusion's centre,
/// mm)`.
pub fn mean_loss(
    points: &[ScanPoint],
    inclusion: &Inclusion,
    keep: impl Fn(f64) -> bool,
) -> Option<(f64, usize)> {
    let (cx, cy) = inclusion.centre_m();
    let v: Vec<f64> = points
        .iter()
        .filter(|p| keep((p.x_mm - cx * 1e3).hypot(p.y_mm - cy * 1e3)))
        .filter_map(|p| p.reading.loss_tangent.map(f64::from))
        .collect();
    (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64, v.len()))
}

/// The mean resonance over the lump and away from it.
fn contrast(spec: &ScanSpec, res: &ScanResult) -> (Option<MeanResonance>, Option<MeanResonance>) {
    let inc = &spec.phantom.inclusion;
    (
        mean_resonance(&res.points, inc, |d| d <= over_radius_mm(inc)),
        mean_resonance(&res.points, inc, |d| d >= away_radius_mm(inc)),
    )
}

/// `scan --json`: the scene, the truth, the contrast, the lump found and every point.
fn scan_json(spec: &ScanSpec, res: &ScanResult) -> Value {
    let inc = spec.phantom.inclusion;
    let (tx, ty) = inc.centre_m();
    let (over, away) = contrast(spec, res);
    let pts: Vec<Value> = res
        .points
        .iter()
        .map(|p| {
            json!({
                "x_mm": p.x_mm, "y_mm": p.y_mm,
                "apparent_kpa": p.apparent_kpa,
                "status": p.reading.status.code(),
                "resonance_hz": p.reading.resonance.map(|f| f.0),
                "resonance_sigma_hz": p.reading.resonance_sigma.map(|f| f.0),
                "modulus_kpa": p.reading.modulus.map(|e| e.0),
                "apparent_loss_tangent": p.apparent_loss_tangent,
                "loss_tangent": p.reading.loss_tangent,
                "loss_tangent_sigma": p.reading.loss_tangent_sigma,
            })
        })
        .collect();
    let lump = res.lump.map(|l| {
        json!({"x_mm": l.x_mm, "y_mm": l.y_mm, "diameter_mm": l.diameter_mm,
               "background_hz": l.background_hz, "peak_hz": l.peak_hz, "cells": l.cells})
    });
    let loss_lump = res.loss_lump.map(|l| {
        json!({"x_mm": l.x_mm, "y_mm": l.y_mm, "diameter_mm": l.diameter_mm,
               "background": l.background, "extreme": l.extreme, "cells": l.cells,
               "min_contrast": l.min_contrast})
    });
    let (over_loss, away_loss) = (
        mean_loss(&res.points, &inc, |d| d <= over_radius_mm(&inc)),
        mean_loss(&res.points, &inc, |d| d >= away_radius_mm(&inc)),
    );
    let material = match spec.phantom.material {
        LumpMaterial::Rigid => json!("rigid"),
        LumpMaterial::Tissue {
            modulus_pa,
            loss_tangent,
        } => json!({"modulus_kpa": modulus_pa / 1e3, "loss_tangent": loss_tangent}),
    };
    json!({
        "scene": spec.phantom.name,
        "method": spec.method.name(),
        "step_mm": spec.step_mm,
        "true_centre_mm": [tx * 1e3, ty * 1e3],
        "true_diameter_mm": 2e3 * inc.radius_m(),
        "matrix_loss_tangent": spec.phantom.matrix.loss_tangent,
        "lump_material": material,
        "over_mean_hz": over.map(|o| o.hz),
        "away_mean_hz": away.map(|o| o.hz),
        "over_mean_loss_tangent": over_loss.map(|o| o.0),
        "away_mean_loss_tangent": away_loss.map(|o| o.0),
        "lump": lump,
        "loss_lump": loss_lump,
        "points": pts,
    })
}

/// The human summary of a scan.
fn print_summary(a: &ScanArgs, spec: &ScanSpec, res: &ScanResult) {
    let inc = spec.phantom.inclusion;
    let (tx, ty) = inc.centre_m();
    let (over, away) = contrast(spec, res);
    let ok = res
        .points
        .iter()
        .filter(|p| p.reading.status == Status::Ok)
        .count();
    println!("probe-bench scan: {}", spec.phantom.source);
    if is_lossy(spec) || spec.phantom.material != LumpMaterial::Rigid || a.lump_depth_mm.is_some() {
        let material = match spec.phantom.material {
            LumpMaterial::Rigid => "rigid".to_owned(),
            LumpMaterial::Tissue {
                modulus_pa,
                loss_tangent,
            } => format!(
                "tissue of {:.1} kPa, tan d {loss_tangent:.2}",
                modulus_pa / 1e3
            ),
        };
        let depth = spec.phantom.inclusion.depth_m() * 1e3;
        println!(
            "  as scanned: the soft material's tan d {:.2}; the inclusion {material}, its top {depth:.2} mm under the surface",
            spec.phantom.matrix.loss_tangent
        );
    }
    println!(
        "  grid {} points, step {} mm, preload {:.0} mN, noise {}, method {}; {} readings ok",
        res.points.len(),
        spec.step_mm,
        a.preload_n * 1e3,
        a.noise.noise,
        spec.method.name(),
        ok
    );
    if let Some(MeanResonance { hz: f, points: k }) = over {
        println!(
            "  over the lump (within {:.1} mm of its centre): mean {f:.2} Hz over {k} points",
            over_radius_mm(&inc)
        );
    }
    if let Some(MeanResonance { hz: f, points: k }) = away {
        println!(
            "  away from it (beyond {:.1} mm): mean {f:.2} Hz over {k} points",
            away_radius_mm(&inc)
        );
    }
    match res.lump {
        Some(l) => println!(
            "  lump found at ({:.2}, {:.2}) mm, {:.1} mm across (true: ({:.2}, {:.2}) mm, {:.1} mm); background {:.2} Hz, peak {:.2} Hz",
            l.x_mm,
            l.y_mm,
            l.diameter_mm,
            tx * 1e3,
            ty * 1e3,
            2e3 * inc.radius_m(),
            l.background_hz,
            l.peak_hz
        ),
        None => println!("  no lump stands out of the map"),
    }
    if is_lossy(spec) {
        let over = mean_loss(&res.points, &inc, |d| d <= over_radius_mm(&inc));
        let away = mean_loss(&res.points, &inc, |d| d >= away_radius_mm(&inc));
        if let (Some((o, n_o)), Some((w, n_w))) = (over, away) {
            println!(
                "  loss tangent over the lump {o:.3} ({n_o} points), away {w:.3} ({n_w} points)"
            );
        }
        match res.loss_lump {
            Some(l) => println!(
                "  loss lump found at ({:.2}, {:.2}) mm, {:.1} mm across; background tan d {:.3}, lump {:.3}",
                l.x_mm, l.y_mm, l.diameter_mm, l.background, l.extreme
            ),
            None => println!(
                "  no loss lump stands out of the loss map (needs {:.3} from the background)",
                loss_min_contrast(&res.points).unwrap_or(MIN_LOSS_CONTRAST)
            ),
        }
    }
    println!("  map: {}", a.plot.display());
}

/// The least departure from its background a loss lump needs on the map of `points`:
/// [`MIN_LOSS_CONTRAST`] or [`LOSS_CONTRAST_SIGMAS`] median reported σ of the loss, the larger
/// (`None` without any σ).
pub fn loss_min_contrast(points: &[ScanPoint]) -> Option<f64> {
    loss_bar(points.iter().map(|p| &p.reading))
}

/// The least departure from its background a loss lump needs among `readings`:
/// [`MIN_LOSS_CONTRAST`] or [`LOSS_CONTRAST_SIGMAS`] times their median reported σ of the
/// loss, the larger (`None` without any σ).
pub fn loss_bar<'a>(readings: impl Iterator<Item = &'a Reading>) -> Option<f64> {
    let mut s: Vec<f64> = readings
        .filter_map(|r| r.loss_tangent_sigma.map(f64::from))
        .filter(|s| s.is_finite())
        .collect();
    s.sort_by(f64::total_cmp);
    let median = *s.get(s.len() / 2)?;
    Some(MIN_LOSS_CONTRAST.max(LOSS_CONTRAST_SIGMAS * median))
}

fn check_step(step: f64) -> Result<()> {
    if !(step.is_finite() && (0.25..=10.0).contains(&step)) {
        bail!("--step-mm must be 0.25 to 10 mm");
    }
    Ok(())
}

/// Viridis-like colour of `t` in `[0, 1]`.
fn colour(t: f64) -> RGBColor {
    const STOPS: [(u8, u8, u8); 5] = [
        (68, 1, 84),
        (59, 82, 139),
        (33, 145, 140),
        (94, 201, 98),
        (253, 231, 37),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STOPS.len() - 1) as f64;
    let k = (x.floor() as usize).min(STOPS.len() - 2);
    let u = x - k as f64;
    let lerp = |a: u8, b: u8| (a as f64 + u * (b as f64 - a as f64)).round() as u8;
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// Which map a panel draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapKind {
    /// The resonance (Hz), with the calibrated modulus at the colour bar's ends.
    Stiffness,
    /// The loss tangent read.
    Loss,
}

impl MapKind {
    /// The panel's value at a point.
    fn value(self, p: &ScanPoint) -> Option<f64> {
        match self {
            MapKind::Stiffness => p.reading.resonance.map(|f| f.0 as f64),
            MapKind::Loss => p.reading.loss_tangent.map(f64::from),
        }
    }
    /// The lump this map found: centre and diameter, mm.
    fn found(self, res: &ScanResult) -> Option<(f64, f64, f64)> {
        match self {
            MapKind::Stiffness => res.lump.map(|l| (l.x_mm, l.y_mm, l.diameter_mm)),
            MapKind::Loss => res.loss_lump.map(|l| (l.x_mm, l.y_mm, l.diameter_mm)),
        }
    }
}

/// Write the stiffness map (resonance per grid point, colour bar in Hz and kPa by the scan's
/// calibration, phantom outline, true inclusion outline, the lump found); on a lossy phantom
/// the loss map beside it (loss tangent per grid point, the loss lump found).
pub fn write_map(path: &Path, spec: &ScanSpec, res: &ScanResult) -> Result<()> {
    fn both<DB: Backend>(root: &Area<DB>, spec: &ScanSpec, res: &ScanResult) -> Result<()> {
        root.fill(&WHITE).map_err(err)?;
        if is_lossy(spec) {
            let (left, right) = root.split_horizontally(PANEL.0);
            draw_map(&left, spec, res, MapKind::Stiffness)?;
            draw_map(&right, spec, res, MapKind::Loss)
        } else {
            draw_map(root, spec, res, MapKind::Stiffness)
        }
    }
    let size = if is_lossy(spec) {
        (2 * PANEL.0, PANEL.1)
    } else {
        PANEL
    };
    draw_to!(path, size, |root| both(root, spec, res))
}

/// One map panel's size, px.
const PANEL: (u32, u32) = (980, 820);

fn circle(cx: f64, cy: f64, r: f64) -> Vec<(f64, f64)> {
    (0..=180)
        .map(|k| {
            let t = 2.0 * std::f64::consts::PI * k as f64 / 180.0;
            (cx + r * t.cos(), cy + r * t.sin())
        })
        .collect()
}

fn draw_map<DB: Backend>(
    root: &Area<DB>,
    spec: &ScanSpec,
    res: &ScanResult,
    kind: MapKind,
) -> Result<()> {
    let (fmin, fmax) = match kind {
        MapKind::Stiffness => resonance_span(res),
        MapKind::Loss => padded_range(
            res.points.iter().filter_map(|p| kind.value(p)),
            0.0,
            (0.0, 0.5),
        ),
    };
    let s = spec.step_mm;
    let (x0, x1) = (
        spec.xs_mm.first().copied().unwrap_or(0.0) - s,
        spec.xs_mm.last().copied().unwrap_or(1.0) + s,
    );
    let (y0, y1) = (
        spec.ys_mm.first().copied().unwrap_or(0.0) - s,
        spec.ys_mm.last().copied().unwrap_or(1.0) + s,
    );
    let (map_area, bar_area) = root.split_horizontally(820);
    let inc = spec.phantom.inclusion;
    let (tx, ty) = inc.centre_m();
    let (tx, ty, tr) = (tx * 1e3, ty * 1e3, inc.radius_m() * 1e3);
    let title = map_title(spec, res, kind);
    // Equal scales on both axes: fit the data span into the plot area.
    let (w_px, h_px) = (820.0 - 80.0, 820.0 - 110.0);
    let (xs, ys) = (x1 - x0, y1 - y0);
    let scale = (w_px / xs).min(h_px / ys);
    let (pad_x, pad_y) = (0.5 * (w_px / scale - xs), 0.5 * (h_px / scale - ys));
    let mut chart = ChartBuilder::on(&map_area)
        .caption(title, ("sans-serif", 17))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x0 - pad_x..x1 + pad_x, y0 - pad_y..y1 + pad_y)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(res.points.iter().map(|p| {
            let c = match kind.value(p) {
                Some(f) => colour((f - fmin) / (fmax - fmin)).filled(),
                None => RGBColor(200, 200, 200).filled(),
            };
            Rectangle::new(
                [
                    (p.x_mm - 0.5 * s, p.y_mm - 0.5 * s),
                    (p.x_mm + 0.5 * s, p.y_mm + 0.5 * s),
                ],
                c,
            )
        }))
        .map_err(err)?;
    // Readings without a valid modulus (out of range, failed) are crossed.
    chart
        .draw_series(
            res.points
                .iter()
                .filter(|p| p.reading.status != Status::Ok)
                .map(|p| Cross::new((p.x_mm, p.y_mm), 3, BLACK.stroke_width(1))),
        )
        .map_err(err)?;
    if let Some(r) = spec.phantom.outline_radius_m {
        plot::line(
            &mut chart,
            circle(0.0, 0.0, r * 1e3),
            BLACK.stroke_width(2),
            "phantom outline",
        )
        .map_err(err)?;
    }
    chart
        .draw_series(LineSeries::new(circle(tx, ty, tr), WHITE.stroke_width(1)))
        .map_err(err)?
        .label("true inclusion outline")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(150, 150, 150)));
    if let Some((lx, ly, ld)) = kind.found(res) {
        plot::line(
            &mut chart,
            circle(lx, ly, 0.5 * ld),
            RED.stroke_width(3),
            "lump found (half-height region, equal-area disc)",
        )
        .map_err(err)?;
        chart
            .draw_series(std::iter::once(Cross::new(
                (lx, ly),
                8,
                RED.stroke_width(3),
            )))
            .map_err(err)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::LowerRight, 0.85).map_err(err)?;
    draw_colour_bar(&bar_area, spec, fmin, fmax, kind)?;
    Ok(())
}

/// The colour scale's span of resonances (Hz): the scan's (±1 Hz about a single one), or
/// 200–230 Hz without any.
fn resonance_span(res: &ScanResult) -> (f64, f64) {
    let resonances = res.points.iter();
    padded_range(
        resonances.filter_map(|p| p.reading.resonance.map(|f| f.0 as f64)),
        0.0,
        (200.0, 230.0),
    )
}

/// The map's title: the scene, the method and the lump found against the truth.
fn map_title(spec: &ScanSpec, res: &ScanResult, kind: MapKind) -> String {
    let inc = spec.phantom.inclusion;
    let (tx, ty) = inc.centre_m();
    let (tx, ty, tr) = (tx * 1e3, ty * 1e3, inc.radius_m() * 1e3);
    let what = match kind {
        MapKind::Stiffness => format!("{} scan, {}", spec.phantom.name, spec.method.name()),
        MapKind::Loss => format!(
            "loss tangent (background tan d {:.2})",
            spec.phantom.matrix.loss_tangent
        ),
    };
    match kind.found(res) {
        Some((x, y, d)) => format!(
            "{what} — lump at ({x:.1}, {y:.1}) mm, {d:.1} mm across (true ({tx:.1}, {ty:.1}), {:.0} mm)",
            2.0 * tr
        ),
        None => format!("{what} — no lump found"),
    }
}

/// The colour bar beside the map: resonance in Hz, with the calibrated modulus at its ends; or
/// the loss tangent.
fn draw_colour_bar<DB: Backend>(
    bar_area: &Area<DB>,
    spec: &ScanSpec,
    fmin: f64,
    fmax: f64,
    kind: MapKind,
) -> Result<()> {
    let mut bar = ChartBuilder::on(bar_area)
        .margin_top(40)
        .margin_bottom(50)
        .margin_right(10)
        .y_label_area_size(0)
        .right_y_label_area_size(75)
        .build_cartesian_2d(0.0..1.0, fmin..fmax)
        .map_err(err)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(match kind {
            MapKind::Stiffness => "resonance (Hz)",
            MapKind::Loss => "loss tangent tan d",
        })
        .draw()
        .map_err(err)?;
    let n = 100;
    bar.draw_series((0..n).map(|k| {
        let a = fmin + (fmax - fmin) * k as f64 / n as f64;
        let b = fmin + (fmax - fmin) * (k + 1) as f64 / n as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            colour(k as f64 / (n - 1) as f64).filled(),
        )
    }))
    .map_err(err)?;
    if kind == MapKind::Loss {
        return Ok(());
    }
    // Modulus at the bar's ends by the scan's calibration.
    let span = fmax - fmin;
    for (f, anchor) in [(fmin, fmin + 0.04 * span), (fmax, fmax - 0.005 * span)] {
        if let Ok(m) = spec
            .unit
            .calibration
            .invert(pzt_probe::Hz(f as f32), pzt_probe::Hz(0.0))
        {
            bar.draw_series(std::iter::once(Text::new(
                format!("{:.0} kPa", m.value.0),
                (0.05, anchor),
                ("sans-serif", 13).into_font().color(&WHITE),
            )))
            .map_err(err)?;
        }
    }
    Ok(())
}
