//! Calibration: the power law `f = a + b E^c` (E in kPa, f in Hz) of paper 003, its inverse with
//! propagated uncertainty and honest range checks, and its least-squares fit from reference
//! readings.
//!
//! The inverse `E = ((a − f) / −b)^(1/c)` exists only for `f < a` (with `b < 0`, `c < 0`); a
//! frequency at or above the asymptote `a`, or one that maps outside the calibrated span, is
//! reported as above or below range — never extrapolated into a number.

use crate::linalg::{inverse3, Real};
use crate::status::Failure;
use crate::units::{Hz, KPa};

/// Most reference readings one calibration takes.
pub const MAX_REFERENCES: usize = 128;

/// `x^y` of the power law. On the host `libm::pow`; in the firmware images
/// (`target_os = "none"`) `exp(y ln x)`, which keeps libm's `pow` (2.5 KiB) out of the STM32
/// image's 64 KiB of flash (`docs/firmware.md`): for the exponents and moduli of a calibration
/// (`|y ln x|` below 20) it differs from `pow` by at most a few tens of `f64` ulps, far below
/// anything a reading reports in `f32`. Same special values where they matter: `x = 0` gives 0 for `y > 0` and
/// infinity for `y < 0`, `x < 0` or NaN gives NaN, `y = 0` gives 1.
#[inline]
fn pow(x: f64, y: f64) -> f64 {
    #[cfg(target_os = "none")]
    {
        if y == 0.0 {
            1.0
        } else {
            libm::exp(y * libm::log(x))
        }
    }
    #[cfg(not(target_os = "none"))]
    {
        libm::pow(x, y)
    }
}

/// Where a calibration comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Source {
    /// Paper 003 eq. 4 (FEM simulation, 14 samples 100–3000 kPa).
    PaperSimulation,
    /// Paper 003 eq. 5 (prototype experiment, samples A–E).
    PaperExperiment,
    /// Fitted on this unit from reference readings.
    Fitted,
}

impl Source {
    /// Every source, in declaration order.
    pub const ALL: [Source; 3] = [
        Source::PaperSimulation,
        Source::PaperExperiment,
        Source::Fitted,
    ];

    /// Stable name (`paper-simulation`, `paper-experiment`, `fitted`).
    pub const fn name(self) -> &'static str {
        match self {
            Source::PaperSimulation => "paper-simulation",
            Source::PaperExperiment => "paper-experiment",
            Source::Fitted => "fitted",
        }
    }

    /// The source of [`name`](Self::name) `s`.
    pub fn from_name(s: &str) -> Option<Source> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }
}

/// A source is written as its [`name`](Source::name).
#[cfg(feature = "serde")]
impl serde::Serialize for Source {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// A source is read from its [`name`](Source::name); any other string is an error that names
/// it: ``unknown calibration source `…` ``.
#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for Source {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = Source;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                f.write_str("a calibration source: paper-simulation, paper-experiment or fitted")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Source, E> {
                Source::from_name(v).ok_or_else(|| {
                    E::custom(format_args!(
                        "unknown calibration source `{v}` (paper-simulation, paper-experiment or fitted)"
                    ))
                })
            }
        }
        d.deserialize_str(Name)
    }
}

/// Fraction by which the calibrated span extends beyond the reference moduli on either side.
pub const SPAN_MARGIN: f64 = 0.10;

/// One reference reading: a resonance measured on tissue of known modulus.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefPoint {
    /// The reference's modulus, kPa.
    pub modulus_kpa: f64,
    /// The measured resonance, Hz.
    pub resonance_hz: f64,
    /// Its standard uncertainty, Hz.
    pub sigma_hz: f64,
    /// The contact force it was read at, N (0: not measured).
    pub force_n: f64,
}

/// The calibration curve `f = a + b E^c` with its parameter covariance and valid span. With the
/// `serde` feature it is (de)serialized as its fields by these names, `source` by its name (the
/// `calibration` object of probe-bench's profile files).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PowerLaw {
    /// Asymptote `a` in Hz (resonance on infinitely stiff tissue).
    pub a: f64,
    /// Scale `b` in Hz / kPa^c (negative).
    pub b: f64,
    /// Exponent `c` (negative).
    pub c: f64,
    /// Covariance of `(a, b, c)` (zero when unknown, as for the published curves).
    pub cov: [[f64; 3]; 3],
    /// Standard deviation (Hz) of the curve's own misfit to reference data: how far a real
    /// unit's resonance strays from the power law between reference points.
    pub model_sigma_hz: f64,
    /// Lowest modulus the calibration vouches for, kPa.
    pub min_kpa: f64,
    /// Highest modulus the calibration vouches for, kPa.
    pub max_kpa: f64,
    /// Origin.
    pub source: Source,
}

