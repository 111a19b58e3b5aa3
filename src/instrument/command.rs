//! The host command line: bytes from the UART (ST-LINK virtual COM port) to typed commands.
//!
//! [`LineBuffer`] assembles bytes into lines (terminated by `\n` or `\r`, bounded at
//! [`MAX_LINE`] bytes); [`parse`] turns one line into a [`Command`]. Any input — malformed,
//! truncated, oversized, not UTF-8, out of range — yields a typed [`CommandError`]; nothing here
//! panics or allocates.
//!
//! # Grammar
//!
//! Words are separated by ASCII blanks; numbers are decimal (`f32` syntax; NaN and infinities
//! are refused); counts (`coarse_points`, `refine_points`, `stages`, `window_cycles`) are whole
//! numbers 0–255. Settings are checked against the board here; that they are settings of the
//! active method (and within that method's knob ranges) is checked when the firmware applies
//! them, by the method's own validation ([`crate::reading::Procedure::new`]).
//!
//! | line | command |
//! |---|---|
//! | `measure` | take a reading with the current method and settings |
//! | `method <name>` | choose the method by its [`Method::name`] — `auto` (the default: hold, falling back to fit, then sweep-G), `hold`, `fit`, `sweep-g`, `paper` — with its default settings |
//! | `sweep <start_hz> <stop_hz> <step_hz> <settle_s> <integrate_s> <drive_v>` | stepped-sweep settings (paper, sweep-g), validated against the board |
//! | `staged <band_start_hz> <band_stop_hz> <coarse_points> <coarse_settle_s> <integrate_s> <refine_points> <refine_span> <settle_tau> <drive_v>` | the fit method's settings (also auto's fit stage), validated against the board |
//! | `sweep default` | back to the method's default settings |
//! | `air` | measure the air reference (probe lifted off) |
//! | `calibrate add <modulus_kpa>` | measure a reference sample of known modulus |
//! | `calibrate fit` | fit the calibration curve to the reference readings |
//! | `calibrate clear` | forget the reference readings |
//! | `calibrate paper` | use the paper's published calibration |
//! | `store` | write calibration and air reference to flash |
//! | `status` | report settings, calibration and counters |
//! | `selftest` | run the self-test of the analog chain (as at power-on); readings are refused while it fails |
//! | `stream <seconds> [<segment_s> [<plan_segments>]]` | read continuously (0.1–600 s): numbered, time-stamped readings ([`crate::instrument::continuous`]); the tracker's segment length and segments per plan default to [`TrackerConfig::DEFAULT`]'s and are validated by [`TrackerConfig::validate`] before the stream starts |

use crate::engine::sweep::{SettingsError, SweepSettings};
use crate::estimate::staged::StagedSettings;
use crate::hal::FrontEndScale;
use crate::instrument::continuous::TrackerConfig;
use crate::loadcell::ForceWindow;
use crate::reading::{Method, Settings};
use crate::units::{Hz, KPa, Newtons, Seconds, Volts};

/// Longest accepted line in bytes (without the terminator).
pub const MAX_LINE: usize = 96;

/// Most words in a line (the longest command, `staged`, has ten).
const MAX_WORDS: usize = 10;

/// Shortest and longest `stream`, s.
pub const STREAM_SECONDS: (f32, f32) = (0.1, 600.0);

/// Lowest and highest reference modulus `calibrate add` accepts, kPa.
pub const REFERENCE_KPA: (f32, f32) = (1.0, 100_000.0);

/// A parsed host command.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Take a reading.
    Measure,
    /// Select a method (with its default settings).
    Method(Method),
    /// Use these settings (checked against the board; the firmware checks they suit the
    /// active method).
    Settings(Settings),
    /// Back to the active method's default settings.
    SettingsDefault,
    /// Measure the air reference.
    Air,
    /// Measure a reference sample of this modulus for the calibration fit.
    CalibrateAdd(KPa),
    /// Fit the calibration to the reference readings taken so far.
    CalibrateFit,
    /// Forget the reference readings.
    CalibrateClear,
    /// Use the paper's published calibration.
    CalibratePaper,
    /// Write calibration and air reference to flash.
    Store,
    /// Report status.
    Status,
    /// Discard unsaved changes: reload the unit profile from flash, as at power-on.
    Reload,
    /// List the commands, the methods and the default method.
    Help,
    /// Run the self-test of the analog chain (as at power-on).
    SelfTest,
    /// Read only inside this contact-force window (`force <min mN> <max mN>`).
    ForceWindow(ForceWindow),
    /// Take the load cell's sensitivity from this known weight resting on the tip
    /// (`weigh <grams>`, after an air reference gave the zero).
    Weigh(Newtons),
    /// Read continuously ([`crate::instrument::continuous`]): numbered, time-stamped readings
    /// until the request's time is over.
    Stream(StreamRequest),
}

