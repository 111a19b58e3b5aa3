//! The unit profile: everything one probe unit needs to read correctly, and the one procedure
//! that takes its air reference.
//!
//! A reading is only as good as the unit data behind it: the calibration curve (with its
//! covariance and valid span), the contact condition the curve holds for (the [`QModel`]), and
//! the air reference — the free probe's resonance and Q, which tell contact from no contact,
//! and its static admittance `G0 + j2πfC0`, which `hold` subtracts. All of it lives in one
//! [`UnitProfile`]; the firmware keeps it in flash ([`crate::unit::store`]), the bench in a file, and
//! every reading goes through [`crate::reading::pipeline`] with it.

use crate::engine::sweep::{SweepPoint, SweepSettings};
use crate::estimate::fit::fit_bvd;
use crate::linalg::Real;
use crate::loadcell::{ContactForce, ForceWindow, LoadCellCal};
use crate::status::Failure;
use crate::unit::calibration::{held_out_rms, Modulus, PowerLaw, RefPoint, MAX_REFERENCES};
use crate::unit::contact_law::{ContactLaw, LawAt};
use crate::unit::q_model::{DampingModel, QModel};
use crate::units::{Farads, Hz, Seconds, Siemens, Volts};

/// A reading whose Q exceeds this fraction of the free Q may be free air.
pub const NO_CONTACT_Q_FRACTION: f32 = 0.6;
/// ... if its resonance is also this close to the free one.
pub const NO_CONTACT_SPAN_HZ: f32 = 5.0;
/// Lowest Q an air reference may have. The free probe rings with Q ≈ 40 (paper 003's plate,
/// `hal-sim`'s free Q); any tissue damps the mode to Q 5–15 at the nominal preload and a light
/// touch to 20–26 (`docs/physics.md`). An "air reference" below this was taken touching
/// something and would make every later contact check wrong.
pub const MIN_AIR_Q: f32 = 30.0;

/// The free probe in air: what "no contact" looks like, and the static admittance of the PZT.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AirReference {
    /// Resonance in air.
    pub free_resonance: Hz,
    /// Quality factor in air.
    pub free_q: f32,
    /// Static (clamped) capacitance `C0` of the PZT and its wiring.
    pub static_capacitance: Farads,
    /// Static conductance `G0` (dielectric loss, leakage).
    pub static_conductance: Siemens,
}

impl AirReference {
    /// True when every value is finite, the resonance and Q positive, `C0` within 0–100 nF and
    /// `G0` within ±1 mS (the ranges `hold` accepts).
    pub fn is_valid(&self) -> bool {
        self.free_resonance.0.is_finite()
            && self.free_resonance.0 > 0.0
            && self.free_q.is_finite()
            && self.free_q > 0.0
            && (0.0..=100e-9).contains(&self.static_capacitance.0)
            && (-1e-3..=1e-3).contains(&self.static_conductance.0)
    }

    /// True when `(f, q)` looks like the free probe.
    ///
    /// Frequency alone cannot tell: near 330 kPa the loaded resonance equals the free one. The
    /// quality factor can: tissue damps the mode, while the free probe rings with Q ≈ 40. A
    /// reading looks free when its Q exceeds [`NO_CONTACT_Q_FRACTION`] of the free Q *and* its
    /// resonance lies within [`NO_CONTACT_SPAN_HZ`] of the free one (a rigid contact also
    /// rings well, but far above).
    pub fn looks_free(&self, f: Hz, q: f32) -> bool {
        q > NO_CONTACT_Q_FRACTION * self.free_q
            && libm::fabsf(f.0 - self.free_resonance.0) < NO_CONTACT_SPAN_HZ
    }
}

/// The stepped sweep an air reference is taken with: 170–290 Hz in 2 Hz steps (the free
/// resonance and the whole band readings use), 50 ms settling, 100 ms integration, 5 V
/// (9.2 s of probe time). Its points go to [`air_from_points`].
pub const AIR_SWEEP: SweepSettings = SweepSettings {
    start: Hz(170.0),
    stop: Hz(290.0),
    step: Hz(2.0),
    settle: Seconds(0.05),
    integrate: Seconds(0.1),
    drive: Volts(5.0),
};

