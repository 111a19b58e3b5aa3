//! Plots of sweeps.

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use pzt_probe::sweep::SweepPoint;
use std::path::Path;

/// Conductance and |Y| of a sweep against frequency, with the estimated resonance marked.
pub fn sweep_svg(
    path: &Path,
    title: &str,
    points: &[SweepPoint],
    resonance_hz: Option<f32>,
) -> Result<()> {
    if points.is_empty() {
        return Err(anyhow!("no points to plot"));
    }
    let f0 = points.first().map(|p| p.freq.0 as f64).unwrap_or(0.0);
    let f1 = points.last().map(|p| p.freq.0 as f64).unwrap_or(1.0);
    let ymax = points
        .iter()
        .map(|p| p.magnitude_s().max(p.g_s) as f64 * 1e9)
        .fold(0.0, f64::max)
        * 1.05;
    let ymin = points
        .iter()
        .map(|p| p.g_s as f64 * 1e9)
        .fold(0.0, f64::min);
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(f0..f1, ymin..ymax)
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc("drive frequency (Hz)")
        .y_desc("admittance (nS)")
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    let g: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.freq.0 as f64, p.g_s as f64 * 1e9))
        .collect();
    let m: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.freq.0 as f64, p.magnitude_s() as f64 * 1e9))
        .collect();
    chart
        .draw_series(LineSeries::new(g.clone(), &BLUE))
        .map_err(|e| anyhow!("{e}"))?
        .label("conductance G = Re(Y)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .draw_series(
            g.iter()
                .map(|&(x, y)| Circle::new((x, y), 2, BLUE.filled())),
        )
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .draw_series(LineSeries::new(m, &RED))
        .map_err(|e| anyhow!("{e}"))?
        .label("|Y| (1/|Z|)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    if let Some(fr) = resonance_hz {
        let fr = fr as f64;
        chart
            .draw_series(LineSeries::new(
                vec![(fr, ymin), (fr, ymax)],
                BLACK.stroke_width(1),
            ))
            .map_err(|e| anyhow!("{e}"))?
            .label(format!("estimate {fr:.3} Hz"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    root.present().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}
