//! Bench captures in CSV, turned into the firmware's [`SweepPoint`]s.
//!
//! The bench's own CSV layouts (the header row names the layout; column order is free):
//!
//! | layout | columns | from |
//! |---|---|---|
//! | impedance | `freq_hz,z_mag_ohm,z_phase_deg` | an impedance analyser |
//! | admittance | `freq_hz,y_re_s,y_im_s` | an impedance analyser |
//! | time domain | `t_s,drive_hz,v_drive_v,i_sense_a` | a DAQ recording a stepped or continuous sweep |
//!
//! Lines whose first non-blank character is `#` are comments; blank lines are skipped; the first
//! other line is the header. Every malformed input is a [`CaptureError`] carrying the 1-based
//! line number of the offending line.
//!
//! Impedance analysers' own exports are read too, recognised from their content: the HP/Agilent
//! 4294A ASCII data file and the Keysight E4990A trace-data CSV (module [`export`], which names
//! the manual sections it follows). They become admittance points like the bench's own
//! frequency-domain layouts.
//!
//! # Uncertainty of frequency-domain points
//!
//! Analyser exports carry no per-point uncertainty, and the estimators need one. It is estimated
//! from the data: a cubic polynomial in frequency is fitted by least squares to `G` and to `B`
//! over every run of [`NOISE_WINDOW`] consecutive points (sliding by one point), and the pooled
//! residual variance `σ² = Σ RSS / Σ (n − 4)` over both components and all windows is the noise
//! variance of each component. The assumption is **white noise of the same size at every point**
//! (an analyser at a fixed drive level and bandwidth). Where the curve bends faster than a cubic
//! follows over seven points (a coarse sweep of a sharp peak), the misfit enters `σ`: the
//! uncertainty errs large, never small. It is floored at [`SIGMA_FLOOR_REL`] of the largest `|Y|`
//! (single-precision resolution of the firmware's points).
//!
//! # Demodulation of time-domain captures
//!
//! The sample rate is `1/Δt` of the `t_s` column, which must be uniform within
//! [`DT_TOLERANCE`] (of the median step). The record is split into points:
//!
//! * **stepped** sweeps (runs of constant `drive_hz` lasting at least [`MIN_STEP_CYCLES`] cycles):
//!   each run is one point; its first part is discarded as settling (`settle_s`, default half the
//!   run) and the last whole number of drive cycles of the rest is fitted;
//! * **continuous** sweeps (`drive_hz` changing every few samples): the drive phase
//!   `φ(t) = 2π ∫ f dt` is integrated from the recorded frequency and the record is cut into
//!   windows of `cycles_per_window` whole cycles; the point's frequency is the window's mean
//!   `drive_hz`. The resonator lags a moving drive, so a fast sweep biases the resonance by about
//!   the sweep rate times the decay time `Q / (π f)`.
//!
//! In each window **both** the recorded drive voltage and the sense current are fitted with the
//! same reference, `x(t) = a cos φ + b sin φ + c`, by least squares, and the admittance is the
//! ratio of the two phasors, `Y = I / V`, so any amplitude or phase error of the drive cancels
//! (the drive is never assumed ideal). The uncertainty of each phasor component is
//! `σ_res² · (XᵀX)⁻¹` of the fit (its residual variance), and
//! `σ_Y² = (σ_I² + |Y|² σ_V²) / |V|²`, the same propagation as the firmware's integer lock-in.
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > y)` also rejects NaN, deliberately

use pzt_probe::engine::sweep::SweepPoint;
use pzt_probe::linalg::{damped_solve, Lsq3};
use pzt_probe::Hz;
use std::f64::consts::PI;
use std::fmt;

mod export;

/// Points per local cubic fit of the frequency-domain noise estimate.
pub const NOISE_WINDOW: usize = 7;
/// Fewest frequency-domain points the noise estimate needs.
pub const MIN_POINTS_FOR_NOISE: usize = NOISE_WINDOW;
/// Floor of the per-point uncertainty, relative to the largest `|Y|` of the capture.
pub const SIGMA_FLOOR_REL: f64 = 1e-6;
/// Largest relative deviation of a time step from the mean step.
pub const DT_TOLERANCE: f64 = 0.02;
/// Least samples per drive cycle: the drive must stay below 0.4 of the sample rate, as in the
/// firmware (anti-alias band).
pub const MIN_SAMPLES_PER_CYCLE: f64 = 2.5;
/// Least duration, in drive cycles, of a run of constant `drive_hz` for the capture to count as
/// a stepped sweep.
pub const MIN_STEP_CYCLES: f64 = 4.0;
/// Default cycles per demodulation window of a continuous sweep.
pub const DEFAULT_CYCLES_PER_WINDOW: usize = 4;

/// The layout of a capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// `freq_hz,z_mag_ohm,z_phase_deg`.
    Impedance,
    /// `freq_hz,y_re_s,y_im_s`.
    Admittance,
    /// `t_s,drive_hz,v_drive_v,i_sense_a`.
    TimeDomain,
    /// An HP/Agilent 4294A ASCII data file (`"TRACE: A"` blocks).
    Hp4294a,
    /// A Keysight E4990A trace-data CSV (`BEGIN CH1_DATA`, `Frequency(Hz), …`).
    E4990a,
}

impl Layout {
    /// The column names of this layout.
    pub const fn columns(self) -> &'static [&'static str] {
        match self {
            Layout::Impedance => &["freq_hz", "z_mag_ohm", "z_phase_deg"],
            Layout::Admittance => &["freq_hz", "y_re_s", "y_im_s"],
            Layout::TimeDomain => &["t_s", "drive_hz", "v_drive_v", "i_sense_a"],
            Layout::Hp4294a => &["Frequency", "Data Trace Real", "Data Trace Imag"],
            Layout::E4990a => &["Frequency(Hz)", "|Z|(Ohm)-data", "theta-z(deg)-data"],
        }
    }
    /// Short name.
    pub const fn name(self) -> &'static str {
        match self {
            Layout::Impedance => "impedance",
            Layout::Admittance => "admittance",
            Layout::TimeDomain => "time-domain",
            Layout::Hp4294a => "4294a-ascii",
            Layout::E4990a => "e4990a-csv",
        }
    }
    /// True for an analyser's own export (not one of the bench's CSV layouts).
    pub const fn is_instrument_export(self) -> bool {
        matches!(self, Layout::Hp4294a | Layout::E4990a)
    }
}

/// Why a capture could not be read. Every variant carries the 1-based line number it refers to.
#[derive(Clone, Debug, PartialEq)]
pub enum CaptureError {
    /// No header row (the file is empty or all comments).
    NoHeader {
        /// Last line of the file.
        line: usize,
    },
    /// A column the layout needs is absent from the header.
    MissingColumn {
        /// Header line.
        line: usize,
        /// The absent column.
        column: &'static str,
        /// The layout the header was taken for.
        layout: Layout,
    },
    /// A header column that no layout (or not this one) has.
    UnknownColumn {
        /// Header line.
        line: usize,
        /// The column as written.
        column: String,
    },
    /// A column named twice in the header.
    DuplicateColumn {
        /// Header line.
        line: usize,
        /// The column.
        column: String,
    },
    /// A data row with the wrong number of cells.
    CellCount {
        /// The row.
        line: usize,
        /// Cells the header names.
        expected: usize,
        /// Cells found.
        found: usize,
    },
    /// A cell that is not a number.
    NotNumeric {
        /// The row.
        line: usize,
        /// Its column.
        column: String,
        /// The cell as written.
        cell: String,
    },
    /// A cell that is NaN or infinite.
    NotFinite {
        /// The row.
        line: usize,
        /// Its column.
        column: String,
    },
    /// A frequency, time or magnitude that must be positive is not.
    NotPositive {
        /// The row.
        line: usize,
        /// Its column.
        column: &'static str,
    },
    /// Frequency (or time) does not increase from the previous row.
    NotIncreasing {
        /// The row.
        line: usize,
        /// `freq_hz` or `t_s`.
        column: &'static str,
        /// Its value.
        value: f64,
        /// The previous row's value.
        previous: f64,
    },
    /// Fewer points than the analysis needs.
    TooFewPoints {
        /// Last line read.
        line: usize,
        /// Points available.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// The time step departs from the median step by more than [`DT_TOLERANCE`].
    NonUniformSampling {
        /// The row whose step is off.
        line: usize,
        /// Its step, s.
        dt_s: f64,
        /// The typical (median) step, s.
        typical_dt_s: f64,
    },
    /// The drive frequency is too high for the sample rate.
    TooCoarse {
        /// The row.
        line: usize,
        /// Drive frequency, Hz.
        drive_hz: f64,
        /// Sample rate, Hz.
        sample_rate_hz: f64,
    },
    /// A demodulation window in which the drive voltage does not stand out of its own noise.
    NoDrive {
        /// First row of the window.
        line: usize,
    },
    /// An analyser's export that cannot be read or does not hold together.
    Export {
        /// The line the problem is on (the last line for a truncated file).
        line: usize,
        /// The export format ([`Layout::name`]).
        format: &'static str,
        /// What is wrong, in one line.
        reason: String,
    },
}

impl CaptureError {
    /// The line the error refers to.
    pub fn line(&self) -> usize {
        match self {
            CaptureError::NoHeader { line }
            | CaptureError::MissingColumn { line, .. }
            | CaptureError::UnknownColumn { line, .. }
            | CaptureError::DuplicateColumn { line, .. }
            | CaptureError::CellCount { line, .. }
            | CaptureError::NotNumeric { line, .. }
            | CaptureError::NotFinite { line, .. }
            | CaptureError::NotPositive { line, .. }
            | CaptureError::NotIncreasing { line, .. }
            | CaptureError::TooFewPoints { line, .. }
            | CaptureError::NonUniformSampling { line, .. }
            | CaptureError::TooCoarse { line, .. }
            | CaptureError::NoDrive { line }
            | CaptureError::Export { line, .. } => *line,
        }
    }

    /// Stable snake_case name of the kind of error.
    pub fn kind(&self) -> &'static str {
        match self {
            CaptureError::NoHeader { .. } => "no_header",
            CaptureError::MissingColumn { .. } => "missing_column",
            CaptureError::UnknownColumn { .. } => "unknown_column",
            CaptureError::DuplicateColumn { .. } => "duplicate_column",
            CaptureError::CellCount { .. } => "cell_count",
            CaptureError::NotNumeric { .. } => "not_numeric",
            CaptureError::NotFinite { .. } => "not_finite",
            CaptureError::NotPositive { .. } => "not_positive",
            CaptureError::NotIncreasing { .. } => "not_increasing",
            CaptureError::TooFewPoints { .. } => "too_few_points",
            CaptureError::NonUniformSampling { .. } => "non_uniform_sampling",
            CaptureError::TooCoarse { .. } => "too_coarse",
            CaptureError::NoDrive { .. } => "no_drive",
            CaptureError::Export { .. } => "bad_export",
        }
    }
}

impl fmt::Display for CaptureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: ", self.line())?;
        match self {
            CaptureError::NoHeader { .. } => write!(
                f,
                "no header row (expected one of: {}; {}; {})",
                Layout::Impedance.columns().join(","),
                Layout::Admittance.columns().join(","),
                Layout::TimeDomain.columns().join(",")
            ),
            CaptureError::MissingColumn { column, layout, .. } => write!(
                f,
                "missing column `{column}` (a {} capture has {})",
                layout.name(),
                layout.columns().join(",")
            ),
            CaptureError::UnknownColumn { column, .. } => write!(
                f,
                "unknown column `{column}` (expected one of: {}; {}; {})",
                Layout::Impedance.columns().join(","),
                Layout::Admittance.columns().join(","),
                Layout::TimeDomain.columns().join(",")
            ),
            CaptureError::DuplicateColumn { column, .. } => {
                write!(f, "column `{column}` appears twice in the header")
            }
            CaptureError::CellCount {
                expected, found, ..
            } => write!(f, "expected {expected} cells, found {found}"),
            CaptureError::NotNumeric { column, cell, .. } => {
                write!(f, "`{cell}` in column `{column}` is not a number")
            }
            CaptureError::NotFinite { column, .. } => {
                write!(f, "column `{column}` is NaN or infinite")
            }
            CaptureError::NotPositive { column, .. } => {
                write!(f, "column `{column}` must be above zero")
            }
            CaptureError::NotIncreasing {
                column,
                value,
                previous,
                ..
            } => write!(
                f,
                "`{column}` must increase from row to row ({value} after {previous})"
            ),
            CaptureError::TooFewPoints { found, needed, .. } => write!(
                f,
                "{found} points, the analysis needs at least {needed}"
            ),
            CaptureError::NonUniformSampling {
                dt_s, typical_dt_s, ..
            } => write!(
                f,
                "non-uniform sampling: step {dt_s:.6e} s against a typical step of {typical_dt_s:.6e} s (tolerance {} %)",
                DT_TOLERANCE * 100.0
            ),
            CaptureError::TooCoarse {
                drive_hz,
                sample_rate_hz,
                ..
            } => write!(
                f,
                "sampling too coarse: drive {drive_hz} Hz needs at least {MIN_SAMPLES_PER_CYCLE} samples a cycle, the sample rate is {sample_rate_hz:.1} Hz"
            ),
            CaptureError::NoDrive { .. } => write!(
                f,
                "no drive voltage in the demodulation window starting here"
            ),
            CaptureError::Export { format, reason, .. } => write!(f, "{format} export: {reason}"),
        }
    }
}

impl std::error::Error for CaptureError {}

/// Options of the time-domain demodulator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemodOptions {
    /// Settling time discarded at the start of each step of a stepped sweep, s (`None`: half of
    /// each step).
    pub settle_s: Option<f64>,
    /// Whole drive cycles per window of a continuous sweep.
    pub cycles_per_window: usize,
}

impl Default for DemodOptions {
    fn default() -> Self {
        Self {
            settle_s: None,
            cycles_per_window: DEFAULT_CYCLES_PER_WINDOW,
        }
    }
}

/// How a time-domain capture was split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepShape {
    /// Runs of constant drive frequency.
    Stepped,
    /// A continuously changing drive frequency.
    Continuous,
}

/// How a time-domain capture was sampled and split into points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeDomain {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Stepped or continuous.
    pub shape: SweepShape,
    /// Steps skipped as shorter than two cycles after settling.
    pub skipped_steps: usize,
}

/// What a capture's domain tells beside its points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    /// A frequency-domain capture.
    Frequency {
        /// Per-component noise estimated from local cubic fits, S.
        noise_sigma_s: f64,
    },
    /// A time-domain capture.
    Time(TimeDomain),
}

impl Domain {
    /// Per-component noise of a frequency-domain capture, S.
    pub fn noise_sigma_s(&self) -> Option<f64> {
        match self {
            Domain::Frequency { noise_sigma_s } => Some(*noise_sigma_s),
            Domain::Time(_) => None,
        }
    }
    /// How a time-domain capture was sampled and split.
    pub fn time(&self) -> Option<TimeDomain> {
        match self {
            Domain::Frequency { .. } => None,
            Domain::Time(t) => Some(*t),
        }
    }
}

/// A capture turned into admittance points.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    /// Its layout.
    pub layout: Layout,
    /// One point per frequency (frequency-domain) or per demodulation window (time domain).
    pub points: Vec<SweepPoint>,
    /// What its domain tells beside the points.
    pub domain: Domain,
    /// Data rows read.
    pub rows: usize,
    /// For an analyser's export: which traces and columns were read, for humans.
    pub source: Option<String>,
}

/// One parsed data row.
struct Row {
    line: usize,
    v: Vec<f64>,
}

/// Read a capture from CSV text. `needed` is the fewest points the estimator needs.
pub fn parse(text: &str, needed: usize, opts: &DemodOptions) -> Result<Capture, CaptureError> {
    match export::detect(text) {
        Some(Layout::Hp4294a) => {
            let r = export::read_4294a(text)?;
            return frequency_capture(Layout::Hp4294a, r.rows, r.last_line, needed, Some(r.read));
        }
        Some(Layout::E4990a) => {
            let r = export::read_e4990a(text)?;
            return frequency_capture(Layout::E4990a, r.rows, r.last_line, needed, Some(r.read));
        }
        _ => {}
    }
    let (layout, cols, rows, last_line) = read_table(text)?;
    let pick = |r: &Row, name: &str| -> f64 {
        let k = cols.iter().position(|c| c == name).unwrap_or(0);
        r.v[k]
    };
    match layout {
        Layout::TimeDomain => {
            let t: Vec<f64> = rows.iter().map(|r| pick(r, "t_s")).collect();
            let f: Vec<f64> = rows.iter().map(|r| pick(r, "drive_hz")).collect();
            let v: Vec<f64> = rows.iter().map(|r| pick(r, "v_drive_v")).collect();
            let i: Vec<f64> = rows.iter().map(|r| pick(r, "i_sense_a")).collect();
            let lines: Vec<usize> = rows.iter().map(|r| r.line).collect();
            demodulate(&Samples { t, f, v, i, lines }, last_line, needed, opts).map(|mut c| {
                c.rows = rows.len();
                c
            })
        }
        _ => {
            let mut fy = Vec::with_capacity(rows.len());
            for r in &rows {
                let f = pick(r, "freq_hz");
                let (g, b) = if layout == Layout::Impedance {
                    let m = pick(r, "z_mag_ohm");
                    if !(m > 0.0) {
                        return Err(CaptureError::NotPositive {
                            line: r.line,
                            column: "z_mag_ohm",
                        });
                    }
                    let ph = pick(r, "z_phase_deg").to_radians();
                    // Y = 1/Z = e^{-j phase} / |Z|.
                    (ph.cos() / m, -ph.sin() / m)
                } else {
                    (pick(r, "y_re_s"), pick(r, "y_im_s"))
                };
                fy.push((r.line, f, g, b));
            }
            frequency_capture(layout, fy, last_line, needed, None)
        }
    }
}

/// A frequency-domain capture from admittance rows `(line, f, G, B)`: frequencies above zero
/// and increasing, at least `needed` (and [`MIN_POINTS_FOR_NOISE`]) points, the noise estimated
/// from the data (module docs).
fn frequency_capture(
    layout: Layout,
    rows: Vec<(usize, f64, f64, f64)>,
    last_line: usize,
    needed: usize,
    source: Option<String>,
) -> Result<Capture, CaptureError> {
    let needed = needed.max(MIN_POINTS_FOR_NOISE);
    let mut prev: Option<f64> = None;
    let mut fy = Vec::with_capacity(rows.len());
    for &(line, f, g, b) in &rows {
        if !(f > 0.0) {
            return Err(CaptureError::NotPositive {
                line,
                column: "freq_hz",
            });
        }
        if let Some(p) = prev {
            if !(f > p) {
                return Err(CaptureError::NotIncreasing {
                    line,
                    column: "freq_hz",
                    value: f,
                    previous: p,
                });
            }
        }
        if !(g.is_finite() && b.is_finite()) {
            return Err(CaptureError::NotFinite {
                line,
                column: "admittance".into(),
            });
        }
        prev = Some(f);
        fy.push((f, g, b));
    }
    if fy.len() < needed {
        return Err(CaptureError::TooFewPoints {
            line: last_line,
            found: fy.len(),
            needed,
        });
    }
    let sigma = noise_sigma(&fy);
    let points = fy
        .iter()
        .map(|&(f, g, b)| SweepPoint {
            freq: Hz(f as f32),
            g_s: g as f32,
            b_s: b as f32,
            sigma_s: sigma as f32,
            // Unknown drive: the point as if driven at 1 V.
            current_a: g.hypot(b) as f32,
            drive_v: 1.0,
            clip_fraction: 0.0,
            residual_a: sigma as f32,
        })
        .collect();
    Ok(Capture {
        layout,
        points,
        domain: Domain::Frequency {
            noise_sigma_s: sigma,
        },
        rows: rows.len(),
        source,
    })
}

/// Read a capture file.
pub fn load(path: &std::path::Path, needed: usize, opts: &DemodOptions) -> anyhow::Result<Capture> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
    parse(&text, needed, opts).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Header and numeric rows of the table, validated cell by cell.
fn read_table(text: &str) -> Result<(Layout, Vec<String>, Vec<Row>, usize), CaptureError> {
    let mut header: Option<(usize, Vec<String>, Layout)> = None;
    let mut rows = Vec::new();
    for (line, s) in content_lines(text, Some('#')) {
        let cells: Vec<&str> = s.split(',').map(str::trim).collect();
        match &header {
            None => {
                let cols: Vec<String> = cells.iter().map(|c| c.to_ascii_lowercase()).collect();
                let layout = header_layout(line, &cols)?;
                header = Some((line, cols, layout));
            }
            Some((_, cols, _)) => {
                if cells.len() != cols.len() {
                    return Err(CaptureError::CellCount {
                        line,
                        expected: cols.len(),
                        found: cells.len(),
                    });
                }
                let mut v = Vec::with_capacity(cells.len());
                for (cell, col) in cells.iter().zip(cols) {
                    let x: f64 = cell.parse().map_err(|_| CaptureError::NotNumeric {
                        line,
                        column: col.clone(),
                        cell: (*cell).to_owned(),
                    })?;
                    if !x.is_finite() {
                        return Err(CaptureError::NotFinite {
                            line,
                            column: col.clone(),
                        });
                    }
                    v.push(x);
                }
                rows.push(Row { line, v });
            }
        }
    }
    match header {
        None => Err(CaptureError::NoHeader {
            line: last_line(text),
        }),
        Some((_, cols, layout)) => Ok((layout, cols, rows, last_line(text))),
    }
}

/// The lines of `text` that hold anything but a comment (a line starting with `comment`),
/// trimmed, with their numbers (from 1).
fn content_lines(text: &str, comment: Option<char>) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(k, raw)| (k + 1, raw.trim()))
        .filter(move |(_, s)| !(s.is_empty() || comment.is_some_and(|c| s.starts_with(c))))
}

/// The number of `text`'s last line (1 for an empty text), where what is missing is reported.
fn last_line(text: &str) -> usize {
    text.lines().count().max(1)
}

/// The layout a header names, or why it names none.
fn header_layout(line: usize, cols: &[String]) -> Result<Layout, CaptureError> {
    for (k, c) in cols.iter().enumerate() {
        if cols[..k].contains(c) {
            return Err(CaptureError::DuplicateColumn {
                line,
                column: c.clone(),
            });
        }
    }
    let has = |n: &str| cols.iter().any(|c| c == n);
    let layout = if has("t_s") || has("drive_hz") || has("v_drive_v") || has("i_sense_a") {
        Layout::TimeDomain
    } else if has("z_mag_ohm") || has("z_phase_deg") {
        Layout::Impedance
    } else if has("y_re_s") || has("y_im_s") {
        Layout::Admittance
    } else if let Some(c) = cols.iter().find(|c| c.as_str() != "freq_hz") {
        return Err(CaptureError::UnknownColumn {
            line,
            column: c.clone(),
        });
    } else {
        // Only `freq_hz` (or nothing): say what a frequency-domain file lacks.
        return Err(CaptureError::MissingColumn {
            line,
            column: "y_re_s",
            layout: Layout::Admittance,
        });
    };
    if let Some(c) = cols
        .iter()
        .find(|c| !layout.columns().contains(&c.as_str()))
    {
        return Err(CaptureError::UnknownColumn {
            line,
            column: c.clone(),
        });
    }
    if let Some(c) = layout.columns().iter().find(|n| !has(n)) {
        return Err(CaptureError::MissingColumn {
            line,
            column: c,
            layout,
        });
    }
    Ok(layout)
}

/// Pooled per-component noise of `(f, G, B)` from local cubic fits (see the module docs).
pub fn noise_sigma(fy: &[(f64, f64, f64)]) -> f64 {
    let peak = fy.iter().map(|&(_, g, b)| g.hypot(b)).fold(0.0, f64::max);
    let floor = SIGMA_FLOOR_REL * peak;
    let n = fy.len();
    if n < NOISE_WINDOW {
        return floor;
    }
    let (mut rss, mut dof) = (0.0, 0usize);
    for w in fy.windows(NOISE_WINDOW) {
        let fc = w.iter().map(|p| p.0).sum::<f64>() / NOISE_WINDOW as f64;
        let half = 0.5 * (w[NOISE_WINDOW - 1].0 - w[0].0);
        let xs: Vec<f64> = w.iter().map(|p| (p.0 - fc) / half).collect();
        for comp in 0..2 {
            let ys: Vec<f64> = w
                .iter()
                .map(|p| if comp == 0 { p.1 } else { p.2 })
                .collect();
            if let Some(r) = cubic_rss(&xs, &ys) {
                rss += r;
                dof += NOISE_WINDOW - 4;
            }
        }
    }
    if dof == 0 {
        return floor;
    }
    (rss / dof as f64).sqrt().max(floor)
}

/// Residual sum of squares of a least-squares cubic through `(x, y)`: the normal equations
/// solved by the core's Cholesky solver ([`damped_solve`] without damping), as every fit of the
/// firmware is.
fn cubic_rss(x: &[f64], y: &[f64]) -> Option<f64> {
    let mut ata = [[0.0f64; 4]; 4];
    let mut aty = [0.0f64; 4];
    let scale = y.iter().map(|v| v.abs()).fold(0.0, f64::max).max(1e-300);
    for (&xi, &yi) in x.iter().zip(y) {
        let b = [1.0, xi, xi * xi, xi * xi * xi];
        for (r, row) in ata.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v += b[r] * b[c];
            }
            aty[r] += b[r] * yi / scale;
        }
    }
    let p = damped_solve(&ata, &aty, 0.0)?;
    let rss = x
        .iter()
        .zip(y)
        .map(|(&xi, &yi)| {
            let m = p[0] + xi * (p[1] + xi * (p[2] + xi * p[3]));
            (yi / scale - m).powi(2)
        })
        .sum::<f64>();
    Some(rss * scale * scale)
}

/// Time-domain columns.
struct Samples {
    t: Vec<f64>,
    f: Vec<f64>,
    v: Vec<f64>,
    i: Vec<f64>,
    lines: Vec<usize>,
}

/// A phasor `a - j b` of `a cos φ + b sin φ + c` with the variance of each component.
#[derive(Clone, Copy, Debug)]
struct Phasor {
    re: f64,
    im: f64,
    var: f64,
    rms_residual: f64,
}

/// Least-squares fit of `x = a cos φ + b sin φ + c` over the samples.
fn fit_phasor(phase: &[f64], x: &[f64]) -> Option<Phasor> {
    let mut l = Lsq3::default();
    for (&p, &xi) in phase.iter().zip(x) {
        l.add([p.cos(), p.sin(), 1.0], xi, 1.0);
    }
    let fit = l.solve()?;
    let n = fit.n as f64;
    let s2 = if n > 3.0 { fit.chi2 / (n - 3.0) } else { 0.0 };
    Some(Phasor {
        re: fit.p[0],
        im: -fit.p[1],
        var: s2 * 0.5 * (fit.cov[0][0] + fit.cov[1][1]),
        rms_residual: (fit.chi2 / n).sqrt(),
    })
}

/// Admittance of one demodulation window `[a, b)` with reference phase `phase`.
fn window_point(
    s: &Samples,
    a: usize,
    b: usize,
    phase: &[f64],
) -> Result<SweepPoint, CaptureError> {
    let line = s.lines[a];
    let fi = fit_phasor(&phase[a..b], &s.i[a..b]).ok_or(CaptureError::TooFewPoints {
        line,
        found: b - a,
        needed: 4,
    })?;
    let fv = fit_phasor(&phase[a..b], &s.v[a..b]).ok_or(CaptureError::TooFewPoints {
        line,
        found: b - a,
        needed: 4,
    })?;
    let v2 = fv.re * fv.re + fv.im * fv.im;
    if !(v2 > 25.0 * fv.var) || !(v2 > 0.0) {
        return Err(CaptureError::NoDrive { line });
    }
    // Y = I / V.
    let g = (fi.re * fv.re + fi.im * fv.im) / v2;
    let bb = (fi.im * fv.re - fi.re * fv.im) / v2;
    let y2 = g * g + bb * bb;
    let var_y = (fi.var + y2 * fv.var) / v2;
    let freq = s.f[a..b].iter().sum::<f64>() / (b - a) as f64;
    Ok(SweepPoint {
        freq: Hz(freq as f32),
        g_s: g as f32,
        b_s: bb as f32,
        sigma_s: var_y.sqrt() as f32,
        current_a: (fi.re * fi.re + fi.im * fi.im).sqrt() as f32,
        drive_v: v2.sqrt() as f32,
        clip_fraction: 0.0,
        residual_a: fi.rms_residual as f32,
    })
}

fn demodulate(
    s: &Samples,
    last_line: usize,
    needed: usize,
    opts: &DemodOptions,
) -> Result<Capture, CaptureError> {
    let n = s.t.len();
    if n < 8 {
        return Err(CaptureError::TooFewPoints {
            line: last_line,
            found: n,
            needed: needed.max(1) * 8,
        });
    }
    let fs = sample_rate(s)?;
    let runs = runs_of_constant_drive(&s.f);
    let mut run_cycles: Vec<f64> = runs
        .iter()
        .map(|r| (r.end - r.start) as f64 / fs * s.f[r.start])
        .collect();
    run_cycles.sort_by(f64::total_cmp);
    let median_cycles = run_cycles[run_cycles.len() / 2];
    let (shape, mut points, skipped) = if median_cycles >= MIN_STEP_CYCLES {
        let (points, skipped) = stepped_points(s, &runs, fs, opts)?;
        (SweepShape::Stepped, points, skipped)
    } else {
        (SweepShape::Continuous, continuous_points(s, opts)?, 0)
    };
    // The estimators take points in increasing frequency (a down sweep is read backwards).
    points.sort_by(|a, b| a.freq.0.total_cmp(&b.freq.0));
    if points.len() < needed.max(3) {
        return Err(CaptureError::TooFewPoints {
            line: last_line,
            found: points.len(),
            needed: needed.max(3),
        });
    }
    Ok(Capture {
        layout: Layout::TimeDomain,
        points,
        domain: Domain::Time(TimeDomain {
            sample_rate_hz: fs,
            shape,
            skipped_steps: skipped,
        }),
        rows: n,
        source: None,
    })
}

/// The sample rate of a capture (from the mean step), after checking that every drive frequency
/// is positive and resolved (at least [`MIN_SAMPLES_PER_CYCLE`] samples a cycle) and that the
/// time steps increase uniformly (each within [`DT_TOLERANCE`] of the median step: robust to
/// the one bad step being looked for).
fn sample_rate(s: &Samples) -> Result<f64, CaptureError> {
    let n = s.t.len();
    for k in 0..n {
        if !(s.f[k] > 0.0) {
            return Err(CaptureError::NotPositive {
                line: s.lines[k],
                column: "drive_hz",
            });
        }
        if k > 0 && !(s.t[k] > s.t[k - 1]) {
            return Err(CaptureError::NotIncreasing {
                line: s.lines[k],
                column: "t_s",
                value: s.t[k],
                previous: s.t[k - 1],
            });
        }
    }
    let mut dts: Vec<f64> = s.t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let median_dt = dts[dts.len() / 2];
    for k in 1..n {
        let dt = s.t[k] - s.t[k - 1];
        if (dt - median_dt).abs() > DT_TOLERANCE * median_dt {
            return Err(CaptureError::NonUniformSampling {
                line: s.lines[k],
                dt_s: dt,
                typical_dt_s: median_dt,
            });
        }
    }
    let fs = (n - 1) as f64 / (s.t[n - 1] - s.t[0]);
    for k in 0..n {
        if s.f[k] * MIN_SAMPLES_PER_CYCLE > fs {
            return Err(CaptureError::TooCoarse {
                line: s.lines[k],
                drive_hz: s.f[k],
                sample_rate_hz: fs,
            });
        }
    }
    Ok(fs)
}

/// Samples `start..end` of a capture, all at one drive frequency.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Run {
    start: usize,
    end: usize,
}

/// The runs of constant drive frequency, in order.
fn runs_of_constant_drive(f: &[f64]) -> Vec<Run> {
    let mut runs = Vec::new();
    let mut start = 0;
    for k in 1..=f.len() {
        if k == f.len() || f[k] != f[start] {
            runs.push(Run { start, end: k });
            start = k;
        }
    }
    runs
}

/// A stepped sweep: one point per run, over the whole drive cycles after its settling (the
/// settle time of `opts`, else the run's first half); runs with fewer than two cycles left are
/// skipped (counted).
fn stepped_points(
    s: &Samples,
    runs: &[Run],
    fs: f64,
    opts: &DemodOptions,
) -> Result<(Vec<SweepPoint>, usize), CaptureError> {
    // Within a run the frequency is constant: the reference phase is 2π f t.
    let phase: Vec<f64> = (0..s.t.len()).map(|k| 2.0 * PI * s.f[k] * s.t[k]).collect();
    let (mut points, mut skipped) = (Vec::new(), 0);
    for r in runs {
        let f = s.f[r.start];
        let len = r.end - r.start;
        let settle = match opts.settle_s {
            Some(x) => ((x * fs).round().max(0.0) as usize).min(len),
            None => len / 2,
        };
        let avail = len - settle;
        let spc = fs / f;
        let cycles = (avail as f64 / spc).floor();
        let take = (cycles * spc).round() as usize;
        if cycles < 2.0 || take < 8 || take > avail {
            skipped += 1;
            continue;
        }
        points.push(window_point(s, r.end - take, r.end, &phase)?);
    }
    Ok((points, skipped))
}

/// A continuous (chirped) sweep: the drive phase integrated from the recorded frequency
/// (trapezoid rule), one point per `cycles_per_window` drive cycles.
fn continuous_points(s: &Samples, opts: &DemodOptions) -> Result<Vec<SweepPoint>, CaptureError> {
    let n = s.t.len();
    let mut acc = 0.0;
    let cyc: Vec<f64> = (0..n)
        .map(|k| {
            if k > 0 {
                acc += 0.5 * (s.f[k] + s.f[k - 1]) * (s.t[k] - s.t[k - 1]);
            }
            acc
        })
        .collect();
    let phase: Vec<f64> = cyc
        .iter()
        .map(|c| 2.0 * PI * (c + s.f[0] * s.t[0]))
        .collect();
    let per = opts.cycles_per_window.max(1) as f64;
    let mut points = Vec::new();
    let mut a = 0;
    let mut next = per;
    for (k, &c) in cyc.iter().enumerate().skip(1) {
        if c >= next {
            if k - a >= 8 {
                points.push(window_point(s, a, k, &phase)?);
            }
            a = k;
            next += per;
        }
    }
    Ok(points)
}

/// The start of a CSV: each of `comments` as a `#` line, then the `header` row.
fn csv_head(comments: &[String], header: &str) -> String {
    let mut s = String::new();
    for c in comments {
        s += &format!("# {c}\n");
    }
    s + header + "\n"
}

/// Write admittance points as an `freq_hz,y_re_s,y_im_s` CSV (with `#` comment lines first).
pub fn write_admittance_csv(comments: &[String], points: &[(f64, f64, f64)]) -> String {
    let mut s = csv_head(comments, "freq_hz,y_re_s,y_im_s");
    for (f, g, b) in points {
        s += &format!("{f},{g:.7e},{b:.7e}\n");
    }
    s
}

/// Write impedance points as an `freq_hz,z_mag_ohm,z_phase_deg` CSV from admittance
/// `(f, G, B)`.
pub fn write_impedance_csv(comments: &[String], points: &[(f64, f64, f64)]) -> String {
    let mut s = csv_head(comments, "freq_hz,z_mag_ohm,z_phase_deg");
    for (f, g, b) in points {
        // Z = 1/Y: |Z| = 1/|Y|, phase(Z) = -phase(Y).
        let mag = 1.0 / g.hypot(*b);
        let ph = -b.atan2(*g).to_degrees();
        s += &format!("{f},{mag:.7e},{ph:.6}\n");
    }
    s
}
