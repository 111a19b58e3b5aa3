//! `probe-bench stream`: continuous reading on the simulated probe (the core's tracker,
//! `pzt_probe::instrument::continuous`), with a step in stiffness, a lift-off and a new contact on the way.

use super::{ImageArgs, OutputArgs};
use crate::plot::{Area, Backend};
use crate::report;
use crate::scene::{parse_noise, print_scene_header, NoiseArgs, SceneArgs};
use crate::stream::{self, settled_after, summarize, StreamScene, Truth};
use anyhow::{bail, Context, Result};
use clap::Args;
use hal_sim::{phantoms, ForceChange, LiftOff, Phantom};
use plotters::prelude::*;
use pzt_probe::instrument::continuous::{StreamReading, TrackerConfig, METHOD};
use pzt_probe::{Seconds, Status};
use serde_json::json;
use std::io::Write;
use std::path::Path;

#[derive(Args)]
pub struct StreamArgs {
    /// What the probe is on, and the preload.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Probe time to stream for, s.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// A slide onto another tissue.
    #[command(flatten)]
    pub step: StepArgs,
    /// The probe lifted off, and put down again.
    #[command(flatten)]
    pub lift: LiftArgs,
    /// The hand's press changing.
    #[command(flatten)]
    pub press: PressArgs,
    /// Random knocks at this mean rate, per s (mechanical 15 mm/s, electrical 0.8 nC, as the
    /// stability catalogue's `knocks` scene).
    #[arg(long)]
    pub knocks_hz: Option<f64>,
    /// The tracker's settings.
    #[command(flatten)]
    pub tracker: TrackerArgs,
    /// The front end's noise and its seed.
    #[command(flatten)]
    pub noise: NoiseArgs,
    /// JSON (each reading's fields with seq, t_s, locked) and the plot (modulus and lock against
    /// time).
    #[command(flatten)]
    pub out: OutputArgs,
    /// The firmware image to stream on instead of the host's simulated probe.
    #[command(flatten)]
    pub image: ImageArgs,
}

/// A slide onto another tissue during the stream (hal-sim `Step`).
#[derive(Args)]
pub struct StepArgs {
    /// Slide onto this phantom (A–E, ..., or a named tissue) at `--step-at-s`.
    #[arg(long)]
    pub step_to: Option<String>,
    /// Time of the step in stiffness, s.
    #[arg(long)]
    pub step_at_s: Option<f64>,
}

impl StepArgs {
    /// The phantom slid onto and the time of the slide, s; `None` without a step.
    pub fn step(&self) -> Result<Option<(Phantom, f64)>> {
        Ok(match (&self.step_to, self.step_at_s) {
            (Some(p), Some(at)) => Some((
                phantoms::by_name(p).with_context(|| format!("unknown phantom `{p}`"))?,
                at,
            )),
            (None, None) => None,
            _ => bail!("--step-to and --step-at-s go together"),
        })
    }
}

/// The probe lifted off the tissue and put down again (hal-sim `LiftOff`).
#[derive(Args)]
pub struct LiftArgs {
    /// Lift the probe off the tissue at this time, s.
    #[arg(long)]
    pub lift_off_at_s: Option<f64>,
    /// Time the preload takes to fall to zero at the lift-off, s (0: the tip leaves at once).
    #[arg(long, default_value_t = 0.0)]
    pub lift_off_ramp_s: f64,
    /// Put the probe down again on the same tissue at this time, s (after `--lift-off-at-s`).
    #[arg(long)]
    pub touch_at_s: Option<f64>,
}

impl LiftArgs {
    /// The lift-off; `None` without one.
    pub fn lift_off(&self) -> Option<LiftOff> {
        self.lift_off_at_s.map(|at_s| LiftOff {
            at_s,
            ramp_s: self.lift_off_ramp_s,
        })
    }
}

