//! Lumps: a rigid inclusion under a soft layer, seen by the probe as an effective modulus.
//!
//! The least model that gives paper 003's lump contrast without finite elements. Pressed at the
//! preload `F` with its spherical tip (radius `R`), the probe makes a Hertz contact of radius
//! `a`. A soft layer of thickness `h` bonded on something rigid is stiffer under that contact than
//! a half-space: Dimitriadis et al. (Biophys. J. 82, 2002) give the force of a sphere indenting
//! a bonded incompressible layer as the Hertz force times
//!
//! `Φ(χ) = 1 + 1.133 χ + 1.283 χ² + 0.769 χ³ + 0.0975 χ⁴`,  `χ = a / h`
//!
//! (their `χ = sqrt(R δ) / h`, and `a = sqrt(R δ)` for Hertz). At a fixed preload the contact is
//! then the Hertz contact of a half-space of modulus `E Φ(χ)` — the *apparent* modulus an
//! indentation reports — with `a³ Φ(a/h) = a_H³` solved self-consistently (`a_H` is the Hertz
//! radius on the bare layer). The probe's contact elements (`k_m`, `c_m`, `m_m`, see
//! [`crate::tissue`]) are computed from that apparent modulus.
//!
//! Two rigid things lie under the surface: the table the phantom is bonded to (depth
//! `thickness`) and the inclusion. How much of the contact's load the inclusion carries is the
//! Boussinesq share of a surface point load that crosses the inclusion's widest horizontal
//! section (`w`, [`load_fraction_on_disc`]): 1 straight over a wide inclusion, 1/2 over its edge,
//! falling off as the cube of the lateral distance beyond it. The layer over the inclusion is as
//! thick as the distance from the contact to the nearest point of the inclusion (`h`). The
//! apparent modulus blends the two supports by that share:
//!
//! `E_app = E (w Φ(a/h) + (1 − w) Φ(a/H))`.
//!
//! Constants: the polynomial is Dimitriadis' bonded, incompressible case (silicone: ν ≈ 0.49);
//! `χ` is capped at 1, the range their expansion was checked over (a layer thinner than the
//! contact radius is outside the model). Nothing is fitted to paper 003: its disc (30 mm across,
//! 15 mm thick, silicone of the modulus it reads away from the lump, 151.8 kPa by eq. 5) with a
//! coin 1 mm under the surface gives an apparent modulus of about 235 kPa over the coin (paper:
//! 246.3 kPa) and 156 kPa away from it, i.e. about 222 Hz and 206 Hz on the simulated probe
//! (paper: 223.5 and 206.3 Hz). The lateral free edge of the phantom is not modelled.
//!
//! **Loss, and a lump that is not rigid** (ours, not from a source; docs/physics.md, "A lump in
//! lossy tissue"). The matrix is viscoelastic, `E*_bg = E_bg (1 + j η_bg)`; an inclusion is
//! either rigid (a coin, a steel ball: it stores no strain energy, so it has no loss) or a tissue
//! of its own, `E*_l = E_l (1 + j η_l)` ([`LumpMaterial`]). Each support of the blend above is a
//! compliance in units of the half-space's `1/E`: the layer over the inclusion holds
//! `1/Φ(a/h)` of it and the rigid inclusion removes the rest down to the table,
//! `1/Φ(a/H) − 1/Φ(a/h)`. A compliant inclusion keeps that slice, at its own modulus:
//!
//! `1/E*_1 = 1/(E*_bg Φ(a/h)) + (1/Φ(a/H) − 1/Φ(a/h)) / E*_l`,
//!
//! and the two supports combine with the same load share as before,
//! `E*_app = w E*_1 + (1 − w) E*_bg Φ(a/H)`. The probe feels the storage modulus
//! `E'_app = Re E*_app` and the loss tangent `Im E*_app / Re E*_app`. Limits: a rigid inclusion
//! (`E_l → ∞`) gives the rigid model above with the matrix's loss everywhere
//! (`E*_app = (1 + j η_bg) E_app`); an inclusion of the matrix's own material gives the bare
//! layer, `E*_bg Φ(a/H)`, as if it were not there. A lump of the matrix's loss tangent therefore
//! shows no loss anomaly, however stiff it is.

