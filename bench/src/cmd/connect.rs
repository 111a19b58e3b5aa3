//! `probe-bench connect <serial-port | qemu>`: talk to a probe over its host link
//! (`docs/protocol.md`) — a console for command lines, or the commands of `-c` one after the
//! other, each to its reply. Readings print through the bench's JSON and line reporters
//! (`report.rs`), as `measure --qemu` prints them.

use crate::link::{Frame, Kind, Link, Received};
use crate::report;
use crate::scene::{parse_noise, NoiseArgs, SceneArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Args)]
pub struct ConnectArgs {
    /// `qemu` (the firmware image in QEMU on the scene of the options below, serving its UART
    /// on a local TCP socket) or a serial port (`/dev/ttyACM0`, `COM3`) at 115 200 Bd.
    pub port: String,
    /// QEMU: what the simulated probe is on, and the preload (default: free air).
    #[command(flatten)]
    pub scene: SceneArgs,
    /// QEMU: noise and seed.
    #[command(flatten)]
    pub noise: NoiseArgs,
    /// A command line to run (repeat for more): each is sent once the previous one's reply has
    /// come (but right after a `sim` line, which the QEMU image serves itself: it then serves
    /// the next command after the scene, as its script does), and `connect` ends after the
    /// last reply (no console).
    #[arg(short = 'c', long = "command")]
    pub commands: Vec<String>,
    /// One JSON object per line: readings as `measure --json` prints them, stream readings as
    /// `stream --json`, every other message as the frame's JSON.
    #[arg(long)]
    pub json: bool,
    /// Record every reading and stream reading to this CSV file.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Most wall time to wait for a command's reply (or for the probe's hello), s.
    #[arg(long, default_value_t = 900.0)]
    pub timeout_s: f64,
    /// QEMU: write the image's raw defmt stream (semihosting) to this file.
    #[arg(long)]
    pub defmt_log: Option<PathBuf>,
}

/// The CSV columns.
const CSV_HEADER: &str = "link_seq,kind,stream_seq,t_s,locked,status,method,f_hz,f_sigma_hz,e_kpa,e_sigma_kpa,e_repeat_kpa,q,loss_tangent,loss_tangent_sigma,force_n,force_sigma_n,probe_time_s,points";

fn cell(v: Option<f32>) -> String {
    v.map_or(String::new(), |x| x.to_string())
}

/// Prints what arrives and keeps the link's accounting.
struct Printer {
    json: bool,
    csv: Option<std::io::BufWriter<std::fs::File>>,
    next_seq: Option<u32>,
    /// Messages the probe dropped (its `dropped` counts).
    dropped: u64,
    /// Messages missing from `seq` beyond those counted (frames lost on the line).
    lost: u64,
    /// Received bytes that were no frame.
    errors: u64,
    rejected: u32,
}

impl Printer {
    fn frame(&mut self, f: &Frame) -> Result<()> {
        if let Some(want) = self.next_seq {
            let gap = f.seq.wrapping_sub(want);
            self.lost += gap.saturating_sub(f.dropped) as u64;
        }
        self.dropped += f.dropped as u64;
        self.next_seq = Some(f.seq.wrapping_add(1));
        let mut out = std::io::stdout().lock();
        match &f.kind {
            Kind::Reading(r) => {
                if self.json {
                    writeln!(out, "{}", report::reading_json(r))?;
                } else {
                    writeln!(out, "{}", report::reading_line(r))?;
                }
                self.record(f.seq, "reading", None, r)?;
            }
            Kind::Stream(s) => {
                if self.json {
                    writeln!(out, "{}", super::stream::stream_json(s))?;
                } else {
                    writeln!(
                        out,
                        "stream {:5} t {:8.3} s {:8}  {}",
                        s.seq,
                        s.t_s.0,
                        if s.locked { "locked" } else { "unlocked" },
                        report::reading_line(&s.reading)
                    )?;
                }
                self.record(f.seq, "stream", Some(s), &s.reading)?;
            }
            Kind::Reply { id, outcome } => {
                if outcome.is_err() {
                    self.rejected += 1;
                }
                if self.json {
                    writeln!(out, "{}", f.json)?;
                } else {
                    match outcome {
                        Ok(()) => writeln!(out, "reply {id}: accepted")?,
                        Err((code, cause, message)) => writeln!(
                            out,
                            "reply {id}: rejected {code}{}: {message}",
                            cause.as_ref().map_or(String::new(), |c| format!(" ({c})"))
                        )?,
                    }
                }
            }
            _ => {
                if self.json {
                    writeln!(out, "{}", f.json)?;
                } else {
                    writeln!(out, "{}", f.json["msg"])?;
                }
            }
        }
        Ok(())
    }

    fn record(
        &mut self,
        seq: u32,
        kind: &str,
        s: Option<&pzt_probe::instrument::continuous::StreamReading>,
        r: &pzt_probe::Reading,
    ) -> Result<()> {
        let Some(w) = self.csv.as_mut() else {
            return Ok(());
        };
        writeln!(
            w,
            "{seq},{kind},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            s.map_or(String::new(), |s| s.seq.to_string()),
            s.map_or(String::new(), |s| s.t_s.0.to_string()),
            s.map_or(String::new(), |s| s.locked.to_string()),
            r.status.code(),
            r.method.name(),
            cell(r.resonance.map(|v| v.0)),
            cell(r.resonance_sigma.map(|v| v.0)),
            cell(r.modulus.map(|v| v.0)),
            cell(r.modulus_sigma.map(|v| v.0)),
            cell(r.modulus_sigma_repeat.map(|v| v.0)),
            cell(r.q),
            cell(r.loss_tangent),
            cell(r.loss_tangent_sigma),
            cell(r.force.map(|w| w.mean.0)),
            cell(r.force.map(|w| w.sigma.0)),
            r.probe_time.0,
            r.points
        )?;
        Ok(())
    }

