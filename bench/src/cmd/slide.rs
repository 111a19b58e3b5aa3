//! `probe-bench scan --continuous`: the probe slides across a lump phantom at a constant speed
//! while the core's tracker (`pzt_probe::instrument::continuous`) reads continuously; the lump is located
//! from the stream (issue #14, point 5).
//!
//! The tip moves along a line through the lump at `y` from `x0` to `x1` after half a second of
//! acquisition at `x0`; before every window the tissue under it is the phantom's apparent
//! tissue at the tip's place then (`board::sim::stream_moving`, `LumpPhantom::tissue_at`). Each
//! `ok` reading is placed at the tip's position at the middle of its window (the acquisition's
//! at the start of the path). The lump is where
//! the readings rise above half-way between the background (the 10th percentile) and the
//! lump's level (the 90th percentile): its edges are the first and last crossings, linearly
//! interpolated, its centre their midpoint, its contrast the ratio of the two levels. The
//! truth is the same rule on the phantom's closed-form apparent modulus along the same line.
//! On a lossy phantom the loss tangents the readings report are located by the same rule, as
//! a rise or a dip that departs from the background by the scan's bar (`scan::loss_bar`), after a
//! running median of seven readings ([`LOSS_MEDIAN_HALF`]), and
//! so are the closed form's (by the bar's floor alone: it has neither noise nor bias).

use crate::plot::{self, draw_legend, draw_to, padded_range, Area, Backend, PALETTE};
use anyhow::{anyhow, bail, Result};
use hal_sim::lump::LumpPhantom;
use hal_sim::Scene;
use plotters::prelude::*;
use pzt_probe::board::sim as simboard;
use pzt_probe::instrument::continuous::{StreamReading, TrackerConfig};
use pzt_probe::{Status, UnitProfile};
use serde_json::{json, Value};
use std::path::Path;

/// The frame of this command's charts.
const FRAME: plot::Frame = plot::Frame {
    margin: 10,
    x_labels: 35,
    y_labels: 70,
};

/// Probe time spent acquiring at the start of the path before the tip moves, s.
pub const ACQUIRE_S: f64 = 0.5;

/// A slide: the line, the speed and the scene under way.
#[derive(Clone, Copy, Debug)]
pub struct Slide {
    /// The phantom.
    pub phantom: LumpPhantom,
    /// The line's `y`, mm.
    pub y_mm: f64,
    /// Where the tip starts and ends, mm.
    pub x_mm: (f64, f64),
    /// Speed, mm/s.
    pub speed_mm_s: f64,
    /// Probe, front end, noise, preload.
    pub base: Scene,
    /// Noise stream.
    pub seed: u64,
}

impl Slide {
    /// The tip's `x` (mm) at probe time `t` (s).
    pub fn x_at(&self, t: f64) -> f64 {
        let (x0, x1) = self.x_mm;
        let d = (self.speed_mm_s * (t - ACQUIRE_S).max(0.0)).min((x1 - x0).abs());
        x0 + d * (x1 - x0).signum()
    }
    /// Probe time of the whole slide, s.
    pub fn seconds(&self) -> f64 {
        ACQUIRE_S + (self.x_mm.1 - self.x_mm.0).abs() / self.speed_mm_s
    }
    /// The closed form along the path: `n + 1` points `(x mm, E kPa)` evenly over it, in `x`.
    pub fn truth_line(&self, n: usize) -> Vec<(f64, f64)> {
        let (lo, hi) = (self.x_mm.0.min(self.x_mm.1), self.x_mm.0.max(self.x_mm.1));
        (0..=n)
            .map(|k| {
                let x = lo + (hi - lo) * k as f64 / n as f64;
                (x, self.truth_kpa(x))
            })
            .collect()
    }
    /// The closed form's loss tangent along the path: `n + 1` points `(x mm, tan δ)` evenly
    /// over it, in `x`.
    pub fn loss_truth_line(&self, n: usize) -> Vec<(f64, f64)> {
        let (lo, hi) = (self.x_mm.0.min(self.x_mm.1), self.x_mm.0.max(self.x_mm.1));
        (0..=n)
            .map(|k| {
                let x = lo + (hi - lo) * k as f64 / n as f64;
                let app = self
                    .phantom
                    .apparent(x * 1e-3, self.y_mm * 1e-3, &self.base.contact);
                (x, app.loss_tangent)
            })
            .collect()
    }
    /// The closed-form apparent modulus (kPa) at `x` mm on the line.
    pub fn truth_kpa(&self, x_mm: f64) -> f64 {
        self.phantom
            .apparent(x_mm * 1e-3, self.y_mm * 1e-3, &self.base.contact)
            .modulus_pa
            * 1e-3
    }
}

