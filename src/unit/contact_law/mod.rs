//! The contact law: the probe's resonance on tissue of modulus `E` from the contact mechanics
//! of paper 003's appendix, as a calibration curve.
//!
//! The probe is one mode (stiffness `k1`, mass `m0`, free resonance `f1 = sqrt(k1/m0)/2π`, the
//! air reference's). Pressed onto tissue at the calibration's preload it gains, through the
//! tip's series coupling `k_s`, the tissue's Hertz contact stiffness `k_m ∝ E^(2/3)` and a
//! co-moving tissue mass `m_m ∝ 1/E` (the contact radius `a ∝ E^(−1/3)` at a fixed force, the
//! stiffness `∝ E a`, the mass `∝ a³`):
//!
//! ```text
//! f(E) = sqrt((K1 + s A E^(2/3)) / (1 + s² B / E)) / 2π,   s = Ks / (Ks + A E^(2/3))
//! ```
//!
//! with `K1 = (2π f1)²`, and three fitted constants per modal mass: `Ks = k_s/m0` (s⁻²),
//! `A = k_m/(m0 E^(2/3))` (s⁻² kPa^(−2/3)) and `B = m_m E/m0` (kPa), fitted as their logarithms
//! (all positive). `f` rises from 0 to `sqrt(K1 + Ks)/2π` (the rigid limit); the paper's power
//! law `f = a + b E^c` is the same rise in three empirical constants.
//!
//! Which of the two a unit uses is chosen at calibration by the reference phantoms held out
//! one at a time ([`crate::unit::profile::calibrate`]): the simulated probe is built on these
//! mechanics, so there the contact law fits by construction; on a real probe it has to earn its
//! place the same way.
//!
//! # The contact force
//!
//! At a force `F` other than the law's reference force `F0` the Hertz contact radius scales as
//! `a ∝ (F/E)^(1/3)`, so `k_m ∝ E a` gives `A(F) = A (F/F0)^(1/3)` and `m_m ∝ a³` gives
//! `B(F) = B F/F0` (docs/physics.md): the law covers every force with the same three
//! constants, and a reading inverts at the force its load cell measured. References read at
//! several forces are fitted together. The exponents are Hertz's, not fitted: the held-out
//! references (each modulus at every force, [`crate::unit::profile::calibrate`]) are what tells
//! whether a probe follows them.

use crate::linalg::{levenberg_marquardt, spd_inverse, LmStop, Real};
use crate::status::Failure;
use crate::unit::calibration::{
    checked_span_of, inversion_input, span, FitError, Modulus, RefPoint,
};
use crate::units::{Hz, KPa};
use core::f64::consts::PI;

/// The contact law of one unit.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContactLaw {
    /// Free resonance `f1`, Hz (the air reference's at calibration).
    pub free_hz: f64,
    /// `ln Ks`, `ln A`, `ln B`.
    pub p: [f64; 3],
    /// Covariance of `p`.
    pub cov: [[f64; 3]; 3],
    /// Standard deviation (Hz) of the law's misfit to the reference readings.
    pub model_sigma_hz: f64,
    /// Lowest modulus the calibration vouches for, kPa.
    pub min_kpa: f64,
    /// Highest modulus the calibration vouches for, kPa.
    pub max_kpa: f64,
    /// The reference force `F0` of `p`, N; 0: the references had no measured force and the law
    /// holds at the one force they were read at.
    pub force_n: f64,
}

/// Exponent of the force in `A` (Hertz: `k_m ∝ E a`, `a ∝ (F/E)^(1/3)`).
pub const FORCE_EXPONENT_A: f64 = 1.0 / 3.0;
/// Exponent of the force in `B` (Hertz: `m_m ∝ a³ ∝ F/E`).
pub const FORCE_EXPONENT_B: f64 = 1.0;
/// Exponent of the modulus in the contact's damping ([`ContactLaw::damping_shape`]: paper
/// 003's `c_m ∝ v S`, `v ∝ E^(1/2)`, `S ∝ a² ∝ (F/E)^(2/3)`).
pub const DAMPING_EXPONENT_E: f64 = -1.0 / 6.0;
/// Exponent of the force in the contact's damping (`S ∝ a² ∝ F^(2/3)`).
pub const DAMPING_EXPONENT_F: f64 = 2.0 / 3.0;

