//! `probe-bench physics` and `probe-bench phantoms`: the simulator against the paper.

use anyhow::Result;
use clap::Args;
use hal_sim::{phantoms, Phantom, Scene};
use pzt_probe::unit::calibration::PowerLaw;

#[derive(Args)]
pub struct PhysicsArgs {
    /// Print a Markdown table (as in docs/physics.md).
    #[arg(long)]
    pub markdown: bool,
}

/// Run the subcommand.
pub fn run(a: PhysicsArgs) -> Result<()> {
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

/// List the phantoms, then the named tissues (with their loss tangent and the loaded Q).
pub fn list_phantoms() {
    for p in phantoms::all() {
        let material = format!("nu {:.3}  rho {:>6.0} kg/m3", p.poisson, p.density_kg_m3);
        phantom_row(15, &p, &material, |_| String::new());
    }
    println!("named tissues (viscoelastic; docs/physics.md, \"Viscoelastic tissue\"):");
    for p in phantoms::tissues() {
        let material = format!("tan d {:.2}", p.loss_tangent);
        phantom_row(20, &p, &material, |s| format!("  Q {:.1}", s.kelvin().q()));
    }
}

/// One row of [`list_phantoms`]: the name right-aligned in `width`, the modulus, what the list
/// says of the material, the probe's resonance on it and `more` of that scene, the source.
fn phantom_row(width: usize, p: &Phantom, material: &str, more: impl Fn(&Scene) -> String) {
    let s = Scene::on_phantom(p);
    println!(
        "{:>width$}  {:>8.2} kPa  {material}  resonance {:.2} Hz{}  ({})",
        p.name,
        p.modulus_kpa,
        s.resonance_hz(),
        more(&s),
        p.source
    );
}
