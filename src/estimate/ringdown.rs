//! **ringdown**: drive a short burst near the resonance, hold the drive, and read the free decay.
//!
//! While the drive is held (DAC at mid-scale, PZT voltage zero) the static capacitance carries
//! no current: what flows is the motional current `alpha q'`, a damped sinusoid at the damped
//! frequency `f_d` with amplitude decay rate `s` (1/s). The sample engine demodulates it in
//! consecutive windows of whole reference cycles against the burst frequency `f_ref`; the window
//! phasors `z_k` then obey `z_k ∝ exp((−s + j 2π (f_d − f_ref)) t_k)`, so weighted straight-line
//! fits of `ln|z_k|` and of the unwrapped `arg z_k` against the window times give `s` and `f_d`
//! with their standard uncertainties (weights `|z_k|² / var(z_k)` from each window's own sine-fit
//! residual). The undamped resonance — the conductance maximum of the other methods — is
//! `f0 = sqrt(f_d² + (s / 2π)²)`, and `Q = π f0 / s`.
//!
//! A first stage bursts at the seed frequency; later stages burst at the previous stage's
//! estimate (a burst near resonance rings up more and rings down with less frequency offset).
//! Fails with `no_resonance` when fewer than three windows stand 5 σ above the noise, with
//! `out_of_band` when the estimate falls outside the settings' band, `low_snr` when its
//! uncertainty exceeds a quarter of the linewidth.

use super::Estimate;
use crate::dsp::dds::{frequency_hz, tuning_word};
use crate::dsp::lockin::solve_value;
use crate::engine::sweep::{
    amplitude_codes, check_band, check_durations, check_frequency, point_from_raw, PointError,
    SettingsError,
};
use crate::engine::{PointPlan, PointRaw};
use crate::hal::FrontEndScale;
use crate::linalg::Line;
use crate::status::Failure;
use crate::units::bounded;
use crate::units::{Hz, Seconds, Volts};
use core::f64::consts::PI;

/// Most windows one ring-down keeps.
pub const MAX_WINDOWS: usize = 64;

/// Ring-down settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RingdownSettings {
    /// Lowest resonance accepted.
    pub band_start: Hz,
    /// Highest resonance accepted.
    pub band_stop: Hz,
    /// Burst frequency of the first stage (a previous reading, or the band centre).
    pub seed: Hz,
    /// Burst length.
    pub burst: Seconds,
    /// Ring-down observation length.
    pub ring: Seconds,
    /// Stages (1–4): each later stage bursts at the previous estimate.
    pub stages: u8,
    /// Drive cycles per demodulation window (1–8; a window must outlast 6 ms at the band's top).
    pub window_cycles: u8,
    /// Burst amplitude at the PZT.
    pub drive: Volts,
}

impl RingdownSettings {
    /// Two stages of 40 ms burst + 40 ms ring over 170–290 Hz, seeded at 230 Hz.
    pub const DEFAULT: Self = Self {
        band_start: Hz(170.0),
        band_stop: Hz(290.0),
        seed: Hz(230.0),
        burst: Seconds(0.04),
        ring: Seconds(0.04),
        stages: 2,
        window_cycles: 2,
        drive: Volts(5.0),
    };
}

impl Default for RingdownSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Samples the filters need to forget the drive after it is held (3 ms: > 15 time constants of
/// the 1 kHz two-pole filters).
const HOLD_SETTLE_S: f32 = 0.003;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    t: f64,
    re: f64,
    im: f64,
    var: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Burst,
    Ring,
    Done,
}

/// A ring-down measurement in progress.
#[derive(Clone, Debug)]
///
/// `W`: most windows it keeps (a seed ring-down of three or four windows needs far fewer than
/// the method's own [`MAX_WINDOWS`]; `validate` refuses a ring that needs more).
pub struct Ringdown<const W: usize = MAX_WINDOWS> {
    s: RingdownSettings,
    fs: f64,
    amplitude: u16,
    stage: u8,
    phase: Phase,
    pending: bool,
    f_ref: f64,
    ftw: u32,
    windows: heapless::Vec<Window, W>,
    n_windows: u16,
    tag: u16,
    last: Option<Result<Estimate, Failure>>,
}