/// Where a profile puts the lump.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// Edges (first and last crossing of the half level), mm.
    pub edges_mm: (f64, f64),
    /// Centre, mm.
    pub centre_mm: f64,
    /// Lump level over background.
    pub contrast: f64,
}

/// The lump in a profile of `(x mm, E kPa)` points ordered in `x` ([`Located`]; `None` with
/// fewer than ten points, or no rise of at least 10 %).
pub fn locate(points: &[(f64, f64)]) -> Option<Located> {
    let (edges, bg, top) = locate_with(points, |bg, top| top >= 1.1 * bg)?;
    Some(Located {
        edges_mm: edges,
        centre_mm: 0.5 * (edges.0 + edges.1),
        contrast: top / bg,
    })
}

/// The rule of [`locate`] with the test of a rise `enough(background, level)`: the edges, the
/// background (10th percentile) and the lump's level (90th percentile).
pub fn locate_with(
    points: &[(f64, f64)],
    enough: impl Fn(f64, f64) -> bool,
) -> Option<((f64, f64), f64, f64)> {
    if points.len() < 10 {
        return None;
    }
    let mut e: Vec<f64> = points.iter().map(|p| p.1).collect();
    e.sort_by(f64::total_cmp);
    let (bg, top) = (e[e.len() / 10], e[e.len() * 9 / 10]);
    if !enough(bg, top) {
        return None;
    }
    let half = 0.5 * (bg + top);
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 + (half - a.1) / (b.1 - a.1) * (b.0 - a.0);
    let first = points
        .windows(2)
        .find(|w| w[0].1 < half && w[1].1 >= half)?;
    let last = points
        .windows(2)
        .rev()
        .find(|w| w[0].1 >= half && w[1].1 < half)?;
    Some((
        (cross(first[0], first[1]), cross(last[0], last[1])),
        bg,
        top,
    ))
}

/// Half-width (readings) of the running median the stream's loss profile is located through.
/// A reading's loss tangent scatters by a third of the contrast a lump can show (0.08 against
/// 0.25 in `bench/tests/scan_loss.rs`) and jumps where the tissue changes within a segment: one
/// reading past the half level would move an edge. Seven readings are 1.4 mm at 5 mm/s.
pub const LOSS_MEDIAN_HALF: usize = 3;

/// The running median of `points`' values over `half` points either side (fewer at the ends).
pub fn running_median(points: &[(f64, f64)], half: usize) -> Vec<(f64, f64)> {
    (0..points.len())
        .map(|i| {
            let w = &points[i.saturating_sub(half)..(i + half + 1).min(points.len())];
            let mut v: Vec<f64> = w.iter().map(|p| p.1).collect();
            v.sort_by(f64::total_cmp);
            (points[i].0, v[v.len() / 2])
        })
        .collect()
}

/// Where a profile of the loss tangent puts the lump.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossLocated {
    /// Edges (first and last crossing of the half level), mm.
    pub edges_mm: (f64, f64),
    /// Centre, mm.
    pub centre_mm: f64,
    /// The background's loss tangent (10th percentile of a rise, 90th of a dip).
    pub background: f64,
    /// The lump's (90th percentile of a rise, 10th of a dip).
    pub level: f64,
}

/// The loss lump in a profile of `(x mm, tan δ)` points ordered in `x`: the rule of [`locate`]
/// with a departure of at least `bar` (`scan::loss_bar`), on the profile if the lump is the
/// lossier, on its negative if it is the less lossy. Which it is, the path's ends tell: a slide
/// starts and ends off the lump, so the background is the level nearer the median of the
/// profile's first and last tenths.
pub fn locate_loss(points: &[(f64, f64)], bar: f64) -> Option<LossLocated> {
    if points.len() < 10 {
        return None;
    }
    let k = points.len() / 10;
    let mut ends: Vec<f64> = points[..k]
        .iter()
        .chain(&points[points.len() - k..])
        .map(|p| p.1)
        .collect();
    ends.sort_by(f64::total_cmp);
    let end = ends[ends.len() / 2];
    let mut l: Vec<f64> = points.iter().map(|p| p.1).collect();
    l.sort_by(f64::total_cmp);
    let (low, high) = (l[l.len() / 10], l[l.len() * 9 / 10]);
    let sign = if (end - low).abs() <= (high - end).abs() {
        1.0
    } else {
        -1.0
    };
    let signed: Vec<(f64, f64)> = points.iter().map(|&(x, l)| (x, sign * l)).collect();
    let (edges, bg, top) = locate_with(&signed, |bg, top| top - bg >= bar)?;
    Some(LossLocated {
        edges_mm: edges,
        centre_mm: 0.5 * (edges.0 + edges.1),
        background: sign * bg,
        level: sign * top,
    })
}

