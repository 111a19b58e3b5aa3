//! Layer 1: the Kelvin model of paper 003 (eq. 1–3) with the appendix contact formulas.
//!
//! The probe is one mode: modal mass `m`, stiffness `k1`, damping `c1`. Pressed onto tissue, the
//! tissue adds a Kelvin element — stiffness `k_m`, damping `c_m`, co-moving mass `m_m` — from the
//! appendix:
//!
//! * `k_m = 2 E a / (1 - nu^2)` (Hertz/Boussinesq contact stiffness, contact radius `a`),
//! * `c_m = kappa * rho * v * S / (1 - nu)`, `v = sqrt(E / (2 (1 + nu) rho))`, `S = pi a^2`,
//! * `m_m = gamma * rho * S^(3/2) / (1 - nu)`,
//!
//! with the contact radius from Hertz contact of the spherical tip under the preload,
//! `a = (3 F R / (4 E*))^(1/3)`, `E* = E / (1 - nu^2)`, saturating at the probe radius.
//!
//! The tissue's elastic restoring force and its co-moving mass reach the mode through the probe's
//! series coupling compliance `k_s` (the bond and local plate stiffness between the mode and the
//! tip). Eliminating the contact node in the Rayleigh sense (node displacement `s x`,
//! `s = k_s / (k_s + k_m)`) keeps eq. 1 a one-degree-of-freedom equation with
//! `k = k1 + s k_m` and `m = m + s^2 m_m`. The tissue's dissipation is driven by the tip's own
//! velocity and is added directly, `c = c1 + c_m`. Without `k_s` the Hertz stiffness (growing as
//! `E^(2/3)`) would drive the resonance far above the saturating experimental curve of the
//! paper; with it the loaded resonance tends to `sqrt((k1 + k_s) / m)` for rigid tissue. The free
//! constants are fitted in `docs/physics.md`.

use core::f64::consts::PI;

/// Tissue under the tip (small-strain, linear viscoelastic).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tissue {
    /// Small-strain Young's modulus in Pa.
    pub modulus_pa: f64,
    /// Poisson ratio (soft tissue and silicone: 0.49).
    pub poisson: f64,
    /// Density in kg/m^3.
    pub density_kg_m3: f64,
    /// Viscoelastic loss tangent `eta = E''/E'` of the tissue at the resonance (0 for the plain
    /// Kelvin model). The contact stiffness becomes complex, `k_m (1 + j eta)`; through the
    /// series coupling it reaches the mode as `s k_m (1 + j s eta)` to first order in `eta`
    /// (`s = k_s / (k_s + k_m)`), i.e. a loss `s² eta k_m`, added as the viscous damping
    /// `s² eta k_m / omega_0` that dissipates the same at the loaded resonance `omega_0`. Ours:
    /// a constant loss tangent over the band (docs/physics.md, "Viscoelastic tissue").
    pub loss_tangent: f64,
}

impl Tissue {
    /// Tissue of the given small-strain modulus (kPa) with `nu = 0.49`, `rho = 1000 kg/m^3`.
    pub fn with_modulus_kpa(modulus_kpa: f64) -> Self {
        Self {
            modulus_pa: modulus_kpa * 1e3,
            poisson: 0.49,
            density_kg_m3: 1000.0,
            loss_tangent: 0.0,
        }
    }
}

/// How the probe is pressed onto the tissue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Preload (contact force) in N; the paper uses 30 mN.
    pub preload_n: f64,
    /// Radius of the spherical tip in m (0.5 mm).
    pub tip_radius_m: f64,
    /// Radius of the probe shaft in m (0.5 mm): the contact radius saturates there.
    pub probe_radius_m: f64,
}

impl Default for Contact {
    fn default() -> Self {
        Self {
            preload_n: 0.030,
            tip_radius_m: 0.5e-3,
            probe_radius_m: 0.5e-3,
        }
    }
}