/// The air reference from the points of a sweep of the free probe ([`AIR_SWEEP`]): a
/// Butterworth–Van Dyke fit of the admittance gives the free resonance and Q and the static
/// admittance. Fails with the fit's code, or `bad_contact` when the Q is too low for a free
/// probe ([`MIN_AIR_Q`]: something touches the tip).
pub fn air_from_points(points: &[SweepPoint]) -> Result<AirReference, Failure> {
    let i = crate::estimate::argmax(points, |p| p.g_s).ok_or(Failure::NoResonance)?;
    let b = fit_bvd(points, points[i].freq.0 as f64, 30.0)?;
    let air = AirReference {
        free_resonance: Hz(b.f0 as f32),
        free_q: b.q as f32,
        static_capacitance: Farads((b.b0 / (2.0 * core::f64::consts::PI * b.f_ref)) as f32),
        static_conductance: Siemens(b.g0 as f32),
    };
    if !air.is_valid() {
        return Err(Failure::NoResonance);
    }
    if !(air.free_q >= MIN_AIR_Q) {
        return Err(Failure::BadContact);
    }
    Ok(air)
}

/// Everything one unit needs to turn a resonance into a trustworthy modulus.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UnitProfile {
    /// Calibration curve of this unit, with covariance and valid span.
    pub calibration: PowerLaw,
    /// The resonance the curve maps (that of the method it was calibrated with): readings by a
    /// method that reports another are refused (`uncalibrated`).
    pub resonance: crate::estimate::Resonance,
    /// The contact condition of the calibration: Q against modulus on the reference phantoms.
    /// Without it no reading is given (`uncalibrated`).
    pub q_model: Option<QModel>,
    /// Air reference, once taken. Without it no reading is given (`no_air_reference`).
    pub air: Option<AirReference>,
    /// The contact law, when the calibration chose it over the power law (it predicted the
    /// held-out reference moduli better, [`calibrate`]): readings then invert through it, at
    /// the contact force each reading measured. The power law stays the curve a user
    /// recognises and compares (at the nominal force, [`NOMINAL_FORCE`]).
    pub contact: Option<ContactLaw>,
    /// The load cell's calibration (sensitivity from a known weight, zero tared with the air
    /// reference). With it every reading needs its contact force (`no_force` without one) and
    /// takes it inside `force_window`; without it (a unit with no load cell) readings carry no
    /// force and the Q model alone judges the contact.
    pub load_cell: Option<LoadCellCal>,
    /// The contact forces readings are taken at (with a load cell).
    pub force_window: ForceWindow,
}

/// The standard uncertainty of the probe's own resonance at a reading against its state at the
/// air reference and the calibration — a term of every reading's combined σ, through the curve
/// (the contact law with its free resonance moved by it). Its source: the simulated probe's
/// thermal drift scenes move the free resonance by 0.3 Hz/s (hal-sim `catalogue::DRIFT_HZ_S`),
/// 0.11 Hz over a reading of 0.37 s (the default until 2026-11-24; 0.04 Hz over today's 0.13 s);
/// rounded up to 0.12 Hz so that the catalogue's
/// second mode, which the calibration never saw and which pulls the resonance by about
/// 0.33 Hz (1.1 % at 300 kPa), stays within 3σ (the stability statement,
/// bench/tests/stability.rs) — a choice, not a derivation. A unit whose probe drifts more needs
/// a fresher air reference. docs/accuracy.md measures what it adds (2–16 % per Hz over
/// 200–2000 kPa) and its coverage.
pub const FREE_RESONANCE_ALLOWANCE: Hz = Hz(0.12);

/// How fast the probe's own resonance may move during a reading, Hz/s: the thermal drift the
/// probe is specified for (the stability catalogue's drift scenes, hal-sim
/// `catalogue::DRIFT_HZ_S`). A reading of probe time `t` allows `DRIFT_EPOCH t` times it on top of
/// [`FREE_RESONANCE_ALLOWANCE`] ([`drift_allowance`]): a long reading (a stepped sweep, the
/// adaptive and track procedures, 1–6 s) sees more of the drift than the default's 0.13 s.
pub const FREE_RESONANCE_DRIFT_HZ_S: f32 = 0.3;

/// Where in its probe time a reading's resonance lies, as a fraction of it: the
/// information-weighted epoch of the default method (a steady drift of the free resonance moves
/// auto's reading by `DRIFT_EPOCH × rate × probe time`: the mean over 300–2500 kPa of what
/// `bench/tests/accuracy.rs::a_steady_drift_moves_the_reading_by_its_epoch` measures). Uniform weighting
/// would give 0.5; hold's information builds up with the response, so its later windows weigh
/// more.
pub const DRIFT_EPOCH: f32 = 0.61;

