//! `probe-bench stability`: methods × the scene catalogue, the stability map.

use super::progress;
use crate::plot::{draw_to, err, Area, Backend};
use crate::stability::{
    calibrated, classify, run_case, statement, stream_catalogue, tally, Must, Outcome, StreamCase,
    FIRST_SEED, STREAM_SETTLE_S,
};
use crate::stream::summarize;
use anyhow::{anyhow, Result};
use clap::Args;
use hal_sim::catalogue::catalogue;
use hal_sim::NoiseScene;
use plotters::prelude::*;
use pzt_probe::{Method, Reading};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Args)]
pub struct StabilityArgs {
    /// Readings (noise seeds) per method and scene.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// Calibration readings per phantom A–E for each method.
    #[arg(long, default_value_t = 10)]
    pub cal_repeats: usize,
    /// Readings (noise seeds) per scene for the statement on the default strategy `auto`.
    #[arg(long, default_value_t = 40)]
    pub auto_seeds: u64,
    /// Folder for stability.{csv,md,svg,png}.
    #[arg(long, default_value = "docs")]
    pub out_dir: PathBuf,
}

struct Cell {
    counts: [usize; 4],
    codes: Vec<&'static str>,
    /// The first code seen with each outcome.
    first_code: [Option<&'static str>; 4],
    worst_err_sigma: f64,
}

impl Cell {
    fn new() -> Self {
        Cell {
            counts: [0; 4],
            codes: Vec::new(),
            first_code: [None; 4],
            worst_err_sigma: 0.0,
        }
    }

    /// Count reading `r` with outcome `o` against the truth `truth` (kPa).
    fn add(&mut self, o: Outcome, r: &Reading, truth: Option<f64>) {
        self.counts[o as usize] += 1;
        self.first_code[o as usize].get_or_insert(r.status.code());
        if !self.codes.contains(&r.status.code()) {
            self.codes.push(r.status.code());
        }
        if let (Some(t), Some(e), Some(sg)) = (truth, r.modulus, r.modulus_sigma) {
            let z = (e.0 as f64 - t).abs() / (sg.0 as f64).max(1e-9);
            self.worst_err_sigma = self.worst_err_sigma.max(z);
        }
    }

    /// The map's label: the worst outcome's count of all and its first code (a silent wrong
    /// number: how many σ off the worst was).
    fn label(&self) -> String {
        let n: usize = self.counts.iter().sum();
        let worst = self.worst();
        if self.worst_err_sigma > 0.0 && worst == 3 {
            format!("{}/{} {:.1}σ", self.counts[worst], n, self.worst_err_sigma)
        } else {
            format!(
                "{}/{} {}",
                self.counts[worst],
                n,
                self.first_code[worst].unwrap_or("")
            )
        }
    }