/// The force ratio `F/F0` of a reading at `force_n` on a law of reference force `ref_n`: 1
/// when either is not a positive force.
fn force_ratio(ref_n: f64, force_n: f64) -> f64 {
    if ref_n > 0.0 && force_n > 0.0 && (force_n / ref_n).is_finite() {
        force_n / ref_n
    } else {
        1.0
    }
}

/// The law's constants out of their logarithms, computed once for many evaluations (an
/// inversion takes about ten), in `T`: `f64` for the calibration's fits, `f32` (the
/// Cortex-M4F's FPU, where every `f64` operation is software) for a reading's inversion and
/// its contact's Q and loss share ([`ContactLaw::at_force`]).
#[derive(Clone, Copy, Debug)]
struct Constants<T> {
    k1: T,
    ks: T,
    a: T,
    b: T,
}

/// `2π` in `T`.
fn two_pi<T: Real>() -> T {
    T::of(2.0 * PI)
}

impl<T: Real> Constants<T> {
    /// At the force ratio `ratio = F/F0`.
    fn of(free_hz: f64, p: &[f64; 3], ratio: f64) -> Self {
        let l = T::of(ratio).ln();
        let w = two_pi::<T>() * T::of(free_hz);
        Self {
            k1: w * w,
            ks: T::of(p[0]).exp(),
            a: (T::of(p[1]) + T::of(FORCE_EXPONENT_A) * l).exp(),
            b: (T::of(p[2]) + T::of(FORCE_EXPONENT_B) * l).exp(),
        }
    }

    /// From the constants themselves (`K1`, `Ks`, `A`, `B` at the reference force).
    fn with(k1: T, ks: T, a: T, b: T) -> Self {
        Self { k1, ks, a, b }
    }

    /// The law and its slopes at `y = E^(1/3)` (E in kPa): `F = sqrt(N/M)/2π` with
    /// `N = K1 + s A y²`, `M = 1 + s² B/y³`, `s = Ks/(Ks + A y²)`, and
    /// `dF = F (dN/N − dM/M)/2` for each variable.
    fn at_cube_root(&self, y: T) -> Slopes<T> {
        let at = self.at_term(y * y, T::ONE / (y * y * y));
        let Term { km, bm, s, n, m } = at.term;
        let half = T::of(0.5);
        let two = T::of(2.0);
        let df = |dn: T, dm: T| half * at.f * (dn / n - dm / m);
        // y: dkm = 2 km/y, ds = −s (1−s) dkm/km, dbm = −3 bm/y.
        let ds_dy = -s * (T::ONE - s) * two / y;
        let df_dy = df(
            ds_dy * km + s * two * km / y,
            two * s * ds_dy * bm - T::of(3.0) * s * s * bm / y,
        );
        Slopes {
            f: at.f,
            df_dy,
            df_dp: at.df_dp,
        }
    }

    /// The law and its slopes in the constants at the factors `u = (F/F0)^(1/3) E^(2/3)` and
    /// `v = (F/F0)/E` of one modulus and force ([`factors`]): `km = A u`, `bm = B v`, the rest
    /// as [`at_cube_root`](Self::at_cube_root) (one square root, no other transcendental).
    fn at_term(&self, u: T, v: T) -> AtTerm<T> {
        let km = self.a * u;
        let s = self.ks / (self.ks + km);
        let bm = self.b * v;
        let n = self.k1 + s * km;
        let m = T::ONE + s * s * bm;
        let f = (n / m).sqrt() / two_pi::<T>();
        let half = T::of(0.5);
        let two = T::of(2.0);
        let df = |dn: T, dm: T| half * f * (dn / n - dm / m);
        // ln Ks: ds = s (1−s). ln A: dkm = km, ds = −s (1−s). ln B: dbm = bm.
        let t = s * (T::ONE - s);
        let df_dp = [
            df(t * km, two * s * t * bm),
            df(s * s * km, -(two * s * t * bm)),
            df(T::ZERO, s * s * bm),
        ];
        AtTerm {
            f,
            df_dp,
            term: Term { km, bm, s, n, m },
        }
    }

    /// The contact stiffness `km = A E^(2/3)` and the series coupling's transfer
    /// `s = Ks/(Ks + km)` at modulus `e_kpa`.
    fn contact(&self, e_kpa: T) -> (T, T) {
        let km = self.a * (e_kpa * e_kpa).cbrt();
        (km, self.ks / (self.ks + km))
    }

    /// Resonance (Hz) at modulus `e_kpa`.
    fn frequency(&self, e_kpa: T) -> T {
        let (km, s) = self.contact(e_kpa);
        ((self.k1 + s * km) / (T::ONE + s * s * self.b / e_kpa)).sqrt() / two_pi::<T>()
    }
}

