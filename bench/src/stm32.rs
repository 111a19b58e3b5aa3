//! `probe-bench measure --stm32`: the STM32 image (`cargo fw`) on the emulated NUCLEO-G474RE
//! (`emu/`, the `stm32-emu` program, run as a subprocess as `--qemu` runs qemu-system-arm: it
//! is GPL and never linked into the bench).
//!
//! The emulated board starts with an empty store, as a fresh board does, so the bench takes the
//! unit through its user's path first: the air reference in free air, a calibration on phantoms
//! A–E with the image's default method, `calibrate fit`; then the readings on the target. The
//! probe is hal-sim's at bench noise, 30 mN, noise seed 1 (the emulator's scene). The decoded
//! log goes through the same parser as `probe-bench log`, and each reading prints through the
//! same JSON and line as a host reading.

use crate::cmd::measure::Request;
use crate::defmt_log;
use crate::qemu::{self, root, target_dir};
use crate::scene::Target;
use anyhow::{bail, Context, Result};
use hal_sim::NoiseScene;
use pzt_probe::reading::Method;
use std::process::{Command, Stdio};

fn cargo(args: &[&str]) -> Result<()> {
    let status = Command::new(env!("CARGO"))
        .current_dir(root())
        .args(args)
        .status()
        .with_context(|| format!("cannot run cargo {}", args.join(" ")))?;
    if !status.success() {
        bail!("cargo {} failed", args.join(" "));
    }
    Ok(())
}

/// The calibration session's phantoms and their moduli (paper 003), as the user types them.
const REFERENCES: [(&str, &str); 5] = [
    ("A", "157.5"),
    ("B", "279"),
    ("C", "414"),
    ("D", "1146"),
    ("E", "2465"),
];

/// `measure --stm32`.
pub fn measure(request: Request) -> Result<()> {
    let (a, target, method, noise) = (request.args, request.target, request.method, request.noise);
    let Target::Phantom(p) = target else {
        bail!("with --stm32 the target is a --phantom (the emulator's probe scenes are phantoms)");
    };
    if method != Method::Auto || *request.settings != method.default_settings() {
        bail!("with --stm32 the image reads with its default method and settings (auto)");
    }
    if noise != NoiseScene::Bench || a.scene.preload_n != 0.03 || a.scene.loss_tangent.is_some() {
        bail!("with --stm32 the probe is at bench noise, 30 mN, the phantom's own loss");
    }
    if a.out.plot.is_some() || a.profile.is_some() || a.calibration != "unit" {
        bail!(
            "with --stm32 the image calibrates itself on A–E (no --plot, --profile, --calibration)"
        );
    }
    if a.repeat == 0 || a.repeat > 100 {
        bail!("with --stm32 --repeat must be 1 to 100");
    }
    cargo(&["fw", "-q"])?;
    cargo(&["build", "-q", "--release", "-p", "stm32-emu"])?;
    let target_dir = target_dir();
    let elf = target_dir.join("thumbv7em-none-eabihf/fw/probe");
    let emu = target_dir.join("release/stm32-emu");

    // The session's schedule (emulated seconds): the air sweep takes about 10 s, a reading
    // with the default method a fraction of a second.
    let mut args: Vec<String> = vec![
        elf.display().to_string(),
        "--phantom".into(),
        "free-air".into(),
        "--send".into(),
        "1".into(),
        "air".into(),
    ];
    let mut t = 13.0;
    for (name, kpa) in REFERENCES {
        args.extend(["--scene".into(), format!("{t}"), name.into()]);
        args.extend([
            "--send".into(),
            format!("{}", t + 0.5),
            format!("calibrate add {kpa}"),
        ]);
        t += 2.0;
    }
    args.extend(["--send".into(), format!("{t}"), "calibrate fit".into()]);
    t += 3.0;
    args.extend(["--scene".into(), format!("{t}"), p.name.to_string()]);
    for _ in 0..a.repeat {
        t += 1.0;
        args.extend(["--send".into(), format!("{t}"), "measure".into()]);
    }
    args.extend(["--seconds".into(), format!("{}", t + 1.5)]);

    if !a.out.json {
        println!(
            "probe-bench measure --stm32: the STM32 image on the emulated NUCLEO-G474RE, {}",
            target.describe()
        );
        println!(
            "  session: air in free air, calibrate add on A–E, calibrate fit, measure × {}",
            a.repeat
        );
    }
    let mut run = Command::new(&emu)
        .args(&args)
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
    // fatal; anything else non-zero is a fault of the emulated board.
    if !(out.status.success() || out.status.code() == Some(3)) {
        bail!("the emulated board failed: {}", stderr.trim());
    }
    if !a.out.json {
        for l in stderr.lines() {
            println!("  {l}");
        }
    }
    let log = String::from_utf8_lossy(&decoded.stdout).into_owned();
    let session = defmt_log::parse_log(&log);
    if let Some(e) = session.errors.first() {
        bail!("the image's log does not parse: {e}");
    }
    // The calibration references are readings too: the target's are the last `repeat`.
    let n = session.readings.len();
    if n < a.repeat as usize + REFERENCES.len() {
        bail!("the image logged {n} readings:\n{log}");
    }
    qemu::print_readings(&session.readings[n - a.repeat as usize..], a.out.json)
}
