//! The phantoms of the source papers, as small-strain linear tissue.

use crate::tissue::Tissue;

/// A named tissue phantom.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phantom {
    /// Short name (`A`..`E`, `ecoflex-00-10`, ...).
    pub name: &'static str,
    /// Where it comes from.
    pub source: &'static str,
    /// Small-strain Young's modulus in kPa.
    pub modulus_kpa: f64,
    /// Poisson ratio.
    pub poisson: f64,
    /// Density in kg/m^3.
    pub density_kg_m3: f64,
}

/// Poisson ratio of the neo-Hookean silicones of paper 001: `nu = (3K - 2mu) / (2 (3K + mu))`
/// with the published bulk and shear moduli (the same ratio K/mu = 11.11 for all three).
pub fn poisson_from_bulk_shear(bulk: f64, shear: f64) -> f64 {
    (3.0 * bulk - 2.0 * shear) / (2.0 * (3.0 * bulk + shear))
}

/// Small-strain Young's modulus (kPa) of a two-term Mooney–Rivlin solid (paper 002):
/// `mu = 2 (C10 + C01)`, `E = 3 mu` (incompressible).
pub fn mooney_rivlin_modulus_kpa(c10_kpa: f64, c01_kpa: f64) -> f64 {
    3.0 * 2.0 * (c10_kpa + c01_kpa)
}

const fn p003(name: &'static str, modulus_kpa: f64) -> Phantom {
    Phantom {
        name,
        source: "paper 003 sample (Shore A silicone)",
        modulus_kpa,
        poisson: 0.49,
        density_kg_m3: 1000.0,
    }
}

/// Paper 003 sample A (Shore 0 HA, 157.5 kPa).
pub const A: Phantom = p003("A", 157.5);
/// Paper 003 sample B (Shore 5 HA, 279 kPa).
pub const B: Phantom = p003("B", 279.0);
/// Paper 003 sample C (Shore 10 HA, 414 kPa).
pub const C: Phantom = p003("C", 414.0);
/// Paper 003 sample D (Shore 30 HA, 1146 kPa).
pub const D: Phantom = p003("D", 1146.0);
/// Paper 003 sample E (Shore 50 HA, 2465 kPa).
pub const E: Phantom = p003("E", 2465.0);

/// The three silicones of papers 001/002 (Ecoflex 00-10, Ecoflex 00-30, Dragon Skin 20).
pub fn silicones() -> [Phantom; 3] {
    // Paper 001 (neo-Hookean): mu, K in MPa; paper 002 (2MR) C10, C01 in kPa agree on mu.
    let nu = poisson_from_bulk_shear(0.030477, 0.002743);
    [
        Phantom {
            name: "ecoflex-00-10",
            source: "papers 001/002: 2MR C10 = 27.147 kPa, C01 = -25.776 kPa",
            modulus_kpa: mooney_rivlin_modulus_kpa(27.147, -25.776),
            poisson: nu,
            density_kg_m3: 1040.0,
        },
        Phantom {
            name: "ecoflex-00-30",
            source: "papers 001/002: 2MR C10 = 85.157 kPa, C01 = -80.385 kPa",
            modulus_kpa: mooney_rivlin_modulus_kpa(85.157, -80.385),
            poisson: poisson_from_bulk_shear(0.106017, 0.009542),
            density_kg_m3: 1070.0,
        },
        Phantom {
            name: "dragon-skin-20",
            source: "paper 001: neo-Hookean mu = 0.063297 MPa, K = 0.703228 MPa",
            modulus_kpa: 3.0 * 0.063297e3,
            poisson: poisson_from_bulk_shear(0.703228, 0.063297),
            density_kg_m3: 1080.0,
        },
    ]
}

/// Every phantom: A–E then the silicones.
pub fn all() -> [Phantom; 8] {
    let s = silicones();
    [A, B, C, D, E, s[0], s[1], s[2]]
}

/// Look a phantom up by name (case-insensitive for `A`..`E`).
pub fn by_name(name: &str) -> Option<Phantom> {
    all()
        .into_iter()
        .find(|p| p.name.eq_ignore_ascii_case(name))
}

impl Phantom {
    /// The phantom as linear tissue (no extra viscoelastic loss).
    pub fn tissue(&self) -> Tissue {
        Tissue {
            modulus_pa: self.modulus_kpa * 1e3,
            poisson: self.poisson,
            density_kg_m3: self.density_kg_m3,
            loss_tangent: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn silicone_moduli_from_published_constants() {
        let s = silicones();
        // mu = 2 (C10 + C01): 2.742 kPa -> E = 8.226 kPa; 9.544 kPa -> 28.63 kPa;
        // Dragon Skin 20: E = 3 * 63.297 = 189.9 kPa.
        assert!((s[0].modulus_kpa - 8.226).abs() < 1e-3);
        assert!((s[1].modulus_kpa - 28.632).abs() < 1e-3);
        assert!((s[2].modulus_kpa - 189.891).abs() < 1e-3);
        // Paper 001's shear moduli agree with paper 002's 2(C10 + C01) within 0.1 %.
        assert!((s[0].modulus_kpa / 3.0 / 2.743 - 1.0).abs() < 1e-3);
        assert!((s[1].modulus_kpa / 3.0 / 9.542 - 1.0).abs() < 1e-3);
        for p in s {
            assert!((p.poisson - 0.4563).abs() < 1e-3, "{}", p.poisson);
        }
    }

    #[test]
    fn lookup() {
        assert_eq!(by_name("b").unwrap().modulus_kpa, 279.0);
        assert!(by_name("Z").is_none());
    }
}
