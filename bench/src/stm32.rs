//! `probe-bench measure --stm32` and `stream --stm32`: the STM32 image (`cargo fw`) on the
//! emulated NUCLEO-G474RE (`emu/`, the `stm32-emu` program, run as a subprocess as `--qemu` runs
//! qemu-system-arm: it is GPL and never linked into the bench).
//!
//! The emulated board starts with an empty store, as a fresh board does, so the bench takes the
//! unit through its user's path first ([`user_path`]): the air reference in free air, the load
//! cell's sensitivity with 10 g resting on the tip (`weigh 10`), a calibration on phantoms A–E
//! with the reading's method, `calibrate fit`; then the readings or the stream on the target.
//! Each step waits for the image's reply to the one before (`done+` times of `stm32-emu`: the
//! command served), so a method's own duration never has to be guessed. The probe is hal-sim's at
//! bench noise with its load cell, noise seed `--seed`. The decoded log goes through the same
//! parser as `probe-bench log`, and each reading prints through the same JSON and line as a host
//! reading (a stream through the same summary as `stream --qemu`).

use crate::cmd::measure::Request;
use crate::cmd::stream::StreamArgs;
use crate::defmt_log;
use crate::qemu::{self, target_dir, workspace_cargo};
use crate::scene::{SceneArgs, Target};
use anyhow::{bail, Context, Result};
use hal_sim::NoiseScene;
use pzt_probe::instrument::command::SettingsLine;
use pzt_probe::instrument::continuous::StreamReading;
use pzt_probe::reading::{Method, Settings};
use std::path::PathBuf;
use std::process::{Command, Stdio};

/// The calibration session's phantoms and their moduli (paper 003), as the user types them.
const REFERENCES: [(&str, &str); 5] = [
    ("A", "157.5"),
    ("B", "279"),
    ("C", "414"),
    ("D", "1146"),
    ("E", "2465"),
];

/// The known weight of the load cell's calibration, g (`weigh 10`; the host's simulated unit
/// is weighed with the same, `pzt_probe::board::sim::CALIBRATION_WEIGHT_N`).
const WEIGHT_G: &str = "10";

/// `stm32-emu` events: (`--send`, `--scene` or `--reset`, time, argument).
struct Schedule(Vec<String>);

impl Schedule {
    fn send(&mut self, at: &str, line: &str) -> &mut Self {
        self.0.extend(["--send".into(), at.into(), line.into()]);
        self
    }
    fn scene(&mut self, at: &str, name: &str) -> &mut Self {
        self.0.extend(["--scene".into(), at.into(), name.into()]);
        self
    }
}

/// The emulator's name of what `target` is, pressed at `preload_n` (hal-sim's bench scene: a
/// phantom, `P@mN` at another force, `free-air`); an error for a target it has no scene for.
fn scene_name(target: &Target, preload_n: f64) -> Result<String> {
    match target {
        Target::FreeAir => Ok("free-air".into()),
        Target::Phantom(p) if preload_n == 0.030 => Ok(p.name.to_string()),
        Target::Phantom(p) => Ok(format!("{}@{}", p.name, preload_n * 1e3)),
        Target::Modulus(_) => {
            bail!("with --stm32 the target is a --phantom or --free-air (the emulator's scenes)")
        }
    }
}

/// The scene options the emulated board can take: bench noise, the target's own loss.
fn check_scene(scene: &SceneArgs, noise: NoiseScene) -> Result<()> {
    if noise != NoiseScene::Bench || scene.loss_tangent.is_some() {
        bail!("with --stm32 the probe is at bench noise, on the phantom's own loss");
    }
    Ok(())
}