/// A modulus found by [`ContactLaw::root`]: its cube root, itself (kPa) and the law's slopes
/// there.
struct Root<T> {
    y: T,
    e: T,
    at: Slopes<T>,
}

/// Most evaluations of the law a root takes: a bound on the loop (Newton inside the bracket
/// converges in a few; a bisection step halves the bracket).
const ROOT_STEPS: usize = 60;

/// The law's value and slopes at one modulus.
struct Slopes<T> {
    /// Resonance, Hz.
    f: T,
    /// `dF/dy`, `y = E^(1/3)`.
    df_dy: T,
    /// `dF/d(ln Ks)`, `dF/d(ln A)`, `dF/d(ln B)`.
    df_dp: [T; 3],
}

/// The intermediate values of the law at one modulus and force (for the slopes in `y`).
struct Term<T> {
    km: T,
    bm: T,
    s: T,
    n: T,
    m: T,
}

/// The law's value and slopes in the constants at one modulus and force.
struct AtTerm<T> {
    /// Resonance, Hz.
    f: T,
    /// `dF/d(ln Ks)`, `dF/d(ln A)`, `dF/d(ln B)`.
    df_dp: [T; 3],
    term: Term<T>,
}

/// A [`ContactLaw`] at one contact force ([`ContactLaw::at_force`]), in `T`.
#[derive(Clone, Copy, Debug)]
pub struct LawAt<T> {
    k: Constants<T>,
    /// The force ratio `F/F0`.
    ratio: T,
}

impl<T: Real> LawAt<T> {
    /// Resonance at modulus `e_kpa`, Hz.
    pub fn frequency(&self, e_kpa: T) -> T {
        self.k.frequency(e_kpa)
    }

    /// The tissue's share of the mode's loss: `s² k_m / k` at modulus `e_kpa`, with
    /// `k_m = A u` the contact stiffness, `s` the series coupling's transfer and
    /// `k = K1 + s k_m` the mode's stiffness (all per modal mass). A tissue of loss tangent `η`
    /// makes the contact stiffness `k_m (1 + jη)`, which reaches the mode as `s k_m (1 + j s η)`
    /// to first order in `η`: it adds `η s² k_m / k` to the mode's `1/Q` (docs/physics.md,
    /// "Viscoelastic tissue").
    pub fn loss_share(&self, e_kpa: T) -> T {
        let (km, s) = self.k.contact(e_kpa);
        s * s * km / (self.k.k1 + s * km)
    }

    /// The loaded mode's `sqrt(k m) / m0` at modulus `e_kpa`, s⁻¹: `sqrt(N M)` with
    /// `N = K1 + s k_m` the mode's stiffness and `M = 1 + s² B/E` its mass, both per modal mass
    /// `m0`. A damping `c` gives the mode `Q = sqrt(k m) / c`, so `Q = mode_rate / (c / m0)`
    /// (paper 003 eq. 1–2; the Kelvin model of `hal-sim`'s `tissue.rs`).
    pub fn mode_rate(&self, e_kpa: T) -> T {
        let (km, s) = self.k.contact(e_kpa);
        ((self.k.k1 + s * km) * (T::ONE + s * s * self.k.b / e_kpa)).sqrt()
    }

    /// How the contact's damping varies with the modulus `e_kpa` (kPa) and the force:
    /// `(E / kPa)^(−1/6) (F/F0)^(2/3)`. Paper 003's appendix gives the contact damping
    /// `c_m = κ ρ v S / (1 − ν)` with the shear-wave speed `v ∝ E^(1/2)` and the contact area
    /// `S = π a²`; with the law's Hertz radius `a ∝ (F/E)^(1/3)` ([`FORCE_EXPONENT_A`]) it is
    /// `∝ E^(−1/6) F^(2/3)` ([`DAMPING_EXPONENT_E`], [`DAMPING_EXPONENT_F`]).
    pub fn damping_shape(&self, e_kpa: T) -> T {
        damping_shape(self.ratio, e_kpa)
    }
}

/// [`LawAt::damping_shape`] at the force ratio `ratio`.
fn damping_shape<T: Real>(ratio: T, e_kpa: T) -> T {
    (ratio * ratio).cbrt() / e_kpa.cbrt().sqrt()
}