/// The hand's press changing during the stream (hal-sim `ForceChange`).
#[derive(Args)]
pub struct PressArgs {
    /// The hand presses harder or lighter (the tip slides down an edge): the preload moves to
    /// this fraction of itself from `--press-at-s` over `--press-ramp-s` (hal-sim ForceChange).
    #[arg(long)]
    pub press_to: Option<f64>,
    /// Time the press starts to change, s.
    #[arg(long)]
    pub press_at_s: Option<f64>,
    /// Time the press takes to change, s.
    #[arg(long, default_value_t = stream::DEFAULT_PRESS_RAMP_S)]
    pub press_ramp_s: f64,
}

impl PressArgs {
    /// The change of the press; `None` without one.
    pub fn change(&self) -> Result<Option<ForceChange>> {
        Ok(match (self.press_to, self.press_at_s) {
            (Some(f), Some(at)) => Some(ForceChange {
                at_s: at,
                ramp_s: self.press_ramp_s,
                to_fraction: f,
            }),
            (None, None) => None,
            _ => bail!("--press-to and --press-at-s go together"),
        })
    }
}

/// The tracker's settings (the core's `TrackerConfig`).
#[derive(Args)]
pub struct TrackerArgs {
    /// Length of one tracking segment (one reading each), s.
    #[arg(long, default_value_t = TrackerConfig::DEFAULT.segment.0 as f64)]
    pub segment_s: f64,
    /// Segments a plan holds (1–8): the drive moves only between plans; a plan's later
    /// segments are fitted with its windows so far (`--segment-s 0.012 --plan-segments 4`:
    /// more than 50 readings a second).
    #[arg(long, default_value_t = TrackerConfig::DEFAULT.plan_segments)]
    pub plan_segments: u8,
    /// How fast the resonance may drift between segments, Hz/s: the tracker's process model
    /// (what it pools over, and the lag its σ states).
    #[arg(long, default_value_t = TrackerConfig::DEFAULT.drift as f64)]
    pub drift_hz_s: f64,
    /// Offset of the drive from the resonance, alternately above and below, in
    /// half-linewidths f0/(2Q) (0: on the resonance).
    #[arg(long, default_value_t = TrackerConfig::DEFAULT.dither as f64)]
    pub dither: f64,
    /// Relative standard uncertainty of the previous segment's Q as the next fit's prior.
    #[arg(long, default_value_t = TrackerConfig::DEFAULT.q_prior as f64)]
    pub q_prior: f64,
}

impl TrackerArgs {
    /// The tracker's configuration: the default with these settings.
    pub fn config(&self) -> TrackerConfig {
        TrackerConfig {
            segment: Seconds(self.segment_s as f32),
            plan_segments: self.plan_segments,
            drift: self.drift_hz_s as f32,
            dither: self.dither as f32,
            q_prior: self.q_prior as f32,
            ..TrackerConfig::DEFAULT
        }
    }

    /// True when every setting the firmware's `stream` command cannot take (all but the
    /// segment and the segments a plan) is the default's, as given (not rounded to `f32`).
    pub fn is_image_settable(&self) -> bool {
        let d = TrackerConfig::DEFAULT;
        self.drift_hz_s == d.drift as f64
            && self.dither == d.dither as f64
            && self.q_prior == d.q_prior as f64
    }
}