/// The free resonance's allowance of a reading that took `probe_time`:
/// [`FREE_RESONANCE_ALLOWANCE`] and [`FREE_RESONANCE_DRIFT_HZ_S`] × [`DRIFT_EPOCH`] ×
/// `probe_time` in quadrature: a reading measures the resonance over its whole window, so a
/// steady drift moves it by what the drift reaches at the reading's epoch, not by its end.
/// (Until 2026-11-24 the whole probe time: the reported σ covered 74.6 % of the truths at 1σ
/// against the 68.3 % it states, docs/accuracy.md.)
pub fn drift_allowance(probe_time: crate::units::Seconds) -> Hz {
    let d = DRIFT_EPOCH * FREE_RESONANCE_DRIFT_HZ_S * probe_time.0.max(0.0);
    Hz(libm::sqrtf(
        FREE_RESONANCE_ALLOWANCE.0 * FREE_RESONANCE_ALLOWANCE.0 + d * d,
    ))
}

/// The force the paper calibrated at, and the power law's: 30 mN (paper 003, a balance and a
/// motorised stage). References read at it (within [`crate::unit::calibration::SAME_FORCE`]), or
/// without a measured force, make the power law.
pub const NOMINAL_FORCE: crate::units::Newtons = crate::units::Newtons(0.030);

impl UnitProfile {
    /// The profile of a unit that was never calibrated: the paper's experimental curve, no
    /// contact condition, no air reference. Readings with it are refused until an air reference
    /// is taken and the unit is calibrated.
    pub fn fallback() -> Self {
        Self {
            calibration: PowerLaw::paper_experiment(),
            resonance: crate::estimate::Resonance::Motional,
            q_model: None,
            air: None,
            contact: None,
            load_cell: None,
            force_window: ForceWindow::DEFAULT,
        }
    }

    /// Read through the power law `law` (mapping `resonance`) from now on: the contact law, if
    /// any, goes (it belongs to the calibration `law` replaces), and with it the Q model's
    /// contact-damping curve (fitted through it; the empirical curve stays).
    pub fn use_power_law(&mut self, law: PowerLaw, resonance: crate::estimate::Resonance) {
        self.calibration = law;
        self.resonance = resonance;
        self.contact = None;
        if let Some(m) = self.q_model.as_mut() {
            m.damping = None;
        }
    }

    /// The tissue's loss tangent and its standard uncertainty from a reading of modulus `e_kpa`
    /// at the contact force `force_n` (N) with quality factor `q ± q_sigma`, beyond the
    /// reference phantoms' own loss: the mode's `1/Q` above the lossless calibrated contact's
    /// ([`QModel::q_at`] through the contact law: the contact-damping curve where the
    /// calibration fitted one) is the tissue's loss tangent times its share of the mode's loss
    /// ([`ContactLaw::loss_share`]), `η = (1/Q − 1/Q_cal) / φ`. Its σ combines the reading's
    /// σ(Q) and the curve's own uncertainty ([`QModel::scatter`]); the contact law's own
    /// uncertainty, a common scale on `φ`, is left out. `None` without a contact law, a Q
    /// model, a σ(Q), or where the tissue's share vanishes.
    pub fn tissue_loss(
        &self,
        e_kpa: f64,
        force_n: Option<f64>,
        q: f64,
        q_sigma: Option<f64>,
    ) -> Option<(f64, f64)> {
        let law = self.contact?.at_force::<f64>(force_n);
        let q_cal = self.q_model?.q_on(e_kpa, force_n, Some(&law));
        self.tissue_loss_on(&law, e_kpa, q_cal, q, q_sigma)
    }

    /// [`Self::tissue_loss`] with the contact law at the reading's force already evaluated
    /// ([`ContactLaw::at_force`]), in `T` (a reading's: `f32`), and the lossless calibrated
    /// contact's `q_cal` there ([`QModel::q_on`] through that law) already known.
    pub fn tissue_loss_on<T: Real>(
        &self,
        law: &LawAt<T>,
        e_kpa: T,
        q_cal: f64,
        q: f64,
        q_sigma: Option<f64>,
    ) -> Option<(f64, f64)> {
        let (model, q_sigma) = (self.q_model?, q_sigma?);
        let share = law.loss_share(e_kpa).wide();
        if !(share > 1e-6) || !(q_cal > 0.0) || !(q > 0.0) {
            return None;
        }
        let eta = (1.0 / q - 1.0 / q_cal) / share;
        let (d_q, d_cal) = (
            q_sigma / (q * q),
            model.scatter(self.contact.as_ref()) / q_cal,
        );
        let sigma = crate::dsp::trig::sqrt32(d_q * d_q + d_cal * d_cal) as f64 / share;
        (eta.is_finite() && sigma.is_finite()).then_some((eta, sigma))
    }