/// The factors of one modulus `e_kpa` and force ratio `ratio` in the law (
/// [`Constants::at_term`]): `u = cbrt(ratio E²)`, `v = ratio/E`.
fn factors(e_kpa: f64, ratio: f64) -> (f64, f64) {
    (libm::cbrt(ratio * e_kpa * e_kpa), ratio / e_kpa)
}

/// `JᵀWJ` and `JᵀW r` of a fit.
type Normal = ([[f64; 3]; 3], [f64; 3]);

/// The readings of a fit reduced to what χ² needs, once per fit: one term per distinct pair of
/// the law's factors `(u, v)` ([`factors`]: a modulus and a force ratio), with the summed weight
/// `W = Σ wᵢ` (`wᵢ = 1/σᵢ²`) and the weighted mean resonance `f̄ = Σ wᵢ fᵢ / W` of its readings.
///
/// χ² over the readings is χ² over the terms plus a constant: within a term the law predicts
/// one value `F` for every reading (it depends on a reading through `u` and `v` alone), and
///
/// ```text
/// Σ wᵢ (fᵢ − F)² = Σ wᵢ ((fᵢ − f̄) + (f̄ − F))²
///                = Σ wᵢ (fᵢ − f̄)² + 2 (f̄ − F) Σ wᵢ (fᵢ − f̄) + W (f̄ − F)²,
/// ```
///
/// where the middle sum is `Σ wᵢ fᵢ − W f̄ = 0`: so `χ² = C + Σ W (f̄ − F)²` with
/// `C = Σ wᵢ (fᵢ − f̄)²`, which does not depend on the constants. The same way `JᵀW r` is
/// `Σ W J (f̄ − F)` and `JᵀWJ` is `Σ W J Jᵀ`. `C` is kept in χ²: the minimisation's relative
/// stopping rule and the covariance's scale (χ² per degree of freedom) see the readings' χ².
/// With readings at measured forces (each its own) there is a term per reading; with set
/// forces, one per modulus and force.
struct Terms {
    /// `u`, `v`, `W`, `f̄` of each term.
    t: [[f64; 4]; crate::unit::calibration::MAX_REFERENCES],
    /// Terms in `t`.
    len: usize,
    /// `C`.
    c: f64,
    /// Readings.
    points: usize,
}

impl Terms {
    /// Fill empty terms with those of `data` for a law of reference force `force_n`; false with
    /// more distinct terms than [`crate::unit::calibration::MAX_REFERENCES`].
    fn fill<'a>(&mut self, data: impl Iterator<Item = &'a RefPoint> + Clone, force_n: f64) -> bool {
        let terms = self;
        let uv = |d: &RefPoint| factors(d.modulus_kpa, force_ratio(force_n, d.force_n));
        let find = |t: &Terms, (u, v): (f64, f64)| {
            t.t[..t.len].iter().position(|x| x[0] == u && x[1] == v)
        };
        // Σ wᵢ and Σ wᵢ fᵢ, then f̄, then C in a second pass (no cancellation).
        for d in data.clone() {
            let w = 1.0 / (d.sigma_hz * d.sigma_hz);
            let (u, v) = uv(d);
            let i = match find(terms, (u, v)) {
                Some(i) => i,
                None => {
                    let i = terms.len;
                    let Some(t) = terms.t.get_mut(i) else {
                        return false;
                    };
                    *t = [u, v, 0.0, 0.0];
                    terms.len += 1;
                    i
                }
            };
            terms.t[i][2] += w;
            terms.t[i][3] += w * d.resonance_hz;
            terms.points += 1;
        }
        for x in terms.t[..terms.len].iter_mut() {
            x[3] /= x[2];
        }
        for d in data {
            let w = 1.0 / (d.sigma_hz * d.sigma_hz);
            if let Some(i) = find(terms, uv(d)) {
                let r = d.resonance_hz - terms.t[i][3];
                terms.c += w * r * r;
            }
        }
        true
    }

    /// χ² of the law with constants `k`.
    fn chi2(&self, k: &Constants<f64>) -> f64 {
        self.chi2_below(k, f64::INFINITY)
    }

    /// χ² of the law with constants `k`, or some partial sum of it not below `bound` once it
    /// reaches it: every term adds a square (or NaN), so a partial sum at or above `bound` says
    /// that χ² is not below it either (the grid of starts keeps only a χ² below the best so far,
    /// and skips the rest of a start that cannot be).
    fn chi2_below(&self, k: &Constants<f64>, bound: f64) -> f64 {
        let mut sum = self.c;
        for &[u, v, w, f] in &self.t[..self.len] {
            let r = f - k.at_term(u, v).f;
            sum += w * r * r;
            if sum >= bound {
                break;
            }
        }
        sum
    }

    /// `JᵀWJ` and `JᵀW r` of the law with constants `k`, `J` its analytic slopes.
    fn normal(&self, k: &Constants<f64>) -> Normal {
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for &[u, v, w, f] in &self.t[..self.len] {
            let at = k.at_term(u, v);
            let (j, r) = (at.df_dp, f - at.f);
            for a in 0..3 {
                jtr[a] += w * j[a] * r;
                for b in 0..3 {
                    jtj[a][b] += w * j[a] * j[b];
                }
            }
        }
        (jtj, jtr)
    }
}

