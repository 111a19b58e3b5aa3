//! The one reading driver over any [`SampleStream`]: what the firmware's interrupt and
//! measurement task do together, in one loop, for the host (tests, `probe-bench`) and for
//! single-threaded images. The time-out rule of a point ([`window_budget_samples`]) is shared
//! with the firmware's measurement task.

use crate::engine::{PointPlan, SampleEngine};
use crate::hal::{AdcFrame, SampleStream, StreamError};
use crate::measure::{Measurement, Reading};
use crate::profile::UnitProfile;
use crate::sweep::SweepPoint;
use crate::units::DacCode;

/// Samples per batch (one DMA half-buffer on the STM32: 5 ms at 10 kHz).
pub const BATCH: usize = 50;

/// Why a run stopped early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunError {
    /// The stream reported an error.
    Stream(StreamError),
    /// A point did not complete within its sample budget.
    Stalled,
}

/// The stall rule: samples a window of `plan` may take before it counts as lost — its
/// settling, its cycles and two more (to find the window's boundary), and the stream's
/// pipeline of `latency_batches` plus two batches of margin.
pub fn window_budget_samples(plan: &PointPlan, fs: f64, latency_batches: usize) -> u64 {
    let f = crate::dsp::dds::frequency_hz(plan.ftw, fs).max(1.0);
    let period = fs / f;
    plan.settle_samples as u64
        + ((plan.cycles as f64 + 2.0) * period) as u64
        + (BATCH * (latency_batches + 2)) as u64
}

/// Run `m` to completion on `stream`, calling `on_point` for every measured admittance point,
/// and return the reading concluded with the unit's profile.
pub fn run_sweep<S: SampleStream, M: Measurement>(
    stream: &mut S,
    engine: &mut SampleEngine,
    m: &mut M,
    unit: &UnitProfile,
    mut on_point: impl FnMut(&SweepPoint),
) -> Result<Reading, RunError> {
    let mut dac = [DacCode::MID; BATCH];
    let mut adc = [AdcFrame::default(); BATCH];
    let fs = stream.scale().sample_rate.0 as f64;
    let latency = stream.latency_batches();
    let mut budget: u64 = 0;
    let mut used: u64 = 0;
    while !m.is_complete() {
        if !engine.busy() {
            match m.next_plan() {
                Some(plan) => {
                    engine.load(plan);
                    budget = window_budget_samples(&plan, fs, latency);
                    used = 0;
                }
                None => break,
            }
        }
        engine.generate(&mut dac);
        stream.exchange(&dac, &mut adc).map_err(RunError::Stream)?;
        used += BATCH as u64;
        if let Some(raw) = engine.demodulate(&adc) {
            if let Some(p) = m.accept(&raw) {
                on_point(&p);
            }
            // Each window of a plan has its own budget.
            used = 0;
            if raw.window + 1 < raw.plan.windows {
                // More windows of the same plan follow without a new plan.
                continue;
            }
        } else if used > budget {
            return Err(RunError::Stalled);
        }
    }
    engine.stop();
    Ok(m.finish(unit))
}
