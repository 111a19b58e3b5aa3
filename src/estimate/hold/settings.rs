//! The hold method's settings, their presets and their validation into a [`Hold`].

use super::{Hold, Phase, MIN_HOLD_S, NOMINAL_Q, NOMINAL_Q_SD, ON_SETTLE_S};
use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::engine::sweep::{
    amplitude_codes, check_band, check_durations, check_frequency, SettingsError,
};
use crate::estimate::resonator::{first_cycles, Carry, Filters, FIRST_WINDOWS};
use crate::estimate::ringdown::RingdownSettings;
use crate::hal::FrontEndScale;
use crate::units::{Farads, Hz, Seconds, Siemens, Volts};
use num_complex::Complex64 as C64;

/// Settings of the hold method.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HoldSettings {
    /// Lowest resonance accepted.
    pub band_start: Hz,
    /// Highest resonance accepted.
    pub band_stop: Hz,
    /// Burst frequency of the seed ring-down (a previous reading, or the band centre).
    pub seed: Hz,
    /// Seed burst length; 0: no ring-down seed — the first hold segment (`refine`) drives at
    /// `seed` from the start, its fit searches the band for the resonance, and the final fit
    /// takes both segments jointly.
    pub seed_burst: Seconds,
    /// Seed ring-down observation length (at least four two-cycle windows are taken; 0: exactly
    /// three, the fewest the decay fit takes).
    pub seed_ring: Seconds,
    /// How long the drive is held on the resonance in all (0.05–10 s).
    pub hold: Seconds,
    /// Length of a first, shorter hold on the seed, after which the drive moves to that hold's
    /// estimate for the rest of `hold` (0: one hold on the seed). Holding within a small
    /// fraction of the linewidth of the resonance makes the estimate insensitive to how far the
    /// resonator departs from the Butterworth–Van Dyke form (viscoelastic tissue does).
    pub refine: Seconds,
    /// Drive amplitude at the PZT.
    pub drive: Volts,
    /// Static capacitance `C0` of the PZT and its wiring, from the air reference.
    pub static_capacitance: Farads,
    /// Static (dielectric and leakage) conductance `G0`, from the air reference.
    pub static_conductance: Siemens,
}

impl HoldSettings {
    /// Seed 20 + 20 ms, hold 80 + 220 ms over 170–290 Hz, seeded at 230 Hz, 5 V; the static
    /// admittance is the PZT plate's nominal 210 pF and no leakage — a unit's own air reference
    /// must replace it (see `docs/methods.md`).
    pub const DEFAULT: Self = Self {
        band_start: Hz(170.0),
        band_stop: Hz(290.0),
        seed: Hz(230.0),
        seed_burst: Seconds(0.02),
        seed_ring: Seconds(0.02),
        hold: Seconds(0.3),
        refine: Seconds(0.08),
        drive: Volts(5.0),
        static_capacitance: Farads(210e-12),
        static_conductance: Siemens(0.0),
    };

    /// The fast hold, auto's first stage (`measure::auto_hold`): no seed ring-down; an 11.5 ms
    /// first segment at `seed` (the band centre), switched on at a zero crossing (`PointPlan::aligned`):
    /// the filters' settle and two one-cycle windows,
    /// whose searched fit — the start state the resonator's response from rest — places the
    /// second; its plan stays open, so that its windows go on while the second's plan passes the
    /// DAC's pipeline; the rest of 120 ms on that estimate; both segments in one fit
    /// (`docs/speed-accuracy.md`, `docs/methods.md`).
    pub const FAST: Self = Self {
        seed_burst: Seconds(0.0),
        seed_ring: Seconds(0.0),
        refine: Seconds(0.0115),
        hold: Seconds(0.12),
        ..Self::DEFAULT
    };

    /// The shortest first segment of a hold with no seed driven at `seed` on a front end
    /// sampling at `fs`: the filters' settle and [`FIRST_WINDOWS`] of the first segment's
    /// windows (the fewest its searched fit takes, [`first_cycles`] each), s.
    pub fn min_first(seed: Hz, fs: Hz) -> Seconds {
        let f = seed.0.max(1.0);
        let cycles = first_cycles(f as f64, fs.0 as f64) as f32;
        Seconds(ON_SETTLE_S as f32 + FIRST_WINDOWS as f32 * cycles / f)
    }