/// Resonance (Hz) of the law `free_hz`, `p` at modulus `e_kpa` and force ratio `ratio`.
fn frequency_of(free_hz: f64, p: &[f64; 3], e_kpa: f64, ratio: f64) -> f64 {
    Constants::<f64>::of(free_hz, p, ratio).frequency(e_kpa)
}

/// How many numbers [`ContactLaw::to_values`] gives.
pub const VALUES: usize = 17;

/// Lowest and highest modulus an inversion searches, kPa.
#[cfg_attr(not(test), allow(dead_code))] // the search takes their cube roots
const SEARCH_KPA: (f64, f64) = (1.0, 1.0e6);
/// Their cube roots (`tests` check them against `libm::cbrt`): two software `cbrt` an inversion
/// fewer.
const SEARCH_CUBE_ROOT: (f64, f64) = (1.0, 100.0);

impl ContactLaw {
    /// A law known rather than calibrated (a model's own, a test's truth): constants `p` with
    /// no covariance and no misfit, for a probe of free resonance `free_hz` (Hz), vouched for
    /// over `span_kpa` (lowest, highest modulus, kPa), referred to the force `force_n` (N; 0:
    /// none).
    pub fn exact(free_hz: f64, p: [f64; 3], span_kpa: (f64, f64), force_n: f64) -> Self {
        Self {
            free_hz,
            p,
            cov: [[0.0; 3]; 3],
            model_sigma_hz: 0.0,
            min_kpa: span_kpa.0,
            max_kpa: span_kpa.1,
            force_n,
        }
    }

    /// The law as the numbers the store's record and the bench's profile file keep, in this
    /// order: `free_hz`, `p` (3), `cov` (9, row major), `model_sigma_hz`, `min_kpa`, `max_kpa`,
    /// `force_n`.
    pub fn to_values(&self) -> [f64; VALUES] {
        let mut v = [0.0; VALUES];
        v[0] = self.free_hz;
        v[1..4].copy_from_slice(&self.p);
        for (i, row) in self.cov.iter().enumerate() {
            v[4 + 3 * i..7 + 3 * i].copy_from_slice(row);
        }
        v[13] = self.model_sigma_hz;
        v[14] = self.min_kpa;
        v[15] = self.max_kpa;
        v[16] = self.force_n;
        v
    }

    /// The law from [`to_values`](Self::to_values)' numbers (not validated: see
    /// [`is_valid`](Self::is_valid)).
    pub fn from_values(v: &[f64; VALUES]) -> Self {
        Self {
            free_hz: v[0],
            p: [v[1], v[2], v[3]],
            cov: [
                [v[4], v[5], v[6]],
                [v[7], v[8], v[9]],
                [v[10], v[11], v[12]],
            ],
            model_sigma_hz: v[13],
            min_kpa: v[14],
            max_kpa: v[15],
            force_n: v[16],
        }
    }

    /// Resonance at modulus `e_kpa` at the reference force, Hz.
    pub fn frequency(&self, e_kpa: f64) -> f64 {
        frequency_of(self.free_hz, &self.p, e_kpa, 1.0)
    }

    /// Resonance at modulus `e_kpa` pressed with `force_n` (N), Hz: at the reference force for
    /// a law without one.
    pub fn frequency_at(&self, e_kpa: f64, force_n: f64) -> f64 {
        frequency_of(
            self.free_hz,
            &self.p,
            e_kpa,
            force_ratio(self.force_n, force_n),
        )
    }