/// What one slide read.
#[derive(Clone, Debug)]
pub struct SlideResult {
    /// The slide.
    pub slide: Slide,
    /// Every reading of the stream.
    pub readings: Vec<StreamReading>,
    /// The `ok` readings as `(x mm, E kPa)`, in order along the path.
    pub profile: Vec<(f64, f64)>,
    /// The lump from the stream.
    pub found: Option<Located>,
    /// The lump from the closed form on the same line.
    pub truth: Option<Located>,
    /// The `ok` readings that report a loss tangent as `(x mm, tan δ)`, in order along the path.
    pub loss_profile: Vec<(f64, f64)>,
    /// The least departure a loss lump needs on this slide (`scan::loss_bar`; `None` without
    /// any loss read).
    pub loss_bar: Option<f64>,
    /// The loss lump from the stream.
    pub loss_found: Option<LossLocated>,
    /// The loss lump from the closed form's loss tangent on the same line (departing by at
    /// least `scan::MIN_LOSS_CONTRAST`).
    pub loss_truth: Option<LossLocated>,
}

impl SlideResult {
    /// `ok` readings per second of probe time.
    pub fn ok_rate(&self) -> f64 {
        self.profile.len() as f64 / self.slide.seconds()
    }
    /// Error of the found centre, mm.
    pub fn centre_error_mm(&self) -> Option<f64> {
        Some(self.found?.centre_mm - self.truth?.centre_mm)
    }
}

/// Slide `s` with the tracker `config` and the unit `unit`, through the one stream driver.
pub fn slide(s: &Slide, config: &TrackerConfig, unit: &UnitProfile) -> Result<SlideResult> {
    if !(s.speed_mm_s > 0.0 && s.speed_mm_s <= 200.0) {
        bail!("--speed-mm-s must be in (0, 200]");
    }
    let mut readings = Vec::new();
    let scene = s.phantom.scene_at(&s.base, s.x_mm.0 * 1e-3, s.y_mm * 1e-3);
    simboard::stream_moving(
        &scene,
        s.seed,
        config,
        unit,
        s.seconds(),
        |t| {
            Some(Some(s.phantom.tissue_at(
                s.x_at(t) * 1e-3,
                s.y_mm * 1e-3,
                &s.base.contact,
            )))
        },
        |r| readings.push(*r),
    )
    .map_err(|e| anyhow!("stream failed: {e}"))?;
    let mut profile: Vec<(f64, f64)> = readings
        .iter()
        .filter(|r| r.reading.status == Status::Ok)
        .filter_map(|r| {
            let mid = r.t_s.0 as f64 - 0.5 * r.reading.probe_time.0 as f64;
            Some((s.x_at(mid), r.reading.modulus?.0 as f64))
        })
        .collect();
    let mut loss_profile: Vec<(f64, f64)> = readings
        .iter()
        .filter(|r| r.reading.status == Status::Ok)
        .filter_map(|r| {
            let mid = r.t_s.0 as f64 - 0.5 * r.reading.probe_time.0 as f64;
            Some((s.x_at(mid), r.reading.loss_tangent? as f64))
        })
        .collect();
    if s.x_mm.1 < s.x_mm.0 {
        profile.reverse();
        loss_profile.reverse();
    }
    let truth_line = s.truth_line(2000);
    let loss_bar = super::scan::loss_bar(
        readings
            .iter()
            .filter(|r| r.reading.status == Status::Ok)
            .map(|r| &r.reading),
    );
    let loss_found =
        loss_bar.and_then(|bar| locate_loss(&running_median(&loss_profile, LOSS_MEDIAN_HALF), bar));
    // The closed form has neither noise nor bias: its least departure is the floor alone.
    let loss_truth = locate_loss(&s.loss_truth_line(2000), super::scan::MIN_LOSS_CONTRAST);
    Ok(SlideResult {
        slide: *s,
        found: locate(&profile),
        truth: locate(&truth_line),
        readings,
        profile,
        loss_profile,
        loss_bar,
        loss_found,
        loss_truth,
    })
}

