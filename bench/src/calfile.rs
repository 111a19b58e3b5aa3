//! Unit profile files: the calibration curve, the contact condition (Q model) and the air
//! reference of one unit as JSON (`probe-bench calibrate --out unit.json`,
//! `measure --profile unit.json`), and the names of the built-in curves.

use anyhow::{bail, Context, Result};
use pzt_probe::estimate::Resonance;
use pzt_probe::loadcell::{ForceWindow, LoadCellCal, LoadCellCounts};
use pzt_probe::unit::calibration::PowerLaw;
use pzt_probe::unit::contact_law::{self, ContactLaw};
use pzt_probe::unit::profile::{AirReference, UnitProfile};
use pzt_probe::unit::q_model::QModel;

fn motional() -> String {
    Resonance::Motional.name().to_owned()
}
use pzt_probe::{Farads, Hz, Newtons, Siemens};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The on-disk form of a calibration: the power law's fields (`a`, `b`, `c`, `cov`,
/// `model_sigma_hz`, `min_kpa`, `max_kpa`, `source` by name; the core's `serde` form), and the
/// method the reference readings were taken with.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CalFile {
    /// The curve.
    #[serde(flatten)]
    pub law: PowerLaw,
    /// Method the reference readings were taken with (informational).
    #[serde(default)]
    pub method: Option<String>,
}

impl CalFile {
    /// From a power law.
    pub fn from_law(p: &PowerLaw, method: Option<&str>) -> Self {
        Self {
            law: *p,
            method: method.map(str::to_owned),
        }
    }

    /// To a power law, validated.
    pub fn to_law(&self) -> Result<PowerLaw> {
        let p = self.law;
        if !p.is_valid()
            || !(p.model_sigma_hz >= 0.0)
            || p.cov.iter().flatten().any(|v| !v.is_finite())
        {
            bail!("calibration is not a saturating curve with b < 0, c < 0 and a valid span");
        }
        Ok(p)
    }
}

/// The on-disk form of the air reference.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct AirFile {
    /// Free resonance, Hz.
    pub free_resonance_hz: f32,
    /// Free quality factor.
    pub free_q: f32,
    /// Static capacitance, F.
    pub static_capacitance_f: f32,
    /// Static conductance, S.
    pub static_conductance_s: f32,
}

/// The on-disk form of the load cell's calibration and the force window.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LoadCellFile {
    /// Newtons per count (from a known weight).
    pub newtons_per_count: f32,
    /// Counts of zero force (tared with the air reference).
    pub tare_counts: i32,
}

/// The on-disk form of the force window.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ForceWindowFile {
    /// Lightest press, N.
    pub min_n: f32,
    /// Hardest press, N.
    pub max_n: f32,
}

/// The on-disk form of a unit profile.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ProfileFile {
    /// Calibration curve.
    pub calibration: CalFile,
    /// The resonance the curve maps: `motional` (every method but paper) or `impedance-dip`
    /// (paper's |Z| dip).
    #[serde(default = "motional")]
    pub resonance: String,
    /// Contact condition of the calibration, `Q = q0 + q1 ln(E / kPa) + q2 ln(F / N)` (the
    /// core's `serde` form: `q0`, `q1`, `q2`, `sigma_rel`).
    pub q_model: Option<QModel>,
    /// Air reference.
    pub air: Option<AirFile>,
    /// The contact law, when the calibration chose it (readings invert through it), as
    /// `ContactLaw::to_values` orders its numbers: free resonance (Hz), `ln Ks`, `ln A`, `ln B`,
    /// their covariance (9, row major), misfit (Hz), lowest and highest modulus (kPa), the
    /// reference force (N).
    #[serde(default)]
    pub contact_law: Option<[f64; contact_law::VALUES]>,
    /// The load cell's calibration, when the unit has one.
    #[serde(default)]
    pub load_cell: Option<LoadCellFile>,
    /// The force window readings are taken in (default 12–55 mN).
    #[serde(default)]
    pub force_window: Option<ForceWindowFile>,
    /// How and when the profile was taken (free text: method, noise, repeats, seeds).
    #[serde(default)]
    pub taken: String,
}