/// What `stream` asks for: how long, and the tracker's settings it may set (the others are
/// [`TrackerConfig::DEFAULT`]'s). The tracker's ranges are checked by [`TrackerConfig::validate`]
/// when the stream is served, before it starts.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StreamRequest {
    /// How long to stream.
    pub seconds: Seconds,
    /// [`TrackerConfig::segment`].
    pub segment: Seconds,
    /// [`TrackerConfig::plan_segments`].
    pub plan_segments: u8,
}

impl StreamRequest {
    /// The tracker's settings this request asks for.
    pub fn tracker(&self) -> TrackerConfig {
        TrackerConfig {
            segment: self.segment,
            plan_segments: self.plan_segments,
            ..TrackerConfig::DEFAULT
        }
    }
}

/// Known weights `weigh` takes, grams: from 1 g (10 mN, a tenth of the window's top) to the
/// 100 g cell's full scale.
pub const WEIGH_GRAMS: (f32, f32) = (1.0, 100.0);
/// Standard gravity, N per gram.
const NEWTONS_PER_GRAM: f32 = 9.806_65e-3;

/// Why a line is not a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandError {
    /// The line holds no word.
    Empty,
    /// The line is longer than [`MAX_LINE`] bytes (it was discarded up to its terminator).
    Oversized,
    /// The line is not valid UTF-8.
    NotUtf8,
    /// The first word is no command.
    UnknownCommand,
    /// A required argument is missing (truncated line).
    MissingArgument,
    /// More arguments than the command takes.
    TooManyArguments,
    /// An argument that should be a number is not one (or is NaN or infinite).
    BadNumber,
    /// `method` names no method.
    UnknownMethod,
    /// `calibrate` with an unknown sub-command.
    UnknownSubcommand,
    /// A number outside its range (reference modulus, a count that is not a whole number
    /// 0–255).
    OutOfRange,
    /// Sweep settings the board rejects.
    Settings(SettingsError),
}

impl CommandError {
    /// Stable snake_case code (the host link's `Rejected` cause, `docs/protocol.md`).
    pub const fn code(self) -> &'static str {
        match self {
            CommandError::Empty => "empty",
            CommandError::Oversized => "oversized",
            CommandError::NotUtf8 => "not_utf8",
            CommandError::UnknownCommand => "unknown_command",
            CommandError::MissingArgument => "missing_argument",
            CommandError::TooManyArguments => "too_many_arguments",
            CommandError::BadNumber => "bad_number",
            CommandError::UnknownMethod => "unknown_method",
            CommandError::UnknownSubcommand => "unknown_subcommand",
            CommandError::OutOfRange => "out_of_range",
            CommandError::Settings(_) => "settings",
        }
    }

    /// One line for a human.
    pub const fn message(self) -> &'static str {
        match self {
            CommandError::Empty => "empty line",
            CommandError::Oversized => "line too long",
            CommandError::NotUtf8 => "line is not UTF-8",
            CommandError::UnknownCommand => "unknown command",
            CommandError::MissingArgument => "missing argument",
            CommandError::TooManyArguments => "too many arguments",
            CommandError::BadNumber => "not a finite number",
            CommandError::UnknownMethod => "unknown method (auto, hold, fit, sweep-g, paper)",
            CommandError::UnknownSubcommand => {
                "unknown calibrate sub-command (add, fit, clear, paper)"
            }
            CommandError::OutOfRange => "value out of range",
            CommandError::Settings(e) => e.message(),
        }
    }
}

impl core::fmt::Display for CommandError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())
    }
}

