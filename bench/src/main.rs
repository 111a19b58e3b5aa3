//! `probe-bench`: the bench engineer's tool for the resonant PZT hardness probe.
//!
//! It runs the firmware's own measurement core on the simulated probe (`hal-sim`). Units are in
//! every option name: Hz, s, V, N, kPa, A/sqrt(Hz).

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use hal_sim::{phantoms, NoiseScene, Scene};
use indicatif::{ProgressBar, ProgressStyle};
use probe_bench::calfile::{self, CalFile};
use probe_bench::scene::{layer_names, noise_name, parse_noise, Target};
use probe_bench::{plot, report};
use pzt_probe::board::sim::{self as simboard, CALIBRATION_PHANTOMS};
use pzt_probe::calibration::PowerLaw;
use pzt_probe::sweep::{SweepPoint, SweepSettings};
use pzt_probe::{Hz, Method, Seconds, Volts};
use std::path::PathBuf;
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
    Measure(MeasureArgs),
    /// Calibrate the simulated unit on phantoms A–E (as paper 003 did) and write the curve.
    Calibrate(CalibrateArgs),
    /// Print the simulator's resonance against the paper's experimental curve f_e(E).
    Physics(PhysicsArgs),
    /// List the phantoms of the source papers.
    Phantoms,
}

#[derive(Args, Clone)]
struct MethodArgs {
    /// Resonance method: `paper` (|Z| minimum, 200–300 Hz in 1 Hz steps) or `sweep-g`
    /// (conductance maximum).
    #[arg(long, default_value = "sweep-g")]
    method: String,
    /// Sweep start frequency, Hz (default: the method's).
    #[arg(long)]
    start_hz: Option<f32>,
    /// Sweep stop frequency, Hz.
    #[arg(long)]
    stop_hz: Option<f32>,
    /// Sweep step, Hz.
    #[arg(long)]
    step_hz: Option<f32>,
    /// Settling time after each frequency step, s.
    #[arg(long)]
    settle_s: Option<f32>,
    /// Integration time per point, s (rounded up to whole drive cycles).
    #[arg(long)]
    integrate_s: Option<f32>,
    /// Drive amplitude at the PZT, V (peak).
    #[arg(long)]
    drive_v: Option<f32>,
    /// Front-end noise: `quiet`, `paper`, `bench`, or a current-noise density in A/sqrt(Hz).
    #[arg(long, default_value = "bench")]
    noise: String,
}

impl MethodArgs {
    fn method(&self) -> Result<Method> {
        Method::from_name(&self.method).with_context(|| {
            let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
            format!(
                "unknown method `{}` (known: {})",
                self.method,
                names.join(", ")
            )
        })
    }
    fn settings(&self, method: Method) -> SweepSettings {
        let d = method.default_sweep();
        SweepSettings {
            start: self.start_hz.map(Hz).unwrap_or(d.start),
            stop: self.stop_hz.map(Hz).unwrap_or(d.stop),
            step: self.step_hz.map(Hz).unwrap_or(d.step),
            settle: self.settle_s.map(Seconds).unwrap_or(d.settle),
            integrate: self.integrate_s.map(Seconds).unwrap_or(d.integrate),
            drive: self.drive_v.map(Volts).unwrap_or(d.drive),
        }
    }
}

#[derive(Args)]
struct MeasureArgs {
    /// Phantom to press on: A–E (paper 003), ecoflex-00-10, ecoflex-00-30, dragon-skin-20.
    #[arg(long)]
    phantom: Option<String>,
    /// Tissue of this small-strain Young's modulus, kPa.
    #[arg(long)]
    modulus_kpa: Option<f64>,
    /// No tissue: the probe in free air.
    #[arg(long)]
    free_air: bool,
    /// Contact preload, N.
    #[arg(long, default_value_t = 0.030)]
    preload_n: f64,
    /// Seed of the simulated noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Readings to take (seeds seed, seed+1, ...); more than one prints their statistics.
    #[arg(long, default_value_t = 1)]
    repeat: u32,
    #[command(flatten)]
    m: MethodArgs,
    /// Calibration: `unit` (fit the simulated unit on A–E × 20 with the same method, settings
    /// and noise first), `paper-experiment` (eq. 5), `paper-simulation` (eq. 4), or a file
    /// written by `probe-bench calibrate`.
    #[arg(long, default_value = "unit")]
    calibration: String,
    /// Print one JSON object per reading instead of the bench log.
    #[arg(long)]
    json: bool,
    /// Write an SVG plot of the (first) admittance sweep with the estimate marked.
    #[arg(long)]
    plot: Option<PathBuf>,
}

