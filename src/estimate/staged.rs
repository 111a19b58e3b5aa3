//! The fit method's two stages: a coarse look over the band, then a few points placed where the
//! coarse estimate says the resonance is, with settling chosen from the estimated Q.
//!
//! Coarse points, Butterworth–Van Dyke fit ([`super::fit`]) for `f0, Q, C0`; refine points
//! spread over `±refine_span` linewidths around it, settled `settle_tau` time constants
//! `τ = Q/(π f0)`; final BVD fit on the refine points (all points if fewer than four).

use super::fit::{fit_bvd, Bvd};
use super::{argmax, Estimate};
use crate::dsp::dds::tuning_word;
use crate::engine::sweep::{
    amplitude_codes, check_band, check_durations, point_from_raw, PointError, SettingsError,
    SweepPoint,
};
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::status::Failure;
use crate::units::bounded;
use crate::units::{Hz, Seconds, Volts};
use heapless::Vec;

/// Most points of each stage.
pub const MAX_STAGE_POINTS: usize = 32;

/// Settings of the fit method (and of auto's fit stage).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StagedSettings {
    /// Band start (coarse points and accepted resonances).
    pub band_start: Hz,
    /// Band stop.
    pub band_stop: Hz,
    /// Coarse points across the band (4–32).
    pub coarse_points: u8,
    /// Settling per coarse point (the first settles four times longer).
    pub coarse_settle: Seconds,
    /// Integration per point (whole cycles, at least one).
    pub integrate: Seconds,
    /// Refine points, 0–32.
    pub refine_points: u8,
    /// Half-width of the refine spread in linewidths `f0/Q` (0.1–3).
    pub refine_span: f32,
    /// Settling of refine points in estimated time constants `τ = Q/(π f0)` (0–20).
    pub settle_tau: f32,
    /// Drive amplitude at the PZT.
    pub drive: Volts,
}

impl StagedSettings {
    /// The defaults (see `docs/methods.md` for how they were chosen).
    pub const DEFAULT: Self = Self {
        band_start: Hz(170.0),
        band_stop: Hz(290.0),
        coarse_points: 6,
        coarse_settle: Seconds(0.02),
        integrate: Seconds(0.02),
        refine_points: 5,
        refine_span: 0.8,
        settle_tau: 5.0,
        drive: Volts(5.0),
    };

    /// Validate for a board.
    pub fn validate(&self, scale: &FrontEndScale) -> Result<Staged, SettingsError> {
        check_band(self.band_start, self.band_stop, scale)?;
        check_durations(self.coarse_settle, self.integrate, self.band_start.0)?;
        let knobs_ok = (4..=MAX_STAGE_POINTS as u8).contains(&self.coarse_points)
            && self.refine_points as usize <= MAX_STAGE_POINTS
            && (0.0..=20.0).contains(&self.settle_tau)
            && (0.1..=3.0).contains(&self.refine_span);
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
            failure: None,
            tag: 0,
            pending: false,
        })
    }
}

/// A fit reading in progress.
#[derive(Clone, Debug)]
pub struct Staged {
    s: StagedSettings,
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
    failure: Option<Failure>,
    tag: u16,
    pending: bool,
}

impl Staged {
    /// The next plan, or `None` when done (or waiting for a point).
    pub fn next_plan(&mut self) -> Option<PointPlan> {
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
            ftw: tuning_word(f as f64, self.fs),
            amplitude_codes: self.amplitude,
            settle_samples: (settle_s * self.fs) as u32,
            cycles,
            windows: 1,
            open: false,
            aligned: false,
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
        }
        Some(p)
    }

    fn after_coarse(&mut self) {
        let i = argmax(&self.coarse, |p| p.g_s).unwrap_or(0);
        let f_start = self.coarse[i].freq.0 as f64;
        let est = fit_bvd(&self.coarse, f_start, 10.0).map(|b| {
            self.bvd = Some(b);
            (b.f0, b.q)
        });
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
        self.q = bounded(q, 1.0, 200.0);
        self.stage = 1;
        self.next = 0;
        self.plan.clear();
        let n = self.s.refine_points as usize;
        // Visit the refine points starting from the end nearest the last coarse point (the
        // band's top), so the drive never jumps across the resonance.
        let half = self.s.refine_span as f64 * f0 / self.q;
        for k in 0..n {
            let x = if n == 1 {
                0.0
            } else {
                1.0 - 2.0 * k as f64 / (n - 1) as f64
            };
            let _ = self.plan.push(bounded(f0 + x * half, a, b) as f32);
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
        let mut all: Vec<SweepPoint, { 2 * MAX_STAGE_POINTS }> = Vec::new();
        let use_all = self.fine.len() < 4;
        for p in self
            .fine
            .iter()
            .chain(self.coarse.iter().filter(|_| use_all))
        {
            let _ = all.push(*p);
        }
        let e = super::fit::estimate(&all, self.f0, self.q)?;
        // Settled refine points scattering at random far beyond their σ: a tone (mains).
        if fine.len() >= 4 {
            let q = e.q.map_or(f64::NAN, f64::from);
            super::interference::misfit(fine, e.resonance.0 as f64, q)?;
        }
        super::in_band(e, self.s.band_start, self.s.band_stop)
    }
}
