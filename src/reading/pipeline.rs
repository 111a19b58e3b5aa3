//! One reading, from an estimate to the number a user gets: the only way to a modulus.
//!
//! ```text
//! estimate ─▶ air reference present? ─▶ Q measured? ─▶ contact force (with a load cell: present,
//!          above no-contact, inside the force window, steady) ─▶ contact (against the air
//!          reference) ─▶ the curve maps this method's resonance ─▶ calibration at the measured
//!          force with range check ─▶ contact condition (Q against the Q model at that force)
//!          ─▶ repeatability small enough to tell tissue apart ─▶ Reading
//! ```
//!
//! Every caller — the firmware's measurement task, `probe-bench measure`, `scan`, `analyze`,
//! `calibrate`, the stability map and the speed chart — ends its readings here with the unit's
//! [`UnitProfile`]; there are no optional after-steps. A check that cannot be made (no air
//! reference, no Q model, no Q) is a failure with its own code, never a skipped check.

use crate::estimate::Estimate;
use crate::loadcell::{ContactForce, RawForce, MAX_FORCE_CHANGE, NO_CONTACT_FORCE};
use crate::reading::{Method, Reading};
use crate::status::{Failure, Status};
use crate::unit::profile::UnitProfile;
use crate::unit::q_model::QDeviation;
use crate::units::Seconds;

/// Largest relative repeatability uncertainty of a modulus that is still a reading. The
/// phantoms a user tells apart differ by 50 % or more (paper 003's A–E: 157–2465 kPa) and a
/// lump by 60 % (151.8 against 246.3 kPa); a reading whose own scatter is a tenth of its value
/// cannot place tissue on that scale, whatever its mean. The default methods read 0.01–0.3 %
/// in the bench noise and below 1 % in the paper's (`docs/speed-accuracy.md`).
pub const MAX_RELATIVE_REPEATABILITY: f32 = 0.10;

/// The lowest quality factor a reading is given at (`broad_resonance` below): on tissue so lossy
/// that the mode's Q falls under it the resonance is wider than a third of its frequency, where
/// the default method's modulus strayed beyond 2 % of the truth on the simulated probe. Ours,
/// with a margin; `bench/tests/lossy_tissue.rs` holds the readings above it over moduli and loss
/// tangents, docs/accuracy.md gives their errors.
pub const MIN_READABLE_Q: f32 = 3.0;

/// What the load cell says against a reading (with a load cell): no force measured, contact lost
/// during the reading, no contact, too light, too hard, or a force that changed during the
/// reading; `None` when the press is fine.
fn press_failure(unit: &UnitProfile, force: Option<&ContactForce>) -> Option<Failure> {
    let Some(w) = force else {
        return Some(Failure::NoForce);
    };
    // The force at the window's end, on the fitted line through it.
    let end = w.mean.0 + 0.5 * w.change.0;
    if !(w.mean.0.is_finite() && w.change.0.is_finite()) {
        Some(Failure::NoForce)
    } else if w.mean.0 >= NO_CONTACT_FORCE.0 && end < NO_CONTACT_FORCE.0 {
        // Pressed at first, off the tissue by the end: the probe was lifted during the reading.
        Some(Failure::ContactLost)
    } else if w.mean.0 < NO_CONTACT_FORCE.0 {
        Some(Failure::NoContact)
    } else if w.mean.0 < unit.force_window.min.0 {
        Some(Failure::TooLight)
    } else if w.mean.0 > unit.force_window.max.0 {
        Some(Failure::TooHard)
    } else if libm::fabsf(w.change.0) > MAX_FORCE_CHANGE.0 {
        Some(Failure::ForceUnstable)
    } else {
        None
    }
}

