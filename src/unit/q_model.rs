//! The unit's Q model: its quality factor against modulus (and contact force) on the reference
//! phantoms, the contact condition its calibration holds for and the lossless contact a
//! reading's tissue loss is read against. May import the leaves and the contact law.

use crate::linalg::Real;
use crate::unit::contact_law::{ContactLaw, LawAt};
use crate::unit::profile::Reference;

/// The unit's quality factor against modulus on the reference phantoms: the contact condition
/// the calibration holds for. A reading whose Q strays from it by more than
/// [`QModel::TOLERANCE`] was not taken in that condition (a different preload changes the
/// contact area and with it the tissue damping) and its modulus cannot be trusted.
///
/// Two curves: `Q ≈ q0 + q1 ln E + q2 ln F`, empirical, which needs nothing else; and, when the
/// calibration kept the contact law, the contact's own damping ([`DampingModel`]), which
/// follows the mode's Q curve through the contact law and is the one used wherever the law is
/// at hand ([`QModel::q_at`]).
///
/// With the `serde` feature it is (de)serialized as its fields by these names, `q2`,
/// `sigma_rel` and `damping` default when absent and `damping` left out when `None` (the
/// `q_model` object of probe-bench's profile files).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct QModel {
    /// Intercept.
    pub q0: f64,
    /// Slope per unit of `ln(E / kPa)`.
    pub q1: f64,
    /// Slope per unit of `ln(F / N)` of the contact force (0 when the references were read at
    /// one force, or without a load cell).
    #[cfg_attr(feature = "serde", serde(default))]
    pub q2: f64,
    /// Relative scatter of the references' Q about the curve `q0 + q1 ln E + q2 ln F` (the RMS
    /// of `Q/Q_model − 1` with the fitted terms' degrees of freedom taken off).
    #[cfg_attr(feature = "serde", serde(default))]
    pub sigma_rel: f64,
    /// The contact-damping curve, fitted through the contact law the calibration kept (`None`
    /// without one).
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "Option::is_none")
    )]
    pub damping: Option<DampingModel>,
}

/// The lossless Q of the unit's contact from the Kelvin model of paper 003 (docs/physics.md,
/// "Equations"; `hal-sim`'s `tissue.rs`): the loaded mode has the damping `c = c1 + c_m` of
/// the probe and the contact, and `Q = sqrt(k m) / c`, so
///
/// ```text
/// 1/Q = (g1 + g2 (E/kPa)^(−1/6) (F/F0)^(2/3)) / R(E, F)
/// ```
///
/// with `g1 = c1/m0` the probe's own damping and `g2 (E/kPa)^(−1/6) (F/F0)^(2/3) = c_m/m0` the
/// contact's (paper 003's appendix, `c_m ∝ v S` on the Hertz contact:
/// [`ContactLaw::damping_shape`]), both per modal mass, and `R = sqrt(k m)/m0` the loaded
/// mode's rate from the unit's contact law ([`ContactLaw::mode_rate`]: its stiffness and its
/// co-moving tissue mass at `E` and `F`). Two constants, fitted to the reference readings'
/// `R/Q` (linear in them). The mode's Q is not monotonic in `E`: on soft tissue the
/// co-moving mass lowers the rate faster than the contact's damping falls; a curve in `ln E`
/// cannot follow that, this one does by construction.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DampingModel {
    /// The probe's own damping per modal mass `c1/m0`, s⁻¹.
    pub probe_per_s: f64,
    /// The contact's damping per modal mass at 1 kPa and the contact law's reference force,
    /// s⁻¹ (`c_m/m0 = contact_per_s (E/kPa)^(−1/6) (F/F0)^(2/3)`).
    pub contact_per_s: f64,
    /// Relative uncertainty of the curve's Q at a modulus between the references: each interior
    /// reference modulus left out in turn, the curve fitted to the others, the mean `Q/Q_model
    /// − 1` of its readings at each force, RMS over those groups. What a reading's loss
    /// inherits from the curve, beside its own σ(Q).
    pub sigma_rel: f64,
}

/// Least relative spread (max/min) of the references' contact forces for the Q model to fit a
/// force term: below it the forces are one force.
pub const FORCE_SPAN_RATIO: f64 = 1.25;

impl QModel {
    /// Largest relative deviation of Q from the curve that still counts as the calibrated
    /// condition. The reference readings scatter by well under 5 %; doubling the preload lowers
    /// Q by about 30 % in `hal-sim`, which the force term follows when the references span
    /// forces.
    pub const TOLERANCE: f64 = 0.2;

