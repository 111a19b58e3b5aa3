//! `probe-bench stability`: methods × the scene catalogue, the stability map.

use super::progress;
use crate::plot::with_backend;
use crate::stability::{air_reference, calibrated, classify, run_case};
use anyhow::{anyhow, Result};
use clap::Args;
use hal_sim::catalogue::catalogue;
use hal_sim::NoiseScene;
use plotters::prelude::*;
use pzt_probe::Method;
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
    /// Folder for stability.{csv,svg,png}.
    #[arg(long, default_value = "docs")]
    pub out_dir: PathBuf,
}

struct Cell {
    counts: [usize; 4],
    codes: Vec<&'static str>,
    worst_err_sigma: f64,
}

/// Run the subcommand.
pub fn run(a: StabilityArgs) -> Result<()> {
    let cases = catalogue(NoiseScene::Bench);
    let air = air_reference().ok_or_else(|| anyhow!("the free-air reference reading failed"))?;
    let pb = progress((Method::ALL.len() * cases.len()) as u64, "stability");
    let mut grid: Vec<Vec<Cell>> = Vec::new();
    let mut csv =
        String::from("method,scene,seed,outcome,status,modulus_kpa,modulus_sigma_kpa,truth_kpa\n");
    for m in Method::ALL {
        let unit = calibrated(m, a.cal_repeats)
            .ok_or_else(|| anyhow!("calibrating {} failed", m.name()))?;
        let mut row = Vec::new();
        for case in &cases {
            let mut cell = Cell {
                counts: [0; 4],
                codes: Vec::new(),
                worst_err_sigma: 0.0,
            };
            for seed in 0..a.seeds {
                let Some(r) = run_case(case, m, &unit, Some(&air), 5000 + seed) else {
                    continue;
                };
                let o = classify(case, &r);
                cell.counts[o as usize] += 1;
                if !cell.codes.contains(&r.status.code()) {
                    cell.codes.push(r.status.code());
                }
                if let (Some(t), Some(e), Some(sg)) = (case.truth_kpa, r.modulus, r.modulus_sigma) {
                    let z = (e.0 as f64 - t).abs() / (sg.0 as f64).max(1e-9);
                    cell.worst_err_sigma = cell.worst_err_sigma.max(z);
                }
                let _ = writeln!(
                    csv,
                    "{},{},{},{},{},{},{},{}",
                    m.name(),
                    case.name,
                    seed,
                    o.name(),
                    r.status.code(),
                    r.modulus.map_or(String::new(), |x| format!("{:.2}", x.0)),
                    r.modulus_sigma
                        .map_or(String::new(), |x| format!("{:.2}", x.0)),
                    case.truth_kpa.map_or(String::new(), |x| format!("{x}"))
                );
            }
            row.push(cell);
            pb.inc(1);
        }
        grid.push(row);
    }
    pb.finish_and_clear();
    std::fs::create_dir_all(&a.out_dir)?;
    std::fs::write(a.out_dir.join("stability.csv"), csv)?;
    let names: Vec<&str> = cases.iter().map(|c| c.name).collect();
    for ext in ["svg", "png"] {
        let path = a.out_dir.join(format!("stability.{ext}"));
        with_backend(
            &path,
            (
                190 + 150 * Method::ALL.len() as u32,
                140 + 34 * names.len() as u32,
            ),
            |root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>| draw(root, &names, &grid),
            |root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>| {
                draw(root, &names, &grid)
            },
        )?;
    }
    let mut total = [0usize; 4];
    println!("| scene | {} |", Method::ALL.map(|m| m.name()).join(" | "));
    println!("|---|{}|", "---|".repeat(Method::ALL.len()));
    for (j, n) in names.iter().enumerate() {
        let cells: Vec<String> = grid.iter().map(|row| summary(&row[j])).collect();
        println!("| {n} | {} |", cells.join(" | "));
        for row in &grid {
            for (t, c) in total.iter_mut().zip(row[j].counts) {
                *t += c;
            }
        }
    }
    println!(
        "\ntotal: {} correct readings, {} correct failure codes, {} wrong failure codes, {} silent wrong numbers",
        total[0], total[1], total[2], total[3]
    );
    Ok(())
}

fn summary(c: &Cell) -> String {
    let n: usize = c.counts.iter().sum();
    let worst = c
        .counts
        .iter()
        .enumerate()
        .rev()
        .find(|(_, k)| **k > 0)
        .map_or(0, |(i, _)| i);
    let label = ["ok", "fail ok", "WRONG CODE", "SILENT WRONG"][worst];
    format!("{label} {}/{n} ({})", c.counts[worst], c.codes.join(","))
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    names: &[&str],
    grid: &[Vec<Cell>],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{x}");
    root.fill(&WHITE).map_err(e)?;
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
    .map_err(e)?;
    for (i, m) in Method::ALL.iter().enumerate() {
        root.draw(&Text::new(
            m.name(),
            (x0 + i as i32 * w + 8, y0 - 20),
            ("sans-serif", 15),
        ))
        .map_err(e)?;
    }
    for (j, n) in names.iter().enumerate() {
        let y = y0 + j as i32 * h;
        root.draw(&Text::new(*n, (8, y + 10), ("sans-serif", 14)))
            .map_err(e)?;
        for (i, row) in grid.iter().enumerate() {
            let c = &row[j];
            let worst = c
                .counts
                .iter()
                .enumerate()
                .rev()
                .find(|(_, k)| **k > 0)
                .map_or(0, |(i, _)| i);
            let x = x0 + i as i32 * w;
            root.draw(&Rectangle::new(
                [(x, y), (x + w - 3, y + h - 3)],
                colors[worst].filled(),
            ))
            .map_err(e)?;
            let n: usize = c.counts.iter().sum();
            let mut label = format!(
                "{}/{} {}",
                c.counts[worst],
                n,
                c.codes.first().copied().unwrap_or("")
            );
            if c.worst_err_sigma > 0.0 && worst == 3 {
                label = format!("{}/{} {:.0}σ", c.counts[worst], n, c.worst_err_sigma);
            }
            root.draw(&Text::new(label, (x + 5, y + 9), ("sans-serif", 12)))
                .map_err(e)?;
        }
    }
    let ly = y0 + names.len() as i32 * h + 12;
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
            .map_err(e)?;
        root.draw(&Text::new(t, (x + 22, ly + 2), ("sans-serif", 13)))
            .map_err(e)?;
    }
    Ok(())
}