/// The user's path of a fresh unit, as events: the air reference in free air, the weight on
/// the tip and `weigh`, `method` with `settings` (when not the image's default), a reference
/// reading on each of A–E, `calibrate fit`. Each step after the reply to the one before.
fn user_path(method: Method, settings: &Settings) -> Result<Schedule> {
    let mut s = Schedule(vec!["--phantom".into(), "free-air".into()]);
    s.send("1", "air")
        .scene("done+0.3", &format!("weight:{WEIGHT_G}"))
        .send("+0.3", &format!("weigh {WEIGHT_G}"));
    if method != Method::Auto || *settings != method.default_settings() {
        s.send("done+0.1", &format!("method {}", method.name()));
    }
    if *settings != method.default_settings() {
        match SettingsLine::of(settings) {
            Some(c) => s.send("done+0.1", &c.to_string()),
            None => bail!(
                "{} settings other than its defaults cannot be passed to the image",
                method.name()
            ),
        };
    }
    for (name, kpa) in REFERENCES {
        s.scene("done+0.3", name)
            .send("+0.5", &format!("calibrate add {kpa}"));
    }
    s.send("done+0.1", "calibrate fit");
    Ok(s)
}

/// Build the image and the emulator; their paths.
fn build() -> Result<(PathBuf, PathBuf)> {
    workspace_cargo(&["fw", "-q"])?;
    workspace_cargo(&["build", "-q", "--release", "-p", "stm32-emu"])?;
    let target_dir = target_dir();
    Ok((
        target_dir.join("thumbv7em-none-eabihf/fw/probe"),
        target_dir.join("release/stm32-emu"),
    ))
}

/// What a run of the emulated board gave: the decoded log, its parse, the emulator's report.
struct Run {
    log: String,
    session: defmt_log::Session,
    stderr: String,
}

impl Run {
    /// The probe time (s) at which the emulator sent the command line `line`.
    fn sent_at_probe_s(&self, line: &str) -> Option<f32> {
        let what = format!("Send({line:?})");
        self.stderr
            .lines()
            .find(|l| l.ends_with(&what))?
            .split("(probe time ")
            .nth(1)?
            .split(' ')
            .next()?
            .parse()
            .ok()
    }
}