    fn error(&mut self, e: probe_proto::FrameError) {
        self.errors += 1;
        eprintln!(
            "connect: bytes from the probe that are no frame ({})",
            e.code()
        );
    }
}

/// Wait for what `done` accepts, printing everything that arrives; fails on a closed line or
/// after `timeout`.
fn until(
    link: &Link,
    p: &mut Printer,
    timeout: Duration,
    what: &str,
    mut done: impl FnMut(&Frame) -> bool,
) -> Result<()> {
    let t0 = Instant::now();
    loop {
        let left = timeout.saturating_sub(t0.elapsed());
        if left.is_zero() {
            bail!("no {what} within {} s", timeout.as_secs_f64());
        }
        match link.recv(left) {
            Some(Received::Frame(f)) => {
                p.frame(&f)?;
                if done(&f) {
                    return Ok(());
                }
            }
            Some(Received::Error(e)) => p.error(e),
            Some(Received::Closed) => bail!("the probe closed the line before its {what}"),
            None => {}
        }
    }
}

/// Run the subcommand.
pub fn run(a: ConnectArgs) -> Result<()> {
    if !(a.timeout_s > 0.0 && a.timeout_s.is_finite()) {
        bail!("--timeout-s must be above 0");
    }
    let timeout = Duration::from_secs_f64(a.timeout_s);
    let mut link = if a.port == "qemu" {
        let noise = parse_noise(&a.noise.noise)?;
        let (target, _) = a.scene.scene(noise, true)?;
        let mut lines = crate::qemu::scene_lines(&target, &a.scene, noise);
        lines.push(format!("sim seed {}", a.noise.seed));
        let elf = crate::qemu::build_image()?;
        if !a.json {
            eprintln!(
                "probe-bench connect qemu: the firmware image on {} (script: {};serve)",
                target.describe(),
                lines.join(";")
            );
        }
        Link::qemu(&elf, &lines, a.defmt_log.clone())?
    } else {
        Link::serial(&a.port)?
    };
    let csv = match &a.csv {
        Some(path) => {
            let mut w = std::io::BufWriter::new(
                std::fs::File::create(path)
                    .with_context(|| format!("cannot write {}", path.display()))?,
            );
            writeln!(w, "{CSV_HEADER}")?;
            Some(w)
        }
        None => None,
    };
    let mut p = Printer {
        json: a.json,
        csv,
        next_seq: None,
        dropped: 0,
        lost: 0,
        errors: 0,
        rejected: 0,
    };
    link.hello()?;
    until(&link, &mut p, timeout, "hello", |f| {
        matches!(f.kind, Kind::Hello { .. })
    })?;
    if a.commands.is_empty() {
        console(&mut link, &mut p)?;
    } else {
        let mut due = std::collections::BTreeSet::new();
        for (k, line) in a.commands.iter().enumerate() {
            due.insert(link.command(line)?);
            // After a `sim` line (QEMU) the next command goes at once: the image serves it
            // after the scene, as its script does, not a host's round trip later.
            if line.starts_with("sim ") && k + 1 < a.commands.len() {
                continue;
            }
            until(&link, &mut p, timeout, "reply", |f| {
                if let Kind::Reply { id, .. } = f.kind {
                    due.remove(&id);
                }
                due.is_empty()
            })?;
        }
    }
    if let Some(w) = p.csv.as_mut() {
        w.flush()?;
    }
    if p.dropped + p.lost + p.errors > 0 {
        eprintln!(
            "connect: {} messages dropped by the probe, {} lost on the line, {} bad frames",
            p.dropped, p.lost, p.errors
        );
    }
    if p.rejected > 0 {
        bail!("{} command(s) rejected", p.rejected);
    }
    Ok(())
}

/// The interactive console: lines from stdin as commands, everything from the probe printed as
/// it comes; ends at the end of input (after the replies still due) or when the probe closes.
fn console(link: &mut Link, p: &mut Printer) -> Result<()> {
    let (tx, rx) = std::sync::mpsc::channel::<Option<String>>();
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut line = String::new();
        loop {
            line.clear();
            match stdin.read_line(&mut line) {
                Ok(0) | Err(_) => break,
                Ok(_) => {
                    if tx.send(Some(line.trim().to_owned())).is_err() {
                        return;
                    }
                }
            }
        }
        let _ = tx.send(None);
    });
    let mut due = std::collections::BTreeSet::new();
    let mut input_open = true;
    loop {
        if input_open {
            while let Ok(l) = rx.try_recv() {
                match l {
                    Some(l) if l.is_empty() || l.starts_with('#') => {}
                    Some(l) if l == "quit" || l == "exit" => input_open = false,
                    Some(l) => match link.command(&l) {
                        Ok(id) => {
                            due.insert(id);
                        }
                        Err(e) => eprintln!("connect: {e}"),
                    },
                    None => input_open = false,
                }
            }
        } else if due.is_empty() {
            return Ok(());
        }
        match link.recv(Duration::from_millis(50)) {
            Some(Received::Frame(f)) => {
                if let Kind::Reply { id, .. } = f.kind {
                    due.remove(&id);
                }
                p.frame(&f)?;
            }
            Some(Received::Error(e)) => p.error(e),
            Some(Received::Closed) => bail!("the probe closed the line"),
            None => {}
        }
    }
}
