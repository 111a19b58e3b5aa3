//! Continuous reading on the simulated probe: a scene with its events in probe time (a step in
//! stiffness, a lift-off, a new contact, a change of press, knocks), its truth, the core's
//! tracker (`pzt_probe::instrument::continuous`) driven over it, and the stream's figures against the truth.
//! `probe-bench stream`, the speed–accuracy study's tracker curve (`crate::pareto`) and the
//! continuous-mode scenes of the stability map (`crate::stability`) all stream through [`run`].

use crate::scene::{noise_name, Target};
use anyhow::{bail, Result};
use hal_sim::catalogue::KNOCKS;
use hal_sim::phantoms::Phantom;
use hal_sim::{ForceChange, Knocks, LiftOff, NoiseScene, Scene, Step};
use pzt_probe::board::sim as simboard;
use pzt_probe::instrument::continuous::{StreamReading, TrackerConfig};
use pzt_probe::unit::profile::UnitProfile;
use pzt_probe::Status;

/// A continuous scene: what the probe is on, how hard, in which noise, and what happens on the
/// way (times in probe time, s, from the scene's start).
#[derive(Clone, Copy, Debug)]
pub struct StreamScene {
    /// What the probe is pressed on at the start.
    pub target: Target,
    /// Contact preload, N.
    pub preload_n: f64,
    /// Front-end noise.
    pub noise: NoiseScene,
    /// Slide onto this phantom at this time, s.
    pub step: Option<(Phantom, f64)>,
    /// Lift the probe off the tissue (the tip leaves at the end of the ramp).
    pub lift_off: Option<LiftOff>,
    /// Put the probe down again on the starting tissue at this time, s (after the lift-off).
    pub touch_at_s: Option<f64>,
    /// The press changes (the tip slides down an edge, the hand creeps).
    pub press: Option<ForceChange>,
    /// Random knocks at this mean rate, per s (the stability catalogue's knocks otherwise).
    pub knocks_hz: Option<f64>,
}

impl StreamScene {
    /// `target` at 30 mN under `noise`, nothing happening.
    pub fn on(target: Target, noise: NoiseScene) -> Self {
        Self {
            target,
            preload_n: 0.030,
            noise,
            step: None,
            lift_off: None,
            touch_at_s: None,
            press: None,
            knocks_hz: None,
        }
    }

    /// The simulated scene and its truth; an error for events that do not fit together.
    pub fn build(&self) -> Result<(Scene, Truth)> {
        if !(self.preload_n.is_finite() && self.preload_n > 0.0 && self.preload_n <= 1.0) {
            bail!("preload {} N is out of range (0 to 1 N)", self.preload_n);
        }
        let mut scene = self
            .target
            .scene()
            .with_noise(self.noise)
            .with_preload_n(self.preload_n);
        let mut truth = Truth {
            start_kpa: self.target.modulus_kpa(),
            ..Truth::default()
        };
        if let Some((ph, at)) = self.step {
            check_time(at, "--step-at-s")?;
            scene = scene.with_step(Step {
                at_s: at,
                tissue: Some(ph.tissue()),
            });
            truth.push(at, Some(ph.modulus_kpa));
            truth.step_s = Some(at);
        }
        if let Some(l) = self.lift_off {
            check_time(l.at_s, "--lift-off-at-s")?;
            if !(l.ramp_s >= 0.0 && l.ramp_s <= 1.0) {
                bail!("--lift-off-ramp-s must be in [0, 1]");
            }
            if truth.step_s.is_some_and(|s| s >= l.at_s) {
                bail!(
                    "--step-at-s after --lift-off-at-s: use --touch-at-s to put the probe down again"
                );
            }
            scene = scene.with_lift_off(l);
            // The tip leaves the tissue at the end of the ramp.
            truth.lift_s = Some(l.at_s + l.ramp_s);
            truth.push(l.at_s + l.ramp_s, None);
        }
        if let Some(t) = self.touch_at_s {
            check_time(t, "--touch-at-s")?;
            if self.step.is_some() || !truth.lift_s.is_some_and(|l| t > l) {
                bail!("--touch-at-s needs an earlier --lift-off-at-s (and no --step-to)");
            }
            scene = scene.with_step(Step {
                at_s: t,
                tissue: scene.tissue,
            });
            truth.touch_s = Some(t);
            truth.push(t, self.target.modulus_kpa());
        }
        if let Some(p) = self.press {
            check_time(p.at_s, "--press-at-s")?;
            if !(p.to_fraction > 0.0 && p.to_fraction <= 10.0 && (0.0..=1.0).contains(&p.ramp_s)) {
                bail!("--press-to must be in (0, 10], --press-ramp-s in [0, 1]");
            }
            scene = scene.with_force_change(p);
        }
        if let Some(rate) = self.knocks_hz {
            if !(rate > 0.0 && rate <= 100.0) {
                bail!("--knocks-hz must be in (0, 100]");
            }
            scene = scene.with_knocks(Knocks {
                rate_hz: rate,
                ..KNOCKS
            });
        }
        Ok((scene, truth))
    }