    /// The law at the contact force `force_n` (N; the reference force when `None` or for a
    /// law without one), in `T`: its constants computed once for the evaluations of one
    /// reading ([`LawAt`]).
    pub fn at_force<T: Real>(&self, force_n: Option<f64>) -> LawAt<T> {
        let ratio = force_ratio(self.force_n, force_n.unwrap_or(0.0));
        LawAt {
            k: Constants::of(self.free_hz, &self.p, ratio),
            ratio: T::of(ratio),
        }
    }

    /// [`LawAt::loss_share`] at `force_n`, in `f64`.
    pub fn loss_share(&self, e_kpa: f64, force_n: Option<f64>) -> f64 {
        self.at_force::<f64>(force_n).loss_share(e_kpa)
    }

    /// [`LawAt::mode_rate`] at `force_n`, in `f64`.
    pub fn mode_rate(&self, e_kpa: f64, force_n: Option<f64>) -> f64 {
        self.at_force::<f64>(force_n).mode_rate(e_kpa)
    }

    /// [`LawAt::damping_shape`] at `force_n`, in `f64` (the force ratio alone: none of the
    /// law's constants).
    pub fn damping_shape(&self, e_kpa: f64, force_n: Option<f64>) -> f64 {
        damping_shape(force_ratio(self.force_n, force_n.unwrap_or(0.0)), e_kpa)
    }

    /// The rigid limit `sqrt(K1 + Ks)/2π`, Hz.
    pub fn rigid_hz(&self) -> f64 {
        let k = Constants::<f64>::of(self.free_hz, &self.p, 1.0);
        libm::sqrt(k.k1 + k.ks) / (2.0 * PI)
    }

    /// True when every constant is finite, the free resonance positive and the span ordered.
    pub fn is_valid(&self) -> bool {
        self.free_hz.is_finite()
            && self.free_hz > 0.0
            && self.p.iter().all(|v| v.is_finite())
            && self.cov.iter().flatten().all(|v| v.is_finite())
            && self.model_sigma_hz.is_finite()
            && self.model_sigma_hz >= 0.0
            && self.min_kpa > 0.0
            && self.max_kpa > self.min_kpa
            && self.force_n.is_finite()
            && self.force_n >= 0.0
    }

    /// Modulus of a resonance `f ± sigma` read at the contact force `force` (mean and standard
    /// uncertainty, N; `None`: at the reference force), with the law's own uncertainty and the
    /// force's propagated: as [`crate::unit::calibration::PowerLaw::invert`] (the same failures for
    /// the same cases). The force's uncertainty counts as the resonance's (`∂f/∂F σ_F` added
    /// in quadrature): a force read anew each reading scatters with it. The root and its slopes
    /// are found in `f32` (a bracketed Newton search), and the uncertainty propagated in it.
    pub fn invert(&self, f: Hz, sigma: Hz, force: Option<(f64, f64)>) -> Result<Modulus, Failure> {
        self.invert_moved(f, sigma, force, 0.0).0
    }

    /// [`ContactLaw::invert`], and the modulus alone had the free resonance moved by `moved_hz`
    /// (the unit's drift allowance, [`crate::unit::profile::UnitProfile::invert`]; not sought
    /// when 0): the second shares the first's constants (the free resonance enters only `K1`)
    /// and starts its Newton steps at the first's root.
    pub fn invert_moved(
        &self,
        f: Hz,
        sigma: Hz,
        force: Option<(f64, f64)>,
        moved_hz: f64,
    ) -> (Result<Modulus, Failure>, Option<Result<KPa, Failure>>) {
        let (f, sf) = match inversion_input(self.is_valid(), f, sigma) {
            Ok(x) => x,
            Err(e) => return (Err(e), None),
        };
        let (ratio, sigma_ln_f) = match force {
            Some((fm, sfm)) if self.force_n > 0.0 && fm > 0.0 => {
                (force_ratio(self.force_n, fm), (sfm / fm).max(0.0))
            }
            _ => (1.0, 0.0),
        };
        let k = Constants::<f32>::of(self.free_hz, &self.p, ratio);
        let root = self.root(&k, f, None);
        let moved = (moved_hz != 0.0).then(|| {
            let w = two_pi::<f32>() * (self.free_hz + moved_hz) as f32;
            let k_moved = Constants { k1: w * w, ..k };
            let near = root.as_ref().ok().map(|r| r.y);
            self.root(&k_moved, f, near).map(|r| KPa(r.e))
        });
        let m = root.map(|r| {
            // In `f32`, as the root and its slopes (the propagation's precision, its own).
            // dE/df = 3 y² / (dF/dy); dE/dp = −(∂F/∂p)(dE/df).
            let de_df = 3.0 * r.y * r.y / r.at.df_dy;
            let g = r.at.df_dp.map(|d| -d * de_df);
            // ∂f/∂ln F through A and B.
            let df_dlnf =
                FORCE_EXPONENT_A as f32 * r.at.df_dp[1] + FORCE_EXPONENT_B as f32 * r.at.df_dp[2];
            let (sf, sl) = (sf as f32, df_dlnf * sigma_ln_f as f32);
            let sf = crate::dsp::trig::sqrtf(sf * sf + sl * sl);
            let (misfit, cov) = (self.model_sigma_hz as f32, &self.cov);
            Modulus::propagated(r.e, de_df, sf, misfit, &g, cov)
        });
        (m, moved)
    }