impl RingdownSettings {
    /// Validate for a board.
    pub fn validate<const W: usize>(
        &self,
        scale: &FrontEndScale,
    ) -> Result<Ringdown<W>, SettingsError> {
        check_band(self.band_start, self.band_stop, scale)?;
        let ftw = check_frequency(self.seed.0, scale)?;
        check_durations(self.burst, self.ring, self.band_start.0)?;
        if !(self.burst.0 > 0.0) {
            return Err(SettingsError::IntegrationShorterThanCycle);
        }
        if !(1..=4).contains(&self.stages) || !(1..=8).contains(&self.window_cycles) {
            return Err(SettingsError::KnobOutOfRange);
        }
        let fs = scale.sample_rate.0 as f64;
        // A window at least 60 samples long at the highest frequency (longer than a batch).
        if (self.window_cycles as f64) * fs / (self.band_stop.0 as f64) < 60.0 {
            return Err(SettingsError::IntegrationShorterThanCycle);
        }
        let amplitude = amplitude_codes(self.drive, scale)?;
        let f_ref = frequency_hz(ftw, fs);
        if libm::ceil(self.ring.0 as f64 * f_ref / self.window_cycles as f64) > W as f64 {
            return Err(SettingsError::KnobOutOfRange);
        }
        Ok(Ringdown {
            s: *self,
            fs,
            amplitude,
            stage: 0,
            phase: Phase::Burst,
            pending: false,
            f_ref,
            ftw,
            windows: heapless::Vec::new(),
            n_windows: 0,
            tag: 0,
            last: None,
        })
    }
}

impl<const W: usize> Ringdown<W> {
    /// The next plan, or `None` when done.
    pub fn next_plan(&mut self) -> Option<PointPlan> {
        if self.pending || self.phase == Phase::Done {
            return None;
        }
        self.tag = self.tag.wrapping_add(1);
        self.pending = true;
        let plan = match self.phase {
            Phase::Burst => PointPlan {
                ftw: self.ftw,
                amplitude_codes: self.amplitude,
                settle_samples: (self.s.burst.0 as f64 * self.fs) as u32,
                cycles: 1,
                windows: 1,
                open: false,
                aligned: false,
                tag: self.tag,
            },
            _ => {
                let per = self.s.window_cycles as f64 / self.f_ref;
                let n = bounded(libm::ceil(self.s.ring.0 as f64 / per), 1.0, W as f64);
                self.n_windows = n as u16;
                self.windows.clear();
                PointPlan {
                    ftw: self.ftw,
                    amplitude_codes: 0,
                    settle_samples: (HOLD_SETTLE_S as f64 * self.fs) as u32,
                    cycles: self.s.window_cycles as u32,
                    windows: self.n_windows,
                    open: false,
                    aligned: false,
                    tag: self.tag,
                }
            }
        };
        Some(plan)
    }

    /// Take a finished window. The burst's last cycle is screened like a sweep point: no drive,
    /// a clipped or an absent current end the reading with their failure code (the ring-down
    /// itself cannot see them: the drive is held while it listens).
    pub fn accept(&mut self, raw: &PointRaw, scale: &FrontEndScale) {
        if raw.plan.tag != self.tag {
            return;
        }
        match self.phase {
            Phase::Burst => {
                self.pending = false;
                let check = match point_from_raw(raw, scale) {
                    Err(PointError::NoDrive) => Err(Failure::DriveFault),
                    Err(PointError::Degenerate) => Err(Failure::BadSettings),
                    Ok(p) => super::screen(&[p, p, p]),
                };
                match check {
                    Ok(()) => self.phase = Phase::Ring,
                    Err(f) => {
                        self.last = Some(Err(f));
                        self.phase = Phase::Done;
                    }
                }
            }
            Phase::Ring => {
                if let Some((value, var)) = solve_value(&raw.sums.current, &raw.sums.reference) {
                    let n = raw.sums.reference.n as f64;
                    let _ = self.windows.push(Window {
                        t: (raw.end_sample as f64 - 0.5 * n) / self.fs,
                        re: value.re,
                        im: value.im,
                        var,
                    });
                }
                if raw.window + 1 >= self.n_windows {
                    let est = fit(&self.windows, self.f_ref);
                    self.stage += 1;
                    let next = est.ok().map(|e| e.resonance.0);
                    self.last = Some(est);
                    match next {
                        Some(f) if self.stage < self.s.stages => {
                            self.ftw = tuning_word(f as f64, self.fs);
                            self.f_ref = frequency_hz(self.ftw, self.fs);
                            self.phase = Phase::Burst;
                        }
                        _ => self.phase = Phase::Done,
                    }
                    self.pending = false;
                }
            }
            Phase::Done => {}
        }
    }

