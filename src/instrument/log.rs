//! The firmware's defmt log: one line per event, in the formats `probe-bench log` parses
//! (`bench/src/defmt_log.rs` lists them; a test checks both lists are the same). Only the
//! report task of the RTIC application calls these (the board's own lines — boot, counters,
//! overrun, exit — it logs itself).
//!
//! # Log lines (parsed by `probe-bench log` and `tests/qemu.rs`; keep them stable)
//!
//! Every line is one defmt message; floats are `{=f32}` (missing values are `NaN`), names
//! `{=str}`:
//!
//! ```text
//! boot board=<qemu|stm32> fs_hz=<f32> batch=<u32>
//! boot fault=<str> clock=<str>                            (error; STM32: a bring-up step failed)
//! store loaded slot=<u8> seq=<u32> other=<str>            (info)
//! store fallback slot0=<str> slot1=<str> calibration=paper-experiment   (warn)
//! store saved slot=<u8> seq=<u32>                          (info)
//! store error=<str>                                        (error)
//! settings method=<str> start_hz=<f32> stop_hz=<f32> step_hz=<f32> settle_s=<f32> integrate_s=<f32> drive_v=<f32>
//! point tag=<u16> f_hz=<f32> g_s=<f32> b_s=<f32> sigma_s=<f32>
//! reading status=<str> f_hz=<f32> f_sigma_hz=<f32> e_kpa=<f32> e_sigma_kpa=<f32> e_repeat_kpa=<f32> q=<f32> probe_time_s=<f32> points=<u16> method=<str> force_n=<f32> force_sigma_n=<f32> loss=<f32> loss_sigma=<f32>
//! stream seq=<u32> t_s=<f32> locked=<bool> status=<str> f_hz=<f32> f_sigma_hz=<f32> e_kpa=<f32> e_sigma_kpa=<f32> e_repeat_kpa=<f32> q=<f32> probe_time_s=<f32> points=<u16> method=<str> force_n=<f32> force_sigma_n=<f32> loss=<f32> loss_sigma=<f32>
//! stream end start_s=<f32> readings=<u32> ok=<u32> dropped=<u32> plan_work=<u32>   (after `stream <s>`: the tracker's readings, how many ok, how many dropped for a full report channel; the most work from a window to the next plan, in the counters' unit, 0: not measured)
//! air f_hz=<f32> q=<f32>
//! loadcell present=<bool> newtons_per_count=<f32> tare=<f32> min_n=<f32> max_n=<f32>   (after force, weigh, air with a load cell, status)
//! reference e_kpa=<f32> f_hz=<f32> f_sigma_hz=<f32> n=<u16>
//! calibration source=<str> a=<f32> b=<f32> c=<f32> min_kpa=<f32> max_kpa=<f32>
//! hint code=<str> message=<str>                           (warn; after a failed reading: what to do)
//! rejected error=<str>                                     (warn)
//! stalled tag=<u16>                                        (error)
//! overrun late=<u32> ring=<u32> dropped=<u32>              (error; whenever a counter grew)
//! counters batches=<u32> late=<u32> ring=<u32> dropped=<u32> isr_mean=<u32> isr_max=<u32> unit=<str> load_cell_errors=<u32>
//! status method=<str> calibration=<str> fallback=<bool> air=<bool> q_model=<bool> references=<u16> selftest=<str>
//! selftest result=<str> f_hz=<f32> c_pf=<f32> c_sigma_pf=<f32> ref_c_pf=<f32> tol=<f32> ref=<str> g_s=<f32> i_a=<f32> v=<f32> probe_time_s=<f32>
//! selftest fault=<str> message=<str>                      (error; after a failed self-test)
//! refused selftest=<str> message=<str>                    (warn; a reading asked for while the self-test fails)
//! stack used_bytes=<u32> init_bytes=<u32> size_bytes=<u32>   (after status and at exit: the painted stack's high-water marks, tasks and interrupts / init)
//! help commands=<str> methods=<str> default=<str>
//! exit ok=<bool>                                           (QEMU script end)
//! ```
//!
//! `settings` carries a stepped sweep's own fields; for the fit method's settings (fit,
//! auto) `start_hz`/`stop_hz` are the band, `step_hz` is `NaN`, `settle_s` the coarse settling
//! and `integrate_s` the integration. `status` of a reading is `ok` or a failure code of
//! [`pzt_probe::Failure::code`]. `selftest` of `status` and `result` of `selftest` are
//! `passed`, a fault code of [`crate::instrument::selftest::SelfTestFault::code`] (`status`: also
//! `not_run`); `ref` is `air` (the air reference's `C0`) or `nominal` (the nominal plate).
//! `isr_mean`
//! and `isr_max` are the sample interrupt's work per batch (plan intake, demodulation, DAC
//! refill, point hand-off) in `unit`: instructions under QEMU, core cycles on the STM32.