/// A modulus with its standard uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Modulus {
    /// Modulus.
    pub value: KPa,
    /// Combined standard uncertainty: the reading's own (repeatability) and the calibration's
    /// (parameter covariance and curve misfit), in quadrature.
    pub sigma: KPa,
    /// The repeatability part alone: the resonance uncertainty through the curve's slope. It is
    /// what the scatter of repeated readings shows; the calibration part is common to them.
    pub sigma_repeat: KPa,
}

/// A curve's inverse takes a resonance and its standard uncertainty as `f64`: `bad_settings`
/// when the curve is not `valid` or the input is not finite (or the uncertainty negative).
pub(crate) fn inversion_input(valid: bool, f: Hz, sigma: Hz) -> Result<(f64, f64), Failure> {
    let (f, sf) = (f.0 as f64, sigma.0 as f64);
    if !valid || !f.is_finite() || !sf.is_finite() || sf < 0.0 {
        return Err(Failure::BadSettings);
    }
    Ok((f, sf))
}

impl Modulus {
    /// The modulus `e_kpa` read through a curve, with its uncertainty (GUM, first order): the
    /// resonance's standard uncertainty `sigma_hz` and the curve's misfit `model_sigma_hz`
    /// through the slope `de_df` (kPa/Hz), and the curve's parameter covariance `cov` through
    /// the gradient `g` of the modulus in its parameters.
    ///
    /// In the caller's precision `T` ([`Real`]): `f64` where the gradient is (the power law's),
    /// `f32` where the inputs are no better (the contact law's root and slopes are found in
    /// `f32`, [`crate::unit::contact_law::ContactLaw::invert`]); the sum `gᵀ C g` then holds
    /// `T`'s relative precision of its largest term, which its inputs already limit
    /// (`propagated_f32_holds_f32s_precision_of_its_terms`).
    pub fn propagated<T: Real>(
        e_kpa: T,
        de_df: T,
        sigma_hz: T,
        model_sigma_hz: T,
        g: &[T; 3],
        cov: &[[f64; 3]; 3],
    ) -> Self {
        let slope2 = de_df * de_df;
        let var_repeat = slope2 * sigma_hz * sigma_hz;
        let mut var = var_repeat + slope2 * model_sigma_hz * model_sigma_hz;
        // gᵀ C g: the diagonal's terms and each pair's once.
        for i in 0..3 {
            var = var + g[i] * g[i] * T::of(cov[i][i]);
            for j in 0..i {
                var = var + g[i] * g[j] * T::of(cov[i][j] + cov[j][i]);
            }
        }
        let root = |v: T| crate::dsp::trig::sqrt32(if v > T::ZERO { v.wide() } else { 0.0 });
        Modulus {
            value: KPa(e_kpa.wide() as f32),
            sigma: KPa(root(var)),
            sigma_repeat: KPa(root(var_repeat)),
        }
    }
}

/// Why a calibration fit failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FitError {
    /// Fewer than four readings or fewer than three distinct moduli.
    TooFewPoints,
    /// A value is not finite or a modulus is not positive.
    BadInput,
    /// The data do not show a saturating curve (`b < 0`, `c < 0`).
    NotSaturating,
}

/// Standard deviation of a published curve's misfit from its R² and the moduli it was fitted
/// on: `sqrt((1 − R²) · Var(f(E_i)))`.
fn misfit_from_r2(a: f64, b: f64, c: f64, r2: f64, moduli: &[f64]) -> f64 {
    let n = moduli.len() as f64;
    let f = |e: f64| a + b * pow(e, c);
    let mean = moduli.iter().map(|&e| f(e)).sum::<f64>() / n;
    let var = moduli
        .iter()
        .map(|&e| (f(e) - mean) * (f(e) - mean))
        .sum::<f64>()
        / n;
    libm::sqrt((1.0 - r2) * var)
}

/// The span a calibration vouches for: its reference moduli widened by [`SPAN_MARGIN`].
pub(crate) fn span(min: f64, max: f64) -> (f64, f64) {
    (min * (1.0 - SPAN_MARGIN), max * (1.0 + SPAN_MARGIN))
}

/// 1.4826 × the median absolute residual of `data` about `law` (first 256 readings).
fn robust_scale(data: &[RefPoint], law: &PowerLaw) -> f64 {
    let mut abs = [0.0f64; 256];
    let m = data.len().min(abs.len());
    for (a, x) in abs.iter_mut().zip(data.iter()) {
        *a = libm::fabs(x.resonance_hz - law.frequency(x.modulus_kpa));
    }
    abs[..m].sort_unstable_by(|x, y| x.total_cmp(y));
    1.4826 * abs[m / 2]
}

