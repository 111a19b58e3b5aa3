//! `stm32-emu <elf> [--seconds S] [--phantom NAME] [--send T TEXT]...`: run the STM32 image on
//! the emulated NUCLEO-G474RE and write its defmt log (the raw RTT bytes) to stdout, for
//! `defmt-print -e <elf>`. With `--phantom` (a name of hal-sim's phantoms, e.g. `B`) the probe
//! front end is hal-sim's, pressed on that phantom at 30 mN with the bench noise, seed 1 (the
//! QEMU board's power-on scene); without it nothing is wired to the analog pins. `--send T TEXT`
//! puts the command line TEXT on LPUART1 RX at T emulated seconds as the host link's command
//! frame (`docs/protocol.md`; 115 200 Bd, back to back), as the ST-LINK virtual COM port
//! delivers a host's bytes. A run ends after `S` emulated seconds
//! (default 2), or at a fault, which is printed to stderr (exit 2). `--scene T NAME|free-air`
//! moves the probe at T s; `--reset T` pulls NRST at T s (a pin reset: RAM and flash kept).
//! The documented rules the image broke are printed to stderr at the end (exit 3 if any).

use std::io::Write;
use std::process::ExitCode;

use stm32_emu::elf::Elf;
use stm32_emu::probe::HalSimProbe;
use stm32_emu::{rtt, Exit, Machine};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let mut elf_path = None;
    let mut seconds = 2.0f64;
    let mut phantom: Option<String> = None;
    let mut sends: Vec<(f64, String)> = Vec::new();
    let mut scenes: Vec<(f64, String)> = Vec::new();
    let mut resets: Vec<f64> = Vec::new();
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--seconds" => {
                i += 1;
                seconds = number(&args, i);
            }
            "--phantom" => {
                i += 1;
                phantom = Some(word(&args, i));
            }
            "--scene" => {
                scenes.push((number(&args, i + 1), word(&args, i + 2)));
                i += 2;
            }
            "--reset" => {
                i += 1;
                resets.push(number(&args, i));
            }
            "--send" => {
                sends.push((number(&args, i + 1), word(&args, i + 2)));
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
    let scene_of = |name: &str| -> Option<hal_sim::Scene> {
        if name == "free-air" {
            return Some(HalSimProbe::bench_scene(None));
        }
        hal_sim::phantoms::by_name(name).map(|p| HalSimProbe::bench_scene(Some(&p)))
    };
    if let Some(name) = phantom {
        let Some(scene) = scene_of(&name) else {
            eprintln!("stm32-emu: no phantom {name}");
            return ExitCode::from(1);
        };
        m.board_mut().periph.analog = Box::new(HalSimProbe::new(scene, 1));
    }
    resets.sort_by(f64::total_cmp);
    sends.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut sends = sends.into_iter().peekable();
    scenes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut scenes = scenes.into_iter().peekable();
    let wall = std::time::Instant::now();
    let mut out = std::io::stdout().lock();
    let mut code = ExitCode::SUCCESS;
    loop {
        while let Some((t, _)) = sends.peek() {
            if *t > m.seconds() {
                break;
            }
            let (_, text) = sends.next().unwrap();
            if let Err(e) = m.send_command(&text) {
                eprintln!("stm32-emu: {e}");
                return ExitCode::FAILURE;
            }
        }
        while let Some((t, _)) = scenes.peek() {
            if *t > m.seconds() {
                break;
            }
            let (_, name) = scenes.next().unwrap();
            let Some(scene) = scene_of(&name) else {
                eprintln!("stm32-emu: no scene {name}");
                return ExitCode::from(1);
            };
            match HalSimProbe::at_pins(&mut m) {
                Some(p) => p.set_scene(scene),
                None => {
                    eprintln!("stm32-emu: --scene needs --phantom (the probe at the pins)");
                    return ExitCode::from(1);
                }
            }
        }
        if resets.first().is_some_and(|t| *t <= m.seconds()) {
            resets.remove(0);
            if let Err(e) = m.system_reset(stm32_emu::periph::ResetCause::Pin) {
                eprintln!("stm32-emu: reset: {e}");
                return ExitCode::from(2);
            }
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
        if m.seconds() >= seconds {
            break;
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

/// The word at `args[i]` (the usage and exit 1 when it is missing).
fn word(args: &[String], i: usize) -> String {
    args.get(i).cloned().unwrap_or_else(|| usage())
}

fn usage() -> ! {
    eprintln!("usage: stm32-emu <elf> [--seconds S] [--phantom NAME] [--scene T NAME|free-air]... [--send T TEXT]... [--reset T]...");
    std::process::exit(1)
}
