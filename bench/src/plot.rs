//! Plots of sweeps.

use anyhow::{anyhow, Result};
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use pzt_probe::engine::sweep::SweepPoint;
use std::path::Path;
use std::sync::Once;

/// Register the embedded DejaVu Sans as the `sans-serif` family, so PNG text renders the same on
/// every machine (no system fonts needed). Idempotent.
pub fn init_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let font = dejavu::sans::regular();
        for style in [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ] {
            // A failure leaves the family unregistered; text then fails to render with a clear
            // error from the plotting call.
            let _ = plotters::style::register_font("sans-serif", style, font);
        }
    });
}

/// The series colours of every chart, in order.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(200, 30, 30),
    RGBColor(30, 90, 200),
    RGBColor(20, 150, 60),
    RGBColor(150, 60, 180),
    RGBColor(230, 140, 0),
    RGBColor(0, 160, 170),
    RGBColor(120, 70, 20),
    RGBColor(90, 90, 90),
];

/// The span of `values` (non-finite ones ignored) widened by `pad` of its width on each side;
/// ±1 about a single value; `empty` without any.
pub fn padded_range(values: impl Iterator<Item = f64>, pad: f64, empty: (f64, f64)) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if hi > lo {
        let w = pad * (hi - lo);
        (lo - w, hi + w)
    } else if lo.is_finite() {
        (lo - 1.0, lo + 1.0)
    } else {
        empty
    }
}

/// A drawing error of plotters as an error of ours, with its message.
pub fn err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("{e}")
}

/// Draw the legend of `chart` at `position` on a white box of `opacity`, bordered in black.
pub fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    opacity: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(opacity))
        .border_style(BLACK)
        .draw()
}

/// The margin round a chart and the sizes of its label areas, px.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// Margin on every side.
    pub margin: u32,
    /// Height of the x axis' label area.
    pub x_labels: u32,
    /// Width of the y axis' label area.
    pub y_labels: u32,
}

/// A cartesian chart of `x` × `y` on `root`, as [`chart`] makes it.
pub type Chart<'a, DB, X, Y> = ChartContext<
    'a,
    DB,
    Cartesian2d<<X as AsRangedCoord>::CoordDescType, <Y as AsRangedCoord>::CoordDescType>,
>;

/// A cartesian chart of `x` × `y` on `root` in `frame`, under `caption` (its text and its
/// sans-serif size, px) when there is one, with the mesh drawn and the axes described
/// `x_desc` and `y_desc`.
pub fn chart<'a, DB, X, Y>(
    root: &'a DrawingArea<DB, Shift>,
    caption: Option<(&str, u32)>,
    frame: Frame,
    (x, y): (X, Y),
    (x_desc, y_desc): (&str, &str),
) -> Result<Chart<'a, DB, X, Y>, DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    X: AsRangedCoord,
    Y: AsRangedCoord,
    X::CoordDescType: ValueFormatter<<X::CoordDescType as Ranged>::ValueType>,
    Y::CoordDescType: ValueFormatter<<Y::CoordDescType as Ranged>::ValueType>,
{
    let mut builder = ChartBuilder::on(root);
    if let Some((text, px)) = caption {
        builder.caption(text, ("sans-serif", px));
    }
    let mut chart = builder
        .margin(frame.margin)
        .x_label_area_size(frame.x_labels)
        .y_label_area_size(frame.y_labels)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

/// Draw `points` on `chart` as a line in `style`, shown in the legend as `label` by a 20 px
/// stroke of the same style.
pub fn line<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    points: impl IntoIterator<Item = CT::From>,
    style: impl Into<ShapeStyle>,
    label: impl Into<String>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
    CT::From: Clone + 'static,
{
    let style = style.into();
    chart
        .draw_series(LineSeries::new(points, style))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
    Ok(())
}

/// A backend a chart draws onto (SVG or bitmap): a [`DrawingBackend`] whose errors are
/// `'static`, so that they convert into [`anyhow::Error`].
pub trait Backend: DrawingBackend<ErrorType: 'static> {}

impl<DB: DrawingBackend<ErrorType: 'static>> Backend for DB {}

/// The whole drawing area of a figure on backend `DB`.
pub type Area<DB> = DrawingArea<DB, Shift>;

/// [`with_backend`] with one drawing for both backends: `draw_to!(path, size, |root| draw(root,
/// ...))`, where `draw` is generic over the [`Backend`].
macro_rules! draw_to {
    ($path:expr, $size:expr, |$root:ident| $draw:expr $(,)?) => {
        $crate::plot::with_backend($path, $size, |$root| $draw, |$root| $draw)
    };
}
pub(crate) use draw_to;

/// Draw onto an SVG or a PNG file chosen by the extension of `path` (`.png` → PNG).
pub fn with_backend(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend, plotters::coord::Shift>) -> Result<()>,
    draw_png: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    init_fonts();
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if png {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        draw_png(&root)?;
        root.present()
            .map_err(|e| anyhow!("{}: {e}", path.display()))
    } else {
        let root = SVGBackend::new(path, size).into_drawing_area();
        draw(&root)?;
        root.present()
            .map_err(|e| anyhow!("{}: {e}", path.display()))
    }
}

/// Conductance and |Y| of a sweep against frequency, with the estimated resonance marked
/// (SVG, or PNG when `path` ends in `.png`).
pub fn sweep_svg(
    path: &Path,
    title: &str,
    points: &[SweepPoint],
    resonance_hz: Option<f32>,
) -> Result<()> {
    if points.is_empty() {
        return Err(anyhow!("no points to plot"));
    }
    draw_to!(path, (900, 560), |root| draw_sweep(
        root,
        title,
        points,
        resonance_hz
    ))
}

fn draw_sweep<DB: Backend>(
    root: &Area<DB>,
    title: &str,
    points: &[SweepPoint],
    resonance_hz: Option<f32>,
) -> Result<()> {
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
    root.fill(&WHITE).map_err(err)?;
    let frame = Frame {
        margin: 12,
        x_labels: 45,
        y_labels: 70,
    };
    let mut chart = self::chart(
        root,
        Some((title, 20)),
        frame,
        (f0..f1, ymin..ymax),
        ("drive frequency (Hz)", "admittance (nS)"),
    )
    .map_err(err)?;
    let g: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.freq.0 as f64, p.g_s as f64 * 1e9))
        .collect();
    let m: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.freq.0 as f64, p.magnitude_s() as f64 * 1e9))
        .collect();
    line(&mut chart, g.clone(), &BLUE, "conductance G = Re(Y)").map_err(err)?;
    chart
        .draw_series(
            g.iter()
                .map(|&(x, y)| Circle::new((x, y), 2, BLUE.filled())),
        )
        .map_err(err)?;
    line(&mut chart, m, &RED, "|Y| (1/|Z|)").map_err(err)?;
    if let Some(fr) = resonance_hz {
        let fr = fr as f64;
        chart
            .draw_series(LineSeries::new(
                vec![(fr, ymin), (fr, ymax)],
                BLACK.stroke_width(1),
            ))
            .map_err(err)?
            .label(format!("estimate {fr:.3} Hz"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    }
    draw_legend(&mut chart, SeriesLabelPosition::MiddleRight, 0.8).map_err(err)?;
    Ok(())
}
