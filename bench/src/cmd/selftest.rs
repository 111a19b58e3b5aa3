//! `probe-bench selftest`: the firmware's power-on self-test (`src/instrument/selftest.rs`, run by the
//! session at power-on and on `selftest`) on the simulated probe, with a fault of `hal-sim` if
//! asked: what the firmware would log, as text or JSON. A failed self-test exits non-zero.

use crate::calfile;
use crate::scene::{noise_name, parse_noise, NoiseArgs, SceneArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use hal_sim::{Fault, SimProbe};
use pzt_probe::board::sim::SimBoard;
use pzt_probe::engine::SampleEngine;
use pzt_probe::instrument::selftest::{self, SelfTestReport};
use pzt_probe::reading::driver::{block_on, SyncSource};
use pzt_probe::UnitProfile;
use std::path::PathBuf;

#[derive(Args)]
pub struct SelftestArgs {
    /// Fault of the analog chain: `open` (PZT disconnected), `short` (shorted through 1 kOhm),
    /// `dac-stuck` (DAC at mid-scale), `adc-rail` (sense ADC at its upper rail); none by default.
    #[arg(long)]
    pub fault: Option<String>,
    /// What the probe is on (default: free air), and the preload.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The front end's noise and its seed.
    #[command(flatten)]
    pub noise: NoiseArgs,
    /// Unit profile file (`probe-bench calibrate --out`); default: the simulated unit's
    /// factory profile (src/board/sim_factory.rs), whose air reference gives C0.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// A fresh unit without an air reference: checked against the nominal plate.
    #[arg(long)]
    pub fresh: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Run the subcommand.
pub fn run(a: SelftestArgs) -> Result<()> {
    let noise = parse_noise(&a.noise.noise)?;
    let (target, mut scene) = a.scene.scene(noise, true)?;
    let fault = match a.fault.as_deref() {
        None | Some("none") => None,
        Some(name) => Some(Fault::from_name(name).with_context(|| {
            let names: Vec<&str> = Fault::ALL.iter().map(|f| f.name()).collect();
            format!("unknown fault `{name}` (known: {}, none)", names.join(", "))
        })?),
    };
    let unit = match (&a.profile, a.fresh) {
        (Some(_), true) => bail!("give only one of --profile, --fresh"),
        (Some(p), false) => calfile::ProfileFile::load(p)?,
        (None, true) => UnitProfile::fallback(),
        (None, false) => pzt_probe::board::sim_factory::profile()
            .context("the simulated unit's factory record is invalid")?,
    };
    if let Some(f) = fault {
        scene = f.apply(scene);
    }
    let mut board = SimBoard::new(SimProbe::new(scene, a.noise.seed));
    let mut engine = SampleEngine::new();
    let mut src = SyncSource::new(&mut board, &mut engine);
    let r = block_on(selftest::run(&mut src, &unit, |_| {}));
    if a.json {
        println!("{}", json(&r));
    } else {
        println!(
            "probe-bench selftest: simulated probe on {}, noise {}, fault {}",
            target.describe(),
            noise_name(noise),
            fault.map_or("none", |f| f.name())
        );
        print!("{}", text(&r));
    }
    match r.outcome {
        Ok(()) => Ok(()),
        Err(f) => bail!("self-test failed: {}", f.code()),
    }
}

fn finite(v: f32) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// The report as the JSON object `--json` prints.
pub fn json(r: &SelfTestReport) -> serde_json::Value {
    let e = &r.expected;
    serde_json::json!({
        "status": selftest::outcome_code(Some(r.outcome)),
        "message": r.outcome.err().map(|f| f.message()),
        "f_hz": finite(r.freq.0),
        "c_pf": finite(r.capacitance.0 * 1e12),
        "c_sigma_pf": finite(r.capacitance_sigma.0 * 1e12),
        "g_s": finite(r.conductance.0),
        "current_a": finite(r.current_a),
        "drive_v": finite(r.drive_v),
        "reference": if e.from_air { "air" } else { "nominal" },
        "ref_c_pf": finite(e.capacitance.0 * 1e12),
        "tolerance": finite(e.tolerance),
        "probe_time_s": finite(r.probe_time.0),
    })
}

fn text(r: &SelfTestReport) -> String {
    let e = &r.expected;
    let mut s = format!(
        "  drive {:.1} Hz: C {:.3} pF ± {:.3} pF, G {:.3e} S, current {:.3e} A at {:.3} V (monitor), {:.2} s\n",
        r.freq.0,
        r.capacitance.0 * 1e12,
        r.capacitance_sigma.0 * 1e12,
        r.conductance.0,
        r.current_a,
        r.drive_v,
        r.probe_time.0
    );
    s += &format!(
        "  reference: {} C0 {:.3} pF ± {:.2} % (+ 5 sigma)\n",
        if e.from_air {
            "air reference"
        } else {
            "nominal plate"
        },
        e.capacitance.0 * 1e12,
        100.0 * e.tolerance
    );
    s += &match r.outcome {
        Ok(()) => "  passed\n".to_owned(),
        Err(f) => format!("  FAILED {}: {}\n", f.code(), f.message()),
    };
    s
}