    /// Least-squares fit of `Q = q0 + q1 ln E + q2 ln F` to `(E kPa, F N, Q)` triples: with
    /// the force term when the forces (all measured, positive) span [`FORCE_SPAN_RATIO`], else
    /// `q2 = 0`. `None` with fewer than two distinct moduli or non-finite input.
    pub fn fit<I: IntoIterator<Item = (f64, f64, f64)>>(data: I) -> Option<QModel>
    where
        I::IntoIter: Clone,
    {
        let data = data.into_iter();
        let ok = |&(e, _, q): &(f64, f64, f64)| e > 0.0 && q > 0.0 && e.is_finite();
        let (mut fmin, mut fmax) = (f64::INFINITY, 0.0f64);
        for (_, f, _) in data.clone().filter(ok) {
            fmin = fmin.min(f);
            fmax = fmax.max(f);
        }
        let with_force = fmin > 0.0 && fmax.is_finite() && fmax >= FORCE_SPAN_RATIO * fmin;
        if with_force {
            let mut a = [[0.0; 3]; 3];
            let mut b = [0.0; 3];
            for (e, f, q) in data.clone().filter(ok) {
                let x = [1.0, libm::log(e), libm::log(f)];
                for i in 0..3 {
                    b[i] += x[i] * q;
                    for j in 0..3 {
                        a[i][j] += x[i] * x[j];
                    }
                }
            }
            let inv = crate::linalg::spd_inverse(&a)?;
            let c: [f64; 3] =
                core::array::from_fn(|i| (0..3).map(|j| inv[i][j] * b[j]).sum::<f64>());
            let m = QModel {
                q0: c[0],
                q1: c[1],
                q2: c[2],
                sigma_rel: 0.0,
                damping: None,
            };
            return c
                .iter()
                .all(|v| v.is_finite())
                .then(|| m.with_scatter(data.filter(ok), 3));
        }
        let mut l = crate::linalg::Line::default();
        for (e, _, q) in data.clone().filter(ok) {
            l.add(libm::log(e), q, 1.0);
        }
        let f = l.solve()?;
        let m = QModel {
            q0: f.a,
            q1: f.b,
            q2: 0.0,
            sigma_rel: 0.0,
            damping: None,
        };
        (f.a.is_finite() && f.b.is_finite()).then(|| m.with_scatter(data.filter(ok), 2))
    }

    /// The model with [`Self::sigma_rel`] from `data`, fitted with `terms` terms.
    fn with_scatter<I: Iterator<Item = (f64, f64, f64)>>(self, data: I, terms: usize) -> Self {
        let (mut n, mut ss) = (0usize, 0.0);
        for (e, f, q) in data {
            let expect = self.log_linear_q(e, (f > 0.0).then_some(f));
            if expect > 0.0 {
                let r = q / expect - 1.0;
                ss += r * r;
                n += 1;
            }
        }
        let sigma_rel = libm::sqrt(ss / n.saturating_sub(terms).max(1) as f64);
        Self {
            sigma_rel: if sigma_rel.is_finite() {
                sigma_rel
            } else {
                0.0
            },
            ..self
        }
    }

    /// The empirical curve `q0 + q1 ln E + q2 ln F` at `e_kpa` and contact force `force_n` (N;
    /// the force term is left out for a model without one or without a force), in `T`.
    pub fn log_linear_q<T: Real>(&self, e_kpa: T, force_n: Option<f64>) -> T {
        let f = match force_n {
            Some(f) if self.q2 != 0.0 && f > 0.0 => T::of(self.q2) * T::of(f).ln(),
            _ => T::ZERO,
        };
        T::of(self.q0) + T::of(self.q1) * e_kpa.ln() + f
    }

    /// Expected Q of the lossless calibrated contact at `e_kpa` and contact force `force_n`
    /// (N): the contact-damping curve ([`DampingModel::q_at`]) through `law` when the model has
    /// one and the unit's contact law `law` is given, else the empirical curve
    /// ([`Self::log_linear_q`]).
    pub fn q_at(&self, e_kpa: f64, force_n: Option<f64>, law: Option<&ContactLaw>) -> f64 {
        // The law evaluated only where the curve needs it.
        let law = law
            .filter(|_| self.damping.is_some())
            .map(|l| l.at_force::<f64>(force_n));
        self.q_on(e_kpa, force_n, law.as_ref())
    }