    /// Index of the worst outcome seen (0 when none).
    fn worst(&self) -> usize {
        self.counts
            .iter()
            .enumerate()
            .rev()
            .find(|(_, k)| **k > 0)
            .map_or(0, |(i, _)| i)
    }
}

/// The CSV cells `outcome,status,modulus_kpa,modulus_sigma_kpa,truth_kpa` of reading `r` with
/// outcome `o` against the truth `truth` (kPa); empty cells for what is missing.
fn outcome_cells(o: Outcome, r: &Reading, truth: Option<f64>) -> String {
    format!(
        "{},{},{},{},{}",
        o.name(),
        r.status.code(),
        r.modulus.map_or(String::new(), |x| format!("{:.2}", x.0)),
        r.modulus_sigma
            .map_or(String::new(), |x| format!("{:.2}", x.0)),
        truth.map_or(String::new(), |x| format!("{x}"))
    )
}

/// Run the subcommand.
pub fn run(a: StabilityArgs) -> Result<()> {
    let cases = catalogue(NoiseScene::Bench);
    let pb = progress((Method::ALL.len() * cases.len()) as u64, "stability");
    let mut grid: Vec<Vec<Cell>> = Vec::new();
    let mut auto_unit = None;
    let mut stream_unit = None;
    let mut csv = String::from(
        "method,scene,seed,outcome,status,modulus_kpa,modulus_sigma_kpa,truth_kpa,t_s\n",
    );
    for m in Method::ALL {
        let unit = calibrated(m, a.cal_repeats)
            .ok_or_else(|| anyhow!("calibrating {} failed", m.name()))?;
        let mut row = Vec::new();
        for case in &cases {
            let mut cell = Cell::new();
            for seed in 0..a.seeds {
                let Some(r) = run_case(case, m, &unit, FIRST_SEED + seed) else {
                    continue;
                };
                let o = classify(case, &r);
                cell.add(o, &r, case.truth_kpa);
                let _ = writeln!(
                    csv,
                    "{},{},{},{},",
                    m.name(),
                    case.name,
                    seed,
                    outcome_cells(o, &r, case.truth_kpa)
                );
            }
            row.push(cell);
            pb.inc(1);
        }
        grid.push(row);
        if m == Method::Auto {
            auto_unit = Some(unit);
        } else if m == pzt_probe::instrument::continuous::METHOD {
            stream_unit = Some(unit);
        }
    }
    pb.finish_and_clear();
    // The continuous mode: the default tracker, with the unit of its method's column.
    let stream_unit =
        stream_unit.ok_or_else(|| anyhow!("the stream's method was not calibrated"))?;
    let stream_cases = stream_catalogue(NoiseScene::Bench);
    let mut streams: Vec<StreamRow> = Vec::new();
    for case in &stream_cases {
        let mut row = StreamRow {
            cell: Cell::new(),
            met: 0,
            checks: vec![Vec::new(); case.must.len()],
            rate: Vec::new(),
        };
        for seed in 0..a.seeds {
            let s = case.run(&stream_unit.profile, FIRST_SEED + seed)?;
            let v = case.judge(&s);
            row.met += v.met() as usize;
            for (k, c) in v.checks.iter().enumerate() {
                row.checks[k].push(*c);
            }
            let sum = summarize(&s.readings, &s.truth, STREAM_SETTLE_S);
            row.rate.push((sum.ok_per_s, sum.rms_rel, sum.worst_rel));
            for r in &s.readings {
                let o = case.classify(&s, r);
                let truth = s.truth.at(r.t_s.0 as f64);
                row.cell.add(o, &r.reading, truth);
                let _ = writeln!(
                    csv,
                    "stream,{},{},{},{:.4}",
                    case.name,
                    seed,
                    outcome_cells(o, &r.reading, truth),
                    r.t_s.0
                );
            }
        }
        streams.push(row);
    }
    std::fs::create_dir_all(&a.out_dir)?;
    std::fs::write(a.out_dir.join("stability.csv"), csv)?;
    let names: Vec<&str> = cases.iter().map(|c| c.name).collect();
    let stream_map: Vec<(String, &StreamRow, usize)> = stream_cases
        .iter()
        .zip(&streams)
        .map(|(c, r)| (format!("stream: {}", c.name), r, a.seeds as usize))
        .collect();
    for ext in ["svg", "png"] {
        let path = a.out_dir.join(format!("stability.{ext}"));
        draw_to!(
            &path,
            (
                190 + 150 * Method::ALL.len() as u32 + STREAM_W as u32 + 20,
                140 + 34 * (names.len() + stream_map.len()) as u32,
            ),
            |root| draw(root, &names, &grid, &stream_map)
        )?;
    }
    let mut total = [0usize; 4];
    let mut md = format!(
        "<!-- generated by `cargo run --release -p probe-bench -- stability` (bench noise, {} \
         seeds per cell, {} for the statement on auto) -->\n\n",
        a.seeds, a.auto_seeds
    );
    let _ = writeln!(
        md,
        "| scene | {} |",
        Method::ALL.map(|m| m.name()).join(" | ")
    );
    let _ = writeln!(md, "|---|{}", "---|".repeat(Method::ALL.len()));
    for (j, n) in names.iter().enumerate() {
        let cells: Vec<String> = grid.iter().map(|row| summary(&row[j])).collect();
        let _ = writeln!(md, "| {n} | {} |", cells.join(" | "));
        for row in &grid {
            for (t, c) in total.iter_mut().zip(row[j].counts) {
                *t += c;
            }
        }
    }
    let _ = writeln!(
        md,
        "\ntotal ({} readings, {} methods × {} scenes × {} seeds): {} correct readings, {} correct \
         failure codes, {} wrong failure codes, {} silent wrong numbers",
        total.iter().sum::<usize>(),
        Method::ALL.len(),
        names.len(),
        a.seeds,
        total[0],
        total[1],
        total[2],
        total[3]
    );
    // The default strategy over more seeds: the statement.
    let unit = auto_unit.ok_or_else(|| anyhow!("auto was not calibrated"))?;
    let t = tally(&cases, Method::Auto, &unit, a.auto_seeds);
    // Where auto loses readings (stderr: not part of the generated table).
    for case in &cases {
        let c = tally(
            std::slice::from_ref(case),
            Method::Auto,
            &unit,
            a.auto_seeds,
        );
        if c.wrong_failures > 0 {
            eprintln!(
                "auto lost {} of {} in {}",
                c.wrong_failures, c.readings, case.name
            );
        }
    }
    let _ = writeln!(
        md,
        "\nDefault strategy — {}",
        statement(Method::Auto, &t, cases.len(), a.auto_seeds)
    );
    md.push_str(&stream_section(&stream_cases, &streams, a.seeds));
    print!("{md}");
    std::fs::write(a.out_dir.join("stability.md"), md)?;
    Ok(())
}

/// Width of the stream column of the map, px.
const STREAM_W: i32 = 330;

/// One continuous scene over the seeds.
struct StreamRow {
    /// Its readings, classed as the single-reading map's.
    cell: Cell,
    /// Streams that did everything the scene asks.
    met: usize,
    /// Each [`Must`]'s (met, figure) per stream.
    checks: Vec<Vec<(bool, f64)>>,
    /// Per stream after the first 0.5 s: ok readings/s, RMS and worst relative error of the ok
    /// readings.
    rate: Vec<(f64, Option<f64>, Option<f64>)>,
}

/// "lo–hi" of `v` with `f`, or the one value.
fn span(v: impl Iterator<Item = f64>, f: impl Fn(f64) -> String) -> String {
    let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    if !lo.is_finite() && !hi.is_finite() {
        return "—".into();
    }
    let (a, b) = (f(lo), f(hi));
    if a == b {
        a
    } else {
        format!("{a}–{b}")
    }
}

/// The continuous mode's section of docs/stability.md.
fn stream_section(cases: &[StreamCase], rows: &[StreamRow], seeds: u64) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n### continuous mode (`probe-bench stream`)\n\n\
         The default tracker (`src/instrument/continuous/mod.rs`) with the unit of the hold column, noise seeds \
         {}–{}; every reading classed as above (an `ok` within 3 σ of the truth under the probe \
         at the start or the end of its probe time is correct; any other `ok` is a silent wrong \
         number; a failure code is correct during the acquisition (the first {STREAM_SETTLE_S} s), \
         where the scene accepts it, or while the stream may still be finding a new truth, a \
         lost reading elsewhere), and each stream checked against what it must do. Measured: \
         per requirement, over the seeds.\n",
        FIRST_SEED,
        FIRST_SEED + seeds.max(1) - 1
    );
    let _ = writeln!(
        md,
        "| scene | `probe-bench stream` | what the stream must do | streams doing it | readings: correct / correct code / wrong code / silent wrong | measured | codes |"
    );
    let _ = writeln!(md, "|---|---|---|---:|---|---|---|");
    let mut total = [0usize; 4];
    let (mut met, mut n) = (0, 0);
    for (case, row) in cases.iter().zip(rows) {
        let must: Vec<String> = case.must.iter().map(|m| m.describe()).collect();
        let measured: Vec<String> = case
            .must
            .iter()
            .zip(&row.checks)
            .map(|(m, c)| {
                let fig = c.iter().map(|x| x.1);
                match m {
                    Must::NoOk { .. } => format!("{} ok", span(fig, |x| format!("{x:.0}"))),
                    Must::Settle { .. } if c.iter().any(|x| x.1.is_infinite()) => {
                        "never within it in some streams".to_owned()
                    }
                    Must::Settle { at_s, .. } if *at_s == 0.0 => {
                        format!("within from {} s", span(fig, |x| format!("{x:.2}")))
                    }
                    Must::Settle { .. } => {
                        format!(
                            "within {} ms after",
                            span(fig, |x| format!("{:.0}", 1e3 * x))
                        )
                    }
                    Must::Code { .. } => {
                        format!("{} other codes", span(fig, |x| format!("{x:.0}")))
                    }
                    Must::Rate { .. } => format!(
                        "{} ok/s, RMS {} %, worst {} %",
                        span(row.rate.iter().map(|r| r.0), |x| format!("{x:.1}")),
                        span(row.rate.iter().filter_map(|r| r.1), |x| format!(
                            "{:.2}",
                            100.0 * x
                        )),
                        span(row.rate.iter().filter_map(|r| r.2), |x| format!(
                            "{:.2}",
                            100.0 * x
                        ))
                    ),
                }
            })
            .collect();
        let c = row.cell.counts;
        for (t, k) in total.iter_mut().zip(c) {
            *t += k;
        }
        met += row.met;
        n += seeds as usize;
        let _ = writeln!(
            md,
            "| {} | `{}` | {} | {}/{} | {} / {} / {} / {} | {} | {} |",
            case.name,
            case.args().join(" "),
            must.join("; "),
            row.met,
            seeds,
            c[0],
            c[1],
            c[2],
            c[3],
            measured.join("; "),
            row.cell.codes.join(", ")
        );
    }
    let _ = writeln!(
        md,
        "\ncontinuous mode ({} readings, {} scenes × {} seeds): {} correct readings, {} correct \
         failure codes, {} wrong failure codes, {} silent wrong numbers; {met} of {n} streams do \
         what their scene asks",
        total.iter().sum::<usize>(),
        cases.len(),
        seeds,
        total[0],
        total[1],
        total[2],
        total[3]
    );
    md
}

