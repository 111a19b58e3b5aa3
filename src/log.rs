//! The firmware's defmt log: one line per event, in the formats `probe-bench log` parses
//! (`bench/src/defmt_log.rs` lists them; a test checks both lists are the same). Only the
//! report task of the RTIC application calls these.

use crate::measure::Settings;
use crate::session::Event;
use crate::store::{SlotState, StoreError};

/// One defmt line per session event (formats in the crate docs).
pub fn event(e: Event) {
    match e {
        Event::Loaded(l) => match l.source {
            crate::store::LoadSource::Stored { slot, seq, other } => defmt::info!(
                "store loaded slot={=u8} seq={=u32} other={=str}",
                slot,
                seq,
                slot_name(other)
            ),
            crate::store::LoadSource::Fallback { slots } => defmt::warn!(
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
        Event::Reading(r) => defmt::info!(
            "reading status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} e_repeat_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str}",
            r.status.code(),
            nan_or(r.resonance.map(|v| v.0)),
            nan_or(r.resonance_sigma.map(|v| v.0)),
            nan_or(r.modulus.map(|v| v.0)),
            nan_or(r.modulus_sigma.map(|v| v.0)),
            nan_or(r.modulus_sigma_repeat.map(|v| v.0)),
            nan_or(r.q),
            r.probe_time.0,
            r.points,
            r.method.name()
        ),
        Event::Hint(f) => defmt::warn!(
            "hint code={=str} message={=str}",
            f.code(),
            f.message()
        ),
        Event::Help => defmt::info!(
            "help commands={=str} methods={=str} default={=str}",
            "measure,method,sweep,staged,ringdown,air,calibrate,store,reload,status,help",
            crate::measure::METHOD_NAMES,
            crate::measure::DEFAULT_METHOD.name()
        ),
        Event::Stalled(tag) => defmt::error!("stalled tag={=u16}", tag),
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
        Event::Refused(why) => defmt::warn!("rejected error={=str}", why.message()),
        Event::Status {
            method,
            calibration,
            fallback,
            air,
            q_model,
            references,
        } => defmt::info!(
            "status method={=str} calibration={=str} fallback={=bool} air={=bool} q_model={=bool} references={=u16}",
            method.name(),
            calibration.source.name(),
            fallback,
            air,
            q_model,
            references
        ),
    }
}

/// `v` or NaN (missing values are logged as NaN).
pub fn nan_or(v: Option<f32>) -> f32 {
    v.unwrap_or(f32::NAN)
}

/// The `settings` line's fields `[start_hz, stop_hz, step_hz, settle_s, integrate_s,
/// drive_v]` of any method's settings: a sweep's own; for the staged methods the band, no
/// step (`NaN`), the coarse settling, the integration and the drive; for ring-down the
/// band, no step, the burst as settling, the ring as integration and the drive; `NaN` for
/// settings of other kinds.
pub fn settings_fields(s: &Settings) -> [f32; 6] {
    match s {
        Settings::Sweep(s) => [
            s.start.0,
            s.stop.0,
            s.step.0,
            s.settle.0,
            s.integrate.0,
            s.drive.0,
        ],
        Settings::Staged(s) => [
            s.band_start.0,
            s.band_stop.0,
            f32::NAN,
            s.coarse_settle.0,
            s.integrate.0,
            s.drive.0,
        ],
        Settings::Ringdown(s) => [
            s.band_start.0,
            s.band_stop.0,
            f32::NAN,
            s.burst.0,
            s.ring.0,
            s.drive.0,
        ],
        Settings::Hold(_) => [f32::NAN; 6],
    }
}

/// A store slot's state, as logged.
pub fn slot_name(s: SlotState) -> &'static str {
    match s {
        SlotState::Valid(_) => "valid",
        SlotState::Empty => "empty",
        SlotState::Corrupt => "corrupt",
        SlotState::Unreadable => "unreadable",
    }
}

/// A store error, as logged.
pub fn store_error_name(e: StoreError) -> &'static str {
    match e {
        StoreError::Geometry => "geometry",
        StoreError::InvalidRecord => "invalid_record",
        StoreError::Erase => "erase",
        StoreError::Program => "program",
        StoreError::Verify => "verify",
    }
}
