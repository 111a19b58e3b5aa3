//! `stm32-emu <elf> [--seconds T] [--phantom NAME] [--seed N] [--send T TEXT]...`: run the STM32
//! image on the emulated NUCLEO-G474RE and write its defmt log (the raw RTT bytes) to stdout,
//! for `defmt-print -e <elf>`. With `--phantom` (a scene name, `HalSimProbe::scene_named`: a
//! phantom of hal-sim's such as `B`, `B@8` for B pressed at 8 mN, `free-air`, `weight:10` for
//! 10 g resting on the tip) the probe front end and its load cell are hal-sim's, at bench
//! noise, pressed at 30 mN unless the name says otherwise, noise seed `N` (default 1; the QEMU
//! board's power-on scene); without it nothing is wired to the pins.
//!
//! Events, in the order given, each after the one before: `--send T TEXT` puts the command line
//! TEXT on LPUART1 RX as the host link's command frame (`docs/protocol.md`; 115 200 Bd, back to
//! back), as the ST-LINK virtual COM port delivers a host's bytes; `--scene T NAME` moves the
//! probe to that scene; `--reset T` pulls NRST (a pin reset: RAM and flash kept). A time `T` is
//! emulated seconds since power-on, `+D` D seconds after the event before, or `done+D` D
//! seconds after the image replied to the last command sent (its `Reply` frame on LPUART1 TX:
//! the command served, with everything it caused, or refused; a reset ends the wait). Each
//! event is printed to stderr as it happens, with the emulated time and the probe's time (its
//! sample periods since the drive started: the firmware's sample clock).
//! `--seconds T` ends the run (default 2; after the last event), `--limit S` stops a run still
//! waiting at S emulated seconds (default 3600; exit 4). A fault is printed to stderr (exit 2).
//! The documented rules the image broke are printed to stderr at the end (exit 3 if any).
//!
//! With `STM32_EMU_PROFILE=FILE` in the environment the instructions executed from the last
//! event to the end are written to FILE, a line `0x<address> <count>` per instruction address
//! (`scripts/profile-stm32` names their functions).

use std::io::Write;
use std::process::ExitCode;

use stm32_emu::elf::Elf;
use stm32_emu::probe::HalSimProbe;
use stm32_emu::{rtt, Exit, Machine};

/// When an event happens (the time forms of the command line).
#[derive(Clone, Copy, Debug)]
enum When {
    /// At this many emulated seconds (`T`).
    At(f64),
    /// This many seconds after the event before it (`+D`).
    After(f64),
    /// This many seconds after the image replied to the last command sent before it (`done+D`).
    Done(f64),
}

