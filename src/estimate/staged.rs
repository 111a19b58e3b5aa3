//! Two-stage procedures: a coarse look over the band, then a few points placed where the coarse
//! estimate says the resonance is, with settling chosen from the estimated Q.
//!
//! * **adaptive** — coarse stepped sweep, conductance estimate; refine points spread over
//!   `±refine_span` linewidths around it, settled `settle_tau` time constants `τ = Q/(π f0)`;
//!   final estimate: the weighted `1/G` fit of [`super::conductance`] on the refine points.
//! * **fit** — coarse points, Butterworth–Van Dyke fit ([`super::fit`]) for `f0, Q, C0`; refine
//!   points as above; final BVD fit on the refine points (all points if fewer than four).
//! * **track** — coarse points and BVD fit as for *fit*; then a phase-tracking loop: at each step
//!   the static part (`G0 + j b0 f/f_ref`, from the fit) is subtracted from the measured
//!   admittance, the phase `φ` of the motional remainder gives `Q u = tan(−φ)` with
//!   `u = f/f0 − f0/f`, which is solved for `f0`; the drive moves there (phase-continuously) for
//!   the next step. Once locked the drive sits on the resonance (`φ = 0`), where the estimate no
//!   longer depends on `Q` or on the motional amplitude. The reading is the weighted mean of the
//!   second half of the steps; `not_locked` when the last step still moved by more than a tenth
//!   of the linewidth or the steps disagree beyond their uncertainty.

use super::fit::{fit_bvd, Bvd};
use super::{argmax, conductance, Estimate};
use crate::dsp::dds::tuning_word;
use crate::engine::sweep::{
    amplitude_codes, check_band, check_durations, point_from_raw, PointError, SettingsError,
    SweepPoint,
};
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::status::Failure;
use crate::units::{Hz, Seconds, Volts};
use heapless::Vec;

/// Most points of each stage.
pub const MAX_STAGE_POINTS: usize = 32;

/// Which refinement a [`Staged`] procedure runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refine {
    /// adaptive: conductance fit on the refine points.
    Conductance,
    /// fit: Butterworth–Van Dyke fit.
    Bvd,
    /// track: phase-locked steps onto the resonance.
    Track,
}

/// Settings of the two-stage methods.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StagedSettings {
    /// Band start (coarse points and accepted resonances).
    pub band_start: Hz,
    /// Band stop.
    pub band_stop: Hz,
    /// Coarse points across the band (3–32; fit and track need 4).
    pub coarse_points: u8,
    /// Settling per coarse point (the first settles four times longer).
    pub coarse_settle: Seconds,
    /// Integration per point (whole cycles, at least one).
    pub integrate: Seconds,
    /// Refine points (adaptive, fit) or tracking steps (track), 0–32.
    pub refine_points: u8,
    /// Half-width of the refine spread in linewidths `f0/Q` (0.1–3).
    pub refine_span: f32,
    /// Settling of refine points in estimated time constants `τ = Q/(π f0)` (0–20).
    pub settle_tau: f32,
    /// Drive amplitude at the PZT.
    pub drive: Volts,
}

impl StagedSettings {
    /// Defaults for each refinement (see `docs/methods.md` for how they were chosen).
    pub const fn default_for(r: Refine) -> Self {
        match r {
            Refine::Conductance => Self {
                band_start: Hz(170.0),
                band_stop: Hz(290.0),
                coarse_points: 13,
                coarse_settle: Seconds(0.02),
                integrate: Seconds(0.02),
                refine_points: 7,
                refine_span: 0.6,
                settle_tau: 8.0,
                drive: Volts(5.0),
            },
            Refine::Bvd => Self {
                band_start: Hz(170.0),
                band_stop: Hz(290.0),
                coarse_points: 6,
                coarse_settle: Seconds(0.02),
                integrate: Seconds(0.02),
                refine_points: 5,
                refine_span: 0.8,
                settle_tau: 5.0,
                drive: Volts(5.0),
            },
            Refine::Track => Self {
                band_start: Hz(170.0),
                band_stop: Hz(290.0),
                coarse_points: 6,
                // The tracker subtracts the static part fitted on the coarse points: they must
                // have settled (4 τ), or their transients change that part from reading to reading.
                coarse_settle: Seconds(0.06),
                integrate: Seconds(0.02),
                refine_points: 8,
                refine_span: 0.0,
                settle_tau: 2.0,
                drive: Volts(5.0),
            },
        }
    }

