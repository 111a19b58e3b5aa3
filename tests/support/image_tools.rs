// The firmware image's build and its log's decoder, for the tests that run an image: included (`#[path]`) by
// tests/qemu_support/mod.rs (the QEMU image) and by emu/tests/image.rs (the STM32 image on the
// emulated board).

use std::path::Path;
use std::process::{Command, ExitStatus};

/// `cargo ARGS` in the firmware package `root`, building into `target_dir` with the defmt log at
/// `info`; the target's link flags come from .cargo/config.toml, so an outer RUSTFLAGS (which
/// would replace them) and build target are removed. Cargo's exit status.
pub fn cargo_firmware(root: &Path, target_dir: &Path, args: &[&str]) -> ExitStatus {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    Command::new(cargo)
        .current_dir(root)
        .args(args)
        .env("CARGO_TARGET_DIR", target_dir)
        .env("DEFMT_LOG", "info")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .status()
        .unwrap_or_else(|e| panic!("run cargo {} (scripts/setup): {e}", args.join(" ")))
}

/// `defmt-print` decoding the defmt frames of `elf` into `LEVEL message` lines (its input and
/// output to be wired by the caller).
pub fn defmt_print(elf: &Path) -> Command {
    let mut c = Command::new("defmt-print");
    c.arg("-e").arg(elf).args(["--log-format", "{L} {s}"]);
    c
}
