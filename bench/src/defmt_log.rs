//! The firmware's decoded defmt log: messages parsed against the firmware's own format strings,
//! and the readings and sweeps they describe.
//!
//! The firmware logs one defmt message per event with structured values (`key={=f32}` …); the
//! formats are listed in the crate docs of `src/bin/probe.rs` (logged there and in
//! `src/instrument/log.rs`) and repeated here in
//! [`TEMPLATES`] (a test checks the two sets are identical, so a change on one side fails the
//! build's tests). The decoder (`defmt-print`, `probe-rs run`, or `scripts/qemu-run`) prints
//! each message as text in a configurable frame, e.g. `INFO  point tag=3 f_hz=204.0 …`,
//! `0.001234 [INFO ] point … (src/bin/probe.rs:771 )`. A line is recognised by the start of one
//! of the templates (`point tag=`); what comes before it is the frame, from which a timestamp
//! (the first number, s; `<time>` when the firmware has none) and the level are taken; a
//! trailing `(file:line)` is dropped. Values are read as the decoder prints them: floats as
//! Rust's `{:?}` (`1.25e-7`, `NaN`), booleans `true`/`false`, strings verbatim.
//!
//! Sweeps and readings: every `point` line between two `reading` lines belongs to the reading
//! that closes them (whatever procedure produced them); the `settings` line last seen before
//! the sweep is kept with it. `boot` and `stalled` abandon a sweep in progress.
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > y)` also rejects NaN, deliberately

use probe_proto::{PointMsg, ReadingMsg};
use std::fmt;

/// The firmware's log formats (defmt format strings), one per message kind.
pub const TEMPLATES: &[&str] = &[
    "boot board={=str} fs_hz={=f32} batch={=u32}",
    "store loaded slot={=u8} seq={=u32} other={=str}",
    "store fallback slot0={=str} slot1={=str} calibration=paper-experiment",
    "store saved slot={=u8} seq={=u32}",
    "store error={=str}",
    "settings method={=str} start_hz={=f32} stop_hz={=f32} step_hz={=f32} settle_s={=f32} integrate_s={=f32} drive_v={=f32}",
    "point tag={=u16} f_hz={=f32} g_s={=f32} b_s={=f32} sigma_s={=f32}",
    "reading status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} e_repeat_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str} force_n={=f32} force_sigma_n={=f32} loss={=f32} loss_sigma={=f32}",
    "loadcell present={=bool} newtons_per_count={=f32} tare={=f32} min_n={=f32} max_n={=f32}",
    "stream seq={=u32} t_s={=f32} locked={=bool} status={=str} f_hz={=f32} f_sigma_hz={=f32} e_kpa={=f32} e_sigma_kpa={=f32} e_repeat_kpa={=f32} q={=f32} probe_time_s={=f32} points={=u16} method={=str} force_n={=f32} force_sigma_n={=f32} loss={=f32} loss_sigma={=f32}",
    "stream end start_s={=f32} readings={=u32} ok={=u32} dropped={=u32} plan_work={=u32}",
    "air f_hz={=f32} q={=f32}",
    "reference e_kpa={=f32} f_hz={=f32} f_sigma_hz={=f32} n={=u16}",
    "calibration source={=str} a={=f32} b={=f32} c={=f32} min_kpa={=f32} max_kpa={=f32}",
    "hint code={=str} message={=str}",
    "rejected error={=str}",
    "stalled tag={=u16}",
    "overrun late={=u32} ring={=u32} dropped={=u32}",
    "counters batches={=u32} late={=u32} ring={=u32} dropped={=u32} isr_mean={=u32} isr_max={=u32} unit={=str} load_cell_errors={=u32} dma_errors={=u32}",
    "status method={=str} calibration={=str} fallback={=bool} air={=bool} q_model={=bool} references={=u16} selftest={=str}",
    "status boot={=str} message={=str}",
    "help commands={=str} methods={=str} default={=str}",
    "exit ok={=bool}",
    "boot fault={=str} clock={=str}",
    "selftest result={=str} f_hz={=f32} c_pf={=f32} c_sigma_pf={=f32} ref_c_pf={=f32} tol={=f32} ref={=str} g_s={=f32} i_a={=f32} v={=f32} probe_time_s={=f32}",
    "selftest fault={=str} message={=str}",
    "refused selftest={=str} message={=str}",
    "refused boot={=str} message={=str}",
    "stack used_bytes={=u32} init_bytes={=u32} size_bytes={=u32}",
];

/// Type of a logged value (the defmt type hint).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    /// `{=f32}`.
    F32,
    /// `{=u8}`, `{=u16}`, `{=u32}`.
    Uint,
    /// `{=bool}`.
    Bool,
    /// `{=str}`.
    Str,
}

/// A piece of a template.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Piece {
    /// Literal text.
    Literal(String),
    /// A value: its key (the word before `=`) and type.
    Field(String, Ty),
}

/// Split a defmt format string into literals and typed fields; `None` for a type hint this
/// parser does not know.
pub fn compile(template: &str) -> Option<Vec<Piece>> {
    let mut out = Vec::new();
    let mut rest = template;
    while let Some(open) = rest.find("{=") {
        let close = open + rest[open..].find('}')?;
        let lit = &rest[..open];
        let key = lit
            .strip_suffix('=')?
            .rsplit(' ')
            .next()
            .unwrap_or_default()
            .to_owned();
        let ty = match &rest[open + 2..close] {
            "f32" => Ty::F32,
            "u8" | "u16" | "u32" => Ty::Uint,
            "bool" => Ty::Bool,
            "str" => Ty::Str,
            _ => return None,
        };
        if !lit.is_empty() {
            out.push(Piece::Literal(lit.to_owned()));
        }
        out.push(Piece::Field(key, ty));
        rest = &rest[close + 1..];
    }
    if !rest.is_empty() {
        out.push(Piece::Literal(rest.to_owned()));
    }
    Some(out)
}

/// A logged value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A float (`NaN` stands for a missing value).
    F32(f32),
    /// An unsigned integer.
    Uint(u32),
    /// A boolean.
    Bool(bool),
    /// A string.
    Str(String),
}

impl Value {
    /// As the decoder prints it.
    pub fn render(&self) -> String {
        match self {
            Value::F32(x) => format!("{x:?}"),
            Value::Uint(x) => x.to_string(),
            Value::Bool(b) => b.to_string(),
            Value::Str(s) => s.clone(),
        }
    }
}

/// Format a message as the firmware logs it (through its format string) and the decoder prints
/// it; `None` when the values do not fit the template.
pub fn render(template: &str, values: &[Value]) -> Option<String> {
    let mut s = String::new();
    let mut v = values.iter();
    for p in compile(template)? {
        match p {
            Piece::Literal(l) => s += &l,
            Piece::Field(_, ty) => {
                let x = v.next()?;
                let fits = matches!(
                    (ty, x),
                    (Ty::F32, Value::F32(_))
                        | (Ty::Uint, Value::Uint(_))
                        | (Ty::Bool, Value::Bool(_))
                        | (Ty::Str, Value::Str(_))
                );
                if !fits {
                    return None;
                }
                s += &x.render();
            }
        }
    }
    v.next().is_none().then_some(s)
}

/// Log level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// TRACE.
    Trace,
    /// DEBUG.
    Debug,
    /// INFO.
    Info,
    /// WARN.
    Warn,
    /// ERROR.
    Error,
}

/// Where a message stands in the log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stamp {
    /// 1-based line in the input.
    pub line: usize,
    /// Timestamp printed by the decoder, s (when the firmware has one).
    pub time_s: Option<f64>,
}

/// One recognised message.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// Where it stands in the log.
    pub at: Stamp,
    /// Level, when printed.
    pub level: Option<Level>,
    /// The message kind: the template's words before its first key (`point`, `store loaded`,
    /// `store` for `store error=`, ...).
    pub kind: String,
    /// Index into [`TEMPLATES`].
    pub template: usize,
    /// Values by key, in template order.
    pub fields: Vec<(String, Value)>,
}

impl Message {
    /// The message as logged: its kind and values (`kind key=value ...`).
    pub fn text(&self) -> String {
        let mut t = self.kind.clone();
        for (k, v) in &self.fields {
            t += &format!(" {k}={}", v.render());
        }
        t
    }
    /// The value of `key`.
    pub fn get(&self, key: &str) -> Option<&Value> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }
    /// A float value (`NaN` → `None`).
    pub fn f32(&self, key: &str) -> Option<f32> {
        match self.get(key) {
            Some(Value::F32(x)) if x.is_finite() => Some(*x),
            _ => None,
        }
    }
    /// An unsigned value.
    pub fn uint(&self, key: &str) -> Option<u32> {
        match self.get(key) {
            Some(Value::Uint(x)) => Some(*x),
            _ => None,
        }
    }
    /// An unsigned value that the firmware logs as `u16` (saturated).
    pub fn u16(&self, key: &str) -> Option<u16> {
        self.uint(key).map(|n| n.min(u16::MAX as u32) as u16)
    }
    /// A string value.
    pub fn str(&self, key: &str) -> Option<&str> {
        match self.get(key) {
            Some(Value::Str(s)) => Some(s),
            _ => None,
        }
    }
}

/// A line that starts like a known message but does not parse.
#[derive(Clone, Debug, PartialEq)]
pub struct LogError {
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.what)
    }
}

struct Compiled {
    pieces: Vec<Piece>,
    prefix: String,
    kind: String,
}

fn compiled() -> Vec<Compiled> {
    TEMPLATES
        .iter()
        .filter_map(|t| {
            let pieces = compile(t)?;
            let prefix = match pieces.first() {
                Some(Piece::Literal(l)) => l.clone(),
                _ => return None,
            };
            let kind = prefix
                .rsplit_once(' ')
                .map(|(k, _)| k.to_owned())
                .unwrap_or_else(|| prefix.clone());
            Some(Compiled {
                pieces,
                prefix,
                kind,
            })
        })
        .collect()
}

fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            if chars.peek() == Some(&'[') {
                chars.next();
                for d in chars.by_ref() {
                    if d.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// Drop a trailing `(file:line)` location the decoder may append.
fn strip_location(s: &str) -> &str {
    let t = s.trim_end();
    if let Some(open) = t.rfind(" (") {
        let inner = t[open + 2..].trim_end();
        if let Some(inner) = inner.strip_suffix(')') {
            let inner = inner.trim();
            if let Some((_, n)) = inner.rsplit_once(':') {
                if !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()) {
                    return t[..open].trim_end();
                }
            }
        }
    }
    t
}

fn parse_time(tok: &str) -> Option<f64> {
    let t = tok.trim_matches(|c| c == '[' || c == ']' || c == '(' || c == ')');
    if let Ok(x) = t.parse::<f64>() {
        return x.is_finite().then_some(x);
    }
    // hh:mm:ss(.fff)
    let parts: Vec<&str> = t.split(':').collect();
    if parts.len() == 3 {
        let h: f64 = parts[0].parse().ok()?;
        let m: f64 = parts[1].parse().ok()?;
        let s: f64 = parts[2].parse().ok()?;
        return Some(h * 3600.0 + m * 60.0 + s);
    }
    None
}

fn parse_level(tok: &str) -> Option<Level> {
    let t = tok.trim_matches(|c: char| c == '[' || c == ']' || c == '<' || c == '>' || c == ' ');
    Some(match t.to_ascii_uppercase().as_str() {
        "TRACE" => Level::Trace,
        "DEBUG" => Level::Debug,
        "INFO" => Level::Info,
        "WARN" | "WARNING" => Level::Warn,
        "ERROR" => Level::Error,
        _ => return None,
    })
}

fn parse_value(ty: Ty, s: &str) -> Option<Value> {
    Some(match ty {
        Ty::F32 => Value::F32(s.parse().ok()?),
        Ty::Uint => Value::Uint(s.parse().ok()?),
        Ty::Bool => Value::Bool(s.parse().ok()?),
        Ty::Str => Value::Str(s.to_owned()),
    })
}

/// Parse one decoded line: `Ok(None)` when it is no firmware message (blank, location line,
/// other output), `Err` when it starts like one but does not parse.
pub fn parse_line(line_no: usize, raw: &str) -> Result<Option<Message>, LogError> {
    parse_with(&compiled(), line_no, raw)
}

fn parse_with(
    templates: &[Compiled],
    line_no: usize,
    raw: &str,
) -> Result<Option<Message>, LogError> {
    let line = strip_ansi(raw);
    let line = line.trim_end();
    // The template whose prefix appears earliest at a word start (longest on ties).
    let mut best: Option<(usize, usize)> = None;
    for (k, t) in templates.iter().enumerate() {
        let mut from = 0;
        while let Some(off) = line[from..].find(&t.prefix) {
            let at = from + off;
            let word_start = at == 0 || line[..at].ends_with([' ', '\t', ']', '|']);
            if word_start {
                let better = match best {
                    None => true,
                    Some((bk, bat)) => {
                        at < bat || (at == bat && t.prefix.len() > templates[bk].prefix.len())
                    }
                };
                if better {
                    best = Some((k, at));
                }
                break;
            }
            from = at + 1;
        }
    }
    let Some((k, at)) = best else {
        return Ok(None);
    };
    let t = &templates[k];
    let frame = &line[..at];
    let mut time_s = None;
    let mut level = None;
    for tok in frame.split_whitespace() {
        if level.is_none() {
            if let Some(l) = parse_level(tok) {
                level = Some(l);
                continue;
            }
        }
        if time_s.is_none() {
            time_s = parse_time(tok);
        }
    }
    let err = |what: String| LogError {
        line: line_no,
        what,
    };
    let body = &line[at..];
    let mut pos = 0;
    let mut fields = Vec::new();
    let n = t.pieces.len();
    for (i, p) in t.pieces.iter().enumerate() {
        match p {
            Piece::Literal(l) => {
                if !body[pos..].starts_with(l.as_str()) {
                    return Err(err(format!("`{}` does not match `{l}`", &body[pos..])));
                }
                pos += l.len();
            }
            Piece::Field(key, ty) => {
                let text = match t.pieces.get(i + 1) {
                    Some(Piece::Literal(next)) => {
                        let Some(end) = body[pos..].find(next.as_str()) else {
                            return Err(err(format!("`{}` lacks `{}`", t.kind, next.trim())));
                        };
                        let v = &body[pos..pos + end];
                        pos += end;
                        v
                    }
                    _ if i + 1 == n => {
                        let rest = strip_location(&body[pos..]);
                        pos = body.len();
                        if *ty == Ty::Str && key == "error" {
                            rest.trim()
                        } else {
                            rest.split_whitespace().next().unwrap_or("")
                        }
                    }
                    _ => return Err(err("two adjacent fields in a template".into())),
                };
                let v = parse_value(*ty, text.trim())
                    .ok_or_else(|| err(format!("`{key}={}`: not a {ty:?} value", text.trim())))?;
                fields.push((key.clone(), v));
            }
        }
    }
    Ok(Some(Message {
        at: Stamp {
            line: line_no,
            time_s,
        },
        level,
        kind: t.kind.clone(),
        template: k,
        fields,
    }))
}

/// The points one measurement logged.
#[derive(Clone, Debug, PartialEq)]
pub struct LoggedSweep {
    /// Line of its first point.
    pub first_line: usize,
    /// The `settings` message in force when it started (`method`, `start_hz`, ...).
    pub settings: Option<Message>,
    /// Points, in log order.
    pub points: Vec<PointMsg>,
    /// Index of the reading that closed it (`None`: abandoned or the log ended).
    pub reading: Option<usize>,
}

/// A logged reading.
#[derive(Clone, Debug, PartialEq)]
pub struct LoggedReading {
    /// Where it stands in the log.
    pub at: Stamp,
    /// Its fields, as the link's reading message carries them: a value the line has not (or
    /// logged as `NaN`) `None`, a missing probe time `NaN`, a missing point count 0.
    pub msg: ReadingMsg<String>,
    /// Index of its sweep, when points were logged.
    pub sweep: Option<usize>,
}

/// One logged reading of a continuous stream (`stream seq=…` line).
#[derive(Clone, Debug, PartialEq)]
pub struct LoggedStreamReading {
    /// Number in the stream (from 0; a missing number is a dropped reading).
    pub seq: u32,
    /// Probe time at its end, s.
    pub t_s: f32,
    /// The tracker was locked.
    pub locked: bool,
    /// The reading's fields (its `line`, `status`, modulus, ...; no sweep).
    pub reading: LoggedReading,
}

/// The end of a stream (`stream end` line): the firmware's own counts.
#[derive(Clone, Debug, PartialEq)]
pub struct LoggedStreamEnd {
    /// Line.
    pub line: usize,
    /// Probe time at the start, s.
    pub start_s: Option<f32>,
    /// Readings the tracker made.
    pub readings: u32,
    /// Of those, `ok`.
    pub ok: u32,
    /// Of those, dropped by the firmware (its report channel was full).
    pub dropped: u32,
    /// Most work from a window to the next plan (the counters' unit; 0: not measured).
    pub plan_work: u32,
}

/// A continuous stream in the log: its readings, and its end when logged.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoggedStream {
    /// The readings, in log order.
    pub readings: Vec<LoggedStreamReading>,
    /// Its end line, if logged.
    pub end: Option<LoggedStreamEnd>,
}

impl LoggedStream {
    /// Readings missing from the log: gaps in `seq` (from 0, and up to the end's count when
    /// the end was logged) — dropped by the firmware or lost on the link.
    pub fn missing(&self) -> u32 {
        let mut expect = 0u32;
        let mut gaps = 0u32;
        for r in &self.readings {
            gaps += r.seq.saturating_sub(expect);
            expect = expect.max(r.seq.saturating_add(1));
        }
        if let Some(e) = &self.end {
            gaps += e.readings.saturating_sub(expect);
        }
        gaps
    }
    /// Readings logged with status `ok`.
    pub fn ok(&self) -> usize {
        self.readings
            .iter()
            .filter(|r| r.reading.msg.status == "ok")
            .count()
    }
    /// Probe time of the start (the end line's) or of the first reading's start, s.
    pub fn start_s(&self) -> Option<f32> {
        self.end.as_ref().and_then(|e| e.start_s).or_else(|| {
            self.readings.first().map(|r| {
                r.t_s
                    - Some(r.reading.msg.probe_time_s)
                        .filter(|p| p.is_finite())
                        .unwrap_or(0.0)
            })
        })
    }
    /// `ok` readings per second of probe time from `after_s` past the start to the last
    /// reading; `None` without readings then.
    pub fn ok_per_s(&self, after_s: f32) -> Option<f64> {
        let from = self.start_s()? + after_s;
        let last = self.readings.last()?.t_s;
        let n = self
            .readings
            .iter()
            .filter(|r| r.t_s > from && r.reading.msg.status == "ok")
            .count();
        (last > from).then(|| n as f64 / (last - from) as f64)
    }
}

/// Everything reconstructed from a log.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Session {
    /// Readings in order.
    pub readings: Vec<LoggedReading>,
    /// Continuous streams in order.
    pub streams: Vec<LoggedStream>,
    /// Sweeps in order.
    pub sweeps: Vec<LoggedSweep>,
    /// Notable messages: warnings and errors, rejections, overruns, stalls, and boots.
    pub events: Vec<Message>,
    /// Messages recognised.
    pub messages: usize,
    /// Lines that were no firmware message.
    pub other_lines: usize,
    /// Lines that looked like a message but did not parse.
    pub errors: Vec<LogError>,
}

impl LoggedReading {
    /// The reading the firmware logged, as the core's [`pzt_probe::Reading`] (so that it prints
    /// through the same JSON as a host reading); `None` when its status or method is unknown.
    /// The same conversion as a reading received on the link ([`crate::link::reading_of`]).
    pub fn to_reading(&self) -> Option<pzt_probe::Reading> {
        crate::link::reading_of(&self.msg)
    }
}

/// The reading fields of a `reading` or `stream` message.
fn reading_of(m: &Message, sweep: Option<usize>) -> LoggedReading {
    LoggedReading {
        at: m.at,
        msg: ReadingMsg {
            status: m.str("status").unwrap_or_default().to_owned(),
            method: m.str("method").unwrap_or_default().to_owned(),
            f_hz: m.f32("f_hz"),
            f_sigma_hz: m.f32("f_sigma_hz"),
            e_kpa: m.f32("e_kpa"),
            e_sigma_kpa: m.f32("e_sigma_kpa"),
            e_repeat_kpa: m.f32("e_repeat_kpa"),
            q: m.f32("q"),
            loss_tangent: m.f32("loss"),
            loss_tangent_sigma: m.f32("loss_sigma"),
            force_n: m.f32("force_n"),
            force_sigma_n: m.f32("force_sigma_n"),
            probe_time_s: m.f32("probe_time_s").unwrap_or(f32::NAN),
            points: m.u16("points").unwrap_or(0),
        },
        sweep,
    }
}

/// Parse a whole decoded log.
pub fn parse_log(text: &str) -> Session {
    let templates = compiled();
    let mut s = Session::default();
    let mut settings: Option<Message> = None;
    let mut open: Option<LoggedSweep> = None;
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let m = match parse_with(&templates, line, raw) {
            Ok(Some(m)) => m,
            Ok(None) => {
                if !raw.trim().is_empty() {
                    s.other_lines += 1;
                }
                continue;
            }
            Err(e) => {
                s.errors.push(e);
                continue;
            }
        };
        s.messages += 1;
        match m.kind.as_str() {
            "settings" => {
                settings = Some(m.clone());
            }
            "point" => {
                let p = PointMsg {
                    tag: m.u16("tag").unwrap_or(0),
                    f_hz: m.f32("f_hz").unwrap_or(f32::NAN),
                    g_s: m.f32("g_s").unwrap_or(f32::NAN),
                    b_s: m.f32("b_s").unwrap_or(f32::NAN),
                    sigma_s: m.f32("sigma_s").unwrap_or(f32::NAN),
                };
                open.get_or_insert_with(|| LoggedSweep {
                    first_line: line,
                    settings: settings.clone(),
                    points: Vec::new(),
                    reading: None,
                })
                .points
                .push(p);
            }
            "reading" => {
                let idx = s.readings.len();
                let sweep = open.take().map(|mut sw| {
                    sw.reading = Some(idx);
                    s.sweeps.push(sw);
                    s.sweeps.len() - 1
                });
                s.readings.push(reading_of(&m, sweep));
            }
            "stream" => {
                let r = LoggedStreamReading {
                    seq: m.uint("seq").unwrap_or(0),
                    t_s: m.f32("t_s").unwrap_or(f32::NAN),
                    locked: m.get("locked") == Some(&Value::Bool(true)),
                    reading: reading_of(&m, None),
                };
                // A new stream after an end, or when the numbering starts again (an end lost).
                let new = match s.streams.last() {
                    None => true,
                    Some(x) => x.end.is_some() || x.readings.last().is_some_and(|p| r.seq <= p.seq),
                };
                if new {
                    s.streams.push(LoggedStream::default());
                }
                if let Some(x) = s.streams.last_mut() {
                    x.readings.push(r);
                }
            }
            "stream end" => {
                let end = LoggedStreamEnd {
                    line,
                    start_s: m.f32("start_s"),
                    readings: m.uint("readings").unwrap_or(0),
                    ok: m.uint("ok").unwrap_or(0),
                    dropped: m.uint("dropped").unwrap_or(0),
                    plan_work: m.uint("plan_work").unwrap_or(0),
                };
                match s.streams.last_mut() {
                    Some(x) if x.end.is_none() => x.end = Some(end),
                    _ => s.streams.push(LoggedStream {
                        readings: Vec::new(),
                        end: Some(end),
                    }),
                }
            }
            "boot" | "stalled" => {
                if let Some(sw) = open.take() {
                    s.sweeps.push(sw);
                }
                s.events.push(m.clone());
            }
            _ => {
                let notable = matches!(m.level, Some(Level::Warn | Level::Error))
                    || matches!(m.kind.as_str(), "rejected" | "overrun" | "stalled");
                if notable {
                    s.events.push(m.clone());
                }
            }
        }
    }
    if let Some(sw) = open.take() {
        s.sweeps.push(sw);
    }
    s
}