use crate::scenes::Scene;
use crate::tissue::{contact_radius_m, Contact, Tissue};
use core::f64::consts::PI;
use num_complex::Complex64;

/// Dimitriadis' bonded-layer correction `Φ(χ)` for an incompressible layer, `χ = a / h`
/// capped at 1.
pub fn thin_layer_factor(chi: f64) -> f64 {
    let x = if chi.is_finite() {
        chi.clamp(0.0, 1.0)
    } else {
        1.0
    };
    1.0 + x * (1.133 + x * (1.283 + x * (0.769 + x * 0.0975)))
}

/// Directions of the angular quadrature in [`load_fraction_on_disc`].
pub const QUADRATURE_DIRECTIONS: usize = 720;

/// Share of a vertical point load on the surface of a half-space that crosses a horizontal disc
/// of radius `radius_m` at depth `depth_m`, whose centre lies `rho_m` from the load's line of
/// action (Boussinesq: `σ_z = 3 P z³ / (2 π (r² + z²)^(5/2))`).
///
/// Along each direction from the load the share beyond horizontal distance `r` is
/// `z³ / (r² + z²)^(3/2)`, so a direction that crosses the disc between `r1` and `r2` carries
/// the difference; the directions are averaged ([`QUADRATURE_DIRECTIONS`] midpoints).
pub fn load_fraction_on_disc(rho_m: f64, radius_m: f64, depth_m: f64) -> f64 {
    if !(radius_m > 0.0) || !(depth_m > 0.0) || !rho_m.is_finite() {
        return 0.0;
    }
    let z3 = depth_m * depth_m * depth_m;
    let beyond = |r: f64| z3 / libm::pow(r * r + depth_m * depth_m, 1.5);
    let rho = rho_m.abs();
    let mut sum = 0.0;
    for k in 0..QUADRATURE_DIRECTIONS {
        let th = 2.0 * PI * (k as f64 + 0.5) / QUADRATURE_DIRECTIONS as f64;
        let c = rho * libm::cos(th);
        let disc = c * c - rho * rho + radius_m * radius_m;
        if disc < 0.0 {
            continue;
        }
        let s = libm::sqrt(disc);
        let (r1, r2) = ((c - s).max(0.0), c + s);
        if r2 > r1 {
            sum += beyond(r1) - beyond(r2);
        }
    }
    sum / QUADRATURE_DIRECTIONS as f64
}

/// A rigid inclusion in the phantom. Positions are on the phantom's surface plane, in m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inclusion {
    /// A flat disc (a coin) lying parallel to the surface, its top face `depth_m` down.
    Disc {
        /// Centre, x.
        x_m: f64,
        /// Centre, y.
        y_m: f64,
        /// Radius.
        radius_m: f64,
        /// Depth of its top face.
        depth_m: f64,
    },
    /// A sphere (a steel ball), its top `depth_m` down.
    Sphere {
        /// Centre, x.
        x_m: f64,
        /// Centre, y.
        y_m: f64,
        /// Radius.
        radius_m: f64,
        /// Depth of its top.
        depth_m: f64,
    },
}

impl Inclusion {
    /// Centre on the surface plane `(x, y)`, m.
    pub fn centre_m(&self) -> (f64, f64) {
        match *self {
            Inclusion::Disc { x_m, y_m, .. } | Inclusion::Sphere { x_m, y_m, .. } => (x_m, y_m),
        }
    }
    /// Radius of its outline seen from above, m.
    pub fn radius_m(&self) -> f64 {
        match *self {
            Inclusion::Disc { radius_m, .. } | Inclusion::Sphere { radius_m, .. } => radius_m,
        }
    }
    /// Depth of its top under the surface, m.
    pub fn depth_m(&self) -> f64 {
        match *self {
            Inclusion::Disc { depth_m, .. } | Inclusion::Sphere { depth_m, .. } => depth_m,
        }
    }
    /// The same inclusion with its top `depth_m` under the surface, m.
    pub fn with_depth_m(mut self, depth_m: f64) -> Self {
        match &mut self {
            Inclusion::Disc { depth_m: d, .. } | Inclusion::Sphere { depth_m: d, .. } => {
                *d = depth_m
            }
        }
        self
    }