    /// Validate for a board.
    pub fn validate(&self, r: Refine, scale: &FrontEndScale) -> Result<Staged, SettingsError> {
        check_band(self.band_start, self.band_stop, scale)?;
        check_durations(self.coarse_settle, self.integrate, self.band_start.0)?;
        let min_coarse = if r == Refine::Conductance { 3 } else { 4 };
        let knobs_ok = (min_coarse..=MAX_STAGE_POINTS as u8).contains(&self.coarse_points)
            && self.refine_points as usize <= MAX_STAGE_POINTS
            && (0.0..=20.0).contains(&self.settle_tau)
            && match r {
                Refine::Track => self.refine_points >= 2,
                _ => (0.1..=3.0).contains(&self.refine_span),
            };
        if !knobs_ok {
            return Err(SettingsError::KnobOutOfRange);
        }
        let amplitude = amplitude_codes(self.drive, scale)?;
        let fs = scale.sample_rate.0 as f64;
        let mut plan = Vec::new();
        let n = self.coarse_points as usize;
        let (a, b) = (self.band_start.0 as f64, self.band_stop.0 as f64);
        for k in 0..n {
            let _ = plan.push((a + (b - a) * k as f64 / (n - 1) as f64) as f32);
        }
        Ok(Staged {
            s: *self,
            r,
            fs,
            amplitude,
            plan,
            next: 0,
            stage: 0,
            coarse: Vec::new(),
            fine: Vec::new(),
            bvd: None,
            f0: 0.0,
            q: 10.0,
            track: Vec::new(),
            failure: None,
            tag: 0,
            pending: false,
        })
    }
}

/// A two-stage measurement in progress.
#[derive(Clone, Debug)]
pub struct Staged {
    s: StagedSettings,
    r: Refine,
    fs: f64,
    amplitude: u16,
    plan: Vec<f32, MAX_STAGE_POINTS>,
    next: usize,
    stage: u8,
    coarse: Vec<SweepPoint, MAX_STAGE_POINTS>,
    fine: Vec<SweepPoint, MAX_STAGE_POINTS>,
    bvd: Option<Bvd>,
    f0: f64,
    q: f64,
    /// Per tracking step: (f0 estimate, its sigma).
    track: Vec<(f64, f64), MAX_STAGE_POINTS>,
    failure: Option<Failure>,
    tag: u16,
    pending: bool,
}

impl Staged {
    /// The refinement.
    fn refine(&self) -> Refine {
        self.r
    }

    /// The next plan, or `None` when done (or waiting for a point).
    pub fn next_plan(&mut self, scale: &FrontEndScale) -> Option<PointPlan> {
        if self.pending || self.is_complete() {
            return None;
        }
        let f = *self.plan.get(self.next)?;
        let first = self.stage == 0 && self.next == 0;
        let settle_s = if self.stage == 0 {
            self.s.coarse_settle.0 as f64 * if first { 4.0 } else { 1.0 }
        } else {
            // The first refine point follows the jump from the band's top: twice the settling.
            let jump = if self.next == 0 { 2.0 } else { 1.0 };
            jump * self.s.settle_tau as f64 * self.q / (core::f64::consts::PI * self.f0)
        };
        let cycles = libm::ceilf(self.s.integrate.0 * f).max(1.0) as u32;
        self.tag = self.tag.wrapping_add(1);
        self.pending = true;
        Some(PointPlan {
            ftw: tuning_word(f as f64, scale.sample_rate.0 as f64),
            amplitude_codes: self.amplitude,
            settle_samples: (settle_s * self.fs) as u32,
            cycles,
            windows: 1,
            open: false,
            tag: self.tag,
        })
    }

