//! `stm32-emu <elf> [--seconds S]`: run the STM32 image on the emulated NUCLEO-G474RE and write
//! its defmt log (the raw RTT bytes) to stdout, for `defmt-print -e <elf>`. A run ends after
//! `S` emulated seconds (default 2), or at a fault, which is printed to stderr (exit 2).
//! The documented rules the image broke are printed to stderr at the end (exit 3 if any).

use std::io::Write;
use std::process::ExitCode;

use stm32_emu::elf::Elf;
use stm32_emu::{rtt, Exit, Machine};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let mut elf_path = None;
    let mut seconds = 2.0f64;
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--seconds" => {
                i += 1;
                seconds = args
                    .get(i)
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| usage());
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
    let wall = std::time::Instant::now();
    let mut out = std::io::stdout().lock();
    let mut code = ExitCode::SUCCESS;
    // Drain RTT every emulated millisecond at 170 MHz (the buffer is 1 KiB).
    let slice = 170_000u64;
    loop {
        let until = m.cycles() + slice;
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

fn usage() -> ! {
    eprintln!("usage: stm32-emu <elf> [--seconds S]");
    std::process::exit(1)
}