    /// The `probe-bench stream` options that stream this scene (defaults left out).
    pub fn args(&self) -> Vec<String> {
        let mut v: Vec<String> = Vec::new();
        let mut push = |k: &str, x: String| {
            v.push(k.to_owned());
            v.push(x);
        };
        match self.target {
            Target::Phantom(p) => push("--phantom", p.name.to_owned()),
            Target::Modulus(e) => push("--modulus-kpa", format!("{e}")),
            Target::FreeAir => {}
        }
        if self.preload_n != 0.030 {
            push("--preload-n", format!("{}", self.preload_n));
        }
        if self.noise != NoiseScene::Bench {
            let n = match self.noise {
                NoiseScene::Density(d) => format!("{d:e}"),
                other => noise_name(other),
            };
            push("--noise", n);
        }
        if let Some((p, at)) = self.step {
            push("--step-to", p.name.to_owned());
            push("--step-at-s", format!("{at}"));
        }
        if let Some(l) = self.lift_off {
            push("--lift-off-at-s", format!("{}", l.at_s));
            if l.ramp_s != 0.0 {
                push("--lift-off-ramp-s", format!("{}", l.ramp_s));
            }
        }
        if let Some(t) = self.touch_at_s {
            push("--touch-at-s", format!("{t}"));
        }
        if let Some(p) = self.press {
            push("--press-to", format!("{}", p.to_fraction));
            push("--press-at-s", format!("{}", p.at_s));
            if p.ramp_s != DEFAULT_PRESS_RAMP_S {
                push("--press-ramp-s", format!("{}", p.ramp_s));
            }
        }
        if let Some(r) = self.knocks_hz {
            push("--knocks-hz", format!("{r}"));
        }
        if matches!(self.target, Target::FreeAir) {
            v.push("--free-air".into());
        }
        v
    }
}

/// A stream's figures count the readings that end after this probe time, s: the issue's "after
/// the first 0.5 s" (the acquisition and the first segments left out).
pub const SETTLE_S: f64 = 0.5;

/// Probe time a stream may run for, s: (0, this].
pub const MAX_SECONDS: f64 = 600.0;

/// `seconds` as a stream's length: in (0, [`MAX_SECONDS`]].
pub fn check_seconds(seconds: f64) -> Result<()> {
    if !(seconds > 0.0 && seconds <= MAX_SECONDS) {
        bail!("--seconds must be in (0, {MAX_SECONDS}]");
    }
    Ok(())
}

/// Time the press takes to change when `--press-ramp-s` is not given, s.
pub const DEFAULT_PRESS_RAMP_S: f64 = 0.03;

fn check_time(t: f64, what: &str) -> Result<()> {
    if !(0.0..=600.0).contains(&t) {
        bail!("{what} must be in [0, 600] s");
    }
    Ok(())
}

/// What the scene's truth is at a time: the modulus under the probe, or none (lifted off): the
/// starting tissue's, then each event's from its time on.
#[derive(Clone, Debug, Default)]
pub struct Truth {
    start_kpa: Option<f64>,
    /// (time, modulus from then on), in time order.
    events: Vec<(f64, Option<f64>)>,
    /// When the tip leaves the tissue, s.
    pub lift_s: Option<f64>,
    /// When the probe is put down again, s.
    pub touch_s: Option<f64>,
    /// When the stiffness steps, s.
    pub step_s: Option<f64>,
}

impl Truth {
    /// The modulus (kPa) under the probe at `t_s` (None: no tissue, or none known).
    pub fn at(&self, t_s: f64) -> Option<f64> {
        self.events
            .iter()
            .rev()
            .find(|(t, _)| t_s >= *t)
            .map_or(self.start_kpa, |(_, e)| *e)
    }

    /// The times (s) at which the truth changes, in order.
    pub fn changes(&self) -> impl Iterator<Item = f64> + '_ {
        self.events.iter().map(|e| e.0)
    }

    fn push(&mut self, t: f64, e: Option<f64>) {
        self.events.push((t, e));
        self.events.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
}

