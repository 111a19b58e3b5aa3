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

/// The simulated front end's noise and the seed of its random numbers: the options `selftest`,
/// `stream` and `scan` share.
#[derive(clap::Args, Clone, Debug)]
pub struct NoiseArgs {
    /// Front-end noise: `quiet`, `paper`, `bench`, or a current-noise density in A/sqrt(Hz).
    #[arg(long, default_value = "bench")]
    pub noise: String,
    /// Seed of the simulated noise (of several runs, as scan's grid points, the k-th uses seed +
    /// k).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// What the simulated probe is pressed on, and how hard: the options `measure` and `selftest`
/// share.
#[derive(clap::Args, Clone, Debug)]
pub struct SceneArgs {
    /// Phantom to press on: A–E (paper 003), ecoflex-00-10, ecoflex-00-30, dragon-skin-20; or a
    /// named tissue (with its own loss tangent): fat-like, fibrous-breast-like, dcis-like,
    /// carcinoma-like, prostate-cancer-like.
    #[arg(long)]
    pub phantom: Option<String>,
    /// Tissue of this small-strain Young's modulus, kPa.
    #[arg(long)]
    pub modulus_kpa: Option<f64>,
    /// No tissue: the probe in free air.
    #[arg(long)]
    pub free_air: bool,
    /// Contact preload, N.
    #[arg(long, default_value_t = 0.030)]
    pub preload_n: f64,
    /// The tissue's viscoelastic loss tangent tan δ at the resonance (0–2; default: the
    /// target's own).
    #[arg(long)]
    pub loss_tangent: Option<f64>,
}

impl SceneArgs {
    /// The target and its scene under `noise`; without a target option, free air when
    /// `free_by_default`, else an error. The preload must lie in (0, 1] N.
    pub fn scene(&self, noise: NoiseScene, free_by_default: bool) -> Result<(Target, Scene)> {
        let free = self.free_air
            || (free_by_default && self.phantom.is_none() && self.modulus_kpa.is_none());
        let target = Target::from_options(self.phantom.as_deref(), self.modulus_kpa, free)?;
        if !(self.preload_n.is_finite() && self.preload_n > 0.0 && self.preload_n <= 1.0) {
            bail!("preload {} N is out of range (0 to 1 N)", self.preload_n);
        }
        let mut scene = target
            .scene()
            .with_noise(noise)
            .with_preload_n(self.preload_n);
        if let Some(t) = self.loss_tangent {
            if !(t.is_finite() && (0.0..=2.0).contains(&t)) {
                bail!("loss tangent {t} is out of range (0 to 2)");
            }
            scene = scene.with_loss_tangent(t);
        }
        Ok((target, scene))
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
                    let names: Vec<&str> = phantoms::all()
                        .iter()
                        .chain(phantoms::tissues().iter())
                        .map(|p| p.name)
                        .collect();
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
            Target::Phantom(p) if p.loss_tangent > 0.0 => format!(
                "phantom {} ({:.1} kPa, tan d {:.2}, {})",
                p.name, p.modulus_kpa, p.loss_tangent, p.source
            ),
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

/// The first lines of a command's bench log on the simulated probe: `probe-bench <command>:`
/// on `target`, then the preload, the noise and the layers of `scene`.
pub fn print_scene_header(
    command: &str,
    target: &Target,
    preload_n: f64,
    noise: NoiseScene,
    scene: &Scene,
) {
    println!(
        "probe-bench {command}: simulated probe on {}",
        target.describe()
    );
    println!(
        "  preload {:.0} mN, noise {}, layers: {}",
        preload_n * 1e3,
        noise_name(noise),
        layer_names(scene)
    );
}