    /// `(w, h)` at surface point `(x, y)`: the load share the inclusion carries and the layer
    /// thickness between the contact and its nearest point.
    pub fn support_at(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        let (cx, cy) = self.centre_m();
        let rho = libm::hypot(x_m - cx, y_m - cy);
        match *self {
            Inclusion::Disc {
                radius_m, depth_m, ..
            } => {
                let h = if rho <= radius_m {
                    depth_m
                } else {
                    libm::hypot(rho - radius_m, depth_m)
                };
                (load_fraction_on_disc(rho, radius_m, depth_m), h)
            }
            Inclusion::Sphere {
                radius_m, depth_m, ..
            } => {
                let zc = depth_m + radius_m;
                let h = libm::hypot(rho, zc) - radius_m;
                (load_fraction_on_disc(rho, radius_m, zc), h)
            }
        }
    }
}

/// What an inclusion is made of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LumpMaterial {
    /// Rigid (a coin, a steel ball): no strain in it, so no loss.
    Rigid,
    /// A linear viscoelastic solid (a tumour-like lump).
    Tissue {
        /// Storage modulus `E'_l`, Pa.
        modulus_pa: f64,
        /// Loss tangent `η_l = E''_l / E'_l`.
        loss_tangent: f64,
    },
}

/// A soft phantom bonded on a rigid table, with one inclusion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumpPhantom {
    /// Short name.
    pub name: &'static str,
    /// Where it comes from and what is assumed.
    pub source: &'static str,
    /// The soft material.
    pub matrix: Tissue,
    /// Thickness of the soft material over the table, m.
    pub thickness_m: f64,
    /// Outline of the phantom seen from above: a disc of this radius centred on the origin
    /// (`None`: wider than any scan).
    pub outline_radius_m: Option<f64>,
    /// The inclusion.
    pub inclusion: Inclusion,
    /// What the inclusion is made of.
    pub material: LumpMaterial,
}

/// The apparent modulus under the probe and how it came about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Apparent {
    /// Apparent Young's (storage) modulus, Pa.
    pub modulus_pa: f64,
    /// Apparent loss tangent `Im E*_app / Re E*_app`.
    pub loss_tangent: f64,
    /// Contact radius, m (self-consistent).
    pub contact_radius_m: f64,
    /// Load share carried by the inclusion.
    pub inclusion_share: f64,
    /// Layer thickness between the contact and the inclusion, m.
    pub layer_over_inclusion_m: f64,
}

impl LumpPhantom {
    /// `E*_app / E_bg` (complex) for contact radius `a`, load share `w` and layer `h` over the
    /// inclusion (module docs).
    fn relative_modulus(&self, a: f64, w: f64, h: f64) -> Complex64 {
        let phi_h = thin_layer_factor(a / h.max(1e-12));
        let phi_big = thin_layer_factor(a / self.thickness_m.max(1e-12));
        let bg = Complex64::new(1.0, self.matrix.loss_tangent);
        let through_inclusion = match self.material {
            LumpMaterial::Rigid => bg * phi_h,
            LumpMaterial::Tissue {
                modulus_pa,
                loss_tangent,
            } => {
                let lump =
                    Complex64::new(1.0, loss_tangent) * (modulus_pa / self.matrix.modulus_pa);
                // The slice the inclusion takes from the layer's compliance (none where the
                // layer over it is deeper than the table).
                let slice = (1.0 / phi_big - 1.0 / phi_h).max(0.0);
                1.0 / (1.0 / (bg * phi_h) + slice / lump)
            }
        };
        through_inclusion * w + bg * (phi_big * (1.0 - w))
    }

    /// The apparent modulus and loss tangent under a contact at surface point `(x, y)`.
    pub fn apparent(&self, x_m: f64, y_m: f64, contact: &Contact) -> Apparent {
        let (w, h) = self.inclusion.support_at(x_m, y_m);
        let a_h = contact_radius_m(&self.matrix, contact);
        let factor = |a: f64| self.relative_modulus(a, w, h).re;
        // a³ Φ(a) = a_H³ (saturated contacts keep the probe radius).
        let mut a = a_h;
        if a_h < contact.probe_radius_m {
            for _ in 0..50 {
                let next = a_h / libm::cbrt(factor(a));
                let done = (next - a).abs() < 1e-12 * a_h;
                a = next;
                if done {
                    break;
                }
            }
        }
        let y = self.relative_modulus(a, w, h);
        Apparent {
            modulus_pa: self.matrix.modulus_pa * y.re,
            loss_tangent: y.im / y.re,
            contact_radius_m: a,
            inclusion_share: w,
            layer_over_inclusion_m: h,
        }
    }