/// An optional sign at `b[*i]`: consumes it and returns true for `-`.
fn sign(b: &[u8], i: &mut usize) -> bool {
    match b.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    }
}

/// A decimal number: `[+-]digits[.digits][(e|E)[+-]digits]` (or `.digits`), finite as `f32`.
///
/// A small parser of its own rather than `f32::from_str`, whose exact-rounding tables cost
/// over 13 KiB of flash: the significand is accumulated exactly in a `u64` (19 digits), scaled
/// by exact powers of ten in `f64` and rounded to `f32` — within one unit in the last place of
/// `f32`, far below any setting's meaning.
fn number(word: &str) -> Result<f32, CommandError> {
    let b = word.as_bytes();
    let mut i = 0;
    let negative = sign(b, &mut i);
    let mut mantissa: u64 = 0;
    let mut digits = 0u32; // significant digits kept in `mantissa`
    let mut seen_digit = false;
    let mut exp10: i32 = 0;
    let mut after_point = false;
    while let Some(&c) = b.get(i) {
        match c {
            b'0'..=b'9' => {
                seen_digit = true;
                if digits < 19 {
                    if mantissa != 0 || c != b'0' {
                        digits += 1;
                    }
                    mantissa = mantissa * 10 + (c - b'0') as u64;
                    if after_point {
                        exp10 -= 1;
                    }
                } else if !after_point {
                    exp10 += 1;
                }
            }
            b'.' if !after_point => after_point = true,
            _ => break,
        }
        i += 1;
    }
    if !seen_digit {
        return Err(CommandError::BadNumber);
    }
    if let Some(b'e' | b'E') = b.get(i) {
        i += 1;
        let neg_exp = sign(b, &mut i);
        let mut e: i32 = 0;
        let mut any = false;
        while let Some(&c @ b'0'..=b'9') = b.get(i) {
            any = true;
            e = (e * 10 + (c - b'0') as i32).min(10_000);
            i += 1;
        }
        if !any {
            return Err(CommandError::BadNumber);
        }
        exp10 = exp10.saturating_add(if neg_exp { -e } else { e });
    }
    if i != b.len() {
        return Err(CommandError::BadNumber);
    }
    let mut v = mantissa as f64;
    let mut e = exp10.clamp(-400, 400);
    while e != 0 && v != 0.0 && v.is_finite() {
        let step = e.clamp(-22, 22);
        let p = POW10[step.unsigned_abs() as usize];
        v = if step > 0 { v * p } else { v / p };
        e -= step;
    }
    let v = if negative { -v } else { v } as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(CommandError::BadNumber)
    }
}

/// A count: a number that is whole, 0–255.
fn count(v: f32) -> Result<u8, CommandError> {
    if (0.0..=255.0).contains(&v) && v == libm::truncf(v) {
        Ok(v as u8)
    } else {
        Err(CommandError::OutOfRange)
    }
}

/// The `N` numbers of `args` (the caller checked the arity).
fn numbers<const N: usize>(args: &[&str]) -> Result<[f32; N], CommandError> {
    let mut v = [0.0f32; N];
    for (slot, w) in v.iter_mut().zip(args) {
        *slot = number(w)?;
    }
    Ok(v)
}

/// Exact powers of ten in `f64` (10^0 ..= 10^22).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The command line that sets a method's settings: the inverse of [`parse`] for `sweep` and
/// `staged` lines (`Display` writes the line; `f32` prints its shortest exact
/// form, so the line parses back to the same settings). Hold's settings have no command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettingsLine(Settings);

impl SettingsLine {
    /// The line for `s`, `None` for hold's settings.
    pub fn of(s: &Settings) -> Option<Self> {
        match s {
            Settings::Hold(_) => None,
            s => Some(Self(*s)),
        }
    }
}

impl core::fmt::Display for SettingsLine {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match &self.0 {
            Settings::Sweep(s) => write!(
                f,
                "sweep {} {} {} {} {} {}",
                s.start.0, s.stop.0, s.step.0, s.settle.0, s.integrate.0, s.drive.0
            ),
            Settings::Staged(s) => write!(
                f,
                "staged {} {} {} {} {} {} {} {} {}",
                s.band_start.0,
                s.band_stop.0,
                s.coarse_points,
                s.coarse_settle.0,
                s.integrate.0,
                s.refine_points,
                s.refine_span,
                s.settle_tau,
                s.drive.0
            ),
            Settings::Hold(_) => Ok(()),
        }
    }
}