/// The probe's own mechanics and the fitted contact constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorMech {
    /// Modal mass `m` in kg.
    pub mass_kg: f64,
    /// Free resonance in Hz (sets `k1 = m (2 pi f)^2`).
    pub free_resonance_hz: f64,
    /// Quality factor of the free (unloaded) probe (sets `c1`).
    pub free_q: f64,
    /// Series coupling stiffness `k_s` between the mode and the tip, N/m.
    pub coupling_stiffness_n_m: f64,
    /// Co-moving tissue mass coefficient `gamma` (appendix: `m_m = gamma rho S^1.5 / (1 - nu)`).
    pub mass_coefficient: f64,
    /// Tissue damping coefficient `kappa` (appendix: `c_m = kappa rho v S / (1 - nu)`).
    pub damping_coefficient: f64,
}

impl Default for SensorMech {
    /// The constants fitted to paper 003 (see `docs/physics.md`).
    fn default() -> Self {
        Self {
            mass_kg: 510e-6,
            free_resonance_hz: 232.3,
            free_q: 40.0,
            coupling_stiffness_n_m: 350.0,
            mass_coefficient: 720.0,
            damping_coefficient: 11.5,
        }
    }
}

impl SensorMech {
    /// Probe stiffness `k1` in N/m.
    pub fn k1(&self) -> f64 {
        let w = 2.0 * PI * self.free_resonance_hz;
        self.mass_kg * w * w
    }
    /// Probe damping `c1` in N s/m.
    pub fn c1(&self) -> f64 {
        libm::sqrt(self.k1() * self.mass_kg) / self.free_q
    }
    /// The unloaded probe as a Kelvin oscillator.
    pub fn free(&self) -> Kelvin {
        Kelvin {
            mass_kg: self.mass_kg,
            stiffness_n_m: self.k1(),
            damping_n_s_m: self.c1(),
        }
    }

    /// The probe pressed onto `tissue` with `contact`.
    pub fn loaded(&self, tissue: &Tissue, contact: &Contact) -> Kelvin {
        let el = TissueElements::new(tissue, contact, self);
        let s = self.coupling_stiffness_n_m / (self.coupling_stiffness_n_m + el.stiffness_n_m);
        let free = self.free();
        let mass_kg = free.mass_kg + s * s * el.mass_kg;
        let stiffness_n_m = free.stiffness_n_m + s * el.stiffness_n_m;
        let w0 = libm::sqrt(stiffness_n_m / mass_kg);
        let loss = if tissue.loss_tangent > 0.0 && w0 > 0.0 {
            s * s * tissue.loss_tangent * el.stiffness_n_m / w0
        } else {
            0.0
        };
        Kelvin {
            mass_kg,
            stiffness_n_m,
            damping_n_s_m: free.damping_n_s_m + el.damping_n_s_m + loss,
        }
    }
}

/// Hertz contact radius in m of the spherical tip on `tissue`, saturating at the probe radius.
pub fn contact_radius_m(tissue: &Tissue, contact: &Contact) -> f64 {
    let e_star = tissue.modulus_pa / (1.0 - tissue.poisson * tissue.poisson);
    if !(e_star > 0.0) {
        return contact.probe_radius_m;
    }
    let a = libm::cbrt(3.0 * contact.preload_n * contact.tip_radius_m / (4.0 * e_star));
    a.min(contact.probe_radius_m)
}

/// The tissue's Kelvin elements at the contact (before the series coupling).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TissueElements {
    /// Contact radius `a` in m.
    pub contact_radius_m: f64,
    /// `k_m` in N/m.
    pub stiffness_n_m: f64,
    /// `c_m` in N s/m: the contact's radiation damping (the tissue's own loss reaches the
    /// mode through the coupling, [`SensorMech::loaded`]).
    pub damping_n_s_m: f64,
    /// `m_m` in kg.
    pub mass_kg: f64,
}

impl TissueElements {
    /// Appendix formulas of paper 003 for `tissue` under `contact`.
    pub fn new(tissue: &Tissue, contact: &Contact, mech: &SensorMech) -> Self {
        let nu = tissue.poisson;
        let rho = tissue.density_kg_m3;
        let e = tissue.modulus_pa.max(0.0);
        let a = contact_radius_m(tissue, contact);
        let area = PI * a * a;
        let k_m = 2.0 * e * a / (1.0 - nu * nu);
        let v = libm::sqrt(e / (2.0 * (1.0 + nu) * rho));
        let c_m = mech.damping_coefficient * rho * v * area / (1.0 - nu);
        let m_m = mech.mass_coefficient * rho * libm::pow(area, 1.5) / (1.0 - nu);
        Self {
            contact_radius_m: a,
            stiffness_n_m: k_m,
            damping_n_s_m: c_m,
            mass_kg: m_m,
        }
    }
}