use crate::instrument::link::reading_msg;
pub use crate::instrument::link::{
    nan_or, settings_fields, slot_name, store_error_name, Report, COMMANDS,
};
use crate::instrument::session::Event;

/// A `reading` or `stream` line: `$format` (written out whole: a defmt format string is one
/// literal, and the line is a wire format), the arguments `$pre` its own fields before
/// `status=` take, then the reading `$r`'s fields from `status=` to `loss_sigma=` (the tissue's
/// loss tangent and its σ), which both lines end with: the host link's message of the reading
/// ([`reading_msg`]), its missing values `NaN`.
macro_rules! reading_line {
    ($format:tt, $r:expr $(, $pre:expr)*) => {{
        let m = reading_msg(&$r);
        defmt::info!(
            $format,
            $($pre,)*
            m.status,
            nan_or(m.f_hz),
            nan_or(m.f_sigma_hz),
            nan_or(m.e_kpa),
            nan_or(m.e_sigma_kpa),
            nan_or(m.e_repeat_kpa),
            nan_or(m.q),
            m.probe_time_s,
            m.points,
            m.method,
            nan_or(m.force_n),
            nan_or(m.force_sigma_n),
            nan_or(m.loss_tangent),
            nan_or(m.loss_tangent_sigma)
        )
    }};
}

/// One defmt line per session event (formats in the crate docs).
pub fn event(e: Event) {
    match e {
        Event::Loaded(source) => match source {
            crate::unit::store::LoadSource::Stored { slot, seq, other } => defmt::info!(
                "store loaded slot={=u8} seq={=u32} other={=str}",
                slot,
                seq,
                slot_name(other)
            ),
            crate::unit::store::LoadSource::Fallback { slots } => defmt::warn!(
                "store fallback slot0={=str} slot1={=str} calibration=paper-experiment",
                slot_name(slots[0]),
                slot_name(slots[1])
            ),
        },
        Event::Saved(v) => defmt::info!("store saved slot={=u8} seq={=u32}", v.slot, v.seq),
        Event::StoreFailed(e) => defmt::error!("store error={=str}", store_error_name(e)),
        Event::Settings(m, s) => {
            let [start, stop, step, settle, integrate, drive] = settings_fields(&s);
            defmt::info!(
                "settings method={=str} start_hz={=f32} stop_hz={=f32} step_hz={=f32} settle_s={=f32} integrate_s={=f32} drive_v={=f32}",
                m.name(),
                start,
                stop,
                step,
                settle,
                integrate,
                drive
            )
        }
        Event::Point { tag, point } => defmt::info!(
            "point tag={=u16} f_hz={=f32} g_s={=f32} b_s={=f32} sigma_s={=f32}",
            tag,
            point.freq.0,
            point.g_s,
            point.b_s,
            point.sigma_s
        ),
        Event::Reading(r) => reading_line!(
            "reading status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} e_repeat_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str} force_n={=f32} force_sigma_n={=f32} loss={=f32} loss_sigma={=f32}",
            r
        ),
        Event::Stream(x) => reading_line!(
            "stream seq={=u32} t_s={=f32} locked={=bool} status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} e_repeat_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str} force_n={=f32} force_sigma_n={=f32} loss={=f32} loss_sigma={=f32}",
            x.reading,
            x.seq,
            x.t_s.0,
            x.locked
        ),
        Event::StreamEnd {
            start,
            readings,
            ok,
            dropped,
            plan_work,
        } => defmt::info!(
            "stream end start_s={=f32} readings={=u32} ok={=u32} dropped={=u32} plan_work={=u32}",
            start.0,
            readings,
            ok,
            dropped,
            plan_work.unwrap_or(0)
        ),
        Event::Hint(f) => defmt::warn!(
            "hint code={=str} message={=str}",
            f.code(),
            f.message()
        ),
        Event::Help => defmt::info!(
            "help commands={=str} methods={=str} default={=str}",
            COMMANDS,
            crate::reading::METHOD_NAMES,
            crate::reading::DEFAULT_METHOD.name()
        ),
        Event::Stalled(tag) => defmt::error!("stalled tag={=u16}", tag),
        Event::LoadCell { cal, window } => defmt::info!(
            "loadcell present={=bool} newtons_per_count={=f32} tare={=f32} min_n={=f32} max_n={=f32}",
            cal.is_some(),
            nan_or(cal.map(|c| c.newtons_per_count)),
            // Counts are 24-bit: exact in f32.
            cal.map_or(f32::NAN, |c| c.tare.0 as f32),
            window.min.0,
            window.max.0
        ),
        Event::Air(a) => defmt::info!(
            "air f_hz={=f32} q={=f32}",
            a.free_resonance.0,
            a.free_q
        ),
        Event::Reference {
            modulus,
            reference,
            n,
        } => defmt::info!(
            "reference e_kpa={=f32} f_hz={=f32} f_sigma_hz={=f32} n={=u16}",
            modulus.0,
            reference.resonance_hz as f32,
            reference.sigma_hz as f32,
            n
        ),
        Event::Calibration(c) => defmt::info!(
            "calibration source={=str} a={=f32} b={=f32} c={=f32} min_kpa={=f32} max_kpa={=f32}",
            c.source.name(),
            c.a as f32,
            c.b as f32,
            c.c as f32,
            c.min_kpa as f32,
            c.max_kpa as f32
        ),
        Event::Refused(crate::instrument::session::Refusal::SelfTest(f)) => defmt::warn!(
            "refused selftest={=str} message={=str}",
            f.code(),
            f.message()
        ),
        Event::Refused(crate::instrument::session::Refusal::Boot(e)) => defmt::warn!(
            "refused boot={=str} message={=str}",
            e.code(),
            e.message()
        ),
        Event::Refused(why) => defmt::warn!("rejected error={=str}", why.message()),
        Event::SelfTest(r) => selftest(&r),
        Event::Status(s) => {
            defmt::info!(
                "status method={=str} calibration={=str} fallback={=bool} air={=bool} q_model={=bool} references={=u16} selftest={=str}",
                s.method.name(),
                s.calibration.source.name(),
                s.fallback,
                s.air,
                s.q_model,
                s.references,
                crate::instrument::selftest::outcome_code(s.selftest)
            );
            // A failed bring-up step, on a line of its own (the status line's format stays).
            if let Some(b) = s.boot {
                defmt::warn!("status boot={=str} message={=str}", b.code(), b.message());
            }
            stack();
        }
    }
}