    /// [`Self::q_at`] with the contact law at the reading's force `force_n` already evaluated
    /// ([`ContactLaw::at_force`]), in `T` (a reading's: `f32`).
    pub fn q_on<T: Real>(&self, e_kpa: T, force_n: Option<f64>, law: Option<&LawAt<T>>) -> T {
        match (self.damping, law) {
            (Some(d), Some(law)) => d.q_on(law, e_kpa),
            _ => self.log_linear_q(e_kpa, force_n),
        }
    }

    /// Relative uncertainty of [`Self::q_at`] with `law`: the contact-damping curve's
    /// ([`DampingModel::sigma_rel`]) or the empirical curve's scatter ([`Self::sigma_rel`]).
    pub fn scatter(&self, law: Option<&ContactLaw>) -> f64 {
        match (self.damping, law) {
            (Some(d), Some(_)) => d.sigma_rel,
            _ => self.sigma_rel,
        }
    }

    /// `q`'s relative deviation from the curve at `e_kpa` (and `force_n`), `q / q_at - 1`
    /// ([`Self::q_at`] with `law`), for [`QDeviation::holds`] and [`QDeviation::exceeded`].
    pub fn deviation(
        &self,
        e_kpa: f64,
        force_n: Option<f64>,
        q: f64,
        law: Option<&ContactLaw>,
    ) -> QDeviation {
        QDeviation::of(q, self.q_at(e_kpa, force_n, law))
    }

    /// True when every coefficient is finite and the scatter not negative.
    pub fn is_valid(&self) -> bool {
        self.q0.is_finite()
            && self.q1.is_finite()
            && self.q2.is_finite()
            && self.sigma_rel.is_finite()
            && self.sigma_rel >= 0.0
            && self.damping.is_none_or(|d| d.is_valid())
    }
}

/// A Q's relative deviation from a [`QModel`]'s curve, `q / q_at - 1` ([`QModel::deviation`]);
/// `None` where the curve is not positive (or NaN).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QDeviation(pub Option<f64>);

impl QDeviation {
    /// `q`'s relative deviation from the curve's `expect`.
    pub fn of(q: f64, expect: f64) -> Self {
        QDeviation((expect > 0.0).then(|| q / expect - 1.0))
    }

    /// True when the Q is within [`QModel::TOLERANCE`] of the curve.
    pub fn holds(self) -> bool {
        self.0.is_some_and(|d| libm::fabs(d) <= QModel::TOLERANCE)
    }

    /// True when the Q stands more than [`QModel::TOLERANCE`] above the curve (or the curve
    /// is not positive): a contact narrower or looser than the calibration's (a tip touching on
    /// its edge radiates less into the tissue). Tissue loss only ever lowers Q, so unlike
    /// [`Self::holds`] no lossy tissue can trigger it.
    pub fn exceeded(self) -> bool {
        self.0.is_none_or(|d| d > QModel::TOLERANCE)
    }
}

impl DampingModel {
    /// Expected Q at `e_kpa` and contact force `force_n` (N; the law's reference force when
    /// `None`) through the unit's contact law `law`: `R / (g1 + g2 shape)` ([`DampingModel`]).
    /// Not positive where the damping is not.
    pub fn q_at(&self, law: &ContactLaw, e_kpa: f64, force_n: Option<f64>) -> f64 {
        self.q_on(&law.at_force(force_n), e_kpa)
    }

    /// [`Self::q_at`] with the law at the reading's force already evaluated, in `T`.
    pub fn q_on<T: Real>(&self, law: &LawAt<T>, e_kpa: T) -> T {
        let c = T::of(self.probe_per_s) + T::of(self.contact_per_s) * law.damping_shape(e_kpa);
        if c > T::ZERO {
            law.mode_rate(e_kpa) / c
        } else {
            T::ZERO
        }
    }

    /// Fit to the reference readings `refs` (modulus, force — 0: not measured, the law's
    /// reference force — and Q of each) through the unit's contact law `law`: weighted least
    /// squares of each reading's damping per modal mass `R/Q` on the shape
    /// ([`ContactLaw::damping_shape`]), a straight line, weights `(Q/R)²` (each reading's
    /// relative error in `Q` counts alike), and [`Self::sigma_rel`] from fits that leave each
    /// interior modulus out. Readings without a positive finite modulus and Q are left out.
    /// `None` without a modulus between the lowest and the highest (none to hold out), or a
    /// damping of either part that comes out
    /// negative (the readings do not follow the contact's mechanics: the empirical curve
    /// stays). Allocation free; `O(n²)` in the readings for the held-out fits.
    pub fn fit(refs: &[Reference], law: &ContactLaw) -> Option<Self> {
        let m = Self::fit_without(refs, law, None)?;
        let sigma_rel = m.held_out(refs, law)?;
        let m = Self { sigma_rel, ..m };
        m.is_valid().then_some(m)
    }

