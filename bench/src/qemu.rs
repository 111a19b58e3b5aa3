//! `probe-bench measure --qemu`: the firmware image in QEMU on the scene of a host reading.
//!
//! The scene, noise, seed, method and settings become the image's command script (`sim ...`
//! lines for the simulated probe, then the firmware's own commands, `src/board/sim_script.rs`),
//! passed on its boot command line by `scripts/qemu-run`; the image's defmt log is parsed by
//! the same parser as `probe-bench log`, and each logged reading prints through the same JSON
//! and line as a host reading.

use crate::cmd::measure::Request;
use crate::defmt_log;
use crate::report;
use crate::scene::{SceneArgs, Target};
use anyhow::{bail, Context, Result};
use hal_sim::NoiseScene;
use pzt_probe::instrument::command::SettingsLine;
use std::path::PathBuf;
use std::process::Command;

/// The workspace root (the firmware package).
pub(crate) fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The target directory cargo builds into from the workspace root (`CARGO_TARGET_DIR`, else
/// `target/`).
pub(crate) fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

/// The `sim` lines that put the simulated probe on `target` as `scene` presses it (its preload
/// and the tissue's loss tangent) under `noise`.
pub fn scene_lines(target: &Target, scene: &SceneArgs, noise: NoiseScene) -> Vec<String> {
    let on = match target {
        Target::Phantom(p) => format!("sim phantom {}", p.name),
        Target::Modulus(e) => format!("sim modulus {e}"),
        Target::FreeAir => "sim free-air".to_owned(),
    };
    let noise = match noise {
        NoiseScene::Quiet => "quiet".to_owned(),
        NoiseScene::Paper => "paper".to_owned(),
        NoiseScene::Bench => "bench".to_owned(),
        NoiseScene::Density(d) => format!("{d:e}"),
    };
    let mut lines = vec![
        on,
        format!("sim preload {}", scene.preload_n),
        format!("sim noise {noise}"),
    ];
    if let Some(t) = scene.loss_tangent {
        lines.push(format!("sim loss {t}"));
    }
    lines
}

/// `cargo ARGS` in the workspace root, under the workspace's toolchain: the cargo that runs
/// this program (`CARGO`, set by `cargo run` together with its toolchain), else the `cargo` on
/// `PATH`, which under rustup takes the workspace's `rust-toolchain.toml` for every compiler it
/// starts. (The cargo this program was built with, called directly, would leave each compiler
/// to rustup's choice in the package it compiles, and a dependency's own toolchain file —
/// fugit's pins a release — would then pick a toolchain that may not be installed.)
pub(crate) fn workspace_cargo(args: &[&str]) -> Result<()> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(root())
        .args(args)
        .status()
        .with_context(|| format!("cannot run cargo {}", args.join(" ")))?;
    if !status.success() {
        bail!(
            "cargo {} failed (is the thumbv7em-none-eabihf target installed? scripts/setup)",
            args.join(" ")
        );
    }
    Ok(())
}

/// Build the QEMU image (`cargo qemu-build`): its path.
pub fn build_image() -> Result<PathBuf> {
    workspace_cargo(&["qemu-build", "-q"])?;
    Ok(target_dir().join("thumbv7em-none-eabihf/fw/probe"))
}

