//! `probe-bench pareto`: the speed–accuracy chart of every method against the Cramér–Rao bound.

use super::progress;
use crate::pareto::{calibrate, configs, crb_pct, evaluate, tau_ms, Cell, Config};
use crate::plot::{with_backend, PALETTE};
use anyhow::{anyhow, Result};
use clap::Args;
use hal_sim::NoiseScene;
use plotters::prelude::*;
use pzt_probe::calibration::PowerLaw;
use pzt_probe::profile::UnitProfile;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Mutex;

/// Moduli of the study, kPa.
pub const MODULI: [f64; 5] = [150.0, 300.0, 500.0, 1000.0, 2500.0];

#[derive(Args)]
pub struct ParetoArgs {
    /// Readings per (method, knobs, modulus, noise).
    #[arg(long, default_value_t = 60)]
    pub seeds: usize,
    /// Calibration readings per phantom A–E (under each noise scene; the paper took 20).
    #[arg(long, default_value_t = 20)]
    pub cal_repeats: usize,
    /// Folder for speed-accuracy.{csv,md,svg,png} and speed-accuracy-paper.{svg,png}.
    #[arg(long, default_value = "docs")]
    pub out_dir: PathBuf,
    /// Focused run instead of the study: hold with these knobs, `burst,ring,refine,hold` in ms
    /// (repeatable), calibrated and read at `--moduli` (bench noise unless `--paper-noise`); prints
    /// one line each.
    #[arg(long)]
    pub hold_knobs: Vec<String>,
    /// Focused run: the default method (auto) at its default settings.
    #[arg(long)]
    pub auto: bool,
    /// Moduli of a focused run, kPa.
    #[arg(long, value_delimiter = ',', default_value = "500")]
    pub moduli: Vec<f64>,
    /// Focused run: in the paper's noise instead of the bench's.
    #[arg(long)]
    pub paper_noise: bool,
    /// Focused run: first seed of the readings (each modulus adds 10 000 per place).
    #[arg(long, default_value_t = 10_000)]
    pub seed0: u64,
}

/// `--hold-knobs`, `--auto`: one line per (config, modulus).
fn focused(a: &ParetoArgs) -> Result<()> {
    use pzt_probe::estimate::hold::HoldSettings;
    use pzt_probe::measure::{Method, Settings};
    use pzt_probe::Seconds;
    let mut cfgs = Vec::new();
    if a.auto {
        cfgs.push(Config::new(
            Method::Auto,
            "default".into(),
            Method::Auto.default_settings(),
        ));
    }
    for k in &a.hold_knobs {
        let v: Vec<f32> = k
            .split(',')
            .map(|x| x.trim().parse::<f32>())
            .collect::<Result<_, _>>()?;
        let [burst, ring, refine, hold] = v[..] else {
            return Err(anyhow!("--hold-knobs burst,ring,refine,hold (ms)"));
        };
        let s = HoldSettings {
            seed_burst: Seconds(burst / 1e3),
            seed_ring: Seconds(ring / 1e3),
            refine: Seconds(refine / 1e3),
            hold: Seconds(hold / 1e3),
            ..HoldSettings::DEFAULT
        };
        cfgs.push(Config::new(Method::Hold, k.clone(), Settings::Hold(s)));
    }
    let noise = if a.paper_noise {
        NoiseScene::Paper
    } else {
        NoiseScene::Bench
    };
    println!("config,modulus_kpa,ok,time_ms,time_tau,noise_rms_pct,rms_pct,sd_pct,repeat_pct,crb_pct,ratio");
    for c in &cfgs {
        let cal = calibrate(c, a.cal_repeats, noise).ok_or_else(|| anyhow!("calibration"))?;
        for (k, e) in a.moduli.iter().enumerate() {
            let cell = evaluate(c, &cal, *e, noise, a.seeds, a.seed0 * (k as u64 + 1));
            let crb = crb_pct(&cal.calibration, *e, noise, 5.0, cell.time_ms * 1e-3);
            println!(
                "{},{e},{}/{},{:.1},{:.2},{:.4},{:.4},{:.4},{:.4},{:.4},{:.2}",
                c.label,
                cell.ok,
                cell.n,
                cell.time_ms,
                cell.time_ms / tau_ms(*e),
                cell.noise_rms_pct(),
                cell.rms_pct(),
                cell.sd_pct(),
                cell.repeat_pct(),
                crb,
                cell.noise_rms_pct() / crb
            );
        }
    }
    Ok(())
}