/// Conclude a reading by `method` from its estimate with the unit's profile and the load
/// cell's counts over the reading's window (`raw_force`; ignored by a unit without a load
/// cell).
pub fn conclude(
    method: Method,
    est: Result<Estimate, Failure>,
    unit: &UnitProfile,
    probe_time: Seconds,
    points: u16,
    raw_force: Option<RawForce>,
) -> Reading {
    let force = unit
        .load_cell
        .zip(raw_force)
        .map(|(cal, w)| cal.contact_force(&w));
    let fail = |f| Reading {
        force,
        ..Reading::failed(method, f, probe_time, points)
    };
    // The contact force, with a load cell: there, pressing, inside the window, steady.
    let press = unit.load_cell.and(press_failure(unit, force.as_ref()));
    let est = match est {
        Ok(e) => e,
        // A press that moved, slipped or lifted during the reading explains whatever the
        // estimator then made of it (a moving resonance reads as interference, lost lock, ...):
        // the load cell's verdict is the one to report. A fault of the instrument stays, and so
        // does the estimator's own failure when the load cell has no verdict on the press (no
        // force: a reading that failed before the cell's first conversion is not a cable fault).
        // A press that moved by less than the window allows is still the likely cause when the
        // estimator refused the reading: the resonance moved with it.
        Err(f) => {
            // (`force` is `None` on a unit without a load cell.)
            let moved = force
                .filter(ContactForce::moved)
                .map(|_| Failure::ForceUnstable);
            let verdict = press
                .filter(|p| *p != Failure::NoForce)
                .or(moved)
                .filter(|_| !f.is_fault());
            return fail(verdict.unwrap_or(f));
        }
    };
    let mut r = Reading::estimated(method, &est, probe_time, points, force);
    let Some(air) = unit.air else {
        r.status = Status::Failed(Failure::NoAirReference);
        return r;
    };
    // Without a Q, contact cannot be told from no contact: the peak's width is not resolved.
    let Some(q) = est.q.filter(|q| q.is_finite() && *q > 0.0) else {
        r.status = Status::Failed(Failure::LowSnr);
        return r;
    };
    if let Some(f) = press {
        r.status = Status::Failed(f);
        return r;
    }
    if q < MIN_READABLE_Q {
        r.status = Status::Failed(Failure::BroadResonance);
        return r;
    }
    if air.looks_free(est.resonance, q) {
        r.status = Status::Failed(Failure::NoContact);
        return r;
    }
    // A curve maps the resonance of the method it was calibrated with; paper's |Z| dip lies
    // several hertz off the motional resonance the others report.
    if method.resonance() != unit.resonance {
        r.status = Status::Failed(Failure::Uncalibrated);
        return r;
    }
    let m = match unit.invert(est.resonance, est.sigma, force.as_ref(), probe_time) {
        Ok(m) => m,
        Err(f) => {
            r.status = Status::Failed(f);
            return r;
        }
    };
    let Some(q_model) = unit.q_model else {
        r.status = Status::Failed(Failure::Uncalibrated);
        return r;
    };
    // The contact: with a load cell the force window and its stability judge the press, and Q
    // may only say what tissue loss cannot (a Q above the calibrated contact's); without one,
    // a Q off the curve either way is the only sign of a press unlike the calibration's. The
    // contact law at the reading's force is evaluated once, in `f32` (the M4F's FPU).
    let force_n = force.map(|w| w.mean.0 as f64);
    let law = unit.contact.map(|c| c.at_force::<f32>(force_n));
    let e_kpa = m.value.0;
    let q_cal = q_model.q_on(e_kpa, force_n, law.as_ref());
    let deviation = QDeviation::of(q as f64, q_cal as f64);
    let contact_unlike = match force_n {
        Some(_) => deviation.exceeded(),
        None => !deviation.holds(),
    };
    if contact_unlike {
        r.status = Status::Failed(Failure::BadContact);
        return r;
    }
    if !(m.sigma_repeat.0 <= MAX_RELATIVE_REPEATABILITY * m.value.0) {
        r.status = Status::Failed(Failure::LowSnr);
        return r;
    }
    r.modulus = Some(m.value);
    r.modulus_sigma = Some(m.sigma);
    r.modulus_sigma_repeat = Some(m.sigma_repeat);
    let q_sigma = est.q_sigma.map(f64::from);
    let q_cal = q_cal as f64;
    let loss = law.and_then(|l| unit.tissue_loss_on(&l, e_kpa, q_cal, q as f64, q_sigma));
    if let Some((loss, sigma)) = loss {
        r.loss_tangent = Some(loss as f32);
        r.loss_tangent_sigma = Some(sigma as f32);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loadcell::RawForce;

    /// A failed estimate with the load cell silent over the reading's window (a reading that
    /// failed before the cell's first conversion) reports the estimator's failure, not
    /// `no_force`; a press the cell judges (too light) still explains the failure; an
    /// estimate that succeeded without a force is `no_force`.
    #[test]
    fn a_silent_load_cell_does_not_hide_the_estimators_failure() {
        let unit = crate::board::sim_factory::profile().expect("the factory profile");
        assert!(unit.load_cell.is_some());
        let t = Seconds(0.01);
        let r = conclude(Method::Hold, Err(Failure::NoResonance), &unit, t, 2, None);
        assert_eq!(r.status, Status::Failed(Failure::NoResonance));
        let cal = unit.load_cell.expect("a load cell");
        // 5 mN: below the window.
        let light: RawForce = cal.stated(crate::units::Newtons(0.005));
        let r = conclude(
            Method::Hold,
            Err(Failure::NoResonance),
            &unit,
            t,
            2,
            Some(light),
        );
        assert_eq!(r.status, Status::Failed(Failure::TooLight));
        let est = Estimate {
            resonance: crate::units::Hz(230.0),
            sigma: crate::units::Hz(0.01),
            q: Some(10.0),
            q_sigma: None,
            points_used: 8,
        };
        let r = conclude(Method::Hold, Ok(est), &unit, t, 8, None);
        assert_eq!(r.status, Status::Failed(Failure::NoForce));
    }

    /// With a load cell the press is judged by its force: a Q far below the calibrated
    /// contact's (lossy tissue adds damping) still gives a modulus, a Q above it (a contact
    /// unlike the calibration's, which no tissue loss can cause) is `bad_contact`. (Without a
    /// force the Q model judges both ways: `tests/mutants_gaps.rs`.)
    #[test]
    fn with_a_load_cell_only_a_q_above_the_contact_model_is_bad_contact() {
        let unit = crate::board::sim_factory::profile().expect("the factory profile");
        let cal = unit.load_cell.expect("a load cell");
        let q_model = unit.q_model.expect("a Q model");
        let press = cal.stated(crate::units::Newtons(0.030));
        let t = Seconds(0.125);
        let air = unit.air.expect("an air reference");
        let f = crate::units::Hz(air.free_resonance.0 - 4.0);
        let at = |q: f32, force| {
            let est = Estimate {
                resonance: f,
                sigma: crate::units::Hz(0.01),
                q: Some(q),
                q_sigma: None,
                points_used: 8,
            };
            conclude(Method::Hold, Ok(est), &unit, t, 8, force)
        };
        let nominal = at(10.0, Some(press));
        let e = nominal
            .modulus
            .expect("a modulus on the calibrated curve")
            .0 as f64;
        let expect = q_model.q_at(e, Some(0.030), unit.contact.as_ref()) as f32;
        // Far below, but above what any reading resolves (`MIN_READABLE_Q`).
        let low = 0.35 * expect;
        assert!(low > MIN_READABLE_Q, "{low}");
        assert_eq!(at(low, Some(press)).status, Status::Ok);
        assert_eq!(
            at(1.5 * expect, Some(press)).status,
            Status::Failed(Failure::BadContact)
        );
    }

    /// A refused estimate during a press that moved by less than the force window allows, but
    /// clearly (1.5 mN over a reading, 0.1 mN noise per conversion over ten conversions), is
    /// `force_unstable`: the press explains it. The same change in a cell too noisy to resolve
    /// it, or a resolved change below 0.5 mN, leaves the estimator's own failure; a fault of the
    /// instrument stays a fault; an accepted estimate on such a press is a reading.
    #[test]
    fn a_press_that_moved_explains_a_refused_estimate() {
        let unit = crate::board::sim_factory::profile().expect("the factory profile");
        let cal = unit.load_cell.expect("a load cell");
        let t = Seconds(0.125);
        // Counts for a force window: 30 mN, the given change, the mean's σ from 0.1 mN per
        // conversion over `n` conversions.
        let window = |change_n: f64, noise_n: f64, n: u16| {
            let k = cal.newtons_per_count as f64;
            RawForce {
                change: change_n / k,
                sigma: noise_n / libm::sqrt(n as f64) / k,
                samples: n,
                ..cal.stated(crate::units::Newtons(0.030))
            }
        };
        let refused =
            |w: RawForce, f: Failure| conclude(Method::Auto, Err(f), &unit, t, 8, Some(w)).status;
        let moving = window(0.0015, 1e-4, 10);
        assert_eq!(
            refused(moving, Failure::Interference),
            Status::Failed(Failure::ForceUnstable)
        );
        // σ_change = sqrt(12) × 2 mN / sqrt(10) = 2.2 mN: not resolved.
        let noisy = window(0.0015, 2e-3, 10);
        assert_eq!(
            refused(noisy, Failure::Interference),
            Status::Failed(Failure::Interference)
        );
        let small = window(0.0004, 1e-5, 10);
        assert_eq!(
            refused(small, Failure::Interference),
            Status::Failed(Failure::Interference)
        );
        assert_eq!(
            refused(moving, Failure::DriveFault),
            Status::Failed(Failure::DriveFault)
        );
        // An accepted estimate over the same press is concluded as any other (here on the
        // factory curve: a resonance inside the calibrated span gives a modulus).
        let air = unit.air.expect("an air reference");
        let est = Estimate {
            resonance: crate::units::Hz(air.free_resonance.0 - 4.0),
            sigma: crate::units::Hz(0.01),
            q: Some(10.0),
            q_sigma: None,
            points_used: 8,
        };
        let r = conclude(Method::Auto, Ok(est), &unit, t, 8, Some(moving));
        assert_ne!(r.status, Status::Failed(Failure::ForceUnstable));
    }
}