/// Build the QEMU image and run `script` on it; the decoded log.
pub fn run_script(script: &str) -> Result<String> {
    let elf = build_image()?;
    let out = Command::new(root().join("scripts/qemu-run"))
        .arg(&elf)
        .env("QEMU_SCRIPT", script)
        .output()
        .context("cannot run scripts/qemu-run")?;
    let log = String::from_utf8_lossy(&out.stdout).into_owned();
    if !log.contains("exit ok=") {
        bail!(
            "the QEMU image did not finish: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(log)
}

/// `probe-bench <command> --qemu`: `lines` as the image's script on `target` (the header and
/// the script printed unless `json`); the decoded log and its parse, which must be clean.
fn run_lines(
    command: &str,
    target: &Target,
    lines: &[String],
    json: bool,
) -> Result<(String, defmt_log::Session)> {
    let script = lines.join(";");
    if !json {
        println!(
            "probe-bench {command} --qemu: the firmware image on {}",
            target.describe()
        );
        println!("  script: {script}");
    }
    let log = run_script(&script)?;
    let session = defmt_log::parse_log(&log);
    if let Some(e) = session.errors.first() {
        bail!("the image's log does not parse: {e}");
    }
    Ok((log, session))
}

/// The `stream` options an image can take (`board`: `--qemu` or `--stm32`, for the message):
/// the tracker's segment and segments a plan (the others the default's), no knocks, a lift-off as a step, the command's range of seconds.
pub(crate) fn check_stream_args(a: &crate::cmd::stream::StreamArgs, board: &str) -> Result<()> {
    if !a.tracker.is_image_settable() {
        bail!("with {board} the image's tracker takes --segment-s and --plan-segments only (no --drift-hz-s, --dither, --q-prior)");
    }
    if a.knocks_hz.is_some() {
        bail!("with {board} there are no knocks (the image's board has no knock)");
    }
    if a.lift.lift_off_ramp_s != 0.0 {
        bail!("with {board} the lift-off is a step (no --lift-off-ramp-s)");
    }
    let (lo, hi) = pzt_probe::instrument::command::STREAM_SECONDS;
    if !(lo as f64..=hi as f64).contains(&a.seconds) {
        bail!("with {board} --seconds must be in [{lo}, {hi}]");
    }
    Ok(())
}

/// The image's `stream` command line for these options (`check_stream_args` passed).
pub(crate) fn stream_line(a: &crate::cmd::stream::StreamArgs) -> String {
    let t = &a.tracker;
    // The segment as the image's `f32` takes it (the shortest text that reads back to it).
    format!(
        "stream {} {} {}",
        a.seconds, t.segment_s as f32, t.plan_segments
    )
}

/// The one stream an image logged, its readings with `t_s` from `origin` (probe time, s: when
/// the scene's clock started) or, without one, from the stream's start (as the host's stream,
/// which starts at probe time 0); the firmware's own counts printed unless `json`.
pub(crate) fn stream_readings(
    log: &str,
    session: &defmt_log::Session,
    json: bool,
    origin: Option<f32>,
) -> Result<Vec<pzt_probe::instrument::continuous::StreamReading>> {
    use pzt_probe::instrument::continuous::StreamReading;
    let [x] = session.streams.as_slice() else {
        bail!(
            "the image logged {} streams, not one:\n{log}",
            session.streams.len()
        );
    };
    let end = x
        .end
        .as_ref()
        .context("the image's stream has no end line")?;
    let start = origin.or(end.start_s).unwrap_or(0.0);
    if !json {
        println!(
            "  the firmware: {} readings, {} ok, {} dropped (report channel full), most work from a window to the next plan {} (the image's counter unit: instructions in QEMU, cycles on the STM32)",
            end.readings, end.ok, end.dropped, end.plan_work
        );
    }
    x.readings
        .iter()
        .map(|r| {
            Ok(StreamReading {
                seq: r.seq,
                t_s: pzt_probe::Seconds(r.t_s - start),
                locked: r.locked,
                reading: r
                    .reading
                    .to_reading()
                    .with_context(|| format!("unknown status or method in {r:?}"))?,
            })
        })
        .collect()
}

/// `stream --qemu`: the image's `stream` command on the scene and its events (`sim` lines,
/// which count from the scene's start, 10 ms before the stream's), its readings with `t_s`
/// from the stream's start (as the host's stream, which starts at probe time 0).
pub fn stream(
    a: &crate::cmd::stream::StreamArgs,
    target: &Target,
    noise: NoiseScene,
) -> Result<Vec<pzt_probe::instrument::continuous::StreamReading>> {
    check_stream_args(a, "--qemu")?;
    let mut lines = scene_lines(target, &a.scene, noise);
    lines.push(format!("sim seed {}", a.noise.seed));
    if let (Some(p), Some(t)) = (&a.step.step_to, a.step.step_at_s) {
        lines.push(format!("sim step {p} {t}"));
    }
    if let Some(t) = a.lift.lift_off_at_s {
        lines.push(format!("sim lift-off {t}"));
    }
    if let (Some(f), Some(t)) = (a.press.press_to, a.press.press_at_s) {
        // The image's press is a step.
        lines.push(format!("sim press {f} {t}"));
    }
    if let Some(t) = a.lift.touch_at_s {
        match target {
            Target::Phantom(p) => lines.push(format!("sim step {} {t}", p.name)),
            _ => bail!("with --qemu --touch-at-s needs a --phantom"),
        }
    }
    lines.push(stream_line(a));
    let (log, session) = run_lines("stream", target, &lines, a.out.json)?;
    stream_readings(&log, &session, a.out.json, None)
}

/// `measure --qemu`.
pub fn measure(request: Request) -> Result<()> {
    let (a, method, settings) = (request.args, request.method, request.settings);
    if a.out.plot.is_some() {
        bail!("--plot is not available with --qemu (use probe-bench log --plot on the log)");
    }
    if a.profile.is_some() || a.calibration != "unit" {
        bail!(
            "with --qemu the image reads with its own factory profile (src/board/sim_factory.rs)"
        );
    }
    let mut lines = scene_lines(request.target, &a.scene, request.noise);
    lines.push(format!("method {}", method.name()));
    if *settings != method.default_settings() {
        match SettingsLine::of(settings) {
            Some(c) => lines.push(c.to_string()),
            None => bail!(
                "{} settings other than its defaults cannot be passed to the image",
                method.name()
            ),
        }
    }
    for k in 0..a.repeat {
        lines.push(format!("sim seed {}", a.seed + k as u64));
        lines.push("measure".to_owned());
    }
    let (log, session) = run_lines("measure", request.target, &lines, a.out.json)?;
    if session.readings.len() != a.repeat as usize {
        bail!(
            "the image logged {} readings of {}:\n{log}",
            session.readings.len(),
            a.repeat
        );
    }
    print_readings(&session.readings, a.out.json)
}

/// Each reading an image logged, printed through the same JSON (`json`) or line as a host
/// reading; an error at a status or method the host does not know.
pub(crate) fn print_readings(readings: &[defmt_log::LoggedReading], json: bool) -> Result<()> {
    for r in readings {
        let r = r
            .to_reading()
            .with_context(|| format!("unknown status or method in {r:?}"))?;
        if json {
            println!("{}", report::reading_json(&r));
        } else {
            println!("{}", report::reading_line(&r));
        }
    }
    Ok(())
}