/// RMS leave-one-out error (Hz) of the power law at the interior reference moduli (all but the
/// lowest and the highest): [`held_out_rms`] with [`PowerLaw::fit_plain`].
fn interior_loo_sigma(data: &[RefPoint]) -> Option<f64> {
    held_out_rms(data, true, |d, e| {
        PowerLaw::fit_without(d, e, PowerLaw::fit_plain)
            .ok()
            .map(|p| move |r: &RefPoint| p.frequency(r.modulus_kpa))
    })
}

/// RMS (Hz), over the groups of readings of `data` at one reference modulus and one contact
/// force (forces within [`SAME_FORCE`] of each other; the first 64 moduli; with `interior`, all
/// but the lowest and the highest modulus), of the mean over the group of the resonance read
/// less what the curve `fit` makes of the other moduli's readings (at every force) predicts
/// for that reading (at its modulus, and at its force for a curve that takes one). `None` with
/// fewer than five distinct moduli, more than [`MAX_REFERENCES`] readings (a
/// fit's scratch copy is on the stack) or a fit that fails. `fit` is given all of `data` and the
/// modulus to leave out of its fit ([`PowerLaw::fit_without`] copies the others). The leave-one-out test of
/// the power law's misfit and of the choice between the power law and the contact law
/// (`profile::calibrate`).
pub(crate) fn held_out_rms<F: Fn(&RefPoint) -> f64>(
    data: &[RefPoint],
    interior: bool,
    fit: impl Fn(&[RefPoint], f64) -> Option<F>,
) -> Option<f64> {
    if distinct_moduli(data) < 5 || data.len() > MAX_REFERENCES {
        return None;
    }
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for d in data {
        lo = lo.min(d.modulus_kpa);
        hi = hi.max(d.modulus_kpa);
    }
    let same_force =
        |a: f64, b: f64| a == b || (a > 0.0 && b > 0.0 && libm::fabs(a / b - 1.0) <= SAME_FORCE);
    let (mut sum2, mut groups) = (0.0, 0u32);
    // Each modulus once, at its first reading (found by looking back: no list of them on the
    // stack, which the firmware's calibration runs on), the first 64 of them; one fit per
    // modulus, then each of its forces once, the same way.
    let mut distinct = 0;
    for (i, d) in data.iter().enumerate() {
        let e = d.modulus_kpa;
        if data[..i].iter().any(|x| x.modulus_kpa == e) {
            continue;
        }
        distinct += 1;
        if distinct > 64 || (interior && (e == lo || e == hi)) {
            continue;
        }
        let curve = fit(data, e)?;
        for (j, g) in data.iter().enumerate().skip(i) {
            let at_e = |x: &&RefPoint| x.modulus_kpa == e;
            if !at_e(&g)
                || data[i..j]
                    .iter()
                    .filter(at_e)
                    .any(|x| same_force(x.force_n, g.force_n))
            {
                continue;
            }
            let (mut rsum, mut k) = (0.0, 0.0);
            for x in data
                .iter()
                .filter(at_e)
                .filter(|x| same_force(x.force_n, g.force_n))
            {
                rsum += x.resonance_hz - curve(x);
                k += 1.0;
            }
            let r = rsum / k;
            sum2 += r * r;
            groups += 1;
        }
    }
    (groups > 0).then(|| libm::sqrt(sum2 / groups as f64))
}

/// Relative difference of two references' contact forces within which they were read at one
/// force (the hand's or the stage's scatter about a set force).
pub const SAME_FORCE: f64 = 0.15;

/// Number of distinct moduli in reference data (counting stops at 64).
fn distinct_moduli(data: &[RefPoint]) -> usize {
    distinct_moduli_of(data.iter())
}

/// [`distinct_moduli`] of the readings `data` yields.
fn distinct_moduli_of<'a>(data: impl Iterator<Item = &'a RefPoint>) -> usize {
    let mut seen = [0.0f64; 64];
    let mut n = 0;
    for e in data.map(|d| d.modulus_kpa) {
        if n < seen.len() && !seen[..n].contains(&e) {
            seen[n] = e;
            n += 1;
        }
    }
    n
}

impl PowerLaw {
    /// Paper 003 eq. 5 (experiment): `f = 266.6 − 2305 E^−0.7243`, calibrated on samples A–E
    /// (157.5–2465 kPa).
    /// Its misfit is derived from the published R² = 99.91 % over A–E.
    pub fn paper_experiment() -> Self {
        let (min_kpa, max_kpa) = span(157.5, 2465.0);
        let (a, b, c) = (266.6, -2305.0, -0.7243);
        Self {
            a,
            b,
            c,
            cov: [[0.0; 3]; 3],
            model_sigma_hz: misfit_from_r2(a, b, c, 0.9991, &[157.5, 279.0, 414.0, 1146.0, 2465.0]),
            min_kpa,
            max_kpa,
            source: Source::PaperExperiment,
        }
    }

