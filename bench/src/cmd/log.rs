//! `probe-bench log`: the readings and sweeps in a decoded defmt log of the firmware.

use crate::defmt_log::{self, Level, LoggedReading, Session};
use crate::plot::{self, draw_legend, draw_to, err, padded_range, Area, Backend, PALETTE};
use anyhow::{bail, Context, Result};
use clap::Args;
use plotters::prelude::*;
use serde_json::{json, Value};
use std::io::Read;
use std::path::{Path, PathBuf};

/// The frame of this command's charts.
const FRAME: plot::Frame = plot::Frame {
    margin: 10,
    x_labels: 40,
    y_labels: 60,
};

#[derive(Args)]
pub struct LogArgs {
    /// Decoded defmt log (from `probe-rs run`, `defmt-print`, `scripts/qemu-run` or a saved
    /// file); `-` or nothing reads stdin.
    pub file: Option<PathBuf>,
    /// JSON (one object: readings, streams, sweeps, events) and the plot (the logged admittance
    /// sweeps, conductance in nS against Hz, and the reading history, resonance in Hz with its
    /// standard uncertainty).
    #[command(flatten)]
    pub out: super::OutputArgs,
}

fn fmt_opt(v: Option<f32>, digits: usize) -> String {
    match v {
        Some(x) => format!("{x:.digits$}"),
        None => "—".into(),
    }
}

fn when(r: &LoggedReading) -> String {
    match r.at.time_s {
        Some(t) => format!("{t:.3} s"),
        None => format!("line {}", r.at.line),
    }
}

/// The readings as a table (one line each).
pub fn table(s: &Session) -> Vec<String> {
    let mut out = vec![format!(
        "{:>3}  {:<12} {:<13} {:>20} {:>18} {:>6} {:>14} {:>6}  {}",
        "#",
        "time",
        "status",
        "resonance (Hz)",
        "modulus (kPa)",
        "Q",
        "force (mN)",
        "points",
        "method"
    )];
    for (k, r) in s.readings.iter().enumerate() {
        let f = match (r.msg.f_hz, r.msg.f_sigma_hz) {
            (Some(f), Some(sf)) => format!("{f:.3} ± {sf:.3}"),
            (Some(f), None) => format!("{f:.3}"),
            _ => "—".into(),
        };
        let e = match (r.msg.e_kpa, r.msg.e_sigma_kpa) {
            (Some(e), Some(se)) => format!("{e:.1} ± {se:.1}"),
            (Some(e), None) => format!("{e:.1}"),
            _ => "—".into(),
        };
        let force = match (r.msg.force_n, r.msg.force_sigma_n) {
            (Some(f), Some(sf)) if f.is_finite() => {
                format!("{:.2} ± {:.2}", f * 1e3, sf * 1e3)
            }
            _ => "—".into(),
        };
        out.push(format!(
            "{:>3}  {:<12} {:<13} {:>20} {:>18} {:>6} {:>14} {:>6}  {}",
            k + 1,
            when(r),
            r.msg.status,
            f,
            e,
            fmt_opt(r.msg.q, 2),
            force,
            r.msg.points,
            r.msg.method
        ));
    }
    out
}

/// The continuous streams, one line each: readings logged, missing (gaps in `seq`, with the
/// firmware's own dropped count), ok and ok/s after the first 0.5 s, the ok moduli.
pub fn stream_table(s: &Session) -> Vec<String> {
    let mut out = Vec::new();
    for (k, x) in s.streams.iter().enumerate() {
        let first = x.readings.first().map_or(0, |r| r.reading.at.line);
        let span = match (x.start_s(), x.readings.last()) {
            (Some(a), Some(b)) => format!("{a:.3}–{:.3} s", b.t_s),
            _ => "—".into(),
        };
        let e: Vec<f64> = x
            .readings
            .iter()
            .filter(|r| r.reading.msg.status == "ok")
            .filter_map(|r| r.reading.msg.e_kpa.map(f64::from))
            .collect();
        let modulus = if e.is_empty() {
            "—".to_owned()
        } else {
            let mean = e.iter().sum::<f64>() / e.len() as f64;
            let sd = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
                / (e.len().max(2) - 1) as f64)
                .sqrt();
            format!("{mean:.1} ± {sd:.1} kPa")
        };
        let fw = x.end.as_ref().map_or("no end line".to_owned(), |e| {
            format!("firmware: {} readings, {} dropped", e.readings, e.dropped)
        });
        out.push(format!(
            "stream {} (line {first}, probe time {span}): {} readings logged, {} missing (gaps in seq; {fw}), {} ok, {} ok/s after 0.5 s, ok modulus {modulus}",
            k + 1,
            x.readings.len(),
            x.missing(),
            x.ok(),
            x.ok_per_s(0.5).map_or("—".to_owned(), |v| format!("{v:.1}")),
        ));
    }
    out
}