/// A second mechanical mode of the probe, driven by the PZT but not moving the tip.
///
/// Paper 003's modal analysis finds modes at 230, 326, 391 and 1332 Hz, of which only the first
/// moves the probe; the second (326 Hz) bends the spiral plate under the PZT, so the PZT drives it
/// and senses it while the tissue does not load it. A mount, a bond or a temperature change can
/// pull it down towards the measuring band. It is a second motional branch in parallel with the
/// first: `Y_2 = alpha_2^2 / (c_2 + j w m_2 + k_2 / (j w))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondMode {
    /// Modal mass in kg.
    pub mass_kg: f64,
    /// Resonance in Hz (sets `k_2 = m_2 (2 pi f_2)^2`).
    pub resonance_hz: f64,
    /// Quality factor (sets `c_2`).
    pub q: f64,
    /// Force factor `alpha_2` of the PZT on this mode, N/V (= A s/m).
    pub force_factor_n_v: f64,
}

impl SecondMode {
    /// The mode at `resonance_hz` with quality `q` and the probe's modal mass, its coupling set
    /// so that its peak motional conductance `alpha_2^2 / c_2` is `peak_s` siemens.
    pub fn with_peak_conductance(resonance_hz: f64, q: f64, peak_s: f64) -> Self {
        let mass_kg = SensorMech::default().mass_kg;
        let c = mass_kg * 2.0 * PI * resonance_hz / q;
        Self {
            mass_kg,
            resonance_hz,
            q,
            force_factor_n_v: libm::sqrt(peak_s.max(0.0) * c),
        }
    }
    /// The mode as a Kelvin oscillator.
    pub fn kelvin(&self) -> Kelvin {
        let w = 2.0 * PI * self.resonance_hz;
        Kelvin {
            mass_kg: self.mass_kg,
            stiffness_n_m: self.mass_kg * w * w,
            damping_n_s_m: self.mass_kg * w / self.q,
        }
    }
    /// Peak motional conductance `alpha_2^2 / c_2` in S.
    pub fn peak_conductance_s(&self) -> f64 {
        self.force_factor_n_v * self.force_factor_n_v / self.kelvin().damping_n_s_m
    }
}

/// A one-degree-of-freedom Kelvin oscillator `m x'' + c x' + k x = F` (paper 003 eq. 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kelvin {
    /// Mass in kg.
    pub mass_kg: f64,
    /// Stiffness in N/m.
    pub stiffness_n_m: f64,
    /// Damping in N s/m.
    pub damping_n_s_m: f64,
}