impl ProfileFile {
    /// From a profile.
    pub fn from_profile(p: &UnitProfile, method: Option<&str>, taken: String) -> Self {
        Self {
            calibration: CalFile::from_law(&p.calibration, method),
            resonance: p.resonance.name().to_owned(),
            q_model: p.q_model,
            air: p.air.map(|a| AirFile {
                free_resonance_hz: a.free_resonance.0,
                free_q: a.free_q,
                static_capacitance_f: a.static_capacitance.0,
                static_conductance_s: a.static_conductance.0,
            }),
            contact_law: p.contact.map(|c| c.to_values()),
            load_cell: p.load_cell.map(|c| LoadCellFile {
                newtons_per_count: c.newtons_per_count,
                tare_counts: c.tare.0,
            }),
            force_window: Some(ForceWindowFile {
                min_n: p.force_window.min.0,
                max_n: p.force_window.max.0,
            }),
            taken,
        }
    }

    /// To a profile, validated.
    pub fn to_profile(&self) -> Result<UnitProfile> {
        let resonance = match self.resonance.as_str() {
            "motional" => Resonance::Motional,
            "impedance-dip" => Resonance::ImpedanceDip,
            r => bail!("unknown resonance `{r}` (motional or impedance-dip)"),
        };
        let p = UnitProfile {
            calibration: self.calibration.to_law()?,
            resonance,
            q_model: self.q_model,
            air: self.air.as_ref().map(|a| AirReference {
                free_resonance: Hz(a.free_resonance_hz),
                free_q: a.free_q,
                static_capacitance: Farads(a.static_capacitance_f),
                static_conductance: Siemens(a.static_conductance_s),
            }),
            contact: self.contact_law.as_ref().map(ContactLaw::from_values),
            load_cell: self.load_cell.as_ref().map(|c| LoadCellCal {
                newtons_per_count: c.newtons_per_count,
                tare: LoadCellCounts(c.tare_counts),
            }),
            force_window: self
                .force_window
                .as_ref()
                .map_or(ForceWindow::DEFAULT, |w| ForceWindow {
                    min: Newtons(w.min_n),
                    max: Newtons(w.max_n),
                }),
        };
        if !p.is_valid() {
            bail!("the profile's Q model, air reference, contact law, load cell or force window is not valid");
        }
        Ok(p)
    }

    /// Read and validate a profile file.
    pub fn load(path: &Path) -> Result<UnitProfile> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read profile file {}", path.display()))?;
        let f: ProfileFile = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a unit profile file", path.display()))?;
        f.to_profile()
            .with_context(|| format!("{}", path.display()))
    }

    /// Write as pretty JSON.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// A built-in curve by name.
pub fn builtin(name: &str) -> Option<PowerLaw> {
    match name {
        "paper-experiment" => Some(PowerLaw::paper_experiment()),
        "paper-simulation" => Some(PowerLaw::paper_simulation()),
        _ => None,
    }
}

/// `f = a + b E^c` for humans.
pub fn describe(p: &PowerLaw) -> String {
    format!(
        "f = {:.3} {} {:.1} E^{:.4} (misfit {:.2} Hz, valid {:.0}–{:.0} kPa)",
        p.a,
        if p.b < 0.0 { "-" } else { "+" },
        p.b.abs(),
        p.c,
        p.model_sigma_hz,
        p.min_kpa,
        p.max_kpa
    )
}

