//! Impedance analysers' own text exports, turned into admittance rows `(line, f, G, B)`.
//!
//! Two formats are read, each recognised from its content (never from the file name):
//!
//! * **HP/Agilent 4294A, ASCII data file** (`.TXT`, saved with the save-data function in ASCII
//!   format). Followed: *Agilent 4294A Operation Manual*, chapter 8 "Analysis and Processing of
//!   Result", section "Save and Recall the Agilent 4294A Internal Data" — the file holds the
//!   instrument's setup lines, then one block per trace (`"TRACE: A"`, `"TRACE: B"`) with a row
//!   of quoted column names and tab-separated rows of numbers; subsection "Data contents saved
//!   in the trace data": the *data array* (`Data Real`, `Data Imag`) always holds R and X (the
//!   impedance before the measurement-parameter conversion), the *data trace array*
//!   (`Data Trace Real`, `Data Trace Imag`) the displayed parameter, with 0 (`0.000000e+00`)
//!   where a parameter has no second value. The header line layout (`4294A REV…`,
//!   `"MEASURE PARAMETER: IMPEDANCE MAG PHASE (DEG)"`, `"TRACE: A"`, `"FORMAT: …"`, the quoted
//!   column row) is that of a real export (ETH Zurich PES, `impedance_analyzer_4294A_matlab`,
//!   `data/impedance.txt`), the manual's own example page not being at hand.
//!   With the data array present it is used (R + jX); otherwise trace A and trace B's
//!   `Data Trace Real` give the measurement parameter's two values: |Z|–θ, |Y|–θ, R–X or G–B
//!   (θ in degrees unless the parameter says `(RAD)`).
//! * **Keysight E4990A, trace data CSV** (Save/Recall > Save Trace Data). Followed: *E4990A
//!   Help*, "Saving Trace Data to a File" › "Saving Data in CSV Format": `!` lines (product
//!   information, date), then per channel `BEGIN CHn_DATA`, optional `Title label, …` and
//!   `DCV(V), …` lines, the header `Frequency(Hz), <param>(<unit>)-data, …, <param>-mem`, the
//!   rows, `END`. The `-data` columns are read (`-mem` ones ignored): `|Z|(Ohm)` with
//!   `theta-z(deg)`, `Z-Real(Ohm)` with `Z-Imag(Ohm)`, `|Y|(S)` with `theta-y(deg)`, or
//!   `Y-Real(S)` with `Y-Imag(S)`, from the first channel that has such a pair. (An older
//!   manual edition describes the same file without `BEGIN`/`END`: product line, date line,
//!   header line, rows; that is read too.)
//!
//! Every inconsistency is a [`CaptureError::Export`] naming its line: no trace, a trace with no
//! rows (a truncated file), a row with the wrong number of values, a value that is not a finite
//! number, traces whose frequencies differ, a measurement parameter that gives no impedance.

use super::{CaptureError, Layout};

/// Admittance rows of an export and what they were read from.
pub(super) struct Rows {
    /// `(line, f Hz, G S, B S)`.
    pub rows: Vec<(usize, f64, f64, f64)>,
    /// Last line of the file.
    pub last_line: usize,
    /// What was read, for humans (e.g. `trace A |Z| (ohm), trace B θ (deg)`).
    pub read: String,
}

/// Which export `text` is, from its content; `None` for the bench's own CSV layouts.
pub(super) fn detect(text: &str) -> Option<Layout> {
    let mut lines = text.lines().map(str::trim).filter(|s| !s.is_empty());
    let first = lines.next()?;
    if starts_ci(first, "4294A") {
        return Some(Layout::Hp4294a);
    }
    if first.starts_with('!') && first.to_ascii_uppercase().contains("E4990A") {
        return Some(Layout::E4990a);
    }
    for s in text.lines().map(str::trim) {
        if starts_ci(unquote(s), "TRACE:") {
            return Some(Layout::Hp4294a);
        }
        if starts_ci(s, "BEGIN CH") || starts_ci(s, "Frequency(") {
            return Some(Layout::E4990a);
        }
    }
    None
}

fn starts_ci(s: &str, prefix: &str) -> bool {
    s.len() >= prefix.len()
        && s.is_char_boundary(prefix.len())
        && s[..prefix.len()].eq_ignore_ascii_case(prefix)
}

fn strip_ci<'a>(s: &'a str, prefix: &str) -> Option<&'a str> {
    starts_ci(s, prefix).then(|| &s[prefix.len()..])
}