struct Row {
    c: usize,
    noise: NoiseScene,
    e: f64,
    cell: Cell,
    crb: f64,
}

fn noise_label(n: NoiseScene) -> &'static str {
    match n {
        NoiseScene::Paper => "paper",
        NoiseScene::Bench => "bench",
        _ => "other",
    }
}

/// Run the subcommand.
pub fn run(a: ParetoArgs) -> Result<()> {
    if a.auto || !a.hold_knobs.is_empty() {
        return focused(&a);
    }
    let cfgs = configs();
    let noises = [NoiseScene::Bench, NoiseScene::Paper];
    let total = cfgs.len() * noises.len() * (1 + MODULI.len());
    let pb = progress(total as u64, "pareto");
    let rows = Mutex::new(Vec::new());
    let cals: Mutex<Vec<Option<UnitProfile>>> = Mutex::new(vec![None; cfgs.len()]);
    let next = Mutex::new(0usize);
    std::thread::scope(|s| {
        for _ in 0..std::thread::available_parallelism().map_or(2, |n| n.get()) {
            s.spawn(|| loop {
                let i = {
                    let mut n = next.lock().unwrap();
                    let i = *n;
                    *n += 1;
                    i
                };
                let Some(c) = cfgs.get(i) else { break };
                for noise in noises {
                    let cal = calibrate(c, a.cal_repeats, noise);
                    pb.inc(1);
                    if let Some(cal) = cal {
                        for (k, e) in MODULI.iter().enumerate() {
                            let seed0 = 10_000 * (k as u64 + 1);
                            let cell = evaluate(c, &cal, *e, noise, a.seeds, seed0);
                            let crb =
                                crb_pct(&cal.calibration, *e, noise, 5.0, cell.time_ms * 1e-3);
                            rows.lock().unwrap().push(Row {
                                c: i,
                                noise,
                                e: *e,
                                cell,
                                crb,
                            });
                            pb.inc(1);
                        }
                        if noise == NoiseScene::Bench {
                            cals.lock().unwrap()[i] = Some(cal);
                        }
                    } else {
                        pb.inc(MODULI.len() as u64);
                    }
                }
            });
        }
    });
    pb.finish_and_clear();
    let mut rows = rows.into_inner().unwrap();
    rows.sort_by(|x, y| {
        (x.c, noise_label(x.noise), x.e as u64).cmp(&(y.c, noise_label(y.noise), y.e as u64))
    });
    let cals = cals.into_inner().unwrap();
    std::fs::create_dir_all(&a.out_dir)?;
    write_csv(&a, &cfgs, &rows)?;
    for noise in noises {
        let suffix = if noise == NoiseScene::Bench {
            ""
        } else {
            "-paper"
        };
        for ext in ["svg", "png"] {
            let path = a.out_dir.join(format!("speed-accuracy{suffix}.{ext}"));
            chart(&path, &cfgs, &rows, &cals, noise)?;
        }
    }
    let md = summary(&cfgs, &rows, &cals);
    std::fs::write(a.out_dir.join("speed-accuracy.md"), &md)?;
    print!("{md}");
    Ok(())
}

fn write_csv(a: &ParetoArgs, cfgs: &[Config], rows: &[Row]) -> Result<()> {
    let mut s = String::from(
        "method,knobs,noise,modulus_kpa,readings,ok,probe_time_ms,tau_ms,rms_err_pct,bias_pct,sd_pct,reported_sigma_pct,reported_repeat_pct,within5,within10,within3sigma,crb_pct,noise_rms_pct,quiet_err_pct\n",
    );
    for r in rows {
        let c = &cfgs[r.c];
        let x = &r.cell;
        writeln!(
            s,
            "{},\"{}\",{},{},{},{},{:.2},{:.2},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{:.5},{:.4},{}",
            c.method.name(),
            c.label,
            noise_label(r.noise),
            r.e,
            x.n,
            x.ok,
            x.time_ms,
            tau_ms(r.e),
            x.rms_pct(),
            x.bias_pct(),
            x.sd_pct(),
            x.sigma_pct(),
            x.repeat_pct(),
            x.within5,
            x.within10,
            x.within3sigma,
            r.crb,
            x.noise_rms_pct(),
            x.quiet_err.map_or("".to_string(), |q| format!("{:.4}", 100.0 * q))
        )?;
    }
    std::fs::write(a.out_dir.join("speed-accuracy.csv"), s)?;
    Ok(())
}