fn streams_json(s: &Session) -> Value {
    Value::Array(
        s.streams
            .iter()
            .map(|x| {
                json!({
                    "start_s": x.start_s(),
                    "readings_logged": x.readings.len(),
                    "missing": x.missing(),
                    "ok": x.ok(),
                    "ok_per_s_after_0_5_s": x.ok_per_s(0.5),
                    "end": x.end.as_ref().map(|e| json!({
                        "line": e.line, "readings": e.readings, "ok": e.ok,
                        "dropped": e.dropped, "plan_work": e.plan_work,
                    })),
                    "readings": x.readings.iter().map(|r| json!({
                        "seq": r.seq, "t_s": r.t_s, "locked": r.locked,
                        "line": r.reading.at.line, "status": r.reading.msg.status,
                        "resonance_hz": r.reading.msg.f_hz, "modulus_kpa": r.reading.msg.e_kpa,
                        "modulus_sigma_kpa": r.reading.msg.e_sigma_kpa, "q_factor": r.reading.msg.q,
                        "loss_tangent": r.reading.msg.loss_tangent, "loss_tangent_sigma": r.reading.msg.loss_tangent_sigma,
                        "force_n": r.reading.msg.force_n,
                    })).collect::<Vec<_>>(),
                })
            })
            .collect(),
    )
}