    /// True when finished.
    pub fn is_complete(&self) -> bool {
        self.phase == Phase::Done
    }

    /// True when the ring's last windows hold a steady tone ([`tail_holds_a_tone`]): what a
    /// seed that did not ring heard instead of noise.
    pub fn heard_a_tone(&self) -> bool {
        tail_holds_a_tone(&self.windows)
    }

    /// The estimate of the last stage.
    pub fn estimate(&self) -> Result<Estimate, Failure> {
        let e = self.last.unwrap_or(Err(Failure::NoResonance))?;
        super::in_band(e, self.s.band_start, self.s.band_stop)
    }
}

/// Noise variance per phasor component, common to all windows (they have equal lengths): the
/// mean residual variance of the last third of the windows, where the decayed signal no longer
/// leaks into the sine-fit residual (early windows see a decaying, frequency-offset signal that a
/// constant sine does not fit exactly, which would overstate their noise).
fn noise_variance(w: &[Window]) -> f64 {
    let n = w.len();
    let tail = &w[n - (n / 3).max(1)..];
    tail.iter().map(|x| x.var).sum::<f64>() / tail.len() as f64
}

/// True when the last third of the windows holds a tone that does not decay rather than noise
/// alone: white noise gives each phasor `|a|²/σ²` a χ² of two degrees of freedom, and their mean
/// stands beyond what it exceeds once in ten thousand
/// ([`super::interference::chi2_limit_per_dof`]); mains hum near the ring's frequency does.
/// False with no windows.
fn tail_holds_a_tone(w: &[Window]) -> bool {
    let n = w.len();
    let tail = &w[n.saturating_sub((n / 3).max(1))..];
    let (mut sum, mut k) = (0.0, 0usize);
    for x in tail.iter().filter(|x| x.var > 0.0) {
        sum += (x.re * x.re + x.im * x.im) / x.var;
        k += 1;
    }
    let dof = 2.0 * k as f64;
    k > 0 && sum / dof > super::interference::chi2_limit_per_dof(dof)
}