/// The profile for humans.
pub fn describe_profile(p: &UnitProfile) -> String {
    let q = p.q_model.map_or("no Q model".to_owned(), |m| {
        let empirical = if m.q2 != 0.0 {
            format!("Q = {:.2} + {:.3} ln E {:+.3} ln F", m.q0, m.q1, m.q2)
        } else {
            format!("Q = {:.2} + {:.3} ln E", m.q0, m.q1)
        };
        match m.damping {
            Some(d) => format!(
                "{empirical}; lossless Q from the contact's damping {:.2} + {:.1} E^(-1/6) (F/F0)^(2/3) s^-1 per modal mass (±{:.2} %)",
                d.probe_per_s,
                d.contact_per_s,
                100.0 * d.sigma_rel
            ),
            None => empirical,
        }
    });
    let cell = p.load_cell.map_or("no load cell".to_owned(), |c| {
        format!(
            "load cell {:.4e} N/count, tare {} counts, force window {:.0}–{:.0} mN",
            c.newtons_per_count,
            c.tare.0,
            p.force_window.min.0 * 1e3,
            p.force_window.max.0 * 1e3
        )
    });
    let air = p.air.map_or("no air reference".to_owned(), |a| {
        format!(
            "air {:.3} Hz, Q {:.1}, C0 {:.2} pF",
            a.free_resonance.0,
            a.free_q,
            a.static_capacitance.0 * 1e12
        )
    });
    let law = match p.contact {
        Some(c) => format!(
            "; readings through the contact law at their measured force (held out it predicts A–E better): free {:.3} Hz, rigid limit {:.3} Hz, misfit {:.4} Hz, reference force {:.0} mN",
            c.free_hz,
            c.rigid_hz(),
            c.model_sigma_hz,
            c.force_n * 1e3
        ),
        None => String::new(),
    };
    format!("{}{law}; {q}; {air}; {cell}", describe(&p.calibration))
}

/// The profile a command reads with: the file given with `--profile`, else the simulated
/// unit's own (`make_unit`: its air reference and a calibration with the command's method),
/// with the curve replaced by a built-in one when `calibration` names one (`paper-experiment`,
/// `paper-simulation`; `unit` keeps the unit's). A `calibration` that is neither is read as
/// a profile file too.
pub fn resolve(
    profile: Option<&Path>,
    calibration: &str,
    make_unit: impl FnOnce() -> Result<UnitProfile>,
) -> Result<UnitProfile> {
    let mut p = match profile {
        Some(path) => ProfileFile::load(path)?,
        None if calibration == "unit" || builtin(calibration).is_some() => make_unit()?,
        None => ProfileFile::load(Path::new(calibration))?,
    };
    if let Some(law) = builtin(calibration) {
        // The papers' curves map the motional resonance (docs/physics.md).
        p.use_power_law(law, Resonance::Motional);
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A calibration as profile files hold it: the curve's fields, `source` by name, `method`.
    const CAL: &str = r#"{
  "a": 266.6,
  "b": -1104.5,
  "c": -0.5,
  "cov": [
    [
      0.25,
      0.0,
      0.0
    ],
    [
      0.0,
      4.0,
      0.0
    ],
    [
      0.0,
      0.0,
      0.0001
    ]
  ],
  "model_sigma_hz": 0.55,
  "min_kpa": 100.0,
  "max_kpa": 3000.0,
  "source": "fitted",
  "method": "auto"
}"#;

    #[test]
    fn calibration_reads_and_writes_the_same_json() {
        let f: CalFile = serde_json::from_str(CAL).unwrap();
        assert_eq!(f.law.a, 266.6);
        assert_eq!(f.law.cov[1][1], 4.0);
        assert_eq!(f.law.source, pzt_probe::unit::calibration::Source::Fitted);
        assert_eq!(f.method.as_deref(), Some("auto"));
        assert_eq!(serde_json::to_string_pretty(&f).unwrap(), CAL);
    }

    #[test]
    fn q_model_reads_and_writes_the_same_json() {
        let text =
            "{\n  \"q0\": 2.5,\n  \"q1\": 1.25,\n  \"q2\": -4.5,\n  \"sigma_rel\": 0.0375\n}";
        let m: QModel = serde_json::from_str(text).unwrap();
        assert_eq!(m.q2, -4.5);
        assert_eq!(serde_json::to_string_pretty(&m).unwrap(), text);
        // Without a force term or a scatter: both 0.
        let m: QModel = serde_json::from_str(r#"{"q0": 2.5, "q1": 1.25}"#).unwrap();
        assert_eq!((m.q2, m.sigma_rel), (0.0, 0.0));
    }

    #[test]
    fn unknown_source_is_named() {
        let text = CAL.replace("\"fitted\"", "\"measured\"");
        let e = serde_json::from_str::<CalFile>(&text)
            .unwrap_err()
            .to_string();
        assert!(e.contains("calibration source `measured`"), "{e}");
    }
}