fn session_json(s: &Session) -> Value {
    let readings: Vec<Value> = s
        .readings
        .iter()
        .map(|r| {
            json!({
                "line": r.at.line, "time_s": r.at.time_s, "status": r.msg.status,
                "resonance_hz": r.msg.f_hz, "resonance_sigma_hz": r.msg.f_sigma_hz,
                "modulus_kpa": r.msg.e_kpa, "modulus_sigma_kpa": r.msg.e_sigma_kpa,
                "modulus_repeatability_kpa": r.msg.e_repeat_kpa,
                "q_factor": r.msg.q, "probe_time_s": r.msg.probe_time_s,
                "points": r.msg.points, "method": r.msg.method, "sweep": r.sweep,
                "contact_force_n": r.msg.force_n, "contact_force_sigma_n": r.msg.force_sigma_n,
                "loss_tangent": r.msg.loss_tangent, "loss_tangent_sigma": r.msg.loss_tangent_sigma,
            })
        })
        .collect();
    let sweeps: Vec<Value> = s
        .sweeps
        .iter()
        .map(|w| {
            json!({
                "first_line": w.first_line,
                "method": w.settings.as_ref().map(|x| x.str("method").unwrap_or_default()),
                "reading": w.reading,
                "points": w.points.iter().map(|p| json!({
                    "tag": p.tag, "f_hz": p.f_hz, "g_s": p.g_s, "b_s": p.b_s, "sigma_s": p.sigma_s
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let events: Vec<Value> = s
        .events
        .iter()
        .map(|e| json!({"line": e.at.line, "time_s": e.at.time_s, "text": e.text()}))
        .collect();
    json!({
        "messages": s.messages,
        "readings": readings,
        "sweeps": sweeps,
        "streams": streams_json(s),
        "events": events,
        "unparsed": s.errors.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
    })
}

/// Run the subcommand.
pub fn run(a: LogArgs) -> Result<()> {
    let (name, text) = match a.file.as_deref() {
        None => ("stdin".to_owned(), read_stdin()?),
        Some(p) if p == Path::new("-") => ("stdin".to_owned(), read_stdin()?),
        Some(p) => (
            p.display().to_string(),
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
        ),
    };
    let s = defmt_log::parse_log(&text);
    if s.messages == 0 {
        match s.errors.first() {
            Some(e) => bail!("{name}: no firmware message could be read ({e})"),
            None => bail!("{name}: no firmware log messages found"),
        }
    }
    for e in &s.errors {
        eprintln!("probe-bench log: {name}: skipped {e}");
    }
    if a.out.json {
        println!("{}", session_json(&s));
    } else {
        println!(
            "probe-bench log: {name} — {} messages, {} readings, {} sweeps, {} streams ({} other lines)",
            s.messages,
            s.readings.len(),
            s.sweeps.len(),
            s.streams.len(),
            s.other_lines
        );
        if !s.readings.is_empty() || s.streams.is_empty() {
            for l in table(&s) {
                println!("  {l}");
            }
        }
        for l in stream_table(&s) {
            println!("  {l}");
        }
        if !s.events.is_empty() {
            println!("  events:");
            for e in &s.events {
                let lvl = match e.level {
                    Some(Level::Error) => "ERROR",
                    Some(Level::Warn) => "WARN ",
                    Some(Level::Info) => "INFO ",
                    Some(Level::Debug) => "DEBUG",
                    Some(Level::Trace) => "TRACE",
                    None => "     ",
                };
                println!("    line {:>5}  {lvl}  {}", e.at.line, e.text());
            }
        }
    }
    a.out.plot_with(|path| {
        if s.sweeps.is_empty() && s.readings.is_empty() {
            bail!("{name}: nothing to plot (no sweeps or readings in the log)");
        }
        write_plot(path, &name, &s)
    })
}

fn read_stdin() -> Result<String> {
    let mut s = String::new();
    std::io::stdin()
        .read_to_string(&mut s)
        .context("cannot read stdin")?;
    Ok(s)
}

/// Sweeps (top) and reading history (bottom) to .svg or .png.
pub fn write_plot(path: &Path, title: &str, s: &Session) -> Result<()> {
    draw_to!(path, (960, 900), |root| draw(root, title, s))
}

fn draw<DB: Backend>(root: &Area<DB>, title: &str, s: &Session) -> Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled(&format!("defmt log: {title}"), ("sans-serif", 20))
        .map_err(err)?;
    let (top, bottom) = root.split_vertically(480);
    // Sweeps.
    let pts = s.sweeps.iter().flat_map(|w| w.points.iter());
    let (mut f0, mut f1, mut g0, mut g1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64, 0.0f64);
    for p in pts {
        if p.f_hz.is_finite() && p.g_s.is_finite() {
            f0 = f0.min(p.f_hz as f64);
            f1 = f1.max(p.f_hz as f64);
            g0 = g0.min(p.g_s as f64 * 1e9);
            g1 = g1.max(p.g_s as f64 * 1e9);
        }
    }
    if !(f1 > f0) {
        (f0, f1) = (0.0, 1.0);
    }
    let g1 = if g1 > g0 { g1 * 1.05 } else { g0 + 1.0 };
    let mut chart = plot::chart(
        &top,
        Some(("logged sweeps: conductance", 16)),
        FRAME,
        (f0..f1, g0..g1),
        ("drive frequency (Hz)", "G = Re(Y) (nS)"),
    )
    .map_err(err)?;
    for (k, w) in s.sweeps.iter().enumerate() {
        let c = PALETTE[k % PALETTE.len()];
        let line: Vec<(f64, f64)> = w
            .points
            .iter()
            .filter(|p| p.f_hz.is_finite() && p.g_s.is_finite())
            .map(|p| (p.f_hz as f64, p.g_s as f64 * 1e9))
            .collect();
        let label = match w.reading.and_then(|r| s.readings.get(r)) {
            Some(r) => format!(
                "reading {}: {} {}",
                w.reading.unwrap_or(0) + 1,
                r.msg.status,
                r.msg.f_hz.map(|f| format!("{f:.2} Hz")).unwrap_or_default()
            ),
            None => format!("sweep at line {} (no reading)", w.first_line),
        };
        plot::line(&mut chart, line.clone(), c.stroke_width(2), label).map_err(err)?;
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, y)| Circle::new((x, y), 2, c.filled())),
            )
            .map_err(err)?;
        if let Some(f) = w
            .reading
            .and_then(|r| s.readings.get(r))
            .and_then(|r| r.msg.f_hz)
        {
            let f = f as f64;
            if f > f0 && f < f1 {
                chart
                    .draw_series(LineSeries::new(vec![(f, g0), (f, g1)], c.mix(0.6)))
                    .map_err(err)?;
            }
        }
    }
    if !s.sweeps.is_empty() {
        draw_legend(&mut chart, SeriesLabelPosition::MiddleRight, 0.85).map_err(err)?;
    }
    // History.
    let rs: Vec<(f64, &LoggedReading)> = s
        .readings
        .iter()
        .enumerate()
        .map(|(k, r)| (r.at.time_s.unwrap_or((k + 1) as f64), r))
        .collect();
    let timed = s.readings.iter().all(|r| r.at.time_s.is_some());
    let (x0, x1) = padded_range(rs.iter().map(|(x, _)| *x), 0.05, (0.0, 1.0));
    let (y0, y1) = padded_range(
        rs.iter().filter_map(|(_, r)| r.msg.f_hz.map(|f| f as f64)),
        0.15,
        (200.0, 260.0),
    );
    let mut hist = plot::chart(
        &bottom,
        Some((
            "reading history: resonance ± standard uncertainty (ok: blue, failed: red)",
            16,
        )),
        FRAME,
        (x0..x1, y0..y1),
        (if timed { "time (s)" } else { "reading" }, "resonance (Hz)"),
    )
    .map_err(err)?;
    for (x, r) in &rs {
        let Some(f) = r.msg.f_hz else { continue };
        let f = f as f64;
        let ok = r.msg.status == "ok";
        let c = if ok { BLUE } else { RED };
        let sf = r.msg.f_sigma_hz.unwrap_or(0.0) as f64;
        // Error bar: the ±σ segment with caps a hundredth of the axis wide.
        let cap = 0.01 * (x1 - x0);
        for seg in [
            vec![(*x, f - sf), (*x, f + sf)],
            vec![(*x - cap, f - sf), (*x + cap, f - sf)],
            vec![(*x - cap, f + sf), (*x + cap, f + sf)],
        ] {
            hist.draw_series(std::iter::once(PathElement::new(seg, c.stroke_width(2))))
                .map_err(err)?;
        }
        if ok {
            hist.draw_series(std::iter::once(Circle::new((*x, f), 4, c.filled())))
                .map_err(err)?;
        } else {
            hist.draw_series(std::iter::once(Cross::new((*x, f), 5, c.stroke_width(2))))
                .map_err(err)?;
        }
    }
    Ok(())
}