    /// The modulus whose resonance is `f` (Hz) with the law's constants `k`, with the law's
    /// slopes there: Newton steps on `y = E^(1/3)` started at `near` when it lies inside the
    /// searched range, kept inside a bracket that shrinks with every evaluation (a bisection
    /// step where Newton would leave it; at most [`ROOT_STEPS`] evaluations). In `y` the law
    /// needs no transcendental but a square root (`km = A y²`, `B/E = B/y³`). Out of the
    /// calibration's span, or where the law does not rise, the failure that says so.
    fn root<T: Real>(&self, k: &Constants<T>, f: f64, near: Option<T>) -> Result<Root<T>, Failure> {
        let f = T::of(f);
        let (mut lo, mut hi) = (T::of(SEARCH_CUBE_ROOT.0), T::of(SEARCH_CUBE_ROOT.1));
        if f >= k.at_cube_root(hi).f {
            return Err(Failure::AboveRange);
        }
        if f <= k.at_cube_root(lo).f {
            return Err(Failure::BelowRange);
        }
        let mut y = match near {
            Some(y) if y > lo && y < hi => y,
            _ => (T::of(self.min_kpa) * T::of(self.max_kpa)).sqrt().cbrt(),
        };
        // Newton converges quadratically: a step below √ε·y leaves an error of order ε·y.
        let tol = T::EPSILON.sqrt();
        let mut at = k.at_cube_root(y);
        for _ in 0..ROOT_STEPS {
            if at.f < f {
                lo = y;
            } else {
                hi = y;
            }
            let newton = y - (at.f - f) / at.df_dy;
            let next = if at.df_dy > T::ZERO && newton >= lo && newton <= hi {
                newton
            } else {
                T::of(0.5) * (lo + hi)
            };
            let done = (next - y).abs() <= tol * y || hi - lo <= tol * y;
            y = next;
            at = k.at_cube_root(y);
            if done {
                break;
            }
        }
        let e = y * y * y;
        if e.wide() > self.max_kpa {
            return Err(Failure::AboveRange);
        }
        if e.wide() < self.min_kpa {
            return Err(Failure::BelowRange);
        }
        if !(at.df_dy > T::ZERO) {
            return Err(Failure::AboveRange);
        }
        Ok(Root { y, e, at })
    }

    /// Weighted least-squares fit of `(ln Ks, ln A, ln B)` at the reference force `force_n` (N;
    /// 0: the references carry no force) to reference readings, each at its own measured
    /// force, with the free resonance `free_hz` held (Levenberg–Marquardt from the best of a
    /// coarse grid of starts; the covariance from the Jacobian at the optimum, scaled by the
    /// reduced χ² when it exceeds 1; the misfit as the RMS residual corrected for the three
    /// constants). `BadInput` for readings at more than [`crate::unit::calibration::MAX_REFERENCES`]
    /// distinct pairs of modulus and force.
    pub fn fit(data: &[RefPoint], free_hz: f64, force_n: f64) -> Result<ContactLaw, FitError> {
        Self::fit_leaving_out(data, free_hz, force_n, None)
    }