    /// Paper 003 eq. 4 (simulation): `f = 254.3 − 3435 E^−0.8432` over 100–3000 kPa.
    /// Its misfit is derived from the published R² = 99.89 % over the 14 FEM samples.
    pub fn paper_simulation() -> Self {
        let (min_kpa, max_kpa) = span(100.0, 3000.0);
        let (a, b, c) = (254.3, -3435.0, -0.8432);
        let samples = [
            100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0, 900.0, 1000.0, 1500.0, 2000.0,
            2500.0, 3000.0,
        ];
        Self {
            a,
            b,
            c,
            cov: [[0.0; 3]; 3],
            model_sigma_hz: misfit_from_r2(a, b, c, 0.9989, &samples),
            min_kpa,
            max_kpa,
            source: Source::PaperSimulation,
        }
    }

    /// Resonance (Hz) of tissue of modulus `e_kpa`.
    pub fn frequency(&self, e_kpa: f64) -> f64 {
        self.a + self.b * pow(e_kpa, self.c)
    }

    /// Slope `df/dE` in Hz/kPa at `e_kpa`.
    pub fn slope(&self, e_kpa: f64) -> f64 {
        self.b * self.c * pow(e_kpa, self.c - 1.0)
    }

    /// True when the parameters describe a usable saturating curve.
    pub fn is_valid(&self) -> bool {
        self.a.is_finite()
            && self.b.is_finite()
            && self.c.is_finite()
            && self.b < 0.0
            && self.c < 0.0
            && self.min_kpa > 0.0
            && self.max_kpa > self.min_kpa
    }

    /// Modulus of a resonance `f ± sigma`, with the curve's own uncertainty propagated.
    pub fn invert(&self, f: Hz, sigma: Hz) -> Result<Modulus, Failure> {
        let (f, sf) = inversion_input(self.is_valid(), f, sigma)?;
        if f >= self.a {
            return Err(Failure::AboveRange);
        }
        let u = (self.a - f) / -self.b;
        let e = pow(u, 1.0 / self.c);
        if !e.is_finite() || e > self.max_kpa {
            return Err(Failure::AboveRange);
        }
        if e < self.min_kpa {
            return Err(Failure::BelowRange);
        }
        let de_df = e / (self.c * (f - self.a));
        let g = [
            -de_df,
            -e / (self.c * self.b),
            -e * libm::log(u) / (self.c * self.c),
        ];
        let (misfit, cov) = (self.model_sigma_hz, &self.cov);
        Ok(Modulus::propagated(e, de_df, sf, misfit, &g, cov))
    }

    /// [`fit`](Self::fit) that discards gross outliers first. Repeatedly, the reading with the
    /// largest residual is compared with a fit of all the others (leave-one-out); if it lies more
    /// than five robust standard deviations of the others' residuals (1.4826 × their median
    /// absolute residual; and at least 0.05 Hz and five of its own standard uncertainties) away,
    /// it is dropped. At most a third of the readings are dropped. A
    /// reference reading gone wrong (a bogus peak, a knock) must not bend the whole curve.
    /// `data` is reordered: the kept readings come first.
    pub fn fit_robust(data: &mut [RefPoint]) -> Result<PowerLaw, FitError> {
        let mut kept = data.len();
        let max_drop = kept / 3;
        let mut fit = Self::fit(data)?;
        while data.len() - kept < max_drop {
            // The three largest residuals of the current fit are the candidates.
            let mut cand = [usize::MAX; 3];
            for _ in 0..3 {
                let mut best = (usize::MAX, -1.0);
                for (i, d) in data[..kept].iter().enumerate() {
                    let r = libm::fabs(d.resonance_hz - fit.frequency(d.modulus_kpa));
                    if !cand.contains(&i) && r > best.1 {
                        best = (i, r);
                    }
                }
                if let Some(slot) = cand.iter_mut().find(|c| **c == usize::MAX) {
                    *slot = best.0;
                }
            }
            // Leave each candidate out in turn; keep the most outlying one.
            let mut pick: Option<(usize, f64, PowerLaw)> = None;
            for &c in cand.iter().filter(|c| **c < kept) {
                data.swap(c, kept - 1);
                if let Ok(loo) = Self::fit(&data[..kept - 1]) {
                    let d = data[kept - 1];
                    let r = libm::fabs(d.resonance_hz - loo.frequency(d.modulus_kpa));
                    let scale = robust_scale(&data[..kept - 1], &loo);
                    let z = r / (5.0 * scale).max(0.05).max(5.0 * d.sigma_hz);
                    if z > 1.0 && pick.as_ref().is_none_or(|p| z > p.1) {
                        pick = Some((c, z, loo));
                    }
                }
                data.swap(c, kept - 1);
            }
            let Some((c, _, loo)) = pick else {
                break;
            };
            data.swap(c, kept - 1);
            kept -= 1;
            fit = loo;
        }
        Ok(fit)
    }

