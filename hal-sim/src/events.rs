//! What changes while a reading runs: lift-off, a step in what is under the probe (a slide onto
//! other tissue, or a new contact after a lift-off), thermal drift of the probe's own resonance,
//! and knocks.
//!
//! A scene's static physics ([`crate::Scene`]) holds between events; a time-varying scene names
//! how it changes, and [`crate::Scene::at`] gives the static physics at any time since the
//! reading started. The simulated probe re-discretises its plant exactly (zero-order hold) each
//! time the physics change and keeps the dynamic state, so the state is continuous across a
//! change and nothing but the piecewise-constant schedule is approximated (see
//! [`SCHEDULE_STEP_S`]). Knocks are impulses: they change the state, not the physics.

use probe_rng::Rng;

/// Time step of the piecewise-constant schedule of slowly changing physics (lift-off ramp,
/// drift), in s. The plant is re-discretised at most this often, and only when the physics
/// changed. A drift of 0.3 Hz/s moves the resonance by 0.0003 Hz per step.
pub const SCHEDULE_STEP_S: f64 = 1e-3;

/// The probe is lifted off the tissue during the reading.
///
/// From `at_s` the preload falls linearly to zero over `ramp_s` (the Hertz contact radius
/// shrinks as the cube root of the force, so the tissue's stiffness, mass and damping fade out
/// continuously); at `at_s + ramp_s` the tip leaves the tissue and the probe is free.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiftOff {
    /// Time since the reading started when the preload starts to fall, s.
    pub at_s: f64,
    /// Duration of the fall of the preload to zero, s (0: a step).
    pub ramp_s: f64,
}

impl LiftOff {
    /// Fraction of the preload left at `t_s`: 1 before the lift, 0 once the tip is off
    /// (`None` then: no contact at all).
    pub fn preload_fraction(&self, t_s: f64) -> Option<f64> {
        if t_s < self.at_s {
            Some(1.0)
        } else if self.ramp_s > 0.0 && t_s < self.at_s + self.ramp_s {
            Some(1.0 - (t_s - self.at_s) / self.ramp_s)
        } else {
            None
        }
    }
}

/// The hand presses harder or lighter during the reading, the tip staying on the tissue: from
/// `at_s` the preload moves linearly to `to_fraction` of its value over `ramp_s`, then stays
/// (a press that creeps on, a tip that slides down a phantom's edge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceChange {
    /// Time since the reading started when the preload starts to change, s.
    pub at_s: f64,
    /// Duration of the change, s (0: a step).
    pub ramp_s: f64,
    /// The preload at the end, as a fraction of the scene's (positive).
    pub to_fraction: f64,
}

impl ForceChange {
    /// Fraction of the scene's preload at `t_s`.
    pub fn preload_fraction(&self, t_s: f64) -> f64 {
        let done = if t_s < self.at_s {
            0.0
        } else if self.ramp_s > 0.0 && t_s < self.at_s + self.ramp_s {
            (t_s - self.at_s) / self.ramp_s
        } else {
            1.0
        };
        1.0 + (self.to_fraction.max(0.0) - 1.0) * done
    }
}

/// What is under the probe changes at once: the tip slides onto other tissue, or it is put down
/// again after a lift-off (at the scene's preload).
///
/// From `at_s` on the scene's tissue is `tissue` (`None`: free air) and any earlier lift-off is
/// over: the physics are piecewise constant, the dynamic state carries over (the simulated
/// probe re-discretises its plant exactly at the step).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// Time since the reading started of the step, s.
    pub at_s: f64,
    /// What is under the tip from then on.
    pub tissue: Option<crate::tissue::Tissue>,
}

/// Thermal drift of the probe's own (free) resonance: the modal stiffness `k1` changes linearly
/// in time, so the free resonance moves by `rate_hz_s` per second from its nominal value at the
/// start of the reading (the temperature of the calibration and of the air reference).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drift {
    /// Rate of change of the free resonance, Hz/s.
    pub rate_hz_s: f64,
}

/// Random knocks: mechanical impulses on the probe's mode and electrical charge spikes into the
/// sense amplifier, at the times of a Poisson process.
///
/// Each event is mechanical or electrical with equal probability, with a random sign and a size
/// uniform between 0.5 and 1.5 times the nominal one. The times and sizes come from their own
/// generator seeded from the probe's seed, so a scene and a seed give the same knocks every time
/// and the noise stream is the same with or without them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knocks {
    /// Mean rate of events, 1/s.
    pub rate_hz: f64,
    /// Nominal velocity step of the mode by a mechanical knock, m/s (momentum / modal mass).
    pub velocity_m_s: f64,
    /// Nominal charge of an electrical spike into the sense input, C.
    pub charge_c: f64,
}

/// One knock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Knock {
    /// The mode's velocity steps by this much, m/s.
    Mechanical(f64),
    /// This charge (C) enters the sense amplifier's input at once.
    Electrical(f64),
}

/// The knocks of one simulated probe, in time order.
#[derive(Clone, Debug)]
pub struct KnockTrain {
    knocks: Knocks,
    rng: Rng,
    next_s: f64,
}

/// Salt of the knock generator's seed (kept apart from the noise stream).
const KNOCK_SALT: u64 = 0x6b6e_6f63_6b73_2121;