/// `s` without one pair of surrounding double quotes.
fn unquote(s: &str) -> &str {
    let s = s.trim();
    s.strip_prefix('"')
        .and_then(|t| t.strip_suffix('"'))
        .unwrap_or(s)
        .trim()
}

/// A cell as quoted in a message: at most 32 characters, printable.
fn shown(cell: &str) -> String {
    let mut s: String = cell
        .chars()
        .take(32)
        .map(|c| if c.is_control() { '?' } else { c })
        .collect();
    if cell.chars().count() > 32 {
        s.push('…');
    }
    s
}

fn err(layout: Layout, line: usize, reason: String) -> CaptureError {
    CaptureError::Export {
        line,
        format: layout.name(),
        reason,
    }
}

/// A finite number, or why not.
fn number(layout: Layout, line: usize, cell: &str) -> Result<f64, CaptureError> {
    match cell.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(err(
            layout,
            line,
            format!("`{}` is not finite", shown(cell)),
        )),
        Err(_) => Err(err(
            layout,
            line,
            format!("`{}` is not a number", shown(cell)),
        )),
    }
}

/// The two values of a measurement parameter and how they make an admittance.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Pair {
    /// |Z| (ohm) and θ (`true`: degrees).
    ZPolar(bool),
    /// R and X (ohm).
    ZRect,
    /// |Y| (S) and θ (`true`: degrees).
    YPolar(bool),
    /// G and B (S).
    YRect,
}

impl Pair {
    /// `(G, B)` of the two values `a`, `b`, or why they make none.
    fn admittance(self, a: f64, b: f64) -> Result<(f64, f64), &'static str> {
        let rad = |x: f64, deg: bool| if deg { x.to_radians() } else { x };
        match self {
            Pair::ZPolar(deg) => {
                if !(a > 0.0) {
                    return Err("|Z| must be above zero");
                }
                // Y = e^{-jθ} / |Z|
                let t = rad(b, deg);
                Ok((t.cos() / a, -t.sin() / a))
            }
            Pair::ZRect => {
                let d = a * a + b * b;
                if !(d > 0.0) || !d.is_finite() {
                    return Err("R and X are both zero");
                }
                // Y = (R − jX) / (R² + X²)
                Ok((a / d, -b / d))
            }
            Pair::YPolar(deg) => {
                if !(a >= 0.0) {
                    return Err("|Y| must not be negative");
                }
                let t = rad(b, deg);
                Ok((a * t.cos(), a * t.sin()))
            }
            Pair::YRect => Ok((a, b)),
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Pair::ZPolar(true) => "|Z| (ohm) and θ (deg)",
            Pair::ZPolar(false) => "|Z| (ohm) and θ (rad)",
            Pair::ZRect => "R and X (ohm)",
            Pair::YPolar(true) => "|Y| (S) and θ (deg)",
            Pair::YPolar(false) => "|Y| (S) and θ (rad)",
            Pair::YRect => "G and B (S)",
        }
    }
}

/// One block of columns and rows of numbers: a `"TRACE: x"` block of a 4294A file, a channel
/// of an E4990A CSV.
struct Block {
    /// `trace` or `channel`, for the messages.
    kind: &'static str,
    name: String,
    line: usize,
    cols: Vec<String>,
    rows: Vec<(usize, Vec<f64>)>,
}

impl Block {
    /// A block named `name` that starts at `line`, with no columns and no rows yet.
    fn new(kind: &'static str, name: String, line: usize) -> Self {
        Self {
            kind,
            name,
            line,
            cols: Vec::new(),
            rows: Vec::new(),
        }
    }

    fn col(&self, name: &str) -> Option<usize> {
        self.cols.iter().position(|c| c.eq_ignore_ascii_case(name))
    }

    /// Keep row `line` of `layout`'s file, its `cells` each a finite number.
    fn push(&mut self, layout: Layout, line: usize, cells: &[&str]) -> Result<(), CaptureError> {
        let v = cells
            .iter()
            .map(|c| number(layout, line, c))
            .collect::<Result<Vec<f64>, _>>()?;
        self.rows.push((line, v));
        Ok(())
    }