/// Aggregate over moduli: (mean time ms, RMS noise-induced error %, ok fraction).
fn aggregate(rows: &[Row], c: usize, noise: NoiseScene) -> Option<(f64, f64, f64)> {
    let r: Vec<&Row> = rows
        .iter()
        .filter(|r| r.c == c && r.noise == noise)
        .collect();
    if r.is_empty() {
        return None;
    }
    let t = r.iter().map(|x| x.cell.time_ms).sum::<f64>() / r.len() as f64;
    let ok: usize = r.iter().map(|x| x.cell.ok).sum();
    let n: usize = r.iter().map(|x| x.cell.n).sum();
    let e2: f64 = r.iter().map(|x| x.cell.sum_dev2).sum();
    if ok == 0 {
        return Some((t, f64::NAN, 0.0));
    }
    Some((t, 100.0 * (e2 / ok as f64).sqrt(), ok as f64 / n as f64))
}

fn chart(
    path: &std::path::Path,
    cfgs: &[Config],
    rows: &[Row],
    cals: &[Option<UnitProfile>],
    noise: NoiseScene,
) -> Result<()> {
    let pts: Vec<(usize, f64, f64, f64)> = (0..cfgs.len())
        .filter_map(|c| aggregate(rows, c, noise).map(|(t, e, ok)| (c, t, e, ok)))
        .filter(|p| p.2.is_finite() && p.2 > 0.0)
        .collect();
    // Pareto front among configs with >= 95 % ok readings.
    let mut front: Vec<(f64, f64)> = Vec::new();
    let mut cand: Vec<&(usize, f64, f64, f64)> = pts.iter().filter(|p| p.3 >= 0.95).collect();
    cand.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut best = f64::INFINITY;
    for p in cand {
        if p.2 < best {
            best = p.2;
            front.push((p.1, p.2));
        }
    }
    // CRB line: RMS over moduli of the per-modulus bound, with a representative calibration.
    let cal = cals
        .iter()
        .flatten()
        .next()
        .map_or_else(PowerLaw::paper_experiment, |u| u.calibration);
    let crb: Vec<(f64, f64)> = (0..60)
        .map(|k| {
            let t = 10f64.powf(1.0 + 3.6 * k as f64 / 59.0);
            let v = MODULI
                .iter()
                .map(|e| crb_pct(&cal, *e, noise, 5.0, t * 1e-3).powi(2))
                .sum::<f64>()
                / MODULI.len() as f64;
            (t, v.sqrt())
        })
        .collect();
    let ymin = pts
        .iter()
        .map(|p| p.2)
        .chain(crb.iter().map(|c| c.1))
        .fold(f64::INFINITY, f64::min)
        .max(1e-4)
        / 2.0;
    let ymax = pts.iter().map(|p| p.2).fold(0.0, f64::max).max(1.0) * 2.0;
    let title = format!(
        "speed vs accuracy, {} noise scene (RMS over {} kPa)",
        noise_label(noise),
        MODULI
            .iter()
            .map(|e| format!("{e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    with_backend(
        path,
        (1000, 680),
        |root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>| {
            draw_chart(root, &title, cfgs, &pts, &front, &crb, ymin, ymax)
        },
        |root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>| {
            draw_chart(root, &title, cfgs, &pts, &front, &crb, ymin, ymax)
        },
    )
}

#[allow(clippy::too_many_arguments)]
fn draw_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    cfgs: &[Config],
    pts: &[(usize, f64, f64, f64)],
    front: &[(f64, f64)],
    crb: &[(f64, f64)],
    ymin: f64,
    ymax: f64,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{x}");
    root.fill(&WHITE).map_err(e)?;
    let mut ch = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 18))
        .margin(14)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d((10f64..50_000f64).log_scale(), (ymin..ymax).log_scale())
        .map_err(e)?;
    ch.configure_mesh()
        .x_desc("probe time per reading (ms)")
        .y_desc("RMS modulus error caused by noise (%)")
        .draw()
        .map_err(e)?;
    ch.draw_series(LineSeries::new(
        front.iter().copied(),
        ShapeStyle::from(&RGBColor(170, 170, 170)).stroke_width(8),
    ))
    .map_err(e)?
    .label("Pareto front")
    .legend(|(x, y)| {
        PathElement::new(
            vec![(x, y), (x + 20, y)],
            RGBColor(170, 170, 170).stroke_width(6),
        )
    });
    ch.draw_series(LineSeries::new(crb.iter().copied(), BLACK.stroke_width(2)))
        .map_err(e)?
        .label("Cramér–Rao bound")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    for (mi, m) in pzt_probe::Method::ALL.iter().enumerate() {
        let col = PALETTE[mi % PALETTE.len()];
        let mut p: Vec<&(usize, f64, f64, f64)> =
            pts.iter().filter(|p| cfgs[p.0].method == *m).collect();
        if p.is_empty() {
            continue;
        }
        p.sort_by(|a, b| a.1.total_cmp(&b.1));
        ch.draw_series(LineSeries::new(
            p.iter().map(|q| (q.1, q.2)),
            col.stroke_width(2),
        ))
        .map_err(e)?
        .label(m.name())
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        ch.draw_series(p.iter().map(|q| {
            let style = if q.3 >= 0.95 {
                col.filled()
            } else {
                col.stroke_width(1)
            };
            Circle::new((q.1, q.2), 4, style)
        }))
        .map_err(e)?;
    }
    ch.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    Ok(())
}

