//! What the QEMU tests share: build a firmware binary for `thumbv7em-none-eabihf` (profile `fw`,
//! feature `qemu`), run it on `mps2-an386` with deterministic time and decode its defmt log.
//!
//! Needs `qemu-system-arm`, `defmt-print` and the target; [`require_tools`] fails the test with
//! the install commands when one is missing. A test never passes by skipping.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The decoded log's fields (shared with the emulated STM32 board's tests).
#[allow(dead_code)] // each test uses some of them
#[path = "../support/log_fields.rs"]
pub mod log_fields;

#[path = "../support/image_tools.rs"]
mod image_tools;
use image_tools::{cargo_firmware, defmt_print};

const TARGET: &str = "thumbv7em-none-eabihf";

fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// True when the Rust standard library for [`TARGET`] is installed for the toolchain this
/// crate builds with (`rust-toolchain.toml`).
fn have_target() -> bool {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    Command::new(rustc)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["--print", "target-libdir", "--target", TARGET])
        .stderr(Stdio::null())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
        .is_some_and(|dir| dir.is_dir())
}

/// Panics, naming every missing tool and the command that installs it, unless
/// `qemu-system-arm`, `defmt-print` and the `thumbv7em-none-eabihf` target are all present.
pub fn require_tools() {
    let mut missing = Vec::new();
    if !have("qemu-system-arm") {
        missing.push("qemu-system-arm is not installed: apt-get install qemu-system-arm");
    }
    if !have("defmt-print") {
        missing.push("defmt-print is not installed: cargo install defmt-print --locked");
    }
    // flip-link has no --version of its own (it hands its arguments to the linker).
    let on_path = |tool: &str| {
        std::env::var_os("PATH")
            .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
    };
    if !on_path("flip-link") {
        missing.push(
            "flip-link (the firmware's linker) is not installed: cargo install flip-link --locked",
        );
    }
    if !have_target() {
        missing.push(
            "the thumbv7em-none-eabihf target is not installed: \
             rustup target add thumbv7em-none-eabihf",
        );
    }
    assert!(
        missing.is_empty(),
        "this test runs the firmware image in QEMU and cannot run without its tools \
         (`scripts/test` installs them all through `scripts/setup`):\n  {}",
        missing.join("\n  ")
    );
}

/// Build firmware binary `bin` with feature `qemu` into the tests' own target directory (shared
/// by the QEMU tests, so the second build only links) and return its ELF.
pub fn build_image(bin: &str) -> PathBuf {
    let target_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qemu-image");
    let status = cargo_firmware(
        Path::new(env!("CARGO_MANIFEST_DIR")),
        &target_dir,
        &[
            "build",
            "--profile",
            "fw",
            "--target",
            TARGET,
            "--no-default-features",
            "--features",
            "qemu",
            "--bin",
            bin,
        ],
    );
    assert!(status.success(), "building the QEMU image `{bin}` failed");
    target_dir.join(TARGET).join("fw").join(bin)
}

/// Run `elf` as `scripts/qemu-run` does (`-icount shift=0,sleep=off`: one instruction per
/// virtual nanosecond); panics after `timeout` of wall time. Returns QEMU's success and the
/// decoded log lines (`LEVEL message`).
pub fn run_image(elf: &Path, timeout: Duration) -> (bool, Vec<String>) {
    run_script(elf, timeout, None)
}

/// Check the tools, build the image `bin`, run it with its built-in script and print its log
/// and the wall time taken: QEMU's success and the decoded log lines.
pub fn build_and_run(bin: &str, timeout: Duration) -> (bool, Vec<String>) {
    require_tools();
    let wall = std::time::Instant::now();
    let elf = build_image(bin);
    let (exited_ok, lines) = run_image(&elf, timeout);
    for l in &lines {
        println!("{l}");
    }
    println!("build + run: {:.1} s", wall.elapsed().as_secs_f64());
    (exited_ok, lines)
}

/// [`run_image`] with `script` as the image's command script (its boot command line, as
/// `scripts/qemu-run` passes `QEMU_SCRIPT`), or its built-in one for `None`.
pub fn run_script(elf: &Path, timeout: Duration, script: Option<&str>) -> (bool, Vec<String>) {
    let semihosting = match script {
        Some(s) => format!(
            "enable=on,target=native,arg=script:{}",
            s.replace(',', ",,")
        ),
        None => "enable=on,target=native".to_owned(),
    };
    let mut qemu = Command::new("qemu-system-arm")
        .args([
            "-machine",
            "mps2-an386",
            "-cpu",
            "cortex-m4",
            "-icount",
            "shift=0,sleep=off",
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            "null",
            "-semihosting-config",
            &semihosting,
            "-kernel",
        ])
        .arg(elf)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start qemu-system-arm");
    let frames = qemu.stdout.take().expect("qemu stdout");
    let mut print = defmt_print(elf)
        .stdin(Stdio::from(frames))
        .stdout(Stdio::piped())
        .spawn()
        .expect("start defmt-print");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = qemu.try_wait().expect("wait for qemu") {
            break s;
        }
        if start.elapsed() > timeout {
            let _ = qemu.kill();
            let _ = print.kill();
            panic!("QEMU image did not exit within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut text = String::new();
    print
        .stdout
        .take()
        .expect("defmt-print stdout")
        .read_to_string(&mut text)
        .expect("read decoded log");
    let printed = print.wait().expect("wait for defmt-print");
    assert!(printed.success(), "defmt-print failed: {printed}");
    (status.success(), text.lines().map(str::to_owned).collect())
}