/// The `selftest` line (and, when it failed, the fault's line).
fn selftest(r: &crate::instrument::selftest::SelfTestReport) {
    let e = &r.expected;
    defmt::info!(
        "selftest result={=str} f_hz={=f32} c_pf={=f32} c_sigma_pf={=f32} ref_c_pf={=f32} tol={=f32} ref={=str} g_s={=f32} i_a={=f32} v={=f32} probe_time_s={=f32}",
        crate::instrument::selftest::outcome_code(Some(r.outcome)),
        r.freq.0,
        r.capacitance.0 * 1e12,
        r.capacitance_sigma.0 * 1e12,
        e.capacitance.0 * 1e12,
        e.tolerance,
        if e.from_air { "air" } else { "nominal" },
        r.conductance.0,
        r.current_a,
        r.drive_v,
        r.probe_time.0
    );
    if let Err(f) = r.outcome {
        defmt::error!(
            "selftest fault={=str} message={=str}",
            f.code(),
            f.message()
        );
    }
}

/// The `stack` line: the painted stack's high-water mark, where the board has one
/// ([`crate::stack`]).
pub fn stack() {
    if let Some(s) = crate::stack::usage() {
        defmt::info!(
            "stack used_bytes={=u32} init_bytes={=u32} size_bytes={=u32}",
            s.used_bytes,
            s.init_bytes,
            s.size_bytes
        );
    }
}

/// The `counters` line; `unit` is the board's unit of the interrupt's work.
pub fn counters(unit: &str) {
    use crate::counters::*;
    use core::sync::atomic::Ordering::Relaxed;
    defmt::info!(
        "counters batches={=u32} late={=u32} ring={=u32} dropped={=u32} isr_mean={=u32} isr_max={=u32} unit={=str} load_cell_errors={=u32}",
        BATCHES.load(Relaxed),
        LATE.load(Relaxed),
        RING.load(Relaxed),
        DROPPED.load(Relaxed),
        ISR_MEAN.load(Relaxed),
        ISR_MAX.load(Relaxed),
        unit,
        LOAD_CELL_ERRORS.load(Relaxed)
    );
}

/// The `overrun` line, whenever a counter grew since `seen` (which it updates).
pub fn overruns_if_grew(seen: &mut crate::counters::Overruns) {
    let now = crate::counters::Overruns::now();
    if now != *seen {
        defmt::error!(
            "overrun late={=u32} ring={=u32} dropped={=u32}",
            now.late,
            now.ring,
            now.dropped
        );
        *seen = now;
    }
}

/// Log `r` (`unit` is the board's unit of the interrupt's work), then the overrun counters if
/// they grew since `seen`; `Some(ok)` for [`Report::Exit`].
pub fn report(r: Report, unit: &str, seen: &mut crate::counters::Overruns) -> Option<bool> {
    let exit = match r {
        Report::Event(e) => {
            event(e);
            None
        }
        Report::Rejected(message) => {
            defmt::warn!("rejected error={=str}", message);
            None
        }
        Report::Counters => {
            counters(unit);
            None
        }
        Report::Exit(ok) => Some(ok),
        Report::Link(crate::instrument::link::LinkEvent::Rejected { error, .. }) => {
            defmt::warn!("rejected error={=str}", error.message());
            None
        }
        Report::Link(_) => None,
    };
    overruns_if_grew(seen);
    if let Some(ok) = exit {
        stack();
        defmt::info!("exit ok={=bool}", ok);
    }
    exit
}