/// Parse one line (without its terminator) into a command; sweep settings are validated
/// against `scale`, the board's front end.
pub fn parse(line: &[u8], scale: &FrontEndScale) -> Result<Command, CommandError> {
    let mut words: [&str; MAX_WORDS] = [""; MAX_WORDS];
    let words = split_words(line, &mut words)?;
    let Some((&head, args)) = words.split_first() else {
        return Err(CommandError::Empty);
    };
    match head {
        "measure" => arity(args, 0).map(|_| Command::Measure),
        "air" => arity(args, 0).map(|_| Command::Air),
        "store" => arity(args, 0).map(|_| Command::Store),
        "status" => arity(args, 0).map(|_| Command::Status),
        "reload" => arity(args, 0).map(|_| Command::Reload),
        "help" => arity(args, 0).map(|_| Command::Help),
        "selftest" => arity(args, 0).map(|_| Command::SelfTest),
        "method" => {
            arity(args, 1)?;
            let name = args.first().copied().unwrap_or_default();
            Method::from_name(name)
                .map(Command::Method)
                .ok_or(CommandError::UnknownMethod)
        }
        "sweep" if args.first() == Some(&"default") => {
            arity(args, 1).map(|_| Command::SettingsDefault)
        }
        "sweep" => sweep(args, scale).map(|s| Command::Settings(Settings::Sweep(s))),
        "staged" => staged(args, scale).map(|s| Command::Settings(Settings::Staged(s))),
        "calibrate" => calibrate(args),
        "force" => force_window(args),
        "weigh" => one_in(args, WEIGH_GRAMS).map(|g| Command::Weigh(Newtons(g * NEWTONS_PER_GRAM))),
        "stream" => stream(args),
        _ => Err(CommandError::UnknownCommand),
    }
}

/// The line's words (at most [`MAX_WORDS`]) in `buf`, after the length and UTF-8 checks.
fn split_words<'a>(
    line: &'a [u8],
    buf: &'a mut [&'a str; MAX_WORDS],
) -> Result<&'a [&'a str], CommandError> {
    if line.len() > MAX_LINE {
        return Err(CommandError::Oversized);
    }
    let text = core::str::from_utf8(line).map_err(|_| CommandError::NotUtf8)?;
    let mut n = 0;
    for w in text.split_ascii_whitespace() {
        match buf.get_mut(n) {
            Some(slot) => *slot = w,
            None => return Err(CommandError::TooManyArguments),
        }
        n += 1;
    }
    Ok(buf.get(..n).unwrap_or(&[]))
}

/// `Ok` when `args` has exactly `want` words.
fn arity(args: &[&str], want: usize) -> Result<(), CommandError> {
    match args.len() {
        k if k < want => Err(CommandError::MissingArgument),
        k if k > want => Err(CommandError::TooManyArguments),
        _ => Ok(()),
    }
}

/// The one argument of a command, a number within `(lo, hi)` (both included).
fn one_in(args: &[&str], (lo, hi): (f32, f32)) -> Result<f32, CommandError> {
    arity(args, 1)?;
    let v = number(args.first().copied().unwrap_or_default())?;
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(CommandError::OutOfRange)
    }
}

/// `stream <seconds> [<segment_s> [<plan_segments>]]`.
fn stream(args: &[&str]) -> Result<Command, CommandError> {
    let (head, rest) = args.split_at(args.len().min(1));
    let seconds = Seconds(one_in(head, STREAM_SECONDS)?);
    let d = TrackerConfig::DEFAULT;
    let segment = match rest.first() {
        Some(w) => Seconds(number(w)?),
        None => d.segment,
    };
    let plan_segments = match rest.get(1) {
        Some(w) => count(number(w)?)?,
        None => d.plan_segments,
    };
    if rest.len() > 2 {
        return Err(CommandError::TooManyArguments);
    }
    Ok(Command::Stream(StreamRequest {
        seconds,
        segment,
        plan_segments,
    }))
}