/// Run the image on the emulated board with `events` (noise seed `seed`) until a second after
/// the reply to the last command; the decoded log and its parse, which must be clean. The
/// emulator's report (the events, its time, the RM0440 rules broken) printed unless `json`.
fn run(events: &Schedule, seed: u64, json: bool) -> Result<Run> {
    let (elf, emu) = build()?;
    let mut run = Command::new(&emu)
        .arg(&elf)
        .args(&events.0)
        .args(["--seed", &seed.to_string(), "--seconds", "done+1"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot run {}", emu.display()))?;
    let frames = run.stdout.take().context("stm32-emu stdout")?;
    let decoded = Command::new("defmt-print")
        .arg("-e")
        .arg(&elf)
        .args(["--log-format", "{L} {s}"])
        .stdin(Stdio::from(frames))
        .output()
        .context("cannot run defmt-print (cargo install defmt-print --locked)")?;
    let out = run.wait_with_output().context("stm32-emu")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    // Exit 3: the run ended with RM0440 rules broken (embassy's clock switch): reported, not
    // fatal; anything else non-zero is a fault of the emulated board or a reply never sent.
    if !(out.status.success() || out.status.code() == Some(3)) {
        bail!("the emulated board failed: {}", stderr.trim());
    }
    if !json {
        for l in stderr.lines() {
            println!("  {l}");
        }
    }
    let log = String::from_utf8_lossy(&decoded.stdout).into_owned();
    let session = defmt_log::parse_log(&log);
    if let Some(e) = session.errors.first() {
        bail!("the image's log does not parse: {e}");
    }
    Ok(Run {
        log,
        session,
        stderr: stderr.into_owned(),
    })
}

/// `measure --stm32`.
pub fn measure(request: Request) -> Result<()> {
    let Request {
        args: a,
        target,
        method,
        settings,
        noise,
    } = request;
    check_scene(&a.scene, noise)?;
    let on = scene_name(target, a.scene.preload_n)?;
    if a.out.plot.is_some() || a.profile.is_some() || a.calibration != "unit" {
        bail!(
            "with --stm32 the image calibrates itself on A–E (no --plot, --profile, --calibration)"
        );
    }
    if a.repeat == 0 || a.repeat > 100 {
        bail!("with --stm32 --repeat must be 1 to 100");
    }
    let mut events = user_path(method, settings)?;
    events.scene("done+0.5", &on);
    for _ in 0..a.repeat {
        events.send("done+0.5", "measure");
    }
    if !a.out.json {
        println!(
            "probe-bench measure --stm32: the STM32 image on the emulated NUCLEO-G474RE, {}",
            target.describe()
        );
        println!(
            "  session: air in free air, weigh {WEIGHT_G} g, calibrate add on A–E with {}, calibrate fit, measure × {}",
            method.name(),
            a.repeat
        );
    }
    let Run { log, session, .. } = run(&events, a.seed, a.out.json)?;
    // The calibration references are readings too: the target's are the last `repeat`.
    let n = session.readings.len();
    if n < a.repeat as usize + REFERENCES.len() {
        bail!("the image logged {n} readings:\n{log}");
    }
    qemu::print_readings(&session.readings[n - a.repeat as usize..], a.out.json)
}

/// `stream --stm32`: the user's path, then the image's `stream` command on the target, the
/// scene's events as the emulator's scene changes at their times after the command was sent
/// (steps: a slide onto another phantom, a lift-off, a new contact, a press to another force).
/// Its readings with `t_s` from the moment the command was sent (the scene's clock: its events
/// fall at their times; the stream starts once the command has arrived and been parsed).
pub fn stream(a: &StreamArgs, target: &Target, noise: NoiseScene) -> Result<Vec<StreamReading>> {
    qemu::check_stream_args(a, "--stm32")?;
    check_scene(&a.scene, noise)?;
    let preload = a.scene.preload_n;
    let on = scene_name(target, preload)?;
    // The scene changes, in stream time (s): (time, scene name).
    let mut changes: Vec<(f64, String)> = Vec::new();
    let step = a.step.step()?;
    if let Some((p, t)) = step {
        changes.push((t, scene_name(&Target::Phantom(p), preload)?));
    }
    if let Some(t) = a.lift.lift_off_at_s {
        changes.push((t, "free-air".into()));
    }
    if let Some(t) = a.lift.touch_at_s {
        changes.push((t, on.clone()));
    }
    if let Some(p) = a.press.change()? {
        // The press on what is under the probe then; a step, as on the QEMU image.
        let under = match step {
            Some((ph, at)) if at <= p.at_s => Target::Phantom(ph),
            _ => *target,
        };
        changes.push((p.at_s, scene_name(&under, p.to_fraction * preload)?));
    }
    changes.sort_by(|x, y| x.0.total_cmp(&y.0));
    let line = crate::qemu::stream_line(a);
    let mut events = user_path(Method::Auto, &Method::Auto.default_settings())?;
    events.scene("done+0.5", &on).send("+0.5", &line);
    // (`stream_readings` finds the command by this line.)
    let mut last = 0.0;
    for (t, name) in &changes {
        events.scene(&format!("+{}", t - last), name);
        last = *t;
    }
    if !a.out.json {
        println!(
            "probe-bench stream --stm32: the STM32 image on the emulated NUCLEO-G474RE, {}",
            target.describe()
        );
        println!("  session: air in free air, weigh {WEIGHT_G} g, calibrate add on A–E, calibrate fit, `{line}`; scene changes (s after the command): {changes:?}");
    }
    let r = run(&events, a.noise.seed, a.out.json)?;
    let origin = r
        .sent_at_probe_s(&line)
        .context("the emulator did not report sending the stream command")?;
    if let (Some(start), false) = (
        r.session
            .streams
            .first()
            .and_then(|x| x.end.as_ref())
            .and_then(|e| e.start_s),
        a.out.json,
    ) {
        println!(
            "  the stream started {:.1} ms of probe time after the command was sent",
            (start - origin) * 1e3
        );
    }
    qemu::stream_readings(&r.log, &r.session, a.out.json, Some(origin))
}