    /// The tissue the probe feels at `(x, y)`: the matrix with its apparent modulus and loss
    /// tangent.
    pub fn tissue_at(&self, x_m: f64, y_m: f64, contact: &Contact) -> Tissue {
        let app = self.apparent(x_m, y_m, contact);
        Tissue {
            modulus_pa: app.modulus_pa,
            loss_tangent: app.loss_tangent,
            ..self.matrix
        }
    }

    /// True when the matrix or the inclusion has any loss.
    pub fn is_lossy(&self) -> bool {
        let lump = match self.material {
            LumpMaterial::Rigid => 0.0,
            LumpMaterial::Tissue { loss_tangent, .. } => loss_tangent,
        };
        self.matrix.loss_tangent > 0.0 || lump > 0.0
    }

    /// The phantom with its matrix's loss tangent set to `loss_tangent`.
    pub fn with_matrix_loss(mut self, loss_tangent: f64) -> Self {
        self.matrix.loss_tangent = loss_tangent;
        self
    }

    /// The phantom with its inclusion made of `material`.
    pub fn with_material(mut self, material: LumpMaterial) -> Self {
        self.material = material;
        self
    }

    /// `base` (probe, front end, noise, preload) pressed onto the phantom at `(x, y)`.
    pub fn scene_at(&self, base: &Scene, x_m: f64, y_m: f64) -> Scene {
        Scene {
            tissue: Some(self.tissue_at(x_m, y_m, &base.contact)),
            ..*base
        }
    }

    /// True when `(x, y)` lies on the phantom at least `margin_m` inside its outline.
    pub fn contains(&self, x_m: f64, y_m: f64, margin_m: f64) -> bool {
        match self.outline_radius_m {
            Some(r) => libm::hypot(x_m, y_m) <= r - margin_m,
            None => true,
        }
    }
}

/// Silicone of paper 003's lump sample: the modulus the paper reads away from the lump
/// (206.3 Hz → 151.8 kPa by eq. 5), ν = 0.49, 1000 kg/m³.
pub fn paper003_silicone() -> Tissue {
    Tissue::with_modulus_kpa(151.8)
}

/// Paper 003's lump sample: a silicone disc 30 mm across and 15 mm thick with a coin 1 mm under
/// the surface. The paper gives neither the coin's size nor its place: a 19 mm coin (the size of
/// a 1-jiao coin) is assumed, centred at `(x, y)` mm.
pub fn paper003_coin(x_mm: f64, y_mm: f64) -> LumpPhantom {
    LumpPhantom {
        name: "coin",
        source: "paper 003 lump sample: silicone disc 30 mm x 15 mm, coin 1 mm under the surface (coin 19 mm across: assumed)",
        matrix: paper003_silicone(),
        thickness_m: 15e-3,
        outline_radius_m: Some(15e-3),
        inclusion: Inclusion::Disc {
            x_m: x_mm * 1e-3,
            y_m: y_mm * 1e-3,
            radius_m: 9.5e-3,
            depth_m: 1.0e-3,
        },
        material: LumpMaterial::Rigid,
    }
}

