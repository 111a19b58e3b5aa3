//! `probe-bench`: the bench engineer's tool for the resonant PZT hardness probe.
//!
//! It runs the firmware's own measurement core on the simulated probe (`hal-sim`). Units are in
//! every option name: Hz, s, V, N, kPa, A/sqrt(Hz).

use clap::{Parser, Subcommand};
use probe_bench::cmd;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "probe-bench",
    version,
    about = "Bench tool of the resonant PZT hardness probe (runs the firmware's measurement core on the simulated probe)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Press the simulated probe at 30 mN onto tissue, sweep, estimate the resonance and map it
    /// to elastic modulus, as the firmware does.
    Measure(cmd::measure::MeasureArgs),
    /// Calibrate the simulated unit on phantoms A–E (as paper 003 did) and write the curve.
    Calibrate(cmd::calibrate::CalibrateArgs),
    /// Print the simulator's resonance against the paper's experimental curve f_e(E).
    Physics(cmd::physics::PhysicsArgs),
    /// List the phantoms of the source papers.
    Phantoms,
    /// Speed against accuracy of every method and knob setting on the simulated probe, charted
    /// against the Cramér–Rao bound (writes docs/speed-accuracy.*).
    Pareto(cmd::pareto::ParetoArgs),
    /// Every method through the scene catalogue where methods break: the stability map
    /// (writes docs/stability.{csv,svg,png}).
    Stability(cmd::stability::StabilityArgs),
    /// The error budget of a reading: what it is off by, by source, and the measured coverage
    /// of the σ it reports (writes docs/accuracy.{md,csv,svg,png}).
    Accuracy(cmd::accuracy::AccuracyArgs),
    /// Analyse a bench capture (impedance analyser or DAQ CSV) with the firmware's estimator and
    /// calibration.
    Analyze(cmd::analyze::AnalyzeArgs),
    /// Scan a simulated phantom with a lump on a grid (press at 30 mN, read, lift, move) and map
    /// its stiffness with the lump found marked.
    Scan(cmd::scan::ScanArgs),
    /// The firmware's power-on self-test of the analog chain on the simulated probe, with a
    /// fault if asked (`--fault open|short|dac-stuck|adc-rail`); a failed test exits non-zero.
    Selftest(cmd::selftest::SelftestArgs),
    /// Continuous reading: one fast acquisition, then the resonance followed without stopping
    /// the drive, a numbered, time-stamped reading per segment (with a step in stiffness, a
    /// lift-off and a new contact if asked).
    Stream(cmd::stream::StreamArgs),
    /// Read the firmware's decoded defmt log: the readings as a table, the sweeps and the
    /// reading history as a plot.
    Log(cmd::log::LogArgs),
    /// Talk to a probe over its host link (docs/protocol.md): `qemu` (the firmware image in
    /// QEMU on a scene) or a serial port; a console, or `-c <command>`… run to their replies.
    Connect(cmd::connect::ConnectArgs),
    /// Rewrite the golden captures of tests/data (for maintainers).
    #[command(hide = true)]
    GenerateCaptures(cmd::generate::GenerateArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Measure(a) => cmd::measure::run(a),
        Cmd::Calibrate(a) => cmd::calibrate::run(a),
        Cmd::Physics(a) => cmd::physics::run(a),
        Cmd::Pareto(a) => cmd::pareto::run(a),
        Cmd::Stability(a) => cmd::stability::run(a),
        Cmd::Phantoms => {
            cmd::physics::list_phantoms();
            Ok(())
        }
        Cmd::Accuracy(a) => cmd::accuracy::run(a),
        Cmd::Analyze(a) => cmd::analyze::run(a),
        Cmd::GenerateCaptures(a) => cmd::generate::run(a),
        Cmd::Scan(a) => cmd::scan::run(a),
        Cmd::Log(a) => cmd::log::run(a),
        Cmd::Stream(a) => cmd::stream::run(a),
        Cmd::Selftest(a) => cmd::selftest::run(a),
        Cmd::Connect(a) => cmd::connect::run(a),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("probe-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}