    /// Take a finished point; returns it in physical units.
    pub fn accept(&mut self, raw: &PointRaw, scale: &FrontEndScale) -> Option<SweepPoint> {
        if raw.plan.tag != self.tag || !self.pending {
            return None;
        }
        self.pending = false;
        let p = match point_from_raw(raw, scale) {
            Ok(p) => p,
            Err(PointError::NoDrive) => {
                self.failure = Some(Failure::DriveFault);
                return None;
            }
            Err(PointError::Degenerate) => {
                self.failure = Some(Failure::BadSettings);
                return None;
            }
        };
        self.next += 1;
        if self.stage == 0 {
            let _ = self.coarse.push(p);
            if self.next >= self.plan.len() {
                self.after_coarse();
            }
        } else {
            let _ = self.fine.push(p);
            if self.refine() == Refine::Track {
                self.track_step(&p);
            }
        }
        Some(p)
    }

    fn after_coarse(&mut self) {
        let est = match self.refine() {
            Refine::Conductance => conductance::estimate(&self.coarse)
                .map(|e| (e.resonance.0 as f64, e.q.unwrap_or(10.0) as f64)),
            Refine::Bvd | Refine::Track => {
                let i = argmax(&self.coarse, |p| p.g_s).unwrap_or(0);
                let f_start = self.coarse[i].freq.0 as f64;
                fit_bvd(&self.coarse, f_start, 10.0).map(|b| {
                    self.bvd = Some(b);
                    (b.f0, b.q)
                })
            }
        };
        let (f0, q) = match est {
            Ok(v) => v,
            Err(f) => {
                self.failure = Some(f);
                return;
            }
        };
        let (a, b) = (self.s.band_start.0 as f64, self.s.band_stop.0 as f64);
        if !(f0 > a && f0 < b && q > 0.5) {
            self.failure = Some(Failure::OutOfBand);
            return;
        }
        self.f0 = f0;
        self.q = q.clamp(1.0, 200.0);
        self.stage = 1;
        self.next = 0;
        self.plan.clear();
        let n = self.s.refine_points as usize;
        if self.refine() == Refine::Track {
            let _ = self.plan.push(f0 as f32);
        } else {
            // Visit the refine points starting from the end nearest the last coarse point (the
            // band's top), so the drive never jumps across the resonance.
            let half = self.s.refine_span as f64 * f0 / self.q;
            for k in 0..n {
                let x = if n == 1 {
                    0.0
                } else {
                    1.0 - 2.0 * k as f64 / (n - 1) as f64
                };
                let _ = self.plan.push((f0 + x * half).clamp(a, b) as f32);
            }
        }
    }

    fn track_step(&mut self, p: &SweepPoint) {
        let Some(b) = self.bvd else {
            self.failure = Some(Failure::NotLocked);
            return;
        };
        let f = p.freq.0 as f64;
        let (sr, si) = b.static_part(f);
        let (mr, mi) = (p.g_s as f64 - sr, p.b_s as f64 - si);
        let m2 = mr * mr + mi * mi;
        if !(m2 > 0.0) {
            self.failure = Some(Failure::NotLocked);
            return;
        }
        // Y_m = g / (1 + j Q u): Q u = -Im/Re.
        let qu = -mi / mr;
        let u = qu / b.q;
        let f0 = 0.5 * (-u * f + libm::sqrt(u * u * f * f + 4.0 * f * f));
        // sigma of the phase = sigma_Y / |Y_m|; d(f0)/d(phase) ≈ f (1 + (Q u)^2) / (2 Q).
        let sphi = p.sigma_s as f64 / libm::sqrt(m2);
        let sf0 = f * (1.0 + qu * qu) / (2.0 * b.q) * sphi;
        let _ = self.track.push((f0, sf0));
        let (a, bb) = (self.s.band_start.0 as f64, self.s.band_stop.0 as f64);
        if self.next < self.s.refine_points as usize && f0.is_finite() {
            let _ = self.plan.push(f0.clamp(a, bb) as f32);
        }
    }

    /// True when finished.
    pub fn is_complete(&self) -> bool {
        self.failure.is_some() || (self.stage == 1 && self.next >= self.plan.len() && !self.pending)
    }