#[derive(Args)]
struct CalibrateArgs {
    #[command(flatten)]
    m: MethodArgs,
    /// Readings per phantom (the paper took 20).
    #[arg(long, default_value_t = 20)]
    repeats: usize,
    /// First noise seed.
    #[arg(long, default_value_t = 1000)]
    seed: u64,
    /// Output calibration file (JSON).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct PhysicsArgs {
    /// Print a Markdown table (as in docs/physics.md).
    #[arg(long)]
    markdown: bool,
}

fn progress(n: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(n);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}

fn calibrate_unit(
    method: Method,
    settings: &SweepSettings,
    noise: NoiseScene,
    repeats: usize,
    seed: u64,
) -> Result<PowerLaw> {
    let repeats = repeats.clamp(1, simboard::MAX_REPEATS);
    let pb = progress(
        (CALIBRATION_PHANTOMS.len() * repeats) as u64,
        "calibrating on A–E",
    );
    // Calibrate phantom by phantom so the bar moves; the fit itself is the library's.
    let mut data = Vec::new();
    let cal = PowerLaw::paper_experiment();
    for (pi, p) in CALIBRATION_PHANTOMS.iter().enumerate() {
        let scene = Scene::on_phantom(p).with_noise(noise);
        for r in 0..repeats {
            let s = seed + (pi * simboard::MAX_REPEATS + r) as u64;
            let reading = simboard::read(&scene, s, method, settings, &cal, |_| {})
                .map_err(|e| anyhow::anyhow!("reference reading failed: {e:?}"))?;
            if let (Some(f), Some(sf)) = (reading.resonance, reading.resonance_sigma) {
                data.push((p.modulus_kpa, f.0 as f64, (sf.0 as f64).max(1e-4)));
            }
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    PowerLaw::fit(&data).map_err(|e| anyhow::anyhow!("calibration fit failed: {e:?}"))
}

fn measure(a: MeasureArgs) -> Result<()> {
    let method = a.m.method()?;
    let settings = a.m.settings(method);
    let noise = parse_noise(&a.m.noise)?;
    let target = Target::from_options(a.phantom.as_deref(), a.modulus_kpa, a.free_air)?;
    if !(a.preload_n.is_finite() && a.preload_n > 0.0 && a.preload_n <= 1.0) {
        bail!("preload {} N is out of range (0 to 1 N)", a.preload_n);
    }
    if a.repeat == 0 || a.repeat > 10_000 {
        bail!("--repeat must be 1 to 10000");
    }
    // Validate the settings before any work (the firmware does the same).
    let scene = target.scene().with_noise(noise).with_preload_n(a.preload_n);
    let scale = simboard::scale_of(&scene.front_end);
    settings
        .validate(&scale)
        .map_err(|e| anyhow::anyhow!("bad sweep settings: {e}"))?;
    let cal = match a.calibration.as_str() {
        "unit" => calibrate_unit(method, &settings, noise, 20, 1000)?,
        name => match calfile::builtin(name) {
            Some(p) => p,
            None => CalFile::load(std::path::Path::new(name))?,
        },
    };
    if !a.json {
        println!(
            "probe-bench measure: simulated probe on {}",
            target.describe()
        );
        println!(
            "  preload {:.0} mN, noise {}, layers: {}",
            a.preload_n * 1e3,
            noise_name(noise),
            layer_names(&scene)
        );
        println!(
            "  simulator ground truth: resonance {:.3} Hz, Q {:.2}",
            scene.resonance_hz(),
            scene.q()
        );
        println!(
            "  calibration {}: {}",
            if a.calibration == "unit" {
                "unit (fitted on A–E × 20)"
            } else {
                &a.calibration
            },
            calfile::describe(&cal)
        );
        println!(
            "  sweep {}–{} Hz step {} Hz, settle {} ms, integrate {} ms, drive {} V, method {}",
            settings.start.0,
            settings.stop.0,
            settings.step.0,
            settings.settle.0 * 1e3,
            settings.integrate.0 * 1e3,
            settings.drive.0,
            method.name()
        );
    }
    let pb = (a.repeat > 1 && !a.json).then(|| progress(a.repeat as u64, "measuring"));
    let mut moduli = Vec::new();
    let mut first_points: Vec<SweepPoint> = Vec::new();
    let mut first_resonance = None;
    for k in 0..a.repeat {
        let mut pts = Vec::new();
        let reading = simboard::read(&scene, a.seed + k as u64, method, &settings, &cal, |p| {
            if k == 0 {
                pts.push(*p)
            }
        })
        .map_err(|e| anyhow::anyhow!("reading failed: {e:?}"))?;
        if k == 0 {
            first_points = pts;
            first_resonance = reading.resonance.map(|f| f.0);
        }
        if a.json {
            println!("{}", report::reading_json(&reading));
        } else if a.repeat == 1 {
            println!("{}", report::reading_line(&reading));
        }
        if let Some(e) = reading.modulus {
            moduli.push(e.0 as f64);
        }
        if let Some(pb) = &pb {
            pb.inc(1);
        }
    }
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    if a.repeat > 1 && !a.json {
        let n = moduli.len();
        println!("  {n} of {} readings ok", a.repeat);
        if n >= 2 {
            let mean = moduli.iter().sum::<f64>() / n as f64;
            let sd =
                (moduli.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0)).sqrt();
            print!("  modulus mean {mean:.2} kPa, sd {sd:.3} kPa");
            if let Some(t) = target.modulus_kpa() {
                print!(", error of the mean {:+.2} %", 100.0 * (mean - t) / t);
            }
            println!();
        }
    }
    if let Some(path) = &a.plot {
        let title = format!("{} — {}", target.describe(), method.name());
        plot::sweep_svg(path, &title, &first_points, first_resonance)?;
        if !a.json {
            println!("  plot: {}", path.display());
        }
    }
    Ok(())
}

fn calibrate(a: CalibrateArgs) -> Result<()> {
    let method = a.m.method()?;
    let settings = a.m.settings(method);
    let noise = parse_noise(&a.m.noise)?;
    settings
        .validate(&simboard::scale_of(&hal_sim::FrontEnd::default()))
        .map_err(|e| anyhow::anyhow!("bad sweep settings: {e}"))?;
    if a.repeats == 0 || a.repeats > simboard::MAX_REPEATS {
        bail!("--repeats must be 1 to {}", simboard::MAX_REPEATS);
    }
    let law = calibrate_unit(method, &settings, noise, a.repeats, a.seed)?;
    CalFile::from_law(&law, Some(method.name())).save(&a.out)?;
    println!(
        "calibrated on A–E × {} with {}: {}",
        a.repeats,
        method.name(),
        calfile::describe(&law)
    );
    println!("written to {}", a.out.display());
    Ok(())
}

fn physics(a: PhysicsArgs) -> Result<()> {
    let free = Scene::free_air();
    let fe = PowerLaw::paper_experiment();
    let moduli = [
        100.0, 150.0, 157.5, 200.0, 279.0, 300.0, 414.0, 500.0, 700.0, 1000.0, 1146.0, 1500.0,
        2000.0, 2465.0, 3000.0,
    ];
    if a.markdown {
        println!("| E (kPa) | f_e(E) paper eq. 5 (Hz) | simulated (Hz) | difference (Hz) | simulated Q |");
        println!("|---:|---:|---:|---:|---:|");
    } else {
        println!(
            "free resonance {:.3} Hz, free Q {:.1}",
            free.resonance_hz(),
            free.q()
        );
        println!(
            "{:>8} {:>10} {:>10} {:>8} {:>6}",
            "E kPa", "f_e Hz", "sim Hz", "diff", "Q"
        );
    }
    for e in moduli {
        let s = Scene::on_modulus_kpa(e);
        let (f, fp) = (s.resonance_hz(), fe.frequency(e));
        if a.markdown {
            println!("| {e} | {fp:.2} | {f:.2} | {:+.2} | {:.2} |", f - fp, s.q());
        } else {
            println!(
                "{e:>8} {fp:>10.2} {f:>10.2} {:>+8.2} {:>6.2}",
                f - fp,
                s.q()
            );
        }
    }
    Ok(())
}

fn list_phantoms() {
    for p in phantoms::all() {
        let s = Scene::on_phantom(&p);
        println!(
            "{:>15}  {:>8.2} kPa  nu {:.3}  rho {:>6.0} kg/m3  resonance {:.2} Hz  ({})",
            p.name,
            p.modulus_kpa,
            p.poisson,
            p.density_kg_m3,
            s.resonance_hz(),
            p.source
        );
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Measure(a) => measure(a),
        Cmd::Calibrate(a) => calibrate(a),
        Cmd::Physics(a) => physics(a),
        Cmd::Phantoms => {
            list_phantoms();
            Ok(())
        }
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("probe-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}