impl Kelvin {
    /// Undamped natural frequency `sqrt(k/m) / 2 pi` in Hz (eq. 2): also the frequency of the
    /// conductance maximum of the motional branch.
    pub fn natural_frequency_hz(&self) -> f64 {
        libm::sqrt(self.stiffness_n_m / self.mass_kg) / (2.0 * PI)
    }
    /// Quality factor `sqrt(k m) / c`.
    pub fn q(&self) -> f64 {
        libm::sqrt(self.stiffness_n_m * self.mass_kg) / self.damping_n_s_m
    }
    /// Amplitude decay time constant `2 m / c` in s (= Q / (pi f0)).
    pub fn time_constant_s(&self) -> f64 {
        2.0 * self.mass_kg / self.damping_n_s_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_tangent_adds_s2_eta_km_over_k_to_the_inverse_q() {
        // 1/Q = C / sqrt(K M); the loss adds C = s² η k_m / ω0 with ω0 = sqrt(K/M), so
        // Δ(1/Q) = s² η k_m / K, whatever the modulus.
        let mech = SensorMech::default();
        let contact = Contact::default();
        for e_kpa in [150.0, 700.0, 2500.0] {
            let lossless = Tissue::with_modulus_kpa(e_kpa);
            let lossy = Tissue {
                loss_tangent: 0.4,
                ..lossless
            };
            let (a, b) = (
                mech.loaded(&lossless, &contact),
                mech.loaded(&lossy, &contact),
            );
            assert_eq!(a.stiffness_n_m, b.stiffness_n_m);
            assert_eq!(a.mass_kg, b.mass_kg);
            let el = TissueElements::new(&lossless, &contact, &mech);
            let s = mech.coupling_stiffness_n_m / (mech.coupling_stiffness_n_m + el.stiffness_n_m);
            let expect = s * s * 0.4 * el.stiffness_n_m / a.stiffness_n_m;
            let got = 1.0 / b.q() - 1.0 / a.q();
            assert!(
                (got / expect - 1.0).abs() < 1e-12,
                "{e_kpa}: {got} vs {expect}"
            );
        }
    }

    #[test]
    fn hertz_radius_closed_form() {
        // E = 1 MPa, nu = 0.49: E* = 1e6 / 0.7599 = 1.31596 MPa;
        // a^3 = 3 * 0.03 N * 0.5e-3 m / (4 E*) = 8.54887e-12 m^3, a = 0.204473 mm (worked by
        // hand; the tolerance is the rounding of the sixth digit).
        let t = Tissue::with_modulus_kpa(1000.0);
        let a = contact_radius_m(&t, &Contact::default());
        assert!((a - 0.204473e-3).abs() <= 0.0000005e-3, "{a}");
        // Soft tissue saturates at the probe radius.
        let soft = Tissue::with_modulus_kpa(8.0);
        assert_eq!(contact_radius_m(&soft, &Contact::default()), 0.5e-3);
    }

    /// Natural frequency (Hz) and Q of a sampled free decay `x[n]` (sample rate `fs`) by
    /// Prony's method: a damped sinusoid obeys `x[n+1] = p1 x[n] + p2 x[n-1]` exactly, with
    /// poles `z = e^{(-s ± j w_d) dt}`, so `|z|^2 = -p2` and `cos(w_d dt) = p1 / (2 |z|)`;
    /// `w_n = sqrt(w_d^2 + s^2)`, `Q = w_n / (2 s)`. `(p1, p2)` by least squares over the
    /// samples, accumulated as they come (no allocation: the crate is `no_std`).
    #[derive(Default)]
    struct Prony {
        last: [f64; 2],
        n: usize,
        s: [f64; 5],
    }

    impl Prony {
        fn push(&mut self, y: f64) {
            let [b, a] = self.last;
            if self.n >= 2 {
                for (acc, v) in self.s.iter_mut().zip([a * a, a * b, b * b, a * y, b * y]) {
                    *acc += v;
                }
            }
            self.last = [a, y];
            self.n += 1;
        }

        fn natural_hz_and_q(&self, fs: f64) -> (f64, f64) {
            let [s11, s12, s22, t1, t2] = self.s;
            let det = s11 * s22 - s12 * s12;
            let p1 = (s22 * t1 - s12 * t2) / det;
            let p2 = (s11 * t2 - s12 * t1) / det;
            let r = libm::sqrt(-p2);
            let wd = libm::acos(p1 / (2.0 * r)) * fs;
            let s = -libm::log(r) * fs;
            let wn = libm::sqrt(wd * wd + s * s);
            (wn / (2.0 * PI), wn / (2.0 * s))
        }
    }

    /// Ring `scene`'s probe as the simulator runs it with a 20 ms burst of 600 codes at
    /// `drive_hz`, hold the DAC at mid-scale and read the mode's free decay from its velocity,
    /// 30 ms to `seconds`, by Prony's method: (natural frequency in Hz, Q).
    fn ring_down(scene: crate::Scene, drive_hz: f64, seconds: f64) -> (f64, f64) {
        use crate::frontend::MID_CODE;
        use crate::{AdcPair, SimProbe};
        let mut p = SimProbe::new(scene, 1);
        let fs = p.front_end().sample_rate_hz;
        let mut adc = [AdcPair::default()];
        let mut decay = Prony::default();
        for k in 0..(seconds * fs) as usize {
            let t = k as f64 / fs;
            let code = if t < 0.02 {
                libm::round(MID_CODE as f64 + 600.0 * libm::sin(2.0 * PI * drive_hz * t)) as u16
            } else {
                MID_CODE
            };
            p.exchange(&[code], &mut adc);
            if t >= 0.03 {
                decay.push(p.velocity_m_s());
            }
        }
        decay.natural_hz_and_q(fs)
    }

    #[test]
    fn free_probe_is_232_hz() {
        // The free probe as the simulator runs it (the exactly discretised 8-state chain of
        // `SimProbe`, free air, 10 kHz): ring it with a 20 ms burst near resonance, hold the DAC
        // at mid-scale (0 V) and read the mode's own free decay from its velocity, 30 ms (the
        // two-pole 1 kHz reconstruction filter has forgotten the burst to 1e-12) to 1 s.
        let (f, q) = ring_down(crate::Scene::free_air(), 232.0, 1.0);
        // Reference 1, paper 003: the prototype's measured free resonance, 232.3 Hz; and the
        // free Q of 40 that docs/physics.md states. On noise-free samples of an exact
        // discretisation Prony's method is exact up to rounding: measured errors 3e-11 Hz
        // (232.299999999968) and 9e-10 in Q (40.000000000884); the tolerances are ten times
        // those.
        assert!(
            (f - 232.3).abs() < 1e-9,
            "free decay {f} Hz vs the paper's 232.3 Hz"
        );
        assert!((q - 40.0).abs() < 1e-8, "free decay Q {q} vs 40");
        // Reference 2, the closed form w = sqrt(k/m) from the constants docs/physics.md
        // documents: m0 = 510 mg, k1 = 1086 N/m. k1 is printed to 4 digits (±0.5 N/m, ±2.3e-4
        // of f): 232.25 Hz ± 0.054 Hz.
        let closed = libm::sqrt(1086.0 / 510e-6) / (2.0 * PI);
        let rounding = 0.5 * 0.5 / 1086.0 * closed;
        assert!(
            (f - closed).abs() <= rounding,
            "free decay {f} Hz vs sqrt(k1/m0)/2pi = {closed} ± {rounding} Hz"
        );
    }

    #[test]
    fn named_tissues_ring_down_with_their_lossy_q() {
        // Each named tissue of `phantoms::tissues` as the simulator runs it (the discretised
        // chain of `SimProbe`, pressed at 30 mN, 10 kHz): ring the probe with a 20 ms burst at
        // the loaded resonance, hold the DAC at mid-scale and read the free decay of the mode's
        // velocity from 30 ms to 150 ms by Prony's method. The decay's Q is the Kelvin model's
        // closed form `sqrt(k m) / c` with the tissue's loss in `c` (below the lossless Q).
        use crate::Scene;
        for t in crate::phantoms::tissues() {
            let scene = Scene::on_phantom(&t);
            let k = scene.kelvin();
            let f0 = k.natural_frequency_hz();
            let (f, q) = ring_down(scene, f0, 0.15);
            let mut lossless = t.tissue();
            lossless.loss_tangent = 0.0;
            let q_lossless = Scene::on_tissue(lossless).kelvin().q();
            // Noise-free samples of an exact discretisation: Prony is exact up to rounding
            // (the free probe's test above: 1e-10 relative); 1e-6 leaves room for the faster
            // decay here.
            assert!((f / f0 - 1.0).abs() < 1e-6, "{}: {f} Hz vs {f0} Hz", t.name);
            assert!(
                (q / k.q() - 1.0).abs() < 1e-6,
                "{}: Q {q} vs {}",
                t.name,
                k.q()
            );
            assert!(
                q < q_lossless,
                "{}: Q {q} not below lossless {q_lossless}",
                t.name
            );
        }
    }

    #[test]
    fn rigid_limit() {
        let m = SensorMech::default();
        let k = m.loaded(&Tissue::with_modulus_kpa(1e9), &Contact::default());
        let lim = libm::sqrt((m.k1() + m.coupling_stiffness_n_m) / m.mass_kg) / (2.0 * PI);
        // At E = 1e9 kPa the contact is still finite (k_m = 5.4e6 N/m): the series coupling
        // passes k_s k_m / (k_s + k_m), short of k_s by k_s^2 / k_m = 0.023 N/m, which lowers f
        // by k_s^2 / (2 k_m (k1 + k_s)) f = 0.0021 Hz (measured 0.0021 Hz; the tissue mass,
        // 3e-19 kg through s^2, is nothing). Tolerance: that shortfall plus 0.001 Hz.
        let d = k.natural_frequency_hz() - lim;
        assert!((-0.003..=0.0).contains(&d), "{d} Hz below the rigid limit");
    }
}
