//! Calibration files: a fitted power law as JSON, and the names of the built-in curves.

use anyhow::{bail, Context, Result};
use pzt_probe::calibration::{PowerLaw, Source};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The on-disk form of a calibration.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CalFile {
    /// Asymptote `a`, Hz.
    pub a: f64,
    /// Scale `b`, Hz/kPa^c.
    pub b: f64,
    /// Exponent `c`.
    pub c: f64,
    /// Covariance of `(a, b, c)`.
    pub cov: [[f64; 3]; 3],
    /// Curve misfit, Hz.
    pub model_sigma_hz: f64,
    /// Lowest modulus vouched for, kPa.
    pub min_kpa: f64,
    /// Highest modulus vouched for, kPa.
    pub max_kpa: f64,
    /// `fitted`, `paper-experiment` or `paper-simulation`.
    pub source: String,
    /// Method the reference readings were taken with (informational).
    #[serde(default)]
    pub method: Option<String>,
}

impl CalFile {
    /// From a power law.
    pub fn from_law(p: &PowerLaw, method: Option<&str>) -> Self {
        Self {
            a: p.a,
            b: p.b,
            c: p.c,
            cov: p.cov,
            model_sigma_hz: p.model_sigma_hz,
            min_kpa: p.min_kpa,
            max_kpa: p.max_kpa,
            source: p.source.name().into(),
            method: method.map(str::to_owned),
        }
    }

    /// To a power law, validated.
    pub fn to_law(&self) -> Result<PowerLaw> {
        let source = match self.source.as_str() {
            "fitted" => Source::Fitted,
            "paper-experiment" => Source::PaperExperiment,
            "paper-simulation" => Source::PaperSimulation,
            s => bail!("unknown calibration source `{s}`"),
        };
        let p = PowerLaw {
            a: self.a,
            b: self.b,
            c: self.c,
            cov: self.cov,
            model_sigma_hz: self.model_sigma_hz,
            min_kpa: self.min_kpa,
            max_kpa: self.max_kpa,
            source,
        };
        if !p.is_valid()
            || !(p.model_sigma_hz >= 0.0)
            || p.cov.iter().flatten().any(|v| !v.is_finite())
        {
            bail!("calibration is not a saturating curve with b < 0, c < 0 and a valid span");
        }
        Ok(p)
    }

    /// Read and validate a calibration file.
    pub fn load(path: &Path) -> Result<PowerLaw> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read calibration file {}", path.display()))?;
        let f: CalFile = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a calibration file", path.display()))?;
        f.to_law().with_context(|| format!("{}", path.display()))
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
