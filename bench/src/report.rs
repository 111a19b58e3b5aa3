//! Readings as JSON and as a bench log line.

use pzt_probe::reading::Reading;
use serde_json::{json, Value};

fn opt(v: Option<f32>) -> Value {
    match v {
        Some(x) if x.is_finite() => json!(x),
        _ => Value::Null,
    }
}

/// The JSON object of a reading.
pub fn reading_json(r: &Reading) -> Value {
    json!({
        "status": r.status.code(),
        "message": match r.status { pzt_probe::Status::Ok => "ok", pzt_probe::Status::Failed(f) => f.message() },
        "method": r.method.name(),
        "resonance_hz": opt(r.resonance.map(|x| x.0)),
        "resonance_sigma_hz": opt(r.resonance_sigma.map(|x| x.0)),
        "modulus_kpa": opt(r.modulus.map(|x| x.0)),
        "modulus_sigma_kpa": opt(r.modulus_sigma.map(|x| x.0)),
        "modulus_repeatability_kpa": opt(r.modulus_sigma_repeat.map(|x| x.0)),
        "q_factor": opt(r.q),
        "loss_tangent": opt(r.loss_tangent),
        "loss_tangent_sigma": opt(r.loss_tangent_sigma),
        "probe_time_ms": r.probe_time.0 * 1e3,
        "points": r.points,
        "contact_force_n": opt(r.force.map(|w| w.mean.0)),
        "contact_force_sigma_n": opt(r.force.map(|w| w.sigma.0)),
    })
}

/// One line for a human, like the probe's log on a bench.
pub fn reading_line(r: &Reading) -> String {
    let mut s = format!("reading: {}", r.status.code());
    if let pzt_probe::Status::Failed(f) = r.status {
        s += &format!(" ({})", f.message());
    }
    if let (Some(e), Some(se)) = (r.modulus, r.modulus_sigma) {
        s += &format!("  E = {:.1} ± {:.1} kPa", e.0, se.0);
        if let Some(rep) = r.modulus_sigma_repeat {
            s += &format!(" (repeatability ± {:.2})", rep.0);
        }
    }
    if let (Some(f), Some(sf)) = (r.resonance, r.resonance_sigma) {
        s += &format!("  f0 = {:.4} ± {:.4} Hz", f.0, sf.0);
    }
    if let Some(q) = r.q {
        s += &format!("  Q = {q:.2}");
    }
    if let (Some(t), Some(st)) = (r.loss_tangent, r.loss_tangent_sigma) {
        s += &format!("  tan δ = {t:.3} ± {st:.3}");
    }
    if let Some(w) = r.force {
        s += &format!("  F = {:.2} ± {:.2} mN", w.mean.0 * 1e3, w.sigma.0 * 1e3);
    }
    s += &format!(
        "  probe time {:.2} s  points {}  [{}]",
        r.probe_time.0,
        r.points,
        r.method.name()
    );
    s
}
