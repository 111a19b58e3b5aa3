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
    /// Viscoelastic loss tangent `tan(delta)` at the resonance (0: lossless, as every silicone
    /// phantom here; the named tissues of [`tissues`] carry their own).
    pub loss_tangent: f64,
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
        loss_tangent: 0.0,
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
            loss_tangent: 0.0,
        },
        Phantom {
            name: "ecoflex-00-30",
            source: "papers 001/002: 2MR C10 = 85.157 kPa, C01 = -80.385 kPa",
            modulus_kpa: mooney_rivlin_modulus_kpa(85.157, -80.385),
            poisson: poisson_from_bulk_shear(0.106017, 0.009542),
            density_kg_m3: 1070.0,
            loss_tangent: 0.0,
        },
        Phantom {
            name: "dragon-skin-20",
            source: "paper 001: neo-Hookean mu = 0.063297 MPa, K = 0.703228 MPa",
            modulus_kpa: 3.0 * 0.063297e3,
            poisson: poisson_from_bulk_shear(0.703228, 0.063297),
            density_kg_m3: 1080.0,
            loss_tangent: 0.0,
        },
    ]
}

/// Every phantom: A–E then the silicones.
pub fn all() -> [Phantom; 8] {
    let s = silicones();
    [A, B, C, D, E, s[0], s[1], s[2]]
}