/// What happens.
#[derive(Clone, Debug)]
enum What {
    Send(String),
    Scene(String),
    Reset,
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let mut elf_path = None;
    let mut end = When::At(2.0);
    let mut limit = 3600.0f64;
    let mut phantom: Option<String> = None;
    let mut seed = 1u64;
    let mut events: Vec<(When, What)> = Vec::new();
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--seconds" => {
                i += 1;
                end = when(&args, i);
            }
            "--limit" => {
                i += 1;
                limit = number(&args, i);
            }
            "--phantom" => {
                i += 1;
                phantom = Some(word(&args, i));
            }
            "--seed" => {
                i += 1;
                seed = word(&args, i).parse().unwrap_or_else(|_| usage());
            }
            "--scene" => {
                events.push((when(&args, i + 1), What::Scene(word(&args, i + 2))));
                i += 2;
            }
            "--reset" => {
                i += 1;
                events.push((when(&args, i), What::Reset));
            }
            "--send" => {
                events.push((when(&args, i + 1), What::Send(word(&args, i + 2))));
                i += 2;
            }
            s if !s.starts_with('-') && elf_path.is_none() => elf_path = Some(s.to_string()),
            _ => usage(),
        }
        i += 1;
    }
    let elf_path = elf_path.unwrap_or_else(|| usage());
    let bytes = std::fs::read(&elf_path).unwrap_or_else(|e| {
        eprintln!("stm32-emu: {elf_path}: {e}");
        std::process::exit(1)
    });
    let elf = Elf::parse(&bytes).unwrap_or_else(|e| {
        eprintln!("stm32-emu: {elf_path}: {e}");
        std::process::exit(1)
    });
    let Some(rtt_cb) = elf.symbol("_SEGGER_RTT") else {
        eprintln!("stm32-emu: {elf_path}: no _SEGGER_RTT symbol (not a defmt-rtt image)");
        return ExitCode::from(1);
    };
    let mut m = Machine::new(&elf).unwrap_or_else(|e| {
        eprintln!("stm32-emu: {e}");
        std::process::exit(1)
    });
    let scene_of = HalSimProbe::scene_named;
    if let Some(name) = phantom {
        let Some(scene) = scene_of(&name) else {
            eprintln!("stm32-emu: no scene {name}");
            return ExitCode::from(1);
        };
        m.board_mut().periph.wiring = Box::new(HalSimProbe::new(scene, seed));
    }
    for (_, what) in &events {
        if let What::Scene(name) = what {
            if scene_of(name).is_none() {
                eprintln!("stm32-emu: no scene {name}");
                return ExitCode::from(1);
            }
        }
    }
    let mut events = events.into_iter().peekable();
    // The time of the last event, and the time the image replied to the last command (a reset
    // ends the wait for a reply: the command died with the core).
    let mut last_event = 0.0f64;
    let mut served_at: Option<f64> = Some(0.0);
    let wall = std::time::Instant::now();
    let profile = std::env::var_os("STM32_EMU_PROFILE");
    if events.peek().is_none() && profile.is_some() {
        m.board_mut().block_runs = Some(Default::default());
    }
    let mut out = std::io::stdout().lock();
    let mut code = ExitCode::SUCCESS;
    loop {
        let now = m.seconds();
        if served_at.is_none() && m.last_reply() >= Some(m.last_command()) {
            served_at = Some(now);
        }
        let due = |w: When, last_event: f64, served_at: Option<f64>| match w {
            When::At(t) => Some(t),
            When::After(d) => Some(last_event + d),
            When::Done(d) => served_at.map(|s| s + d),
        };
        while let Some((w, _)) = events.peek() {
            if !due(*w, last_event, served_at).is_some_and(|t| t <= now) {
                break;
            }
            let (_, what) = events.next().unwrap();
            last_event = now;
            if events.peek().is_none() && profile.is_some() {
                m.board_mut().block_runs = Some(Default::default());
            }
            let probe_s = HalSimProbe::at_pins(&mut m).map_or(f64::NAN, |p| p.probe().time_s());
            eprintln!("stm32-emu: event at {now:.6} s (probe time {probe_s:.6} s): {what:?}");
            match what {
                What::Send(text) => {
                    if let Err(e) = m.send_command(&text) {
                        eprintln!("stm32-emu: {e}");
                        return ExitCode::FAILURE;
                    }
                    served_at = None;
                }
                What::Scene(name) => match HalSimProbe::at_pins(&mut m) {
                    Some(p) => p.set_scene(scene_of(&name).unwrap()),
                    None => {
                        eprintln!("stm32-emu: --scene needs --phantom (the probe at the pins)");
                        return ExitCode::from(1);
                    }
                },
                What::Reset => {
                    if let Err(e) = m.system_reset(stm32_emu::periph::ResetCause::Pin) {
                        eprintln!("stm32-emu: reset: {e}");
                        return ExitCode::from(2);
                    }
                    served_at = Some(now);
                }
            }
        }
        if events.peek().is_none() && due(end, last_event, served_at).is_some_and(|t| t <= now) {
            break;
        }
        if now >= limit {
            eprintln!(
                "stm32-emu: the run reached its limit of {limit} s with events or a reply to command {} still awaited",
                m.last_command()
            );
            code = ExitCode::from(4);
            break;
        }
        let until = m.cycles() + rtt::DRAIN_CYCLES;
        let exit = m.run_until(until);
        if std::env::var_os("STM32_EMU_DEBUG").is_some() {
            eprintln!(
                "debug: cycle {} pc {:#010x} ipsr {}",
                m.cycles(),
                m.register(unicorn_engine::RegisterARM::PC),
                m.register(unicorn_engine::RegisterARM::IPSR)
            );
        }
        if let Ok(b) = rtt::drain(&mut m, rtt_cb) {
            out.write_all(&b).ok();
        }
        match exit {
            Exit::Limit => {}
            Exit::Fault(f) => {
                let b = m.board();
                eprintln!(
                    "stm32-emu: fault at {:.6} s (cycle {}): {f}",
                    b.seconds(),
                    b.now
                );
                code = ExitCode::from(2);
                break;
            }
        }
    }
    out.flush().ok();
    let b = m.board();
    eprintln!(
        "stm32-emu: {:.6} s emulated ({} cycles, {} executed, {} resets) in {:.3} s wall",
        b.seconds(),
        b.now,
        b.executed,
        m.resets,
        wall.elapsed().as_secs_f64()
    );
    if let Some(path) = &profile {
        let lines: String = b
            .profile()
            .iter()
            .map(|(a, n)| format!("{a:#010x} {n}\n"))
            .collect();
        if let Err(e) = std::fs::write(path, lines) {
            eprintln!("stm32-emu: {}: {e}", path.to_string_lossy());
            code = ExitCode::FAILURE;
        }
    }
    for v in &b.periph.violations {
        eprintln!("stm32-emu: rule broken at cycle {}: {}", v.at, v.rule);
    }
    if !b.periph.violations.is_empty() && code == ExitCode::SUCCESS {
        code = ExitCode::from(3);
    }
    code
}

/// The number at `args[i]` (the usage and exit 1 when it is missing or not a number).
fn number(args: &[String], i: usize) -> f64 {
    args.get(i)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| usage())
}

/// The time at `args[i]`: `T` (absolute emulated seconds), `+D` (after the event before),
/// `done+D` (after the reply to the last command sent); the usage and exit 1 otherwise.
fn when(args: &[String], i: usize) -> When {
    let w = word(args, i);
    let parse = |s: &str| {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .unwrap_or_else(|| usage())
    };
    if let Some(d) = w.strip_prefix("done+") {
        When::Done(parse(d))
    } else if let Some(d) = w.strip_prefix('+') {
        When::After(parse(d))
    } else {
        When::At(parse(&w))
    }
}

/// The word at `args[i]` (the usage and exit 1 when it is missing).
fn word(args: &[String], i: usize) -> String {
    args.get(i).cloned().unwrap_or_else(|| usage())
}

fn usage() -> ! {
    eprintln!("usage: stm32-emu <elf> [--seconds T] [--limit S] [--phantom NAME] [--seed N] [--scene T NAME]... [--send T TEXT]... [--reset T]...\n  T: seconds | +seconds (after the event before) | done+seconds (after the reply to the last command)");
    std::process::exit(1)
}