/// Run the subcommand.
pub fn run(a: StreamArgs) -> Result<()> {
    let noise = parse_noise(&a.noise.noise)?;
    let (target, _) = a.scene.scene(noise, false)?;
    let step = a.step.step()?;
    let press = a.press.change()?;
    let stream_scene = StreamScene {
        preload_n: a.scene.preload_n,
        step,
        lift_off: a.lift.lift_off(),
        touch_at_s: a.lift.touch_at_s,
        press,
        knocks_hz: a.knocks_hz,
        ..StreamScene::on(target, noise)
    };
    // The events and the seconds are checked before anything is printed or run.
    let (scene, truth) = stream_scene.build()?;
    stream::check_seconds(a.seconds)?;
    let config = a.tracker.config();
    let unit = crate::unit::default_for(METHOD)?;
    if !a.out.json {
        print_scene_header("stream", &target, a.scene.preload_n, noise, &scene);
        if !(a.image.qemu || a.image.stm32) {
            println!(
            "  tracker: segments of {:.0} ms, {} a plan, drive ±{} half-linewidths off the resonance, drift {} Hz/s; unit profile of the simulated unit ({} calibration)",
            a.tracker.segment_s * 1e3,
            a.tracker.plan_segments,
            a.tracker.dither,
            a.tracker.drift_hz_s,
            METHOD.name()
        );
        }
    }
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut last_progress = -1.0f64;
    let mut write_err = None;
    let mut each = |r: &StreamReading| {
        if a.out.json {
            if let Err(e) = writeln!(out, "{}", stream_json(r)) {
                write_err.get_or_insert(e);
            }
        } else if r.t_s.0 as f64 - last_progress >= 0.1 {
            last_progress = r.t_s.0 as f64;
            eprint!(
                "\r  t {:6.2} s  seq {:5}  {:12} {:>10}  {}",
                r.t_s.0,
                r.seq,
                r.reading.status.code(),
                r.reading
                    .modulus
                    .map_or("—".to_owned(), |e| format!("{:.1} kPa", e.0)),
                if r.locked { "locked" } else { "unlocked" }
            );
        }
    };
    let readings = if a.image.qemu || a.image.stm32 {
        let v = if a.image.qemu {
            crate::qemu::stream(&a, &target, noise)?
        } else {
            crate::stm32::stream(&a, &target, noise)?
        };
        v.iter().for_each(&mut each);
        v
    } else {
        stream::run(&stream_scene, &config, &unit, a.noise.seed, a.seconds, each)?.readings
    };
    if let Some(e) = write_err {
        return Err(e.into());
    }
    let s = summarize(&readings, &truth, stream::SETTLE_S);
    if !a.out.json {
        eprintln!();
        println!(
            "  {} readings in {:.2} s of probe time, {} dropped (gaps in seq)",
            readings.len(),
            readings.last().map_or(0.0, |r| r.t_s.0),
            s.dropped
        );
        println!(
            "  after {} s: {:.1} ok readings/s; {} of {} with a truth ok, RMS error {}",
            stream::SETTLE_S,
            s.ok_per_s,
            s.ok_with_truth,
            s.with_truth,
            s.rms_rel
                .map_or("—".to_owned(), |e| format!("{:.3} %", 100.0 * e))
        );
        if let Some(l) = truth.lift_s {
            println!(
                "  lift-off at {l:.3} s: last ok reading at {}",
                s.last_ok_after_lift
                    .map_or("— (none after it)".to_owned(), |t| format!("{t:.3} s"))
            );
        }
        for (label, at) in [("step", truth.step_s), ("new contact", truth.touch_s)] {
            if let Some(at) = at {
                println!(
                    "  {label} at {at:.3} s: within 3 % of the truth from {}",
                    settled_after(&readings, &truth, at, 0.03).map_or(
                        "— (never)".to_owned(),
                        |t| format!("{t:.3} s ({:.0} ms after)", (t - at) * 1e3)
                    )
                );
            }
        }
    }
    a.out
        .plot_with(|path| plot(path, &target.describe(), &readings, &truth))
}

/// The JSON object of one stream reading: the reading's own fields and seq, t_s, locked.
pub fn stream_json(r: &StreamReading) -> serde_json::Value {
    let mut v = report::reading_json(&r.reading);
    if let Some(o) = v.as_object_mut() {
        o.insert("seq".into(), json!(r.seq));
        o.insert("t_s".into(), json!(r.t_s.0));
        o.insert("locked".into(), json!(r.locked));
    }
    v
}