    /// Weighted least-squares fit of `(a, b, c)` to reference readings.
    ///
    /// Variable projection: for a fixed exponent the model is linear in `(a, b)`; the exponent is
    /// found by a coarse scan and golden-section refinement over `[-3, -0.05]`. The covariance
    /// comes from the full Jacobian at the optimum, scaled by the reduced χ² when it exceeds 1.
    ///
    /// The curve's misfit (`model_sigma_hz`) is the larger of the residual scatter (corrected for
    /// the three fitted parameters) and, with five or more reference moduli, the RMS
    /// leave-one-out error at the interior moduli: each is predicted by a fit without it. The
    /// residuals at the reference moduli understate how far the power law strays between them;
    /// the leave-one-out errors do not.
    pub fn fit(data: &[RefPoint]) -> Result<PowerLaw, FitError> {
        let mut p = Self::fit_plain(data)?;
        if let Some(loo) = interior_loo_sigma(data) {
            p.model_sigma_hz = p.model_sigma_hz.max(loo);
        }
        Ok(p)
    }

    /// `fit` (a fit of this law) of the readings of `data` not at modulus `e` (the first
    /// [`MAX_REFERENCES`] of them), copied to a scratch array: the held-out
    /// fits of [`held_out_rms`]. Not inlined: the copy (4 KiB) sits on the stack only while it
    /// runs.
    #[inline(never)]
    pub(crate) fn fit_without(
        data: &[RefPoint],
        e: f64,
        fit: fn(&[RefPoint]) -> Result<PowerLaw, FitError>,
    ) -> Result<PowerLaw, FitError> {
        let mut scratch = [RefPoint::default(); MAX_REFERENCES];
        let mut n = 0;
        for (s, x) in scratch
            .iter_mut()
            .zip(data.iter().filter(|x| x.modulus_kpa != e))
        {
            *s = *x;
            n += 1;
        }
        fit(&scratch[..n])
    }

    fn fit_plain(data: &[RefPoint]) -> Result<PowerLaw, FitError> {
        let (emin, emax) = checked_span(data)?;
        let sums = Sums::of(data);
        let c = best_exponent(&sums)?;
        let AtExponent { a, b, chi2 } = at_exponent(&sums, c).ok_or(FitError::NotSaturating)?;
        if !(b < 0.0) || !(c < 0.0) || !a.is_finite() {
            return Err(FitError::NotSaturating);
        }
        let cov = covariance(data, b, c, chi2)?;
        let (min_kpa, max_kpa) = span(emin, emax);
        let mut law = PowerLaw {
            a,
            b,
            c,
            cov,
            model_sigma_hz: 0.0,
            min_kpa,
            max_kpa,
            source: Source::Fitted,
        };
        law.model_sigma_hz = residual_misfit(data, &law);
        Ok(law)
    }
}

/// The modulus span of reference data, `TooFewPoints` with fewer than four readings or three
/// distinct moduli, `BadInput` on a reading that is not finite and positive.
pub(crate) fn checked_span(data: &[RefPoint]) -> Result<(f64, f64), FitError> {
    checked_span_of(data.iter())
}

/// [`checked_span`] of the readings `data` yields.
pub(crate) fn checked_span_of<'a>(
    data: impl Iterator<Item = &'a RefPoint> + Clone,
) -> Result<(f64, f64), FitError> {
    if data.clone().count() < 4 {
        return Err(FitError::TooFewPoints);
    }
    let (mut emin, mut emax) = (f64::INFINITY, 0.0f64);
    for d in data.clone() {
        let (e, f, s) = (d.modulus_kpa, d.resonance_hz, d.sigma_hz);
        if !(e > 0.0) || !e.is_finite() || !f.is_finite() || !(s > 0.0) || !s.is_finite() {
            return Err(FitError::BadInput);
        }
        emin = emin.min(e);
        emax = emax.max(e);
    }
    if distinct_moduli_of(data) < 3 {
        return Err(FitError::TooFewPoints);
    }
    Ok((emin, emax))
}

/// The best straight line `f = a + b x`, `x = E^c`, for one exponent `c`, and its χ².
#[derive(Clone, Copy, Debug, PartialEq)]
struct AtExponent {
    a: f64,
    b: f64,
    chi2: f64,
}

/// Reference data as the power law's fit sums it: per distinct modulus `E` (up to eight), the
/// summed weight `W = Σ wᵢ` (`wᵢ = 1/σᵢ²`) and `T = Σ wᵢ fᵢ` of its readings, else per reading
/// (`W = w`, `T = w f`); and `Σ wᵢ fᵢ²`. At a given exponent every reading at one modulus has
/// the same `x = E^c`, so the normal equations' sums `Σ w x`, `Σ w x²`, `Σ w x f` are sums over
/// the moduli of `W x`, `W x²`, `x T`: one power per modulus and exponent where there was one
/// per reading (each an exponential and a logarithm in software on the M4; a calibration reads
/// each of five phantoms many times).
struct Sums<'a> {
    data: &'a [RefPoint],
    /// `E`, `W`, `T` per modulus; `len` 0: per reading.
    moduli: [[f64; 3]; 8],
    len: usize,
    /// `Σ wᵢ fᵢ²`.
    tt: f64,
}