    /// The seed ring-down's settings, bursting at `seed`.
    pub(super) fn seed_settings(&self, seed: Hz) -> RingdownSettings {
        // The ring-down fit needs three windows of two cycles. A `seed_ring` of 0 asks for
        // exactly those three (5.5 cycles round up to three windows: the shortest seed, auto's);
        // otherwise at least six cycles and a millisecond, which round up to four windows — the
        // fourth keeps a seed whose first window is lost in the noise (the paper's noise, a
        // resonance far from the burst) from failing.
        let min_ring = if self.seed_ring.0 == 0.0 {
            5.5 / seed.0.max(1.0)
        } else {
            6.0 / seed.0.max(1.0) + 0.001
        };
        RingdownSettings {
            band_start: self.band_start,
            band_stop: self.band_stop,
            seed,
            burst: self.seed_burst,
            ring: Seconds(self.seed_ring.0.max(min_ring)),
            stages: 1,
            window_cycles: 2,
            drive: self.drive,
        }
    }

    /// Validate for a board.
    pub fn validate(&self, scale: &FrontEndScale) -> Result<Hold, SettingsError> {
        let seedless = self.seed_burst.0 == 0.0;
        let seed = if seedless {
            check_frequency(self.seed.0, scale)?;
            check_band(self.band_start, self.band_stop, scale)?;
            None
        } else {
            Some(self.seed_settings(self.seed).validate(scale)?)
        };
        if !self.hold.0.is_finite()
            || !self.refine.0.is_finite()
            || !self.static_capacitance.0.is_finite()
            || !self.static_conductance.0.is_finite()
        {
            return Err(SettingsError::NotFinite);
        }
        check_durations(Seconds(0.0), self.hold, self.band_start.0)?;
        // Each hold at least 50 ms (four windows of two cycles at the band's bottom); C0 of a
        // plate and its cable (0–100 nF); |G0| up to 1 mS (a fitted G0 may come out a little
        // negative).
        // With no seed the first segment only places the second, and counts in the joint fit:
        // three two-cycle windows suffice (`min_first`); the second is a hold of its own.
        let refine_ok = if seedless {
            self.refine.0 >= Self::min_first(self.seed, scale.sample_rate).0
                && self.hold.0 - self.refine.0 >= MIN_HOLD_S
        } else {
            self.refine.0 == 0.0
                || (self.refine.0 >= MIN_HOLD_S && self.hold.0 - self.refine.0 >= MIN_HOLD_S)
        };
        let knobs_ok = self.hold.0 >= MIN_HOLD_S
            && refine_ok
            && (0.0..=100e-9).contains(&self.static_capacitance.0)
            && (-1e-3..=1e-3).contains(&self.static_conductance.0);
        if !knobs_ok {
            return Err(SettingsError::KnobOutOfRange);
        }
        let amplitude = amplitude_codes(self.drive, scale)?;
        let fs = scale.sample_rate.0 as f64;
        let ftw = tuning_word(self.seed.0 as f64, fs);
        Ok(Hold {
            s: *self,
            fs,
            dt: 1.0 / fs,
            amplitude,
            phase: if seed.is_some() {
                Phase::Seed
            } else {
                Phase::Hold
            },
            seed,
            pending: false,
            ftw,
            f_hold: frequency_hz(ftw, fs),
            q_seed: NOMINAL_Q,
            q_seed_sd: NOMINAL_Q_SD * NOMINAL_Q,
            f_seed: self.seed.0 as f64,
            first_len: 0,
            first_cap: 0,
            f_first: 0.0,
            q_first: 0.0,
            linear_first: (0.0, C64::new(0.0, 0.0)),
            v_first: C64::new(0.0, 0.0),
            var_v_first: 0.0,
            v_hold: C64::new(0.0, 0.0),
            carry: Carry {
                t_switch: 0.0,
                rho: C64::new(1.0, 0.0),
                filters: Filters::of(scale),
            },
            t_on: 0.0,
            quiet: f32::INFINITY,
            at_rest: false,
            more: 0,
            plan: Default::default(),
            continued: false,
            n_windows: 0,
            segment: 0,
            seeds_tried: 1,
            seed_tones: 0,
            monitor: Default::default(),
            windows: heapless::Vec::new(),
            clipped: false,
            last: None,
        })
    }
}

impl Default for HoldSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}
