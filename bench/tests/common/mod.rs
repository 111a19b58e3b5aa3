//! What the CLI tests of `probe-bench` share: running the binary and checking its two kinds of
//! outcome (success with output, or a one-line error and a non-zero exit), a scratch directory;
//! and, in [`scan`], what the scan tests share.
#![allow(dead_code)] // each test file uses its own subset

pub mod scan;

use std::path::PathBuf;
use std::process::{Command, Output};

/// The firmware images of both boards are built to one path
/// (`target/thumbv7em-none-eabihf/fw/probe`: `cargo qemu-build` and `cargo fw`), so a test that
/// runs `--qemu` or `--stm32` holds this for as long as it runs: another thread's build of the
/// other board's image would replace its ELF under it (the test binaries themselves run one
/// after another).
pub fn image_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The `probe-bench` binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_probe-bench"))
}

/// Run `cmd`, assert it succeeded (showing its stderr if not) and return its output.
pub fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Run `cmd`, assert it succeeded and that its stdout holds every one of `parts` (showing the
/// stdout if not); return the output.
pub fn run_ok_containing(cmd: &mut Command, parts: &[&str]) -> Output {
    let out = run_ok(cmd);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(parts.iter().all(|p| stdout.contains(p)), "{stdout}");
    out
}

/// Run `cmd`, assert it succeeded, and parse its stdout as one JSON value.
pub fn run_json(cmd: &mut Command) -> serde_json::Value {
    serde_json::from_slice(&run_ok(cmd).stdout).unwrap()
}

/// Run `cmd`, assert it failed with a non-zero exit and a one-line message; return the message.
pub fn run_fails_one_line(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    e
}

/// A test's own scratch directory, `probe-bench-NAME-PID` under the system's temporary
/// directory: made when created, removed with all it holds when dropped.
pub struct Scratch(PathBuf);

impl Scratch {
    pub fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("probe-bench-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
    /// The path of `file` in it.
    pub fn join(&self, file: impl AsRef<std::path::Path>) -> PathBuf {
        self.0.join(file)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