/// `sweep <start_hz> <stop_hz> <step_hz> <settle_s> <integrate_s> <drive_v>`.
fn sweep(args: &[&str], scale: &FrontEndScale) -> Result<SweepSettings, CommandError> {
    arity(args, 6)?;
    let [start, stop, step, settle, integrate, drive] = numbers(args)?;
    let s = SweepSettings {
        start: Hz(start),
        stop: Hz(stop),
        step: Hz(step),
        settle: Seconds(settle),
        integrate: Seconds(integrate),
        drive: Volts(drive),
    };
    s.validate(scale).map_err(CommandError::Settings)?;
    Ok(s)
}

/// `staged <band_start_hz> <band_stop_hz> <coarse_points> <coarse_settle_s> <integrate_s>
/// <refine_points> <refine_span> <settle_tau> <drive_v>`: the fit method's settings.
fn staged(args: &[&str], scale: &FrontEndScale) -> Result<StagedSettings, CommandError> {
    arity(args, 9)?;
    let [start, stop, coarse_points, coarse_settle, integrate, refine_points, refine_span, settle_tau, drive] =
        numbers(args)?;
    let s = StagedSettings {
        band_start: Hz(start),
        band_stop: Hz(stop),
        coarse_points: count(coarse_points)?,
        coarse_settle: Seconds(coarse_settle),
        integrate: Seconds(integrate),
        refine_points: count(refine_points)?,
        refine_span,
        settle_tau,
        drive: Volts(drive),
    };
    s.validate(scale).map_err(CommandError::Settings)?;
    Ok(s)
}

/// `calibrate add <kPa> | fit | clear | paper`.
/// `force <min mN> <max mN>`: the window, validated ([`ForceWindow::new`]).
fn force_window(args: &[&str]) -> Result<Command, CommandError> {
    arity(args, 2)?;
    let min = number(args.first().copied().unwrap_or_default())?;
    let max = number(args.get(1).copied().unwrap_or_default())?;
    ForceWindow::new(Newtons(min * 1e-3), Newtons(max * 1e-3))
        .map(Command::ForceWindow)
        .map_err(|_| CommandError::OutOfRange)
}

fn calibrate(args: &[&str]) -> Result<Command, CommandError> {
    let (&sub, rest) = args.split_first().ok_or(CommandError::MissingArgument)?;
    let none = |c: Command| arity(rest, 0).map(|_| c);
    match sub {
        "add" => one_in(rest, REFERENCE_KPA).map(|e| Command::CalibrateAdd(KPa(e))),
        "fit" => none(Command::CalibrateFit),
        "clear" => none(Command::CalibrateClear),
        "paper" => none(Command::CalibratePaper),
        _ => Err(CommandError::UnknownSubcommand),
    }
}

/// Assembles received bytes into lines of at most [`MAX_LINE`] bytes.
///
/// A line ends at `\n` or `\r`; empty lines (as between `\r` and `\n`) are skipped. A line that
/// grows beyond [`MAX_LINE`] is discarded up to its terminator and reported once as
/// [`CommandError::Oversized`].
#[derive(Clone, Debug, Default)]
pub struct LineBuffer {
    buf: heapless::Vec<u8, MAX_LINE>,
    overflow: bool,
    complete: bool,
}

