//! Parsing of what is under the simulated probe and how noisy it is.

use anyhow::{bail, Context, Result};
use hal_sim::{phantoms, NoiseScene, Phantom, Scene};

/// A named noise level or a density in A/sqrt(Hz).
pub fn parse_noise(s: &str) -> Result<NoiseScene> {
    Ok(match s {
        "quiet" => NoiseScene::Quiet,
        "paper" => NoiseScene::Paper,
        "bench" => NoiseScene::Bench,
        other => {
            let d: f64 = other.parse().with_context(|| {
                format!("noise `{other}`: expected quiet, paper, bench or a density in A/sqrt(Hz)")
            })?;
            if !(0.0..1e-3).contains(&d) {
                bail!("noise density {other} A/sqrt(Hz) is out of range (0 to 1e-3)");
            }
            NoiseScene::Density(d)
        }
    })
}

/// Name of a noise level for humans.
pub fn noise_name(n: NoiseScene) -> String {
    match n {
        NoiseScene::Quiet => "quiet".into(),
        NoiseScene::Paper => format!("paper ({:.1e} A/sqrt(Hz))", n.density_a_rthz()),
        NoiseScene::Bench => format!("bench ({:.1e} A/sqrt(Hz))", n.density_a_rthz()),
        NoiseScene::Density(d) => format!("{d:.2e} A/sqrt(Hz)"),
    }
}

/// What the probe is pressed on.
#[derive(Clone, Copy, Debug)]
pub enum Target {
    /// A named phantom.
    Phantom(Phantom),
    /// Tissue of a given modulus (kPa).
    Modulus(f64),
    /// Nothing: free air.
    FreeAir,
}

impl Target {
    /// From the command-line options (at most one of them).
    pub fn from_options(
        phantom: Option<&str>,
        modulus_kpa: Option<f64>,
        free_air: bool,
    ) -> Result<Self> {
        match (phantom, modulus_kpa, free_air) {
            (Some(p), None, false) => {
                phantoms::by_name(p).map(Target::Phantom).with_context(|| {
                    let names: Vec<&str> = phantoms::all().iter().map(|p| p.name).collect();
                    format!("unknown phantom `{p}` (known: {})", names.join(", "))
                })
            }
            (None, Some(e), false) => {
                if !(e.is_finite() && e > 0.0 && e <= 1e6) {
                    bail!("modulus {e} kPa is out of range (0 to 1e6 kPa)");
                }
                Ok(Target::Modulus(e))
            }
            (None, None, true) => Ok(Target::FreeAir),
            (None, None, false) => {
                bail!("say what the probe is on: --phantom, --modulus-kpa or --free-air")
            }
            _ => bail!("give only one of --phantom, --modulus-kpa, --free-air"),
        }
    }

    /// The scene (30 mN preload unless changed by the caller).
    pub fn scene(&self) -> Scene {
        match self {
            Target::Phantom(p) => Scene::on_phantom(p),
            Target::Modulus(e) => Scene::on_modulus_kpa(*e),
            Target::FreeAir => Scene::free_air(),
        }
    }

    /// True modulus, if any.
    pub fn modulus_kpa(&self) -> Option<f64> {
        match self {
            Target::Phantom(p) => Some(p.modulus_kpa),
            Target::Modulus(e) => Some(*e),
            Target::FreeAir => None,
        }
    }

    /// Description for humans.
    pub fn describe(&self) -> String {
        match self {
            Target::Phantom(p) => format!(
                "phantom {} ({:.1} kPa, {})",
                p.name, p.modulus_kpa, p.source
            ),
            Target::Modulus(e) => format!("tissue of {e:.1} kPa"),
            Target::FreeAir => "free air (no contact)".into(),
        }
    }
}

/// Layers a scene uses, comma separated.
pub fn layer_names(scene: &Scene) -> String {
    let mut l = [hal_sim::Layer::Kelvin; hal_sim::Layer::COUNT];
    let n = scene.layers(&mut l);
    l[..n]
        .iter()
        .map(|x| x.name())
        .collect::<Vec<_>>()
        .join(", ")
}