fn fit(w: &[Window], f_ref: f64) -> Result<Estimate, Failure> {
    if w.is_empty() {
        return Err(Failure::NoResonance);
    }
    let noise = noise_variance(w);
    // Keep windows whose amplitude stands 5 sigma above the noise.
    let mut mag = Line::default();
    let mut ph = Line::default();
    let mut prev_arg: Option<f64> = None;
    let mut unwrap = 0.0;
    let t0 = w.first().map_or(0.0, |x| x.t);
    let mut used = 0u16;
    for x in w {
        let a2 = x.re * x.re + x.im * x.im;
        if !(noise > 0.0) || !(a2 > 25.0 * noise) {
            break;
        }
        let arg = libm::atan2(x.im, x.re);
        if let Some(p) = prev_arg {
            let mut d = arg + unwrap - p;
            while d > PI {
                unwrap -= 2.0 * PI;
                d -= 2.0 * PI;
            }
            while d < -PI {
                unwrap += 2.0 * PI;
                d += 2.0 * PI;
            }
        }
        let a = arg + unwrap;
        prev_arg = Some(a);
        let wgt = a2 / noise;
        mag.add(x.t - t0, 0.5 * libm::log(a2), wgt);
        ph.add(x.t - t0, a, wgt);
        used += 1;
    }
    if used < 3 {
        return Err(Failure::NoResonance);
    }
    let m = mag.solve().ok_or(Failure::NoResonance)?;
    let p = ph.solve().ok_or(Failure::NoResonance)?;
    super::interference::decay(&m, &p)?;
    let decay = -m.b;
    if !(decay > 0.0) {
        return Err(Failure::NoResonance);
    }
    let fd = f_ref + p.b / (2.0 * PI);
    let sd = decay / (2.0 * PI);
    let f0 = libm::sqrt(fd * fd + sd * sd);
    let var_fd = p.var_b / (4.0 * PI * PI);
    let var_sd = m.var_b / (4.0 * PI * PI);
    let var_f0 = (fd / f0) * (fd / f0) * var_fd + (sd / f0) * (sd / f0) * var_sd;
    let sigma = libm::sqrt(var_f0);
    let q = PI * f0 / decay;
    if !f0.is_finite() {
        return Err(Failure::LowSnr);
    }
    super::resolved(sigma, f0 / q)?;
    Ok(Estimate {
        resonance: Hz(f0 as f32),
        sigma: Hz(sigma as f32),
        q: Some(q as f32),
        // q = π f0 / decay: the decay's relative uncertainty (f0's is far smaller).
        q_sigma: Some((q * libm::sqrt(m.var_b.max(0.0)) / decay) as f32),
        points_used: used,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring that never rose above the noise is `no_resonance`; its tail holds no tone when its
    /// windows hold white noise
    /// of their stated variance (from `probe_rng`), and a tone when a steady one of three σ
    /// in magnitude sits in every window (`|a|²/σ²` about 11 a window against white noise's 2),
    /// both below the fit's 5 σ threshold.
    #[test]
    fn a_ring_that_did_not_rise_tells_a_steady_tone_from_noise() {
        let mut rng = probe_rng::Rng::new(11);
        let var = 4.0;
        let mut noise = heapless::Vec::<Window, 64>::new();
        let mut tone = heapless::Vec::<Window, 64>::new();
        for k in 0..24 {
            let t = 0.002 * k as f64;
            let (re, im) = (2.0 * rng.normal(), 2.0 * rng.normal());
            noise.push(Window { t, re, im, var }).unwrap();
            let (c, s) = (libm::cos(7.0 * t), libm::sin(7.0 * t));
            tone.push(Window {
                t,
                re: re + 6.0 * c,
                im: im + 6.0 * s,
                var,
            })
            .unwrap();
        }
        assert_eq!(fit(&noise, 230.0), Err(Failure::NoResonance));
        assert_eq!(fit(&tone, 230.0), Err(Failure::NoResonance));
        assert!(!tail_holds_a_tone(&noise));
        assert!(
            !tail_holds_a_tone(&[]),
            "no windows, no tone (and no panic)"
        );
        assert!(tail_holds_a_tone(&tone));
    }

    /// Synthetic window phasors of a known damped sinusoid.
    #[test]
    fn fit_recovers_frequency_and_decay() {
        let (f0, q, f_ref) = (241.3f64, 10.4f64, 236.0f64);
        let s = PI * f0 / q;
        let fd = libm::sqrt(f0 * f0 - (s / (2.0 * PI)) * (s / (2.0 * PI)));
        let mut w = heapless::Vec::<Window, 64>::new();
        for k in 0..20 {
            let t = 0.003 + k as f64 * 2.0 / f_ref;
            let a = 1000.0 * libm::exp(-s * t);
            let ph = 0.3 + 2.0 * PI * (fd - f_ref) * t;
            w.push(Window {
                t,
                re: a * libm::cos(ph),
                im: a * libm::sin(ph),
                var: 1e-6,
            })
            .unwrap();
        }
        let e = fit(&w, f_ref).unwrap();
        assert!(
            (e.resonance.0 as f64 - f0).abs() < 1e-3,
            "{}",
            e.resonance.0
        );
        assert!((e.q.unwrap() as f64 / q - 1.0).abs() < 1e-4);
    }
}