    /// The modulus of a resonance `f ± sigma` read at the contact force `force` by the unit's
    /// curve: the contact law at that force when the calibration chose it, else the power law
    /// (which holds at [`NOMINAL_FORCE`] alone).
    ///
    /// Its combined σ is the curve's ([`crate::unit::calibration::Modulus::propagated`]: the
    /// resonance's and the force's repeatability, the calibration's parameter covariance and
    /// its held-out misfit) and the free resonance's allowance over a reading of `probe_time`
    /// ([`drift_allowance`]), in quadrature.
    pub fn invert(
        &self,
        f: crate::units::Hz,
        sigma: crate::units::Hz,
        force: Option<&ContactForce>,
        probe_time: crate::units::Seconds,
    ) -> Result<Modulus, Failure> {
        self.invert_with(f, sigma, force, drift_allowance(probe_time))
    }

    /// [`UnitProfile::invert`] with the free resonance's allowance `allowance` (the error
    /// budget takes the σ apart with it; readings use [`drift_allowance`] of their probe time).
    pub fn invert_with(
        &self,
        f: crate::units::Hz,
        sigma: crate::units::Hz,
        force: Option<&ContactForce>,
        allowance: Hz,
    ) -> Result<Modulus, Failure> {
        let force = force.map(|w| (w.mean.0 as f64, w.sigma.0 as f64));
        let u = allowance.0 as f64;
        // The modulus, and what it would be had the probe's free resonance moved by the
        // allowance since the air reference: the contact law with its free resonance moved, the
        // power law (which has none) with the resonance moved by as much.
        let (m, moved) = match &self.contact {
            Some(c) => {
                let (m, moved) = c.invert_moved(f, sigma, force, u);
                (m?, moved)
            }
            None => (
                self.calibration.invert(f, sigma)?,
                (u != 0.0).then(|| {
                    let moved = self.calibration.invert(Hz(f.0 - u as f32), sigma);
                    moved.map(|x| x.value)
                }),
            ),
        };
        // Near the span's ends the moved inversion may leave it: the allowance then goes by the
        // slope on the other side (the same to first order).
        let drift = match moved {
            Some(Ok(x)) if u > 0.0 => libm::fabsf(x.0 - m.value.0),
            _ => 0.0,
        };
        Ok(Modulus {
            sigma: crate::units::KPa(libm::sqrtf(m.sigma.0 * m.sigma.0 + drift * drift)),
            ..m
        })
    }

    /// True when the profile may be stored and used (valid curve, finite covariance, finite
    /// contact condition and valid air reference where present; a contact-damping curve only
    /// with the contact law it was fitted through).
    pub fn is_valid(&self) -> bool {
        self.calibration.is_valid()
            && self.calibration.cov.iter().flatten().all(|v| v.is_finite())
            && self.calibration.model_sigma_hz.is_finite()
            && self.calibration.model_sigma_hz >= 0.0
            && self
                .q_model
                .is_none_or(|m| m.is_valid() && (m.damping.is_none() || self.contact.is_some()))
            && self.air.is_none_or(|a| a.is_valid())
            && self.contact.is_none_or(|c| c.is_valid())
            && self.load_cell.is_none_or(|c| c.is_valid())
            && self.force_window.is_valid()
    }
}

/// One reference reading for a calibration: a phantom of known modulus and what the unit read
/// on it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reference {
    /// The phantom's modulus, kPa.
    pub modulus_kpa: f64,
    /// The resonance read on it, Hz.
    pub resonance_hz: f64,
    /// Its standard uncertainty, Hz.
    pub sigma_hz: f64,
    /// Its quality factor.
    pub q: f64,
    /// The contact force it was read at, N (0: not measured).
    pub force_n: f64,
}

/// What a calibration gives a unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// The power law `f = a + b E^c`.
    pub law: PowerLaw,
    /// The contact condition `Q(E)`.
    pub q_model: QModel,
    /// The contact law, when it predicts the held-out references better than the power law.
    pub contact: Option<ContactLaw>,
}

