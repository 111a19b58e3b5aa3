//! Contact lost during a reading.
//!
//! Tissue adds damping to the probe's mode: pressed on tissue the loaded quality factor is 7–15,
//! free it is about 40, so the motional branch's peak conductance `g = alpha^2 / c` is three to
//! four times higher once the tip leaves the tissue (`c` falls from `c1 + c_m` to `c1`). A
//! two-stage reading learns `g` in its first stage (the coarse points) and then measures
//! near the resonance; if the tip lifts off in between, the later points show a conductance the
//! contact that was there cannot produce. [`lost`] compares the largest conductance of the later
//! points with the first stage's peak: more than [`LIFT_OFF_RATIO`] times it is `contact_lost`.
//!
//! The first stage's peak is taken from its fitted motional conductance when it has one (the
//! Butterworth–Van Dyke fit of *fit* and *track*), otherwise from its largest measured
//! conductance, which within half a coarse step of the peak stands for it only when the steps
//! are small against the linewidth (*adaptive*: 10 Hz at Q 10, the largest lies within 20 % of
//! the peak; *fit*'s 24 Hz steps could miss it by half). Either way a contact that holds gives a ratio near 1 (at most the
//! first stage's underestimate of its peak); a lift-off gives 3–4. Points spoiled by a knock are
//! the business of [`super::interference::transients`], which should run first.

use crate::engine::sweep::SweepPoint;
use crate::status::Failure;

/// The later points' largest conductance above this multiple of the first stage's peak means
/// the contact was lost between the stages.
pub const LIFT_OFF_RATIO: f64 = 2.0;

/// `contact_lost` when the largest conductance of `later` exceeds [`LIFT_OFF_RATIO`] times the
/// first stage's peak: its fitted motional peak conductance `fitted_peak_s` when there is one,
/// else the largest conductance of `first`. `Ok` when there is nothing to compare.
pub fn lost(
    first: &[SweepPoint],
    fitted_peak_s: Option<f64>,
    later: &[SweepPoint],
) -> Result<(), Failure> {
    let largest = |pts: &[SweepPoint]| {
        pts.iter()
            .map(|p| p.g_s as f64)
            .filter(|g| g.is_finite())
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let peak = match fitted_peak_s {
        Some(g) if g.is_finite() && g > 0.0 => g,
        _ => largest(first),
    };
    if peak > 0.0 && largest(later) > LIFT_OFF_RATIO * peak {
        Err(Failure::ContactLost)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::Hz;

    /// Motional conductance `g / (1 + Q² u²)` of a resonance at 230 Hz with peak `g`.
    fn points(g: f64, q: f64, freqs: &[f64]) -> heapless::Vec<SweepPoint, 16> {
        let mut v = heapless::Vec::new();
        for &f in freqs {
            let u = f / 230.0 - 230.0 / f;
            let _ = v.push(SweepPoint {
                freq: Hz(f as f32),
                g_s: (g / (1.0 + q * q * u * u)) as f32,
                ..SweepPoint::default()
            });
        }
        v
    }

    #[test]
    fn lift_off_raises_the_conductance_and_a_held_contact_does_not() {
        // Loaded: Q 10, peak 1.75e-7 S; free: Q 40 with the same force factor, 4x the peak.
        let refine = [212.0, 221.0, 230.0, 239.0, 248.0];
        let held = points(1.75e-7, 10.0, &refine);
        let free = points(7.0e-7, 40.0, &refine);
        // fit's six coarse points (24 Hz steps) with their fitted peak.
        let coarse = points(1.75e-7, 10.0, &[170.0, 194.0, 218.0, 242.0, 266.0, 290.0]);
        assert_eq!(lost(&coarse, Some(1.75e-7), &held), Ok(()));
        assert_eq!(
            lost(&coarse, Some(1.75e-7), &free),
            Err(Failure::ContactLost)
        );
        // Without the fit their largest conductance (at 218 and 242 Hz) is 0.47 of the peak:
        // too coarse to stand for it.
        assert_eq!(lost(&coarse, None, &held), Err(Failure::ContactLost));
        // adaptive's thirteen (10 Hz steps): the largest lies within 20 % of the peak.
        let mut f = [0.0; 13];
        for (k, x) in f.iter_mut().enumerate() {
            *x = 173.0 + 10.0 * k as f64;
        }
        let coarse = points(1.75e-7, 10.0, &f);
        assert_eq!(lost(&coarse, None, &held), Ok(()));
        assert_eq!(lost(&coarse, None, &free), Err(Failure::ContactLost));
        // Nothing to compare: no panic, no verdict.
        assert_eq!(lost(&[], None, &free), Ok(()));
        assert_eq!(lost(&coarse, Some(f64::NAN), &[]), Ok(()));
    }
}