impl<'a> Sums<'a> {
    fn of(data: &'a [RefPoint]) -> Self {
        let mut s = Sums {
            data,
            moduli: [[0.0; 3]; 8],
            len: 0,
            tt: 0.0,
        };
        for d in data {
            let w = 1.0 / (d.sigma_hz * d.sigma_hz);
            s.tt += w * d.resonance_hz * d.resonance_hz;
            if s.len == usize::MAX {
                continue;
            }
            let i = match s.moduli[..s.len].iter().position(|m| m[0] == d.modulus_kpa) {
                Some(i) => i,
                None if s.len < s.moduli.len() => {
                    s.moduli[s.len][0] = d.modulus_kpa;
                    s.len += 1;
                    s.len - 1
                }
                None => {
                    s.len = usize::MAX;
                    continue;
                }
            };
            s.moduli[i][1] += w;
            s.moduli[i][2] += w * d.resonance_hz;
        }
        if s.len == usize::MAX {
            s.len = 0;
        }
        s
    }

    /// `(E, W, T)` of each modulus, or of each reading.
    fn each(&self, mut f: impl FnMut(f64, f64, f64)) {
        if self.len > 0 {
            for m in &self.moduli[..self.len] {
                f(m[0], m[1], m[2]);
            }
        } else {
            for d in self.data {
                let w = 1.0 / (d.sigma_hz * d.sigma_hz);
                f(d.modulus_kpa, w, w * d.resonance_hz);
            }
        }
    }
}