    /// The two constants fitted to the usable readings of `refs` not at the modulus
    /// `leave_out`.
    fn fit_without(refs: &[Reference], law: &ContactLaw, leave_out: Option<f64>) -> Option<Self> {
        let mut line = crate::linalg::Line::default();
        for r in refs
            .iter()
            .filter(|r| usable(r) && Some(r.modulus_kpa) != leave_out)
        {
            let force = force_of(r);
            let c = law.mode_rate(r.modulus_kpa, force) / r.q;
            line.add(law.damping_shape(r.modulus_kpa, force), c, 1.0 / (c * c));
        }
        let fit = line.solve()?;
        let m = Self {
            probe_per_s: fit.a,
            contact_per_s: fit.b,
            sigma_rel: 0.0,
        };
        (m.is_valid() && m.contact_per_s > 0.0).then_some(m)
    }

    /// `Q/Q_model − 1` of the reading `r`.
    fn residual(&self, law: &ContactLaw, r: &Reference) -> f64 {
        r.q / self.q_at(law, r.modulus_kpa, force_of(r)) - 1.0
    }

    /// RMS over the groups of usable readings at one interior modulus and one force (forces
    /// within [`crate::unit::calibration::SAME_FORCE`]) of the mean [`Self::residual`], the
    /// model fitted without that modulus; `None` without an interior modulus or where a fit
    /// fails.
    fn held_out(&self, refs: &[Reference], law: &ContactLaw) -> Option<f64> {
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for r in refs.iter().filter(|r| usable(r)) {
            lo = lo.min(r.modulus_kpa);
            hi = hi.max(r.modulus_kpa);
        }
        let (mut sum2, mut groups) = (0.0, 0u32);
        // Each group once, at its first reading (found by looking back: nothing is listed),
        // against the model fitted without its modulus.
        for (j, g) in refs.iter().enumerate() {
            let e = g.modulus_kpa;
            if !usable(g)
                || e == lo
                || e == hi
                || refs[..j]
                    .iter()
                    .any(|x| usable(x) && x.modulus_kpa == e && same_force(x, g))
            {
                continue;
            }
            let m = Self::fit_without(refs, law, Some(e))?;
            let (mut rsum, mut k) = (0.0, 0.0);
            for x in refs[j..].iter() {
                if usable(x) && x.modulus_kpa == e && same_force(x, g) {
                    rsum += m.residual(law, x);
                    k += 1.0;
                }
            }
            let r = rsum / k;
            sum2 += r * r;
            groups += 1;
        }
        (groups > 0).then(|| libm::sqrt(sum2 / groups as f64))
    }

    /// True when both constants are finite and not negative and the uncertainty finite and
    /// not negative.
    pub fn is_valid(&self) -> bool {
        self.probe_per_s.is_finite()
            && self.probe_per_s >= 0.0
            && self.contact_per_s.is_finite()
            && self.contact_per_s >= 0.0
            && self.sigma_rel.is_finite()
            && self.sigma_rel >= 0.0
    }
}

/// A reading a fit can use: positive finite modulus and Q, a force not negative.
fn usable(r: &Reference) -> bool {
    let (e, f, q) = (r.modulus_kpa, r.force_n, r.q);
    e > 0.0 && e.is_finite() && q > 0.0 && q.is_finite() && f >= 0.0 && f.is_finite()
}

/// True when `a` and `b` were read at one force (within
/// [`crate::unit::calibration::SAME_FORCE`]; both unmeasured counts as one).
fn same_force(a: &Reference, b: &Reference) -> bool {
    let (a, b) = (a.force_n, b.force_n);
    a == b
        || (a > 0.0 && b > 0.0 && libm::fabs(a / b - 1.0) <= crate::unit::calibration::SAME_FORCE)
}