    /// [`fit`](Self::fit) to the readings of `data` not at the modulus `leave_out` (kPa): the
    /// held-out fits of [`crate::unit::profile::calibrate`], without a copy of the others.
    ///
    /// Cost (the firmware's `calibrate fit`, every `f64` operation software on the M4): the
    /// readings are reduced once to the law's two force-and-modulus factors per distinct pair
    /// of (modulus, force) ([`Terms`]); each parameter vector then costs three exponentials
    /// ([`Constants::with`]) and one square root per term, and the Jacobian is the law's
    /// analytic slopes ([`Constants::at_term`]) instead of three more evaluations.
    // Not inlined: its terms (4 KiB) sit on the stack only while it runs, not in every
    // caller's frame (`profile::calibrate` calls it for the fit and per held-out modulus).
    #[inline(never)]
    pub(crate) fn fit_leaving_out(
        data: &[RefPoint],
        free_hz: f64,
        force_n: f64,
        leave_out: Option<f64>,
    ) -> Result<ContactLaw, FitError> {
        let kept = |d: &&RefPoint| Some(d.modulus_kpa) != leave_out;
        let (emin, emax) = checked_span_of(data.iter().filter(kept))?;
        if !(free_hz > 0.0) || !free_hz.is_finite() || !(force_n >= 0.0) || !force_n.is_finite() {
            return Err(FitError::BadInput);
        }
        // Filled in place: a 4 KiB value moved through `Option`/`Result` would be copied.
        let mut terms = Terms {
            t: [[0.0; 4]; crate::unit::calibration::MAX_REFERENCES],
            len: 0,
            c: 0.0,
            points: 0,
        };
        if !terms.fill(data.iter().filter(kept), force_n) {
            return Err(FitError::BadInput);
        }
        let n_points = terms.points;
        let k1 = Constants::<f64>::of(free_hz, &[0.0; 3], 1.0).k1;
        // Starts: Ks from the rigid limit over the highest reading (its square less K1, times
        // 1–16), A and B over three decades each about the simulated probe's. The grid's
        // exponentials once per axis value (19, not 3 × 245).
        let mut p = [0.0; 3];
        let mut best = f64::INFINITY;
        let fmax = data
            .iter()
            .filter(kept)
            .map(|d| d.resonance_hz)
            .fold(0.0, f64::max);
        let ks0 = ((2.0 * PI * fmax) * (2.0 * PI * fmax) - k1).max(1.0);
        let axis = |i: usize| {
            [
                libm::log(ks0) + 0.7 * i as f64,
                7.0 + 1.15 * i as f64,
                5.0 + 1.15 * i as f64,
            ]
        };
        let mut exps = [[0.0; 3]; 7];
        for (i, e) in exps.iter_mut().enumerate() {
            *e = axis(i).map(libm::exp);
        }
        for i in 0..5 {
            for j in 0..7 {
                for k in 0..7 {
                    let c = Constants::with(k1, exps[i][0], exps[j][1], exps[k][2]);
                    let chi2 = terms.chi2_below(&c, best);
                    if chi2 < best {
                        best = chi2;
                        p = [axis(i)[0], axis(j)[1], axis(k)[2]];
                    }
                }
            }
        }
        let constants =
            |p: &[f64; 3]| Constants::with(k1, libm::exp(p[0]), libm::exp(p[1]), libm::exp(p[2]));
        let chi2 = |p: &[f64; 3]| terms.chi2(&constants(p));
        // The driver asks for the normal equations again at the same parameters after a step it
        // rejects: the last answer is kept.
        let last: core::cell::Cell<Option<([f64; 3], Normal)>> = core::cell::Cell::new(None);
        let normal = |p: &[f64; 3]| -> Normal {
            if let Some((q, n)) = last.get() {
                if q == *p {
                    return n;
                }
            }
            let n = terms.normal(&constants(p));
            last.set(Some((*p, n)));
            n
        };
        let (p, best) = levenberg_marquardt(p, chi2, normal, LmStop::new(200, 1e-12, 1e12));
        let (jtj, _) = normal(&p);
        let mut cov = spd_inverse(&jtj).ok_or(FitError::NotSaturating)?;
        let dof = n_points.saturating_sub(3).max(1) as f64;
        let scale = (best / dof).max(1.0);
        for v in cov.iter_mut().flatten() {
            *v *= scale;
        }
        let c = constants(&p);
        let ss: f64 = data
            .iter()
            .filter(kept)
            .map(|d| {
                let (u, v) = factors(d.modulus_kpa, force_ratio(force_n, d.force_n));
                let r = d.resonance_hz - c.at_term(u, v).f;
                r * r
            })
            .sum();
        let law = ContactLaw {
            free_hz,
            p,
            cov,
            model_sigma_hz: libm::sqrt(ss / dof),
            min_kpa: span(emin, emax).0,
            max_kpa: span(emin, emax).1,
            force_n,
        };
        if law.is_valid() {
            Ok(law)
        } else {
            Err(FitError::NotSaturating)
        }
    }
}

#[cfg(test)]
mod tests;