fn summary(cfgs: &[Config], rows: &[Row], cals: &[Option<UnitProfile>]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<!-- generated by `cargo run --release -p probe-bench -- pareto` -->"
    );
    for noise in [NoiseScene::Bench, NoiseScene::Paper] {
        let _ = writeln!(
            s,
            "\n### {} noise scene, 500 kPa (τ = {:.1} ms)\n",
            noise_label(noise),
            tau_ms(500.0)
        );
        let _ = writeln!(s, "| method | knobs | probe time (ms) | probe time (τ) | RMS error from noise (%) | RMS error vs truth (%) | noise-free error (%) | sd (%) | reported repeatability σ (%) | ok | CRB (%) | error / CRB |");
        let _ = writeln!(
            s,
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        for r in rows.iter().filter(|r| r.noise == noise && r.e == 500.0) {
            let c = &cfgs[r.c];
            let x = &r.cell;
            let _ = writeln!(
                s,
                "| {} | {} | {:.0} | {:.1} | {:.3} | {:.3} | {} | {:.3} | {:.3} | {}/{} | {:.4} | {:.1} |",
                c.method.name(),
                c.label,
                x.time_ms,
                x.time_ms / tau_ms(500.0),
                x.noise_rms_pct(),
                x.rms_pct(),
                x.quiet_err
                    .map_or("—".to_string(), |q| format!("{:+.3}", 100.0 * q)),
                x.sd_pct(),
                x.repeat_pct(),
                x.ok,
                x.n,
                r.crb,
                x.noise_rms_pct() / r.crb
            );
        }
        let _ = writeln!(
            s,
            "\n#### reliable moduli, {} noise (19 of 20 readings within ±5 % / ±10 % of the truth)\n",
            noise_label(noise)
        );
        let _ = writeln!(s, "| method | knobs | probe time at 500 kPa (ms) | reliable ±5 % (kPa) | reliable ±10 % (kPa) |");
        let _ = writeln!(s, "|---|---|---:|---|---|");
        for (i, c) in cfgs.iter().enumerate() {
            if cals[i].is_none() {
                continue;
            }
            let list = |thr: fn(&Cell) -> usize| {
                let v: Vec<String> = MODULI
                    .iter()
                    .filter(|e| {
                        rows.iter().any(|r| {
                            r.c == i
                                && r.noise == noise
                                && r.e == **e
                                && r.cell.n > 0
                                && thr(&r.cell) * 20 >= 19 * r.cell.n
                        })
                    })
                    .map(|e| format!("{e}"))
                    .collect();
                if v.is_empty() {
                    "none".to_string()
                } else {
                    v.join(", ")
                }
            };
            let t = rows
                .iter()
                .find(|r| r.c == i && r.noise == noise && r.e == 500.0)
                .map_or(0.0, |r| r.cell.time_ms);
            let _ = writeln!(
                s,
                "| {} | {} | {:.0} | {} | {} |",
                c.method.name(),
                c.label,
                t,
                list(|c| c.within5),
                list(|c| c.within10)
            );
        }
    }
    s.push_str(&honesty(cfgs, rows));
    s
}