    /// All measured points (coarse then fine).
    pub fn points(&self) -> impl Iterator<Item = &SweepPoint> {
        self.coarse.iter().chain(self.fine.iter())
    }

    /// Number of measured points.
    pub fn len(&self) -> usize {
        self.coarse.len() + self.fine.len()
    }

    /// True before any point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The final estimate.
    pub fn estimate(&self) -> Result<Estimate, Failure> {
        if let Some(f) = self.failure {
            return Err(f);
        }
        // A knock among the refine points, then a lift-off between the stages.
        super::interference::transients(&self.fine)?;
        super::contact::lost(&self.coarse, self.bvd.map(|b| b.g), &self.fine)?;
        let fine = &self.fine;
        let e = match self.refine() {
            Refine::Conductance => {
                // The sweep estimator wants ascending frequencies; the refine points were
                // visited from the top down. Put in order by insertion (at most
                // `MAX_STAGE_POINTS`): a library sort costs the firmware image 1.7 KiB.
                let mut asc: Vec<SweepPoint, MAX_STAGE_POINTS> = Vec::new();
                for p in fine.iter() {
                    let at = asc
                        .iter()
                        .position(|q| q.freq.0 > p.freq.0)
                        .unwrap_or(asc.len());
                    // Same capacity as `fine`: cannot fail.
                    let _ = asc.insert(at, *p);
                }
                conductance::estimate(&asc)
            }
            Refine::Bvd => {
                let mut all: Vec<SweepPoint, { 2 * MAX_STAGE_POINTS }> = Vec::new();
                let use_all = self.fine.len() < 4;
                for p in self
                    .fine
                    .iter()
                    .chain(self.coarse.iter().filter(|_| use_all))
                {
                    let _ = all.push(*p);
                }
                super::fit::estimate(&all, self.f0, self.q)
            }
            Refine::Track => self.track_estimate(),
        }?;
        // Settled refine points scattering at random far beyond their σ: a tone (mains).
        if self.refine() != Refine::Track && fine.len() >= 4 {
            let q = e.q.map_or(f64::NAN, f64::from);
            super::interference::misfit(fine, e.resonance.0 as f64, q)?;
        }
        super::in_band(e, self.s.band_start, self.s.band_stop)
    }

    fn track_estimate(&self) -> Result<Estimate, Failure> {
        let n = self.track.len();
        if n < 2 {
            return Err(Failure::NotLocked);
        }
        let used = &self.track[n / 2..];
        let (mut sw, mut swf) = (0.0, 0.0);
        for &(f, s) in used {
            let w = 1.0 / (s * s).max(1e-30);
            sw += w;
            swf += w * f;
        }
        let mean = swf / sw;
        let mut chi2 = 0.0;
        for &(f, s) in used {
            chi2 += (f - mean) * (f - mean) / (s * s).max(1e-30);
        }
        let dof = (used.len() - 1).max(1) as f64;
        let linewidth = mean / self.q;
        let last_move = libm::fabs(self.track[n - 1].0 - self.track[n - 2].0);
        if last_move > 0.1 * linewidth || chi2 / dof > conductance::GROSS_CHI2 {
            return Err(Failure::NotLocked);
        }
        // Every step subtracts the same fitted static part, so its error is common to all steps
        // and does not average down: a susceptance error dB turns the motional phase by dB / g,
        // and f0 by f0 / (2 Q) of that (at the resonance, where the steps sit; an error in the
        // conductance G0 changes only the magnitude there).
        let common = self.bvd.map_or(0.0, |b| {
            let db = b.sigma_b0 * mean / b.f_ref;
            if b.g > 0.0 {
                mean / (2.0 * self.q) * db / b.g
            } else {
                0.0
            }
        });
        let sigma = libm::sqrt(1.0 / sw + common * common);
        Ok(Estimate {
            resonance: Hz(mean as f32),
            sigma: Hz(sigma as f32),
            q: Some(self.q as f32),
            points_used: used.len() as u16,
        })
    }
}