/// Paper 002's hidden mass: a stainless-steel ball in the Dragon Skin 20 phantom (tissue 3, the
/// one 002 used for its hidden-mass study), at `d` mm along the probe path (002: 0–20 mm). The
/// paper gives neither the ball's size and depth nor the block's thickness: a 6 mm ball with
/// its top 1 mm under the surface of a 10 mm block is assumed.
pub fn paper002_ball(d_mm: f64) -> LumpPhantom {
    let ds = crate::phantoms::silicones()[2];
    LumpPhantom {
        name: "ball",
        source: "paper 002 hidden mass: steel ball in Dragon Skin 20 (ball 6 mm, top 1 mm deep, block 10 mm: assumed)",
        matrix: ds.tissue(),
        thickness_m: 10e-3,
        outline_radius_m: None,
        inclusion: Inclusion::Sphere {
            x_m: d_mm * 1e-3,
            y_m: 0.0,
            radius_m: 3e-3,
            depth_m: 1.0e-3,
        },
        material: LumpMaterial::Rigid,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thin_layer_factor_is_dimitriadis() {
        assert_eq!(thin_layer_factor(0.0), 1.0);
        let x: f64 = 0.4;
        let expect = 1.0 + 1.133 * x + 1.283 * x * x + 0.769 * x.powi(3) + 0.0975 * x.powi(4);
        assert!((thin_layer_factor(x) - expect).abs() < 1e-12);
        // Capped at chi = 1.
        assert_eq!(thin_layer_factor(5.0), thin_layer_factor(1.0));
        assert_eq!(thin_layer_factor(f64::NAN), thin_layer_factor(1.0));
    }

    #[test]
    fn boussinesq_share_closed_forms() {
        // Centred disc: 1 - z^3 / (R^2 + z^2)^(3/2).
        let (r, z): (f64, f64) = (9.5e-3, 1e-3);
        let expect = 1.0 - z * z * z / (r * r + z * z).powf(1.5);
        assert!((load_fraction_on_disc(0.0, r, z) - expect).abs() < 1e-9);
        // Over the edge of a disc much wider than deep: a half-plane carries one half.
        let edge = load_fraction_on_disc(0.5, 0.5, 1e-3);
        assert!((edge - 0.5).abs() < 0.01, "{edge}");
        // Beyond a straight edge at distance s: 1/2 - (atan t + t/(1+t^2))/pi, t = s/z.
        let t: f64 = 2.0;
        let half_plane = 0.5 - (t.atan() + t / (1.0 + t * t)) / PI;
        let got = load_fraction_on_disc(1.0 + t * 1e-3, 1.0, 1e-3);
        assert!((got - half_plane).abs() < 2e-3, "{got} vs {half_plane}");
        // Far away: nothing.
        assert!(load_fraction_on_disc(30e-3, 9.5e-3, 1e-3) < 1e-4);
    }

    #[test]
    fn coin_contrast_and_self_consistent_contact() {
        let p = paper003_coin(0.0, 0.0);
        let c = Contact::default();
        let over = p.apparent(0.0, 0.0, &c);
        let away = p.apparent(14e-3, 0.0, &c);
        // Over the coin: ~1.55 x the silicone (Dimitriadis at a/h ~ 0.33).
        let e_over = over.modulus_pa / 1e3;
        assert!(e_over > 225.0 && e_over < 245.0, "{e_over}");
        // Away: the 15 mm layer adds ~3 %.
        let e_away = away.modulus_pa / 1e3;
        assert!(e_away > 152.0 && e_away < 160.0, "{e_away}");
        // The contact radius is the Hertz radius of the apparent modulus.
        let t = p.tissue_at(0.0, 0.0, &c);
        assert!((contact_radius_m(&t, &c) - over.contact_radius_m).abs() < 1e-9);
        // Monotone fall-off beyond the edge.
        let mut last = f64::INFINITY;
        for k in 0..8 {
            let e = p.apparent(8e-3 + k as f64 * 1e-3, 0.0, &c).modulus_pa;
            assert!(e <= last);
            last = e;
        }
    }

    #[test]
    fn a_rigid_lump_carries_the_matrix_loss_everywhere() {
        // A rigid inclusion stores no strain energy: E*_app = (1 + j η_bg) E_app, so the
        // storage modulus is the lossless model's and the loss tangent the matrix's, at every
        // point (equal up to rounding).
        let c = Contact::default();
        for p in [paper003_coin(1.5, -1.0), paper002_ball(5.0)] {
            let lossy = p.with_matrix_loss(0.3);
            for x in [-12.0, -4.0, 0.0, 1.5, 5.0, 9.0] {
                let (a, b) = (
                    p.apparent(x * 1e-3, 0.0, &c),
                    lossy.apparent(x * 1e-3, 0.0, &c),
                );
                assert!((a.modulus_pa / b.modulus_pa - 1.0).abs() < 1e-12, "{x}");
                assert_eq!(a.loss_tangent, 0.0);
                assert!(
                    (b.loss_tangent - 0.3).abs() < 1e-12,
                    "{x}: {}",
                    b.loss_tangent
                );
                let t = lossy.tissue_at(x * 1e-3, 0.0, &c);
                assert_eq!(t.loss_tangent, b.loss_tangent);
            }
        }
    }

    #[test]
    fn a_compliant_lump_lies_between_no_lump_and_a_rigid_one() {
        let c = Contact::default();
        let coin = paper003_coin(0.0, 0.0).with_matrix_loss(0.3);
        let e_bg = coin.matrix.modulus_pa;
        let lump = |k: f64, eta: f64| {
            coin.with_material(LumpMaterial::Tissue {
                modulus_pa: k * e_bg,
                loss_tangent: eta,
            })
        };
        let rigid = coin.apparent(0.0, 0.0, &c);
        // A lump of the matrix's own material is no lump: the bare layer's E*_bg Φ(a/H) over
        // it and beside it alike (equal up to rounding).
        let same = lump(1.0, 0.3).apparent(0.0, 0.0, &c);
        let beside = lump(1.0, 0.3).apparent(14e-3, 0.0, &c);
        assert!((same.modulus_pa / beside.modulus_pa - 1.0).abs() < 1e-12);
        assert!(same.modulus_pa < 1.05 * e_bg, "{}", same.modulus_pa);
        assert!((same.loss_tangent - 0.3).abs() < 1e-12);
        // Stiffer lumps of the matrix's loss tangent: stiffer over the lump, rising towards
        // the rigid one with E_l, and exactly the matrix's loss tangent (no loss anomaly).
        let mut last = same.modulus_pa;
        for k in [2.0, 5.0, 20.0, 1e6] {
            let a = lump(k, 0.3).apparent(0.0, 0.0, &c);
            assert!(
                a.modulus_pa > last && a.modulus_pa < rigid.modulus_pa,
                "{k}"
            );
            assert!(
                (a.loss_tangent - 0.3).abs() < 1e-12,
                "{k}: {}",
                a.loss_tangent
            );
            last = a.modulus_pa;
        }
        assert!((last / rigid.modulus_pa - 1.0).abs() < 1e-5);
        // A lump of another loss tangent: the closed form of the series-parallel blend by
        // hand in real arithmetic, at the model's own contact radius, w and h.
        let (k, eta_l, eta_b) = (5.0, 0.05, 0.3);
        let a = lump(k, eta_l).apparent(0.0, 0.0, &c);
        let (w, h) = coin.inclusion.support_at(0.0, 0.0);
        let ph = thin_layer_factor(a.contact_radius_m / h);
        let pb = thin_layer_factor(a.contact_radius_m / coin.thickness_m);
        let slice = 1.0 / pb - 1.0 / ph;
        // 1/(1 + jη) = (1 − jη)/(1 + η²): the compliance's real and imaginary parts.
        let (cr, ci) = (
            1.0 / ph / (1.0 + eta_b * eta_b) + slice / k / (1.0 + eta_l * eta_l),
            -(eta_b / ph / (1.0 + eta_b * eta_b) + slice * eta_l / k / (1.0 + eta_l * eta_l)),
        );
        let n = cr * cr + ci * ci;
        let (yr, yi) = (
            w * cr / n + (1.0 - w) * pb,
            -w * ci / n + (1.0 - w) * pb * eta_b,
        );
        assert!((a.modulus_pa / (e_bg * yr) - 1.0).abs() < 1e-12);
        assert!((a.loss_tangent - yi / yr).abs() < 1e-12);
        // A less lossy lump lowers the loss over it; far away the matrix's loss remains.
        assert!(a.loss_tangent < eta_b - 0.01, "{}", a.loss_tangent);
        let away = lump(k, eta_l).apparent(14e-3, 0.0, &c);
        assert!(
            (away.loss_tangent - eta_b).abs() < 1e-3,
            "{}",
            away.loss_tangent
        );
    }

    #[test]
    fn ball_peaks_over_its_centre() {
        let p = paper002_ball(5.0);
        let c = Contact::default();
        let at = |x: f64| p.apparent(x * 1e-3, 0.0, &c).modulus_pa;
        assert!(at(5.0) > at(3.0) && at(3.0) > at(0.0) && at(0.0) > at(-5.0));
        assert!((at(3.0) - at(7.0)).abs() < 1e-6 * at(5.0));
    }
}