    /// The block's rows, or the error of a file truncated after its header (reported at
    /// `last_line`).
    fn data_rows(
        &self,
        layout: Layout,
        last_line: usize,
    ) -> Result<&[(usize, Vec<f64>)], CaptureError> {
        if self.rows.is_empty() {
            return Err(err(
                layout,
                last_line,
                format!(
                    "{} {} (line {}) has no data rows: the file is truncated",
                    self.kind, self.name, self.line
                ),
            ));
        }
        Ok(&self.rows)
    }
}

/// Column names of a 4294A column row: tab separated, each in quotes (or, without tabs, the
/// quoted names in order).
fn quoted_cells(s: &str) -> Vec<String> {
    if s.contains('\t') {
        return s.split('\t').map(|c| unquote(c).to_owned()).collect();
    }
    s.split('"')
        .enumerate()
        .filter(|(k, _)| k % 2 == 1)
        .map(|(_, c)| c.trim().to_owned())
        .collect()
}

/// The measurement parameter of a 4294A `MEASURE PARAMETER:` line.
fn parameter_4294a(p: &str) -> Option<Pair> {
    let p = p.to_ascii_uppercase();
    let deg = !p.contains("(RAD)");
    if p.contains("IMPEDANCE") && p.contains("PHASE") {
        Some(Pair::ZPolar(deg))
    } else if p.contains("ADMITTANCE") && p.contains("PHASE") {
        Some(Pair::YPolar(deg))
    } else if (p.contains("RESIST") && p.contains("REACT")) || p.trim() == "R-X" {
        Some(Pair::ZRect)
    } else if (p.contains("CONDUCT") && p.contains("SUSCEPT")) || p.trim() == "G-B" {
        Some(Pair::YRect)
    } else {
        None
    }
}

/// Read a 4294A ASCII data file (see the module docs).
pub(super) fn read_4294a(text: &str) -> Result<Rows, CaptureError> {
    const L: Layout = Layout::Hp4294a;
    let mut measure: Option<(usize, String)> = None;
    let mut traces: Vec<Block> = Vec::new();
    let last_line = super::last_line(text);
    for (line, s) in super::content_lines(text, None) {
        let u = unquote(s);
        if let Some(v) = strip_ci(u, "MEASURE PARAMETER:") {
            measure = Some((line, v.trim().to_owned()));
            continue;
        }
        if let Some(v) = strip_ci(u, "TRACE:") {
            traces.push(Block::new("trace", v.trim().to_ascii_uppercase(), line));
            continue;
        }
        let Some(t) = traces.last_mut() else {
            // Setup lines before the first trace (revision, date, sweep, oscillator level).
            continue;
        };
        if s.starts_with('"') {
            if t.cols.is_empty() {
                let cells = quoted_cells(s);
                if cells
                    .first()
                    .is_some_and(|c| c.eq_ignore_ascii_case("Frequency"))
                {
                    t.cols = cells;
                }
                // Otherwise a trace setting (`"FORMAT: LOG"`).
                continue;
            }
            return Err(err(
                L,
                line,
                format!("text `{}` among trace {}'s rows", shown(s), t.name),
            ));
        }
        if t.cols.is_empty() {
            return Err(err(
                L,
                line,
                format!(
                    "a data row before trace {}'s column row (\"Frequency\" …)",
                    t.name
                ),
            ));
        }
        let cells: Vec<&str> = s.split_whitespace().collect();
        if cells.len() != t.cols.len() {
            return Err(err(
                L,
                line,
                format!(
                    "expected {} values ({}), found {}",
                    t.cols.len(),
                    t.cols.join(", "),
                    cells.len()
                ),
            ));
        }
        t.push(L, line, &cells)?;
    }
    let Some(a) = traces.first() else {
        return Err(err(L, last_line, "no \"TRACE: A\" block".into()));
    };
    for t in &traces {
        if t.cols.is_empty() {
            return Err(err(
                L,
                last_line,
                format!(
                    "trace {} (line {}) has no column row: the file is truncated",
                    t.name, t.line
                ),
            ));
        }
        t.data_rows(L, last_line)?;
    }
    let fcol = a.col("Frequency").unwrap_or(0);
    // The data array holds R and X whatever the measurement parameter ("Data contents saved in
    // the trace data").
    if let (Some(re), Some(im)) = (a.col("Data Real"), a.col("Data Imag")) {
        let rows = convert(L, Pair::ZRect, a, fcol, re, a, im)?;
        return Ok(Rows {
            rows,
            last_line,
            read: format!("trace {} data array: R and X (ohm)", a.name),
        });
    }
    let Some((pline, param)) = measure else {
        return Err(err(
            L,
            a.line,
            "no \"MEASURE PARAMETER:\" line and no data array (Data Real, Data Imag): the traces cannot be read as an impedance".into(),
        ));
    };
    let Some(pair) = parameter_4294a(&param) else {
        return Err(err(
            L,
            pline,
            format!(
                "measurement parameter `{}` gives no impedance (|Z|-θ, |Y|-θ, R-X or G-B, or save the data array)",
                shown(&param)
            ),
        ));
    };
    let Some(b) = traces.get(1) else {
        return Err(err(
            L,
            last_line,
            format!("only one trace: {} needs trace B too", pair.describe()),
        ));
    };
    let (Some(ra), Some(rb)) = (a.col("Data Trace Real"), b.col("Data Trace Real")) else {
        return Err(err(
            L,
            b.line,
            "a trace has no \"Data Trace Real\" column".into(),
        ));
    };
    let rows = convert(L, pair, a, fcol, ra, b, rb)?;
    Ok(Rows {
        rows,
        last_line,
        read: format!(
            "{}: trace {} and trace {} ({})",
            shown(&param),
            a.name,
            b.name,
            pair.describe()
        ),
    })
}