/// Calibrate a unit from its reference readings: the robust weighted fit of `f = a + b E^c`
/// ([`PowerLaw::fit_robust`]) on the readings at the nominal force ([`NOMINAL_FORCE`], or all
/// of them when none has a measured force), the contact condition `Q(E, F)` ([`QModel::fit`];
/// with the contact law kept, also its contact-damping curve through it, [`DampingModel::fit`])
/// and, with the air reference's free resonance, the contact law ([`ContactLaw::fit`]) of
/// every reading at its own force. The contact law is kept only when it predicts the
/// references better held out: each distinct reference modulus in turn is left out (at every
/// force it was read at), both curves are fitted to the rest, and the RMS over the moduli of
/// the mean difference between the left-out readings and each curve's prediction for them
/// decides. The one calibration procedure of the firmware's `calibrate fit` and the bench's
/// `calibrate`. Uses the first [`MAX_REFERENCES`] readings. The contact law's misfit
/// (`model_sigma_hz`, a term of every reading's σ) is the same held-out RMS over the interior
/// moduli (all but the lowest and the highest: a reading inside the span interpolates; three
/// more fits of the law) — docs/accuracy.md measures what it covers.
// Not inlined: its scratch (the references, 4 KiB) then sits on the stack only while a
// calibration runs, not in every caller's frame (the firmware's session handles every command).
#[inline(never)]
pub fn calibrate(
    refs: &[Reference],
    air: Option<&AirReference>,
) -> Result<Calibration, crate::unit::calibration::FitError> {
    let n = refs.len().min(MAX_REFERENCES);
    let refs = &refs[..n];
    let mut points = [RefPoint::default(); MAX_REFERENCES];
    for (d, r) in points.iter_mut().zip(refs) {
        *d = RefPoint {
            modulus_kpa: r.modulus_kpa,
            resonance_hz: r.resonance_hz,
            sigma_hz: r.sigma_hz,
            force_n: r.force_n,
        };
    }
    let any_force = refs.iter().any(|d| d.force_n > 0.0);
    let f0 = if any_force {
        NOMINAL_FORCE.0 as f64
    } else {
        0.0
    };
    // The contact law and the held-out comparison take every reading as given.
    let all = &points[..n];
    let contact = air.and_then(|a| {
        let free = a.free_resonance.0 as f64;
        let c = ContactLaw::fit(all, free, f0).ok()?;
        let held_contact = held_out_rms(all, false, |d, e| {
            ContactLaw::fit_leaving_out(d, free, f0, Some(e))
                .ok()
                .map(|c| move |r: &RefPoint| c.frequency_at(r.modulus_kpa, r.force_n))
        })?;
        let held_power = held_out_rms(all, false, |d, e| {
            PowerLaw::fit_without(d, e, PowerLaw::fit)
                .ok()
                .map(|p| move |r: &RefPoint| p.frequency(r.modulus_kpa))
        })?;
        // The law's misfit is its held-out one: how far the curve fitted without an interior
        // modulus misses that modulus's readings (their mean, at each force), RMS over the
        // moduli — what a reading between the references is off by, where the in-sample
        // residual is mostly the readings' own noise, already in their repeatability.
        let interior = held_out_rms(all, true, |d, e| {
            ContactLaw::fit_leaving_out(d, free, f0, Some(e))
                .ok()
                .map(|c| move |r: &RefPoint| c.frequency_at(r.modulus_kpa, r.force_n))
        })?;
        (held_contact < held_power).then_some(ContactLaw {
            model_sigma_hz: interior,
            ..c
        })
    });
    // The power law holds at one force: the nominal one's references (all, without forces),
    // moved to the front; its robust fit reorders them, kept ones first.
    let mut m = 0;
    for i in 0..n {
        let d = points[i];
        if !any_force || libm::fabs(d.force_n / f0 - 1.0) <= crate::unit::calibration::SAME_FORCE {
            points.swap(i, m);
            m += 1;
        }
    }
    let law = PowerLaw::fit_robust(&mut points[..m])?;
    let q_model = QModel {
        damping: contact.as_ref().and_then(|c| DampingModel::fit(refs, c)),
        ..QModel::fit(refs.iter().map(|r| (r.modulus_kpa, r.force_n, r.q)))
            .ok_or(crate::unit::calibration::FitError::TooFewPoints)?
    };
    Ok(Calibration {
        law,
        q_model,
        contact,
    })
}