/// Weighted 2×2 normal equations of `f = a + b E^c` at exponent `c`; `None` when singular.
fn at_exponent(data: &Sums, c: f64) -> Option<AtExponent> {
    let (mut s11, mut s12, mut s22, mut t1, mut t2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    data.each(|e, w, t| {
        let x = pow(e, c);
        s11 += w;
        s12 += w * x;
        s22 += w * x * x;
        t1 += t;
        t2 += x * t;
    });
    let tt = data.tt;
    let det = s11 * s22 - s12 * s12;
    if !(det.abs() > 0.0) {
        return None;
    }
    let a = (s22 * t1 - s12 * t2) / det;
    let b = (s11 * t2 - s12 * t1) / det;
    let chi2 = tt - a * t1 - b * t2;
    Some(AtExponent { a, b, chi2 })
}

/// The exponent of least χ² over `[-3, -0.05]`: a scan of 61 values, then 80 golden-section
/// steps around the best.
fn best_exponent(data: &Sums) -> Result<f64, FitError> {
    let (lo, hi) = (-3.0f64, -0.05f64);
    let steps = 60;
    let mut best_c = f64::NAN;
    let mut best_chi = f64::INFINITY;
    for k in 0..=steps {
        let c = lo + (hi - lo) * k as f64 / steps as f64;
        if let Some(p) = at_exponent(data, c) {
            if p.chi2 < best_chi {
                best_chi = p.chi2;
                best_c = c;
            }
        }
    }
    if !best_c.is_finite() {
        return Err(FitError::NotSaturating);
    }
    let h = (hi - lo) / steps as f64;
    let (mut x0, mut x3) = ((best_c - h).max(lo), (best_c + h).min(hi));
    let gr = 0.618_033_988_749_895;
    let chi = |c: f64| at_exponent(data, c).map_or(f64::INFINITY, |p| p.chi2);
    let mut x1 = x3 - gr * (x3 - x0);
    let mut x2 = x0 + gr * (x3 - x0);
    let (mut f1, mut f2) = (chi(x1), chi(x2));
    for _ in 0..80 {
        if f1 < f2 {
            x3 = x2;
            x2 = x1;
            f2 = f1;
            x1 = x3 - gr * (x3 - x0);
            f1 = chi(x1);
        } else {
            x0 = x1;
            x1 = x2;
            f1 = f2;
            x2 = x0 + gr * (x3 - x0);
            f2 = chi(x2);
        }
    }
    Ok(0.5 * (x1 + x2))
}

/// Covariance of `(a, b, c)` from the Jacobian `[1, E^c, b E^c ln E]`, scaled by the reduced
/// χ² when it exceeds 1.
fn covariance(data: &[RefPoint], b: f64, c: f64, chi2: f64) -> Result<[[f64; 3]; 3], FitError> {
    let mut jtj = [[0.0; 3]; 3];
    for d in data {
        let w = 1.0 / (d.sigma_hz * d.sigma_hz);
        let x = pow(d.modulus_kpa, c);
        let j = [1.0, x, b * x * libm::log(d.modulus_kpa)];
        for r in 0..3 {
            for q in 0..3 {
                jtj[r][q] += w * j[r] * j[q];
            }
        }
    }
    let mut cov = inverse3(&jtj).ok_or(FitError::NotSaturating)?;
    let dof = data.len().saturating_sub(3).max(1) as f64;
    let scale = (chi2 / dof).max(1.0);
    for row in cov.iter_mut() {
        for v in row.iter_mut() {
            *v *= scale;
        }
    }
    Ok(cov)
}

/// Curve misfit (Hz): the mean square residual about `law`, corrected for the three parameters
/// fitted to the distinct reference moduli (only those carry independent misfit).
fn residual_misfit(data: &[RefPoint], law: &PowerLaw) -> f64 {
    let mut ss = 0.0;
    for d in data {
        let r = d.resonance_hz - (law.a + law.b * pow(d.modulus_kpa, law.c));
        ss += r * r;
    }
    let groups = distinct_moduli(data) as f64;
    let misfit2 = if groups > 3.0 {
        ss / data.len() as f64 * groups / (groups - 3.0)
    } else {
        ss / data.len() as f64
    };
    libm::sqrt(misfit2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`Modulus::propagated`] in `f32` against the sum written out in `f64` (every term of
    /// `gᵀ C g` over the full matrix), over inputs wider than any calibration's: moduli
    /// 10–5000 kPa, slopes 1–1000 kPa/Hz, σ 1e-4–10 Hz, misfits 0–1 Hz, gradients up to 1e4 kPa
    /// of either sign, and covariances of parameter σ 1e-3–0.3 correlated up to 0.9999 (where
    /// `gᵀ C g` may cancel to a small part of its terms). The variance is held to 2e-6 of the
    /// sum of its terms' magnitudes — a few of `f32`'s roundings of the largest term, the
    /// measured worst case with a margin of four — and the repeatability σ, a product, to 1e-6
    /// of itself.
    #[test]
    fn propagated_f32_holds_f32s_precision_of_its_terms() {
        let mut rng = probe_rng::Rng::new(5);
        let mut u = |lo: f64, hi: f64| lo * (hi / lo).powf(rng.uniform());
        for k in 0..20_000 {
            let e = u(10.0, 5000.0);
            let de_df = -u(1.0, 1000.0);
            let (sf, misfit) = (u(1e-4, 10.0), if k % 5 == 0 { 0.0 } else { u(1e-3, 1.0) });
            let sign = |k: usize, i: usize| if (k >> i) & 1 == 0 { 1.0 } else { -1.0 };
            let g: [f64; 3] = core::array::from_fn(|i| sign(k, i) * u(1.0, 1e4));
            let sd: [f64; 3] = core::array::from_fn(|_| u(1e-3, 0.3));
            let rho = [
                sign(k, 3) * (1.0 - u(1e-4, 1.0)),
                sign(k, 4) * (1.0 - u(1e-4, 1.0)),
            ];
            // A positive semi-definite correlation: rows of unit vectors' dot products.
            let v = [
                [1.0, 0.0],
                [rho[0], (1.0 - rho[0] * rho[0]).sqrt()],
                [rho[1], (1.0 - rho[1] * rho[1]).sqrt()],
            ];
            let cov: [[f64; 3]; 3] = core::array::from_fn(|i| {
                core::array::from_fn(|j| sd[i] * sd[j] * (v[i][0] * v[j][0] + v[i][1] * v[j][1]))
            });
            let mut terms = [
                de_df * de_df * sf * sf,
                de_df * de_df * misfit * misfit,
                0.0,
            ];
            let mut gcg = 0.0;
            for i in 0..3 {
                for j in 0..3 {
                    let t = g[i] * g[j] * cov[i][j];
                    gcg += t;
                    terms[2] += t.abs();
                }
            }
            let var = terms[0] + terms[1] + gcg;
            let scale: f64 = terms.iter().sum();
            let g32 = g.map(|x| x as f32);
            let m =
                Modulus::propagated(e as f32, de_df as f32, sf as f32, misfit as f32, &g32, &cov);
            let err = ((m.sigma.0 as f64).powi(2) - var.max(0.0)).abs() / scale;
            assert!(err < 2e-6, "{k}: {} vs {}", m.sigma.0, var.sqrt());
            let rep = de_df.abs() * sf;
            assert!((m.sigma_repeat.0 as f64 / rep - 1.0).abs() < 1e-6, "{k}");
            assert_eq!(m.value.0, e as f32);
        }
    }

    #[test]
    fn published_values() {
        // DIGEST: f_e(100 kPa) = 184.5 Hz; slopes 0.09 Hz/kPa at 300 kPa, 0.011 at 1 MPa,
        // 0.0023 at 2.5 MPa.
        let p = PowerLaw::paper_experiment();
        assert!((p.frequency(100.0) - 184.5).abs() < 0.1);
        assert!((p.slope(300.0) - 0.09).abs() < 0.005);
        assert!((p.slope(1000.0) - 0.011).abs() < 0.001);
        assert!((p.slope(2500.0) - 0.0023).abs() < 0.0003);
        // Misfit from R² = 99.91 % over A–E (f spans 207.6..258.5 Hz): about 0.55 Hz.
        assert!(
            (p.model_sigma_hz - 0.55).abs() < 0.03,
            "{}",
            p.model_sigma_hz
        );
        // Paper: 206.3 Hz and 223.5 Hz are 151.8 and 246.3 kPa by f_e. The published rounded
        // constants give 153.0 and 243.2 kPa: within 1.5 % of the paper's figures.
        let m = p.invert(Hz(206.3), Hz(0.0)).unwrap();
        assert!((m.value.0 / 151.8 - 1.0).abs() < 0.015, "{}", m.value.0);
        let m = p.invert(Hz(223.5), Hz(0.0)).unwrap();
        assert!((m.value.0 / 246.3 - 1.0).abs() < 0.015, "{}", m.value.0);
    }

    #[test]
    fn source_names_round_trip() {
        for s in Source::ALL {
            assert_eq!(Source::from_name(s.name()), Some(s));
        }
        assert_eq!(Source::from_name("measured"), None);
    }

    #[test]
    fn inverse_round_trip_and_uncertainty() {
        let p = PowerLaw::paper_experiment();
        for e in [200.0, 500.0, 1000.0, 2000.0] {
            let f = p.frequency(e);
            let m = p.invert(Hz(f as f32), Hz(0.1)).unwrap();
            assert!((m.value.0 as f64 / e - 1.0).abs() < 1e-4);
            // repeatability: sigma_E = sigma_f / slope; combined adds the curve misfit.
            let expect = 0.1 / p.slope(e);
            assert!((m.sigma_repeat.0 as f64 / expect - 1.0).abs() < 1e-3);
            let combined = (0.1f64.powi(2) + p.model_sigma_hz.powi(2)).sqrt() / p.slope(e);
            assert!((m.sigma.0 as f64 / combined - 1.0).abs() < 1e-3);
        }
    }

    #[test]
    fn range_checks() {
        let p = PowerLaw::paper_experiment();
        assert_eq!(p.invert(Hz(266.6), Hz(0.1)), Err(Failure::AboveRange));
        assert_eq!(p.invert(Hz(300.0), Hz(0.1)), Err(Failure::AboveRange));
        assert_eq!(p.invert(Hz(265.0), Hz(0.1)), Err(Failure::AboveRange));
        assert_eq!(p.invert(Hz(150.0), Hz(0.1)), Err(Failure::BelowRange));
        assert_eq!(p.invert(Hz(-5.0), Hz(0.1)), Err(Failure::BelowRange));
        assert_eq!(p.invert(Hz(f32::NAN), Hz(0.1)), Err(Failure::BadSettings));
    }

    #[test]
    fn fit_recovers_known_curve() {
        let truth = PowerLaw::paper_experiment();
        let at = |e: f64| RefPoint {
            modulus_kpa: e,
            resonance_hz: truth.frequency(e),
            sigma_hz: 0.05,
            force_n: 0.0,
        };
        let data = [157.5, 279.0, 414.0, 1146.0, 2465.0].map(at);
        let fit = PowerLaw::fit(&data).unwrap();
        assert!((fit.a - truth.a).abs() < 1e-3, "{}", fit.a);
        assert!((fit.b / truth.b - 1.0).abs() < 1e-4);
        assert!((fit.c - truth.c).abs() < 1e-5);
        assert_eq!(fit.source, Source::Fitted);
        // One bogus reference reading (a wrong peak) is discarded by the robust fit.
        let mut noisy = [
            157.5, 279.0, 414.0, 1146.0, 2465.0, 200.0, 600.0, 900.0, 1800.0,
        ]
        .map(at);
        noisy[0].resonance_hz += 12.0;
        let plain = PowerLaw::fit(&noisy).unwrap();
        let robust = PowerLaw::fit_robust(&mut noisy).unwrap();
        assert!(
            (plain.a - truth.a).abs() > 0.5,
            "plain fit should be bent: {}",
            plain.a
        );
        assert!((robust.a - truth.a).abs() < 1e-3, "{}", robust.a);
        assert!(PowerLaw::fit(&data[..3]).is_err());
        let bad = [RefPoint {
            modulus_kpa: 1.0,
            resonance_hz: f64::NAN,
            sigma_hz: 0.1,
            force_n: 0.0,
        }; 5];
        assert_eq!(PowerLaw::fit(&bad), Err(FitError::BadInput));
    }
}