impl KnockTrain {
    /// The train of `knocks` for the probe seeded with `seed`.
    pub fn new(knocks: Knocks, seed: u64) -> Self {
        let mut rng = Rng::new(seed ^ KNOCK_SALT);
        let next_s = Self::gap(&mut rng, knocks.rate_hz);
        Self {
            knocks,
            rng,
            next_s,
        }
    }

    fn gap(rng: &mut Rng, rate_hz: f64) -> f64 {
        if !(rate_hz > 0.0) {
            return f64::INFINITY;
        }
        // Exponential waiting time; 1 - u lies in (0, 1].
        -libm::log(1.0 - rng.uniform()) / rate_hz
    }

    /// Time of the next knock, s since the start.
    pub fn next_time_s(&self) -> f64 {
        self.next_s
    }

    /// The next knock (at [`next_time_s`](Self::next_time_s)); advances the train.
    pub fn pop(&mut self) -> Knock {
        let size = 0.5 + self.rng.uniform();
        let sign = if self.rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let k = if self.rng.uniform() < 0.5 {
            Knock::Mechanical(sign * size * self.knocks.velocity_m_s)
        } else {
            Knock::Electrical(sign * size * self.knocks.charge_c)
        };
        self.next_s += Self::gap(&mut self.rng, self.knocks.rate_hz);
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knock_times_are_poisson() {
        // Over 2000 s at 1.5/s: 3000 knocks expected, Poisson sd 55; half of each kind
        // (binomial sd 39 of 1500).
        let mut t = KnockTrain::new(
            Knocks {
                rate_hz: 1.5,
                velocity_m_s: 1.0,
                charge_c: 1.0,
            },
            3,
        );
        let (mut n, mut mech) = (0, 0);
        while t.next_time_s() < 2000.0 {
            if let Knock::Mechanical(v) = t.pop() {
                assert!((0.5..=1.5).contains(&v.abs()));
                mech += 1;
            }
            n += 1;
        }
        assert!((n as f64 - 3000.0).abs() < 4.0 * 55.0, "{n}");
        assert!((mech as f64 - n as f64 / 2.0).abs() < 4.0 * 39.0, "{mech}");
    }

    #[test]
    fn lift_off_ramp() {
        let l = LiftOff {
            at_s: 1.0,
            ramp_s: 0.5,
        };
        assert_eq!(l.preload_fraction(0.9), Some(1.0));
        assert!((l.preload_fraction(1.25).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(l.preload_fraction(1.5), None);
        let step = LiftOff {
            at_s: 1.0,
            ramp_s: 0.0,
        };
        assert_eq!(step.preload_fraction(1.0), None);
        // A press from 1 to 1.6 of the preload between 0.1 and 1.1 s.
        let press = ForceChange {
            at_s: 0.1,
            ramp_s: 1.0,
            to_fraction: 1.6,
        };
        assert_eq!(press.preload_fraction(0.05), 1.0);
        assert!((press.preload_fraction(0.6) - 1.3).abs() < 1e-12);
        assert_eq!(press.preload_fraction(2.0), 1.6);
    }

    /// A step puts other tissue under the probe at its time, ends a lift-off (a new contact at
    /// the scene's preload), and the simulated probe follows it: its physics after the step are
    /// those of a scene on the new tissue.
    #[test]
    fn step_changes_the_tissue_and_ends_a_lift_off() {
        use crate::{phantoms, Scene, SimProbe};
        let d = phantoms::D.tissue();
        let s = Scene::on_phantom(&phantoms::B).with_step(Step {
            at_s: 0.5,
            tissue: Some(d),
        });
        assert_eq!(s.at(0.499).tissue, Some(phantoms::B.tissue()));
        assert_eq!(s.at(0.5).tissue, Some(d));
        let back = Scene::on_phantom(&phantoms::C)
            .with_lift_off(LiftOff {
                at_s: 0.2,
                ramp_s: 0.1,
            })
            .with_step(Step {
                at_s: 0.6,
                tissue: Some(phantoms::C.tissue()),
            });
        assert!((back.at(0.25).contact.preload_n - 0.015).abs() < 1e-12);
        assert_eq!(back.at(0.4).tissue, None);
        assert_eq!(
            back.at(0.6),
            Scene::on_phantom(&phantoms::C)
                .at(0.0)
                .with_lift_off(LiftOff {
                    at_s: 0.2,
                    ramp_s: 0.1
                })
                .with_step(Step {
                    at_s: 0.6,
                    tissue: Some(phantoms::C.tissue())
                })
        );
        // A lift-off after a step lifts the probe off the new tissue.
        let slide_then_lift = s.with_lift_off(LiftOff {
            at_s: 0.8,
            ramp_s: 0.0,
        });
        assert_eq!(slide_then_lift.at(0.7).tissue, Some(d));
        assert_eq!(slide_then_lift.at(0.8).tissue, None);
        let mut p = SimProbe::new(s, 1);
        p.idle(6000);
        let want = Scene::on_phantom(&phantoms::D).resonance_hz();
        assert!((p.scene().resonance_hz() - want).abs() < 1e-9);
        assert!(p.scene().resonance_hz() > Scene::on_phantom(&phantoms::B).resonance_hz() + 1.0);
    }
}