/// Modulus (ok readings, with their σ, and the truth) and lock against time.
fn plot(path: &Path, title: &str, readings: &[StreamReading], truth: &Truth) -> Result<()> {
    let pts: Vec<(f64, f64, f64)> = readings
        .iter()
        .filter(|r| r.reading.status == Status::Ok)
        .filter_map(|r| {
            Some((
                r.t_s.0 as f64,
                r.reading.modulus?.0 as f64,
                r.reading.modulus_sigma.map_or(0.0, |s| s.0 as f64),
            ))
        })
        .collect();
    let t_end = readings.last().map_or(1.0, |r| r.t_s.0 as f64).max(0.1);
    let truths: Vec<f64> = readings
        .iter()
        .filter_map(|r| truth.at(r.t_s.0 as f64))
        .collect();
    let (lo, hi) = crate::plot::padded_range(
        pts.iter().map(|p| p.1).chain(truths.iter().copied()),
        0.1,
        (0.0, 1.0),
    );
    let title = format!("stream — {title}");
    let p = Plot {
        title: &title,
        readings,
        truth,
        pts: &pts,
        t_end,
        range: (lo, hi),
    };
    crate::plot::draw_to!(path, (900, 560), |r| draw(r, &p))
}

struct Plot<'a> {
    title: &'a str,
    readings: &'a [StreamReading],
    truth: &'a Truth,
    pts: &'a [(f64, f64, f64)],
    t_end: f64,
    range: (f64, f64),
}

fn draw<DB: Backend>(root: &Area<DB>, p: &Plot) -> Result<()> {
    let (title, readings, truth, pts, t_end) = (p.title, p.readings, p.truth, p.pts, p.t_end);
    let (lo, hi) = p.range;
    {
        root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let (upper, lower) = root.split_vertically(380);
        let mut c = crate::plot::chart(
            &upper,
            Some((title, 18)),
            crate::plot::Frame {
                margin: 10,
                x_labels: 30,
                y_labels: 70,
            },
            (0.0..t_end, lo..hi),
            ("probe time, s", "modulus, kPa"),
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let col = crate::plot::PALETTE[1];
        let tcol = crate::plot::PALETTE[0];
        // The truth: a step line sampled at the readings' times.
        let steps: Vec<(f64, f64)> = readings
            .iter()
            .filter_map(|r| truth.at(r.t_s.0 as f64).map(|x| (r.t_s.0 as f64, x)))
            .collect();
        // A line between consecutive readings under the same tissue.
        c.draw_series(
            steps
                .windows(2)
                .filter(|w| w[0].1 == w[1].1)
                .map(|w| PathElement::new(vec![w[0], w[1]], tcol.stroke_width(2))),
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?
        .label("truth")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], tcol.stroke_width(2)));
        c.draw_series(
            pts.iter().map(|&(t, e, s)| {
                PathElement::new(vec![(t, e - s), (t, e + s)], col.stroke_width(1))
            }),
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        c.draw_series(
            pts.iter()
                .map(|&(t, e, _)| Circle::new((t, e), 2, col.filled())),
        )
        .map_err(|e| anyhow::anyhow!("{e:?}"))?
        .label("ok reading ± σ")
        .legend(move |(x, y)| Circle::new((x, y), 3, col.filled()));
        crate::plot::draw_legend(&mut c, SeriesLabelPosition::MiddleRight, 0.8)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let mut l = ChartBuilder::on(&lower)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_end, -0.2..1.2)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        l.configure_mesh()
            .x_desc("probe time, s")
            .y_desc("locked / ok")
            .y_labels(2)
            .draw()
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let lock: Vec<(f64, f64)> = readings
            .iter()
            .map(|r| (r.t_s.0 as f64, if r.locked { 1.0 } else { 0.0 }))
            .collect();
        let ok: Vec<(f64, f64)> = readings
            .iter()
            .map(|r| {
                let ok = r.reading.status == Status::Ok;
                (r.t_s.0 as f64, if ok { 0.9 } else { 0.1 })
            })
            .collect();
        let g = crate::plot::PALETTE[2];
        l.draw_series(LineSeries::new(lock, g.stroke_width(2)))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?
            .label("locked")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], g));
        let o = crate::plot::PALETTE[4];
        l.draw_series(LineSeries::new(ok, o.stroke_width(1)))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?
            .label("ok")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], o));
        crate::plot::draw_legend(&mut l, SeriesLabelPosition::MiddleRight, 0.8)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        Ok(())
    }
}