/// The measured contact force of `r`, N (`None`: not measured).
fn force_of(r: &Reference) -> Option<f64> {
    (r.force_n > 0.0).then_some(r.force_n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;
    use hal_sim::tissue::{Contact, SensorMech, Tissue, TissueElements};

    /// hal-sim's mechanics as a contact law (paper 003's Kelvin model with the appendix's
    /// elements, `hal_sim::tissue`): `Ks = k_s/m0`, `A = k_m/(m0 E^(2/3))` and `B = m_m E/m0`
    /// at 30 mN, read off the elements at 1000 kPa (exact for the Hertz radius below the
    /// probe's, which holds above 68 kPa at 30 mN).
    fn simulated_law() -> (ContactLaw, SensorMech) {
        let mech = SensorMech::default();
        let el = TissueElements::new(
            &Tissue::with_modulus_kpa(1000.0),
            &Contact::default(),
            &mech,
        );
        let m0 = mech.mass_kg;
        let p = [
            libm::log(mech.coupling_stiffness_n_m / m0),
            libm::log(el.stiffness_n_m / (m0 * 100.0)),
            libm::log(el.mass_kg * 1000.0 / m0),
        ];
        let law = ContactLaw::exact(mech.free_resonance_hz, p, (100.0, 3000.0), 0.030);
        (law, mech)
    }

    /// The simulated probe's lossless Q at `e_kpa` pressed with `force_n` (hal-sim's closed
    /// form `sqrt(k m)/c`).
    fn kelvin_q(mech: &SensorMech, e_kpa: f64, force_n: f64) -> f64 {
        let contact = Contact {
            preload_n: force_n,
            ..Contact::default()
        };
        mech.loaded(&Tissue::with_modulus_kpa(e_kpa), &contact).q()
    }

    const PHANTOMS: [f64; 5] = [157.5, 279.0, 414.0, 1146.0, 2465.0];

    /// Reference readings of `(E kPa, F N, Q)` (their resonance is not used here).
    fn references(data: &[(f64, f64, f64)]) -> Vec<Reference> {
        data.iter()
            .map(|&(modulus_kpa, force_n, q)| Reference {
                modulus_kpa,
                resonance_hz: 0.0,
                sigma_hz: 0.0,
                q,
                force_n,
            })
            .collect()
    }
    const FORCES: [f64; 3] = [0.030, 0.015, 0.050];

    /// Fitted to hal-sim's own lossless Q of A–E at 15, 30 and 50 mN, the curve is that Q at
    /// every modulus and force the references do not include: its two constants are the
    /// probe's damping `c1/m0 = 2π f1/Q_air` and the contact's at 1 kPa, and its held-out
    /// uncertainty is rounding. The damping shape is the appendix's exponents.
    #[test]
    fn fitted_to_the_kelvin_q_the_curve_is_the_kelvin_q() {
        let (law, mech) = simulated_law();
        let refs: Vec<(f64, f64, f64)> = PHANTOMS
            .iter()
            .flat_map(|&e| FORCES.map(|f| (e, f, kelvin_q(&mech, e, f))))
            .collect();
        let m = DampingModel::fit(&references(&refs), &law).expect("a fit");
        let probe = 2.0 * PI * mech.free_resonance_hz / mech.free_q;
        assert!(
            (m.probe_per_s / probe - 1.0).abs() < 1e-9,
            "{m:?} vs {probe}"
        );
        let el = TissueElements::new(
            &Tissue::with_modulus_kpa(1000.0),
            &Contact::default(),
            &mech,
        );
        let contact = el.damping_n_s_m / mech.mass_kg * libm::pow(1000.0, 1.0 / 6.0);
        assert!((m.contact_per_s / contact - 1.0).abs() < 1e-9, "{m:?}");
        assert!(m.sigma_rel < 1e-9, "{m:?}");
        for e in [140.0, 200.0, 340.0, 600.0, 850.0, 1700.0, 2200.0, 2700.0] {
            for f in [0.012, 0.020, 0.030, 0.040, 0.055] {
                let want = kelvin_q(&mech, e, f);
                let got = m.q_at(&law, e, Some(f));
                assert!(
                    (got / want - 1.0).abs() < 1e-9,
                    "{e} kPa {f} N: {got} vs {want}"
                );
            }
        }
        for (e, f) in [(150.0, 0.012), (900.0, 0.030), (2500.0, 0.055)] {
            let want = libm::pow(e, DAMPING_E) * libm::pow(f / law.force_n, DAMPING_F);
            assert!((law.damping_shape(e, Some(f)) / want - 1.0).abs() < 1e-12);
        }
    }

    use crate::unit::contact_law::{
        DAMPING_EXPONENT_E as DAMPING_E, DAMPING_EXPONENT_F as DAMPING_F,
    };

    /// The held-out uncertainty is the noise of the references' group means when the curve
    /// follows them: each group (modulus, force) of readings off the Kelvin Q by a relative
    /// offset `±d` gives a σ of the order of `d`, not of the spread of Q over the moduli; an
    /// empirical curve in `ln E` fitted to the same readings scatters by far more.
    #[test]
    fn the_held_out_uncertainty_is_the_references_noise() {
        let (law, mech) = simulated_law();
        let d = 0.002;
        let mut refs = Vec::new();
        for (i, &e) in PHANTOMS.iter().enumerate() {
            for (j, &f) in FORCES.iter().enumerate() {
                let off = if (i + j) % 2 == 0 { d } else { -d };
                for _ in 0..6 {
                    refs.push((e, f, kelvin_q(&mech, e, f) * (1.0 + off)));
                }
            }
        }
        let m = DampingModel::fit(&references(&refs), &law).expect("a fit");
        assert!(m.sigma_rel > 0.5 * d && m.sigma_rel < 3.0 * d, "{m:?}");
        let empirical = QModel::fit(refs.iter().copied()).expect("a fit");
        assert!(
            empirical.sigma_rel > 5.0 * m.sigma_rel,
            "{empirical:?} vs {m:?}"
        );
    }

    /// Readings that do not follow the contact's damping (Q falling with the modulus, so the
    /// contact's damping would have to grow with it), fewer than two moduli, or no usable
    /// reading give no curve: the empirical one stays.
    #[test]
    fn readings_unlike_a_contact_give_no_curve() {
        let (law, _) = simulated_law();
        let falling: Vec<(f64, f64, f64)> = PHANTOMS
            .iter()
            .map(|&e| (e, 0.030, 30.0 - 10.0 * libm::log10(e)))
            .collect();
        assert_eq!(DampingModel::fit(&references(&falling), &law), None);
        assert_eq!(
            DampingModel::fit(&references(&[(300.0, 0.03, 10.0); 4]), &law),
            None
        );
        assert_eq!(
            DampingModel::fit(
                &references(&[(-1.0, 0.03, 10.0), (f64::NAN, 0.03, 9.0)]),
                &law
            ),
            None
        );
    }

    /// With a contact law the Q model reads through its damping curve, without one through the
    /// empirical curve; the one-sided contact check follows the curve in use.
    #[test]
    fn the_curve_in_use_follows_the_contact_law() {
        let (law, mech) = simulated_law();
        let d = DampingModel {
            probe_per_s: 2.0 * PI * mech.free_resonance_hz / mech.free_q,
            contact_per_s: 336.0,
            sigma_rel: 0.002,
        };
        let m = QModel {
            q0: 5.0,
            q1: 0.0,
            q2: 0.0,
            sigma_rel: 0.04,
            damping: Some(d),
        };
        let q = d.q_at(&law, 600.0, Some(0.030));
        assert_eq!(m.q_at(600.0, Some(0.030), Some(&law)), q);
        assert_eq!(m.scatter(Some(&law)), 0.002);
        assert_eq!(m.q_at(600.0, Some(0.030), None), 5.0);
        assert_eq!(m.scatter(None), 0.04);
        assert!(!m
            .deviation(600.0, Some(0.030), 1.19 * q, Some(&law))
            .exceeded());
        assert!(m
            .deviation(600.0, Some(0.030), 1.21 * q, Some(&law))
            .exceeded());
        assert!(!m
            .deviation(600.0, Some(0.030), 0.3 * q, Some(&law))
            .exceeded());
        assert!(m.deviation(600.0, None, 1.19 * q, Some(&law)).holds());
        assert!(!m.deviation(600.0, None, 0.79 * q, Some(&law)).holds());
    }

    /// The damping curve belongs to the contact law it was fitted through: a profile keeps it
    /// only with that law, and reading through a power law instead drops it.
    #[test]
    fn the_damping_curve_goes_with_its_contact_law() {
        let mut p = crate::board::sim_factory::profile().expect("the factory profile");
        assert!(p.is_valid() && p.q_model.is_some_and(|m| m.damping.is_some()));
        let without_law = crate::unit::profile::UnitProfile { contact: None, ..p };
        assert!(!without_law.is_valid());
        p.use_power_law(p.calibration, p.resonance);
        assert!(p.is_valid() && p.q_model.is_some_and(|m| m.damping.is_none()));
    }
}