/// A stream and the truth of its scene.
#[derive(Clone, Debug)]
pub struct Streamed {
    /// Every reading, in order.
    pub readings: Vec<StreamReading>,
    /// The scene's truth.
    pub truth: Truth,
}

/// Stream `scene` on the simulated probe (noise seed `seed`) with the tracker `config` and the
/// unit `unit` until a reading ends `seconds` (s of probe time) in, handing each reading to
/// `each` as it comes: the core's driver (`board::sim::stream`), as `probe-bench stream` runs it.
pub fn run(
    scene: &StreamScene,
    config: &TrackerConfig,
    unit: &UnitProfile,
    seed: u64,
    seconds: f64,
    mut each: impl FnMut(&StreamReading),
) -> Result<Streamed> {
    check_seconds(seconds)?;
    let (sim, truth) = scene.build()?;
    let mut readings = Vec::new();
    simboard::stream(&sim, seed, config, unit, seconds, |r| {
        each(r);
        readings.push(*r);
    })
    .map_err(|e| anyhow::anyhow!("the stream failed: {e}"))?;
    Ok(Streamed { readings, truth })
}

/// A stream's figures against the scene's truth.
#[derive(Clone, Copy, Debug, Default)]
pub struct Summary {
    /// Readings missing from the sequence numbers.
    pub dropped: u64,
    /// Ok readings per second of probe time after `settle_s`.
    pub ok_per_s: f64,
    /// Readings after `settle_s` with a truth (the probe on tissue).
    pub with_truth: usize,
    /// Of them, ok.
    pub ok_with_truth: usize,
    /// RMS relative error of the ok readings against the truth (a fraction).
    pub rms_rel: Option<f64>,
    /// Largest relative error of an ok reading against the truth (a fraction).
    pub worst_rel: Option<f64>,
    /// Time of the last ok reading after the lift-off (and before a new contact), s.
    pub last_ok_after_lift: Option<f64>,
}

/// The figures of `readings` against `truth`, counting from `settle_s` (s).
pub fn summarize(readings: &[StreamReading], truth: &Truth, settle_s: f64) -> Summary {
    let mut s = Summary::default();
    let mut expect = 0u64;
    for r in readings {
        s.dropped += (r.seq as u64).saturating_sub(expect);
        expect = r.seq as u64 + 1;
    }
    let end = readings.last().map_or(0.0, |r| r.t_s.0 as f64);
    let (mut n_ok, mut sq) = (0usize, 0.0);
    for r in readings.iter().filter(|r| r.t_s.0 as f64 > settle_s) {
        let ok = r.reading.status == Status::Ok;
        if ok {
            n_ok += 1;
        }
        if let Some(t) = truth.at(r.t_s.0 as f64) {
            s.with_truth += 1;
            if let (true, Some(e)) = (ok, r.reading.modulus) {
                s.ok_with_truth += 1;
                let rel = e.0 as f64 / t - 1.0;
                sq += rel * rel;
                s.worst_rel = Some(s.worst_rel.map_or(rel.abs(), |w: f64| w.max(rel.abs())));
            }
        }
    }
    if end > settle_s {
        s.ok_per_s = n_ok as f64 / (end - settle_s);
    }
    if s.ok_with_truth > 0 {
        s.rms_rel = Some((sq / s.ok_with_truth as f64).sqrt());
    }
    if let Some(l) = truth.lift_s {
        s.last_ok_after_lift = readings
            .iter()
            .filter(|r| r.reading.status == Status::Ok && r.t_s.0 as f64 >= l)
            .filter(|r| truth.touch_s.is_none_or(|t| (r.t_s.0 as f64) < t))
            .map(|r| r.t_s.0 as f64)
            .next_back();
    }
    s
}

/// The time (s) after `at` (s) from which every reading until the truth's next change is ok
/// and within `tol` (a fraction) of the truth (None: never).
pub fn settled_after(readings: &[StreamReading], truth: &Truth, at: f64, tol: f64) -> Option<f64> {
    let next = truth.changes().find(|t| *t > at).unwrap_or(f64::INFINITY);
    let mut from = None;
    for r in readings
        .iter()
        .filter(|r| (at..next).contains(&(r.t_s.0 as f64)))
    {
        let t = r.t_s.0 as f64;
        let good = match (truth.at(t), r.reading.modulus, r.reading.status) {
            (Some(x), Some(e), Status::Ok) => (e.0 as f64 / x - 1.0).abs() <= tol,
            _ => false,
        };
        match (good, from) {
            (true, None) => from = Some(t),
            (false, _) => from = None,
            _ => {}
        }
    }
    from
}