impl LineBuffer {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            buf: heapless::Vec::new(),
            overflow: false,
            complete: false,
        }
    }

    /// Take one byte; returns a finished line (or the oversize error) at a terminator. The
    /// returned line stays valid until the next call.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], CommandError>> {
        if self.complete {
            self.buf.clear();
            self.complete = false;
        }
        if byte == b'\n' || byte == b'\r' {
            if self.overflow {
                self.overflow = false;
                self.buf.clear();
                return Some(Err(CommandError::Oversized));
            }
            if self.buf.is_empty() {
                return None;
            }
            self.complete = true;
            return Some(Ok(&self.buf));
        }
        if !self.overflow && self.buf.push(byte).is_err() {
            self.overflow = true;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<Command, CommandError> {
        parse(s.as_bytes(), &FrontEndScale::PROBE)
    }

    /// Each line parses to what it is paired with.
    fn check(cases: &[(&str, Result<Command, CommandError>)]) {
        for (line, want) in cases {
            assert_eq!(p(line), *want, "{line}");
        }
    }

    #[test]
    fn stream_takes_its_seconds_within_range() {
        use CommandError::*;
        let d = TrackerConfig::DEFAULT;
        let stream = |seconds, segment, plan_segments| {
            Command::Stream(StreamRequest {
                seconds: Seconds(seconds),
                segment: Seconds(segment),
                plan_segments,
            })
        };
        check(&[
            ("stream 3", Ok(stream(3.0, d.segment.0, d.plan_segments))),
            ("stream 0.1", Ok(stream(0.1, d.segment.0, d.plan_segments))),
            ("stream 3 0.012", Ok(stream(3.0, 0.012, d.plan_segments))),
            ("stream 3 0.012 4", Ok(stream(3.0, 0.012, 4))),
            ("stream", Err(MissingArgument)),
            ("stream 3 0.012 4 5", Err(TooManyArguments)),
            ("stream 3 x", Err(BadNumber)),
            ("stream 3 nan", Err(BadNumber)),
            ("stream 3 0.012 nan", Err(BadNumber)),
            ("stream 3 0.012 2.5", Err(OutOfRange)),
            ("stream 3 0.012 -1", Err(OutOfRange)),
            ("stream 3 0.012 256", Err(OutOfRange)),
            ("stream x", Err(BadNumber)),
            ("stream nan", Err(BadNumber)),
            ("stream 0.05", Err(OutOfRange)),
            ("stream 601", Err(OutOfRange)),
            ("stream -1", Err(OutOfRange)),
        ]);
    }

    #[test]
    fn commands() {
        check(&[
            ("measure", Ok(Command::Measure)),
            ("  measure \t", Ok(Command::Measure)),
            ("status", Ok(Command::Status)),
            ("store", Ok(Command::Store)),
            ("air", Ok(Command::Air)),
            ("selftest", Ok(Command::SelfTest)),
            ("selftest now", Err(CommandError::TooManyArguments)),
        ]);
        // The force window in mN, validated: ordered, inside 3–200 mN.
        assert_eq!(
            p("force 15 50"),
            Ok(Command::ForceWindow(
                ForceWindow::new(Newtons(15.0 * 1e-3), Newtons(50.0 * 1e-3)).unwrap()
            ))
        );
        for bad in ["force 50 15", "force 2 50", "force 15 250", "force 15 15"] {
            assert_eq!(p(bad), Err(CommandError::OutOfRange), "{bad}");
        }
        assert_eq!(p("force 15"), Err(CommandError::MissingArgument));
        assert_eq!(p("force 15 nan"), Err(CommandError::BadNumber));
        // A known weight of 1–100 g.
        assert_eq!(
            p("weigh 10"),
            Ok(Command::Weigh(Newtons(10.0 * 9.806_65e-3)))
        );
        assert_eq!(p("weigh 0.5"), Err(CommandError::OutOfRange));
        assert_eq!(p("weigh 101"), Err(CommandError::OutOfRange));
        // Every method by its name.
        for m in Method::ALL {
            assert_eq!(
                p(&std::format!("method {}", m.name())),
                Ok(Command::Method(m))
            );
        }
        assert_eq!(p("method auto"), Ok(Command::Method(Method::Auto)));
        assert_eq!(p("sweep default"), Ok(Command::SettingsDefault));
        assert_eq!(
            p("sweep 200 260 2 0.02 0.03 5"),
            Ok(Command::Settings(Settings::Sweep(SweepSettings {
                start: Hz(200.0),
                stop: Hz(260.0),
                step: Hz(2.0),
                settle: Seconds(0.02),
                integrate: Seconds(0.03),
                drive: Volts(5.0),
            })))
        );
        // Every method's defaults, as `SettingsLine` spells them, parse back to themselves;
        // hold's have no line.
        for s in Method::ALL.map(|m| m.default_settings()).iter() {
            match SettingsLine::of(s) {
                Some(line) => {
                    let line = std::format!("{line}");
                    assert_eq!(p(&line), Ok(Command::Settings(*s)), "{line}");
                }
                None => assert!(matches!(s, Settings::Hold(_))),
            }
        }
        // Settings the fit method cannot take: three coarse points, a zero span.
        assert!(p("staged 170 290 3 0.02 0.02 5 0.8 3 5").is_err());
        assert!(p("staged 170 290 6 0.02 0.02 8 0 2 5").is_err());
        check(&[
            ("calibrate add 279", Ok(Command::CalibrateAdd(KPa(279.0)))),
            ("calibrate fit", Ok(Command::CalibrateFit)),
            ("calibrate clear", Ok(Command::CalibrateClear)),
            ("calibrate paper", Ok(Command::CalibratePaper)),
        ]);
    }

    #[test]
    fn errors() {
        use CommandError::*;
        use SettingsError as S;
        let set = Settings;
        // Each line and the error it must give.
        let cases: &[(&str, CommandError)] = &[
            ("", Empty),
            ("   ", Empty),
            ("measur", UnknownCommand),
            ("MEASURE", UnknownCommand),
            ("measure now", TooManyArguments),
            ("method", MissingArgument),
            ("method fft", UnknownMethod),
            ("method paper sweep-g", TooManyArguments),
            ("sweep 200 260 2 0.02 0.03", MissingArgument),
            ("sweep 200 260 2 0.02 0.03 5 6", TooManyArguments),
            ("sweep 200 260 2 0.02 0.03 5 6 7 8", TooManyArguments),
            ("sweep default x", TooManyArguments),
            ("sweep 200 260 2 0.02 0.03 five", BadNumber),
            ("sweep 200 NaN 2 0.02 0.03 5", BadNumber),
            ("sweep 200 inf 2 0.02 0.03 5", BadNumber),
            ("sweep 200 1e39 2 0.02 0.03 5", BadNumber),
            ("sweep 260 200 2 0.02 0.03 5", set(S::EmptyBand)),
            ("sweep 200 260 0 0.02 0.03 5", set(S::StepNotPositive)),
            ("sweep 200 260 2 0.02 0.03 500", set(S::DriveOutOfRange)),
            ("sweep 200 3000 2 0.02 0.03 5", set(S::TooManyPoints)),
            ("sweep 200 260 2 -1 0.03 5", set(S::SettleNegative)),
            ("staged 170 290 6 0.02 0.02 5 0.8 3", MissingArgument),
            ("staged 170 290 6 0.02 0.02 5 0.8 3 5 6", TooManyArguments),
            ("staged 170 290 6.5 0.02 0.02 5 0.8 3 5", OutOfRange),
            ("staged 170 290 256 0.02 0.02 5 0.8 3 5", OutOfRange),
            ("staged 170 290 6 0.02 0.02 -1 0.8 3 5", OutOfRange),
            ("staged 170 290 6 0.02 0.02 5 x 3 5", BadNumber),
            ("staged 290 170 6 0.02 0.02 5 0.8 3 5", set(S::EmptyBand)),
            // Two coarse points suit no refinement; a span of 5 linewidths with one refine point
            // neither (track ignores the span but needs two steps).
            (
                "staged 170 290 2 0.02 0.02 5 0.8 3 5",
                set(S::KnobOutOfRange),
            ),
            ("staged 170 290 6 0.02 0.02 1 5 3 5", set(S::KnobOutOfRange)),
            (
                "staged 170 290 6 0.02 0.02 5 0.8 3 500",
                set(S::DriveOutOfRange),
            ),
            ("ringdown 170 290 230 0.04 0.04 2 2 5", UnknownCommand),
            ("calibrate", MissingArgument),
            ("calibrate add", MissingArgument),
            ("calibrate add 0", OutOfRange),
            ("calibrate add -5", OutOfRange),
            ("calibrate add 1e6", OutOfRange),
            ("calibrate add 5 6", TooManyArguments),
            ("calibrate fit now", TooManyArguments),
            ("calibrate undo", UnknownSubcommand),
        ];
        for (line, want) in cases {
            assert_eq!(p(line), Err(*want), "{line}");
        }
        assert_eq!(parse(b"meas\xffure", &FrontEndScale::PROBE), Err(NotUtf8));
        assert_eq!(parse(b"\xc3", &FrontEndScale::PROBE), Err(NotUtf8));
        assert_eq!(
            parse(&[b'a'; MAX_LINE + 1], &FrontEndScale::PROBE),
            Err(Oversized)
        );
        for e in [Empty, Oversized, NotUtf8, Settings(SettingsError::TooLong)] {
            assert!(!e.message().is_empty());
        }
    }

    fn feed(
        lb: &mut LineBuffer,
        bytes: &[u8],
    ) -> std::vec::Vec<Result<std::vec::Vec<u8>, CommandError>> {
        let mut out = std::vec::Vec::new();
        for &b in bytes {
            if let Some(r) = lb.push(b) {
                out.push(r.map(|l| l.to_vec()));
            }
        }
        out
    }

    #[test]
    fn every_method_is_named_in_the_unknown_method_message() {
        // One method set everywhere: the STM32 image parses every method too, and the error
        // for an unknown one lists them all.
        let msg = CommandError::UnknownMethod.message();
        for m in Method::ALL {
            assert!(msg.contains(m.name()), "{msg} lacks {}", m.name());
        }
        let p = |s: &str| parse(s.as_bytes(), &FrontEndScale::PROBE);
        assert_eq!(p("method fft"), Err(CommandError::UnknownMethod));
    }

    #[test]
    fn line_buffer() {
        let mut lb = LineBuffer::new();
        let got = feed(&mut lb, b"status\r\nmeasure\n\n\rmeth");
        assert_eq!(got, vec![Ok(b"status".to_vec()), Ok(b"measure".to_vec())]);
        let got = feed(&mut lb, b"od paper\n");
        assert_eq!(got, vec![Ok(b"method paper".to_vec())]);
        // Oversized: reported once, then the next line is fine.
        let mut long = vec![b'x'; 300];
        long.extend_from_slice(b"\nstatus\n");
        let got = feed(&mut lb, &long);
        assert_eq!(
            got,
            vec![Err(CommandError::Oversized), Ok(b"status".to_vec())]
        );
        // Exactly MAX_LINE fits.
        let mut exact = vec![b'y'; MAX_LINE];
        exact.push(b'\n');
        let got = feed(&mut lb, &exact);
        assert_eq!(got, vec![Ok(vec![b'y'; MAX_LINE])]);
    }

    #[test]
    fn numbers() {
        for (s, v) in [
            ("0", 0.0f32),
            ("5", 5.0),
            ("-5", -5.0),
            ("+2.5", 2.5),
            ("0.02", 0.02),
            ("0.03", 0.03),
            (".5", 0.5),
            ("5.", 5.0),
            ("200", 200.0),
            ("1e3", 1000.0),
            ("2.5E-2", 0.025),
            ("1e-50", 0.0),
            ("123456789012345678901234", 1.234_567_9e23),
            ("0.000000000000000000000000123", 1.23e-25),
        ] {
            assert_eq!(number(s), Ok(v), "{s}");
        }
        for s in [
            "", "-", ".", "e5", "1e", "1e+", "1.2.3", "1x", "inf", "NaN", "1e39", "--1", "0x10",
        ] {
            assert_eq!(number(s), Err(CommandError::BadNumber), "{s}");
        }
        // Agrees with the standard library's correctly rounded parser to within one ulp.
        let mut x: u64 = 0x1234_5678_9ABC_DEF1;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let s = std::format!(
                "{}.{:03}e{}",
                x % 100_000,
                (x >> 20) % 1000,
                ((x >> 40) % 40) as i32 - 20
            );
            let ours = number(&s).unwrap();
            let std_: f32 = s.parse().unwrap();
            assert!(
                (ours - std_).abs() <= std_.abs() * f32::EPSILON,
                "{s}: {ours} vs {std_}"
            );
        }
    }

    /// Arbitrary bytes never panic, and every line is either a command or a typed error.
    #[test]
    fn arbitrary_bytes_never_panic() {
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        let mut lb = LineBuffer::new();
        let alphabet = b"measure method sweep staged calibrate add fit auto status store air paper sweep-g default 0123456789.-e+ \n\r\xff\xc3\x80NaNinf";
        let mut lines = 0;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let b = if x.is_multiple_of(3) {
                (x >> 8) as u8
            } else {
                alphabet[((x >> 16) as usize) % alphabet.len()]
            };
            if let Some(Ok(line)) = lb.push(b) {
                let _ = parse(line, &FrontEndScale::PROBE);
                lines += 1;
            }
        }
        assert!(lines > 1000);
    }
}