/// Honest uncertainty: for every config, modulus and noise scene with at least 10 ok readings,
/// the ratio of the observed scatter (standard deviation of the readings) to the RMS reported
/// repeatability σ; per method at its default settings and over all knob settings.
fn honesty(cfgs: &[Config], rows: &[Row]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n### honest uncertainty: observed scatter / reported repeatability σ\n"
    );
    let _ = writeln!(
        s,
        "Every (modulus 150–2500 kPa, noise scene) cell with at least 10 ok readings; scatter = \
         standard deviation of the readings' errors; 1 is honest, the bar is 1/1.5 … 1.5. The \
         last column is the largest shift of a method's mean reading from its noise-free reading \
         in units of the reported σ (a bias that noise itself causes; calibration in the same \
         noise absorbs most of it).\n"
    );
    let _ = writeln!(
        s,
        "| method | default knobs: cells within the bar | default knobs: range | all knobs: cells within | all knobs: lowest (over-stated) | all knobs: highest (under-stated) | noise-induced shift / σ (max) |"
    );
    let _ = writeln!(s, "|---|---:|---|---:|---|---|---:|");
    let ok = |r: f64| (1.0 / 1.5..=1.5).contains(&r);
    for m in pzt_probe::Method::ALL {
        let cells: Vec<(&Row, f64)> = rows
            .iter()
            .filter(|r| cfgs[r.c].method == m && r.cell.ok >= 10 && r.cell.repeat_pct() > 0.0)
            .map(|r| (r, r.cell.sd_pct() / r.cell.repeat_pct()))
            .collect();
        if cells.is_empty() {
            continue;
        }
        let what = |(r, x): &(&Row, f64)| {
            format!(
                "{:.2} ({}, {} kPa, {})",
                x,
                cfgs[r.c].label,
                r.e,
                noise_label(r.noise)
            )
        };
        let defaults: Vec<&(&Row, f64)> = cells
            .iter()
            .filter(|(r, _)| cfgs[r.c].is_default())
            .collect();
        let (dlo, dhi) = defaults
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), (_, x)| {
                (lo.min(*x), hi.max(*x))
            });
        let lo = cells.iter().min_by(|a, b| a.1.total_cmp(&b.1));
        let hi = cells.iter().max_by(|a, b| a.1.total_cmp(&b.1));
        let shift = cells
            .iter()
            .map(|(r, _)| {
                let c = &r.cell;
                let d2 = (c.noise_rms_pct().powi(2) - c.sd_pct().powi(2)).max(0.0);
                d2.sqrt() / c.repeat_pct()
            })
            .fold(0.0f64, f64::max);
        let _ = writeln!(
            s,
            "| {} | {}/{} | {} | {}/{} | {} | {} | {:.1} |",
            m.name(),
            defaults.iter().filter(|(_, x)| ok(*x)).count(),
            defaults.len(),
            if defaults.is_empty() {
                "—".to_string()
            } else {
                format!("{dlo:.2} … {dhi:.2}")
            },
            cells.iter().filter(|(_, x)| ok(*x)).count(),
            cells.len(),
            lo.map_or(String::new(), what),
            hi.map_or(String::new(), what),
            shift
        );
    }
    s
}