fn summary(c: &Cell) -> String {
    let n: usize = c.counts.iter().sum();
    let worst = c.worst();
    let label = ["ok", "fail ok", "WRONG CODE", "SILENT WRONG"][worst];
    format!("{label} {}/{n} ({})", c.counts[worst], c.codes.join(","))
}

fn draw<DB: Backend>(
    root: &Area<DB>,
    names: &[&str],
    grid: &[Vec<Cell>],
    stream: &[(String, &StreamRow, usize)],
) -> Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let colors = [
        RGBColor(90, 180, 90),
        RGBColor(150, 200, 240),
        RGBColor(250, 190, 60),
        RGBColor(220, 60, 60),
    ];
    let (x0, y0, w, h) = (170i32, 60i32, 150i32, 34i32);
    root.draw(&Text::new(
        "stability map: method × scene (bench noise; worst outcome of the readings, codes seen)",
        (10, 12),
        ("sans-serif", 18),
    ))
    .map_err(err)?;
    for (i, m) in Method::ALL.iter().enumerate() {
        root.draw(&Text::new(
            m.name(),
            (x0 + i as i32 * w + 8, y0 - 20),
            ("sans-serif", 15),
        ))
        .map_err(err)?;
    }
    for (j, n) in names.iter().enumerate() {
        let y = y0 + j as i32 * h;
        root.draw(&Text::new(*n, (8, y + 10), ("sans-serif", 14)))
            .map_err(err)?;
        for (i, row) in grid.iter().enumerate() {
            let c = &row[j];
            let worst = c.worst();
            let x = x0 + i as i32 * w;
            root.draw(&Rectangle::new(
                [(x, y), (x + w - 3, y + h - 3)],
                colors[worst].filled(),
            ))
            .map_err(err)?;
            root.draw(&Text::new(c.label(), (x + 5, y + 9), ("sans-serif", 12)))
                .map_err(err)?;
        }
    }
    // The continuous scenes: one row each, in a column of their own.
    let xs = x0 + Method::ALL.len() as i32 * w;
    root.draw(&Text::new("stream", (xs + 8, y0 - 20), ("sans-serif", 15)))
        .map_err(err)?;
    for (j, (name, row, seeds)) in stream.iter().enumerate() {
        let y = y0 + (names.len() + j) as i32 * h;
        root.draw(&Text::new(name.as_str(), (8, y + 10), ("sans-serif", 14)))
            .map_err(err)?;
        let c = &row.cell;
        let worst = c.worst();
        root.draw(&Rectangle::new(
            [(xs, y), (xs + STREAM_W - 3, y + h - 3)],
            colors[worst].filled(),
        ))
        .map_err(err)?;
        let label = format!("{}; {}/{} streams do it", c.label(), row.met, seeds);
        root.draw(&Text::new(label, (xs + 5, y + 9), ("sans-serif", 12)))
            .map_err(err)?;
    }
    let ly = y0 + (names.len() + stream.len()) as i32 * h + 12;
    for (k, (c, t)) in colors
        .iter()
        .zip([
            "correct reading",
            "correct failure code",
            "wrong failure code",
            "silent wrong number",
        ])
        .enumerate()
    {
        let x = x0 + k as i32 * 200;
        root.draw(&Rectangle::new([(x, ly), (x + 16, ly + 16)], c.filled()))
            .map_err(err)?;
        root.draw(&Text::new(t, (x + 22, ly + 2), ("sans-serif", 13)))
            .map_err(err)?;
    }
    Ok(())
}