/// Soft tissue of Krouskop et al. 1998 (quasi-static compression of excised tissue), one line a
/// tissue: `NAME = "name", "tissue", precompression %, modulus kPa, loss tangent;`. `nu` 0.49 and
/// `rho` 1000 kg/m^3 as [`Tissue::with_modulus_kpa`]; the modulus is the paper's mean at the
/// stated precompression and 1 Hz, the loss tangent ours (see [`tissues`]).
macro_rules! krouskop {
    ($($(#[$doc:meta])* $id:ident = $name:literal, $tissue:literal, $pre:literal, $kpa:literal, $tan:literal;)*) => {$(
        $(#[$doc])*
        pub const $id: Phantom = Phantom {
            name: $name,
            source: concat!("Krouskop 1998: ", $tissue, ", ", $pre, " % precompression, 1 Hz (tan d ours)"),
            modulus_kpa: $kpa,
            poisson: 0.49,
            density_kg_m3: 1000.0,
            loss_tangent: $tan,
        };
    )*};
}

krouskop! {
    /// Breast fat: Krouskop et al. 1998 (Ultrasonic Imaging 20:260), normal fat, 20 %
    /// precompression, 1 Hz: 20 ± 8 kPa (18 ± 7 kPa at 5 %; fat's modulus does not depend on the
    /// strain). Far below the probe's range: the probe reads it as its softest. Loss tangent 0.20
    /// is ours (below the 0.40 bound of the same paper; see `docs/physics.md`).
    FAT_LIKE = "fat-like", "breast fat", 20, 20.0, 0.20;
    /// Fibrous breast tissue: Krouskop et al. 1998, normal fibrous tissue, 20 % precompression,
    /// 1 Hz: 233 ± 59 kPa (96–116 kPa at 5 %). Loss tangent 0.15 is ours.
    FIBROUS_BREAST_LIKE = "fibrous-breast-like", "fibrous breast tissue", 20, 233.0, 0.15;
    /// Ductal carcinoma in situ: Krouskop et al. 1998, intraductal (in situ) carcinoma, 20 %
    /// precompression, 1 Hz: 301 ± 58 kPa (like fat at 5 %, 22–28 kPa). Loss tangent 0.25 is
    /// ours (malignant lesions are the more liquid-like, Sinkus et al. 2007).
    DCIS_LIKE = "dcis-like", "ductal carcinoma in situ", 20, 301.0, 0.25;
    /// Invasive ductal carcinoma: Krouskop et al. 1998, infiltrating ductal carcinoma, 20 %
    /// precompression, 1 Hz: 490 ± 112 kPa (460–558 kPa over 0.1–4 Hz), the stiffest breast
    /// tissue of the paper. Loss tangent 0.30 is ours (the most liquid-like, Sinkus et al. 2007).
    CARCINOMA_LIKE = "carcinoma-like", "invasive ductal carcinoma", 20, 490.0, 0.30;
    /// Prostate cancer: Krouskop et al. 1998, prostate cancer, 4 % precompression, 1 Hz:
    /// 230 ± 34 kPa (96–100 kPa at 2 %). Loss tangent 0.25 is ours.
    PROSTATE_CANCER_LIKE = "prostate-cancer-like", "prostate cancer", 4, 230.0, 0.25;
}

/// Named soft-tissue targets: sourced moduli and a viscoelastic loss.
///
/// Not phantoms of the papers and not used by any calibration: scenes of what the probe meets
/// in use. The moduli are Krouskop et al. 1998's quasi-static (0.1–4 Hz) compression moduli;
/// hal-sim takes them as the storage modulus at the probe's resonance, which a dispersive
/// tissue exceeds by `(f_res / f_static)^y` (`docs/physics.md`, "Viscoelastic tissue"). No
/// source gave a loss tangent per tissue: the values are ours, inside Krouskop's bound (the
/// storage modulus is over 93 % of the complex modulus above 1 Hz, so `tan(delta) < 0.40`) and
/// ordered as Sinkus et al. 2007 (MRM 58:1135) found (malignant lesions the more liquid-like).
pub fn tissues() -> [Phantom; 5] {
    [
        FAT_LIKE,
        FIBROUS_BREAST_LIKE,
        DCIS_LIKE,
        CARCINOMA_LIKE,
        PROSTATE_CANCER_LIKE,
    ]
}

/// Look a phantom or a named tissue up by name (case-insensitive): [`all`], then [`tissues`].
pub fn by_name(name: &str) -> Option<Phantom> {
    all()
        .into_iter()
        .chain(tissues())
        .find(|p| p.name.eq_ignore_ascii_case(name))
}

impl Phantom {
    /// The phantom as linear viscoelastic tissue (its own loss tangent: 0 for the silicones).
    pub fn tissue(&self) -> Tissue {
        Tissue {
            modulus_pa: self.modulus_kpa * 1e3,
            poisson: self.poisson,
            density_kg_m3: self.density_kg_m3,
            loss_tangent: self.loss_tangent,
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

    #[test]
    fn named_tissues_are_found_and_leave_the_phantoms_alone() {
        for t in tissues() {
            assert_eq!(by_name(t.name), Some(t));
            assert_eq!(by_name(&t.name.to_ascii_uppercase()), Some(t));
            // No name shadows a phantom of the papers.
            assert!(all().iter().all(|p| !p.name.eq_ignore_ascii_case(t.name)));
            // Inside the bound of Krouskop 1998 (E' over 93 % of |E*|: tan d < 0.395).
            assert!(t.loss_tangent > 0.0 && t.loss_tangent < 0.395, "{}", t.name);
        }
        // The papers' phantoms stay lossless, with their published moduli.
        for p in all() {
            assert_eq!(p.loss_tangent, 0.0, "{}", p.name);
            assert_eq!(p.tissue().loss_tangent, 0.0);
        }
        let moduli: Vec<f64> = [A, B, C, D, E].iter().map(|p| p.modulus_kpa).collect();
        assert_eq!(moduli, [157.5, 279.0, 414.0, 1146.0, 2465.0]);
    }

    #[test]
    fn each_named_tissue_loss_lowers_the_q_by_the_kelvin_closed_form() {
        use crate::tissue::{Contact, SensorMech, TissueElements};
        use crate::Scene;
        let mech = SensorMech::default();
        let contact = Contact::default();
        for t in tissues() {
            let lossy = Scene::on_phantom(&t).kelvin();
            let mut lossless_t = t.tissue();
            lossless_t.loss_tangent = 0.0;
            let lossless = Scene::on_tissue(lossless_t).kelvin();
            // The loss leaves the storage stiffness and the mass: the same resonance.
            assert_eq!(lossy.stiffness_n_m, lossless.stiffness_n_m, "{}", t.name);
            assert_eq!(lossy.mass_kg, lossless.mass_kg, "{}", t.name);
            // It adds s² tan d k_m / w0 (k_m the Hertz stiffness before the series coupling,
            // s its transfer, w0 the loaded resonance): Q = sqrt(k m) / (c_lossless + that).
            let k_m = TissueElements::new(&lossless_t, &contact, &mech).stiffness_n_m;
            let s = mech.coupling_stiffness_n_m / (mech.coupling_stiffness_n_m + k_m);
            let w0 = libm::sqrt(lossless.stiffness_n_m / lossless.mass_kg);
            let c = lossless.damping_n_s_m + s * s * t.loss_tangent * k_m / w0;
            let q_closed = libm::sqrt(lossless.stiffness_n_m * lossless.mass_kg) / c;
            assert!(
                (lossy.q() / q_closed - 1.0).abs() < 1e-12,
                "{}: Q {} vs closed form {q_closed}",
                t.name,
                lossy.q()
            );
            assert!(lossy.q() < lossless.q(), "{}", t.name);
        }
    }
}