/// The figures of one slide as JSON.
pub fn slide_json(r: &SlideResult) -> Value {
    json!({
        "speed_mm_s": r.slide.speed_mm_s,
        "y_mm": r.slide.y_mm,
        "from_mm": r.slide.x_mm.0,
        "to_mm": r.slide.x_mm.1,
        "probe_time_s": r.slide.seconds(),
        "readings": r.readings.len(),
        "ok_on_path": r.profile.len(),
        "ok_per_s": r.ok_rate(),
        "centre_mm": r.found.map(|l| l.centre_mm),
        "edges_mm": r.found.map(|l| [l.edges_mm.0, l.edges_mm.1]),
        "contrast": r.found.map(|l| l.contrast),
        "truth_centre_mm": r.truth.map(|l| l.centre_mm),
        "truth_edges_mm": r.truth.map(|l| [l.edges_mm.0, l.edges_mm.1]),
        "truth_contrast": r.truth.map(|l| l.contrast),
        "centre_error_mm": r.centre_error_mm(),
        "loss_ok_on_path": r.loss_profile.len(),
        "loss_bar": r.loss_bar,
        "loss_centre_mm": r.loss_found.map(|l| l.centre_mm),
        "loss_edges_mm": r.loss_found.map(|l| [l.edges_mm.0, l.edges_mm.1]),
        "loss_background": r.loss_found.map(|l| l.background),
        "loss_level": r.loss_found.map(|l| l.level),
        "truth_loss_centre_mm": r.loss_truth.map(|l| l.centre_mm),
        "truth_loss_background": r.loss_truth.map(|l| l.background),
        "truth_loss_level": r.loss_truth.map(|l| l.level),
    })
}

/// One line for a human.
pub fn summary(r: &SlideResult) -> String {
    let f = |l: Option<Located>| {
        l.map_or("no lump found".to_owned(), |l| {
            format!(
                "centre {:+.2} mm (edges {:+.2} … {:+.2}), contrast {:.2}",
                l.centre_mm, l.edges_mm.0, l.edges_mm.1, l.contrast
            )
        })
    };
    let mut line = format!(
        "{:6.1} mm/s: {:4} ok readings on the path ({:.1}/s); stream: {}; closed form: {}; centre error {}",
        r.slide.speed_mm_s,
        r.profile.len(),
        r.ok_rate(),
        f(r.found),
        f(r.truth),
        r.centre_error_mm()
            .map_or("—".to_owned(), |e| format!("{e:+.2} mm"))
    );
    if r.slide.phantom.is_lossy() {
        let g = |l: Option<LossLocated>| {
            l.map_or("no loss lump".to_owned(), |l| {
                format!(
                    "centre {:+.2} mm, tan d {:.3} -> {:.3}",
                    l.centre_mm, l.background, l.level
                )
            })
        };
        line.push_str(&format!(
            "; loss (bar {}): stream: {}; closed form: {}",
            r.loss_bar.map_or("—".to_owned(), |b| format!("{b:.3}")),
            g(r.loss_found),
            g(r.loss_truth)
        ));
    }
    line
}

/// Plot one slide (modulus against position, with the closed form) or, for several speeds,
/// the centre's error and the contrast against speed.
pub fn plot(path: &Path, results: &[SlideResult]) -> Result<()> {
    match results {
        [one] => draw_to!(path, (900, 480), |r| draw_profile(r, one)),
        many => draw_to!(path, (900, 620), |r| draw_speeds(r, many)),
    }
}

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("{e:?}")
}