/// Rows of `a` (column `ca`) and `b` (column `cb`) taken as `pair`, their frequencies in column
/// `fcol` of each; the two must have the same frequencies.
fn convert(
    layout: Layout,
    pair: Pair,
    a: &Block,
    fcol: usize,
    ca: usize,
    b: &Block,
    cb: usize,
) -> Result<Vec<(usize, f64, f64, f64)>, CaptureError> {
    let fb = b.col("Frequency").unwrap_or(0);
    if a.rows.len() != b.rows.len() {
        return Err(err(
            layout,
            b.line,
            format!(
                "trace {} has {} rows, trace {} {}",
                a.name,
                a.rows.len(),
                b.name,
                b.rows.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(a.rows.len());
    for ((la, va), (lb, vb)) in a.rows.iter().zip(&b.rows) {
        let (f, f2) = (va[fcol], vb[fb]);
        if (f - f2).abs() > 1e-9 * f.abs().max(f2.abs()) {
            return Err(err(
                layout,
                *lb,
                format!(
                    "frequency {f2} differs from trace {}'s {f} (line {la})",
                    a.name
                ),
            ));
        }
        let (g, bb) = pair
            .admittance(va[ca], vb[cb])
            .map_err(|why| err(layout, *la, why.into()))?;
        out.push((*la, f, g, bb));
    }
    Ok(out)
}

/// A `-data` column of an E4990A header.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Quantity {
    ZMag,
    ZTheta(bool),
    ZRe,
    ZIm,
    YMag,
    YTheta(bool),
    YRe,
    YIm,
}

fn quantity_e4990a(header: &str) -> Option<Quantity> {
    let h = header.trim().to_ascii_lowercase();
    let h = h.strip_suffix("-data")?;
    let (name, unit) = match h.find('(') {
        Some(i) => (&h[..i], h[i..].trim_matches(|c| c == '(' || c == ')')),
        None => (h, ""),
    };
    let deg = unit != "rad";
    Some(match name.trim() {
        "|z|" => Quantity::ZMag,
        "theta-z" => Quantity::ZTheta(deg),
        "z-real" => Quantity::ZRe,
        "z-imag" => Quantity::ZIm,
        "|y|" => Quantity::YMag,
        "theta-y" => Quantity::YTheta(deg),
        "y-real" => Quantity::YRe,
        "y-imag" => Quantity::YIm,
        _ => return None,
    })
}

/// A test of a column's quantity.
type QuantityIs = fn(Quantity) -> bool;

/// The pairs of E4990A `-data` columns that give the admittance, in the order they are looked
/// for: the first column's quantity, the second's, and the pair they make.
const PAIRS_E4990A: [(QuantityIs, QuantityIs, Pair); 4] = [
    (|q| q == Quantity::ZRe, |q| q == Quantity::ZIm, Pair::ZRect),
    (
        |q| q == Quantity::ZMag,
        |q| matches!(q, Quantity::ZTheta(_)),
        Pair::ZPolar(true),
    ),
    (|q| q == Quantity::YRe, |q| q == Quantity::YIm, Pair::YRect),
    (
        |q| q == Quantity::YMag,
        |q| matches!(q, Quantity::YTheta(_)),
        Pair::YPolar(true),
    ),
];

/// Read an E4990A trace-data CSV (see the module docs).
pub(super) fn read_e4990a(text: &str) -> Result<Rows, CaptureError> {
    const L: Layout = Layout::E4990a;
    let mut chans: Vec<Block> = Vec::new();
    let mut open = false;
    let last_line = super::last_line(text);
    for (line, s) in super::content_lines(text, Some('!')) {
        if let Some(v) = strip_ci(s, "BEGIN") {
            chans.push(Block::new("channel", v.trim().to_owned(), line));
            open = true;
            continue;
        }
        if s.eq_ignore_ascii_case("END") {
            if !open {
                return Err(err(L, line, "END without BEGIN".into()));
            }
            open = false;
            continue;
        }
        let cells: Vec<&str> = s.split(',').map(str::trim).collect();
        let first = cells.first().copied().unwrap_or("");
        if starts_ci(first, "Frequency") {
            if !open {
                // The file without BEGIN/END: one implicit channel.
                chans.push(Block::new("channel", "CH1".into(), line));
                open = true;
            }
            let Some(c) = chans.last_mut() else { continue };
            if !c.cols.is_empty() {
                return Err(err(L, line, "a second header row in one channel".into()));
            }
            if !first.eq_ignore_ascii_case("Frequency(Hz)") {
                return Err(err(
                    L,
                    line,
                    format!("frequency column `{}` is not in Hz", shown(first)),
                ));
            }
            c.cols = cells.iter().map(|c| (*c).to_owned()).collect();
            continue;
        }
        let numeric = first.parse::<f64>().is_ok();
        let Some(c) = chans.last_mut().filter(|_| open) else {
            if numeric {
                return Err(err(L, line, "a data row outside a channel block".into()));
            }
            continue;
        };
        if c.cols.is_empty() {
            if numeric {
                return Err(err(
                    L,
                    line,
                    "a data row before the `Frequency(Hz), …` header".into(),
                ));
            }
            // `Title label, …`, `DCV(V), …`.
            continue;
        }
        if cells.len() != c.cols.len() {
            return Err(err(
                L,
                line,
                format!("expected {} values, found {}", c.cols.len(), cells.len()),
            ));
        }
        c.push(L, line, &cells)?;
    }
    if chans.is_empty() {
        return Err(err(L, last_line, "no `Frequency(Hz), …` header".into()));
    }
    if open && text.lines().any(|l| starts_ci(l.trim(), "BEGIN")) {
        return Err(err(
            L,
            last_line,
            "the last channel has no END: the file is truncated".into(),
        ));
    }
    let mut seen = Vec::new();
    for c in &chans {
        let find = |q: fn(Quantity) -> bool| {
            c.cols
                .iter()
                .position(|h| quantity_e4990a(h).is_some_and(q))
        };
        let Some((ia, ib, pair)) = PAIRS_E4990A
            .iter()
            .find_map(|&(a, b, p)| Some((find(a)?, find(b)?, p)))
        else {
            seen.extend(c.cols.iter().skip(1).cloned());
            continue;
        };
        // The θ column's own unit.
        let pair = match (pair, c.cols.get(ib).and_then(|h| quantity_e4990a(h))) {
            (Pair::ZPolar(_), Some(Quantity::ZTheta(d))) => Pair::ZPolar(d),
            (Pair::YPolar(_), Some(Quantity::YTheta(d))) => Pair::YPolar(d),
            (p, _) => p,
        };
        let c_rows = c.data_rows(L, last_line)?;
        let mut rows = Vec::with_capacity(c_rows.len());
        for (line, v) in c_rows {
            let (g, b) = pair
                .admittance(v[ia], v[ib])
                .map_err(|why| err(L, *line, why.into()))?;
            rows.push((*line, v[0], g, b));
        }
        return Ok(Rows {
            rows,
            last_line,
            read: format!(
                "channel {}: {} and {} ({})",
                c.name,
                c.cols[ia],
                c.cols[ib],
                pair.describe()
            ),
        });
    }
    Err(err(
        L,
        chans[0].line,
        format!(
            "no impedance or admittance pair among the -data columns (|Z| and theta-z, Z-Real and Z-Imag, |Y| and theta-y, Y-Real and Y-Imag); found: {}",
            shown(&seen.join(", "))
        ),
    ))
}