fn draw_profile<DB: Backend>(root: &Area<DB>, r: &SlideResult) -> Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let s = &r.slide;
    let (lo, hi) = (s.x_mm.0.min(s.x_mm.1), s.x_mm.0.max(s.x_mm.1));
    let truth = s.truth_line(400);
    let (elo, ehi) = padded_range(
        r.profile.iter().chain(truth.iter()).map(|p| p.1),
        0.1,
        (0.0, 1.0),
    );
    let title = format!(
        "sliding scan of the {} phantom at {} mm/s (y = {} mm)",
        s.phantom.name, s.speed_mm_s, s.y_mm
    );
    let mut c = plot::chart(
        root,
        Some((&title, 18)),
        FRAME,
        (lo..hi, elo..ehi),
        ("tip position x, mm", "modulus, kPa"),
    )
    .map_err(err)?;
    let (tc, rc) = (PALETTE[0], PALETTE[1]);
    c.draw_series(LineSeries::new(truth, tc.stroke_width(2)))
        .map_err(err)?
        .label("closed form (apparent modulus)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], tc.stroke_width(2)));
    c.draw_series(
        r.profile
            .iter()
            .map(|&(x, e)| Circle::new((x, e), 2, rc.filled())),
    )
    .map_err(err)?
    .label("ok stream reading")
    .legend(move |(x, y)| Circle::new((x, y), 3, rc.filled()));
    for (l, col) in [(r.truth, tc), (r.found, rc)] {
        if let Some(l) = l {
            for x in [l.edges_mm.0, l.edges_mm.1, l.centre_mm] {
                c.draw_series(std::iter::once(PathElement::new(
                    vec![(x, elo), (x, ehi)],
                    col.stroke_width(1),
                )))
                .map_err(err)?;
            }
        }
    }
    draw_legend(&mut c, SeriesLabelPosition::MiddleRight, 0.8).map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

fn draw_speeds<DB: Backend>(root: &Area<DB>, results: &[SlideResult]) -> Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let (upper, lower) = root.split_vertically(310);
    let vmax = results
        .iter()
        .map(|r| r.slide.speed_mm_s)
        .fold(1.0, f64::max)
        * 1.1;
    let errs: Vec<(f64, f64)> = results
        .iter()
        .filter_map(|r| Some((r.slide.speed_mm_s, r.centre_error_mm()?)))
        .collect();
    let (lo, hi) = padded_range(errs.iter().map(|p| p.1).chain([0.0]), 0.2, (-1.0, 1.0));
    let mut c = plot::chart(
        &upper,
        Some((
            "sliding scan: the lump's centre and contrast against speed",
            18,
        )),
        FRAME,
        (0.0..vmax, lo..hi),
        ("sliding speed, mm/s", "centre error, mm"),
    )
    .map_err(err)?;
    let col = PALETTE[1];
    c.draw_series(LineSeries::new(errs.clone(), col.stroke_width(2)))
        .map_err(err)?;
    c.draw_series(errs.iter().map(|&p| Circle::new(p, 3, col.filled())))
        .map_err(err)?;
    let found: Vec<(f64, f64)> = results
        .iter()
        .filter_map(|r| Some((r.slide.speed_mm_s, r.found?.contrast)))
        .collect();
    let truth: Vec<(f64, f64)> = results
        .iter()
        .filter_map(|r| Some((r.slide.speed_mm_s, r.truth?.contrast)))
        .collect();
    let (clo, chi) = padded_range(
        found.iter().chain(truth.iter()).map(|p| p.1),
        0.2,
        (1.0, 2.0),
    );
    let mut l = plot::chart(
        &lower,
        None,
        FRAME,
        (0.0..vmax, clo..chi),
        ("sliding speed, mm/s", "contrast (lump / background)"),
    )
    .map_err(err)?;
    let tc = PALETTE[0];
    l.draw_series(LineSeries::new(truth, tc.stroke_width(2)))
        .map_err(err)?
        .label("closed form")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], tc.stroke_width(2)));
    l.draw_series(LineSeries::new(found.clone(), col.stroke_width(2)))
        .map_err(err)?
        .label("stream")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], col.stroke_width(2)));
    l.draw_series(found.iter().map(|&p| Circle::new(p, 3, col.filled())))
        .map_err(err)?;
    draw_legend(&mut l, SeriesLabelPosition::MiddleRight, 0.8).map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plateau from 2 to 6 over a background of 100 kPa at 200 kPa: edges at the half level
    /// (150) by linear interpolation between the samples around the steps.
    #[test]
    fn locate_finds_the_plateau_by_its_half_level() {
        let pts: Vec<(f64, f64)> = (0..=40)
            .map(|k| {
                let x = k as f64 * 0.25;
                (
                    x,
                    if (2.0..=6.0).contains(&x) {
                        200.0
                    } else {
                        100.0
                    },
                )
            })
            .collect();
        let l = locate(&pts).unwrap();
        // Rising between x = 1.75 (100) and 2.0 (200): 150 at 1.875; falling between 6.0
        // and 6.25: 6.125.
        assert!((l.edges_mm.0 - 1.875).abs() < 1e-12, "{l:?}");
        assert!((l.edges_mm.1 - 6.125).abs() < 1e-12, "{l:?}");
        assert!((l.centre_mm - 4.0).abs() < 1e-12);
        assert!((l.contrast - 2.0).abs() < 1e-12);
        // Flat: no lump.
        let flat: Vec<(f64, f64)> = (0..20).map(|k| (k as f64, 100.0)).collect();
        assert!(locate(&flat).is_none());
        assert!(locate(&pts[..5]).is_none());
    }
}
