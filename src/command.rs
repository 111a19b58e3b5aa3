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
//! are refused).
//!
//! | line | command |
//! |---|---|
//! | `measure` | take a reading with the current method and sweep |
//! | `method <paper\|sweep-g>` | choose the method (its default sweep is selected too) |
//! | `sweep <start_hz> <stop_hz> <step_hz> <settle_s> <integrate_s> <drive_v>` | set the sweep, validated against the board |
//! | `sweep default` | back to the method's default sweep |
//! | `air` | measure the air reference (probe lifted off) |
//! | `calibrate add <modulus_kpa>` | measure a reference sample of known modulus |
//! | `calibrate fit` | fit the calibration curve to the reference readings |
//! | `calibrate clear` | forget the reference readings |
//! | `calibrate paper` | use the paper's published calibration |
//! | `store` | write calibration and air reference to flash |
//! | `status` | report settings, calibration and counters |

use crate::hal::FrontEndScale;
use crate::measure::Method;
use crate::sweep::{SettingsError, SweepSettings};
use crate::units::{Hz, KPa, Seconds, Volts};

/// Longest accepted line in bytes (without the terminator).
pub const MAX_LINE: usize = 96;

/// Most words in a line (the longest command, `sweep`, has seven).
const MAX_WORDS: usize = 8;

/// Lowest and highest reference modulus `calibrate add` accepts, kPa.
pub const REFERENCE_KPA: (f32, f32) = (1.0, 100_000.0);

/// A parsed host command.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Take a reading.
    Measure,
    /// Select a method (and its default sweep).
    Method(Method),
    /// Use these (already validated) sweep settings.
    Sweep(SweepSettings),
    /// Use the method's default sweep.
    SweepDefault,
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
}

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
    /// A number outside its range (reference modulus).
    OutOfRange,
    /// Sweep settings the board rejects.
    Settings(SettingsError),
}

impl CommandError {
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
            CommandError::UnknownMethod => "unknown method (paper, sweep-g)",
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

/// Exact powers of ten in `f64` (10^0 ..= 10^22).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Parse one line (without its terminator) into a command; sweep settings are validated
/// against `scale`, the board's front end.
pub fn parse(line: &[u8], scale: &FrontEndScale) -> Result<Command, CommandError> {
    if line.len() > MAX_LINE {
        return Err(CommandError::Oversized);
    }
    let text = core::str::from_utf8(line).map_err(|_| CommandError::NotUtf8)?;
    let mut words: [&str; MAX_WORDS] = [""; MAX_WORDS];
    let mut n = 0;
    for w in text.split_ascii_whitespace() {
        match words.get_mut(n) {
            Some(slot) => *slot = w,
            None => return Err(CommandError::TooManyArguments),
        }
        n += 1;
    }
    let words = words.get(..n).unwrap_or(&[]);
    let Some((&head, args)) = words.split_first() else {
        return Err(CommandError::Empty);
    };
    let arity = |want: usize| -> Result<(), CommandError> {
        match args.len() {
            k if k < want => Err(CommandError::MissingArgument),
            k if k > want => Err(CommandError::TooManyArguments),
            _ => Ok(()),
        }
    };
    match head {
        "measure" => arity(0).map(|_| Command::Measure),
        "air" => arity(0).map(|_| Command::Air),
        "store" => arity(0).map(|_| Command::Store),
        "status" => arity(0).map(|_| Command::Status),
        "method" => {
            arity(1)?;
            args.first()
                .and_then(|m| Method::from_name(m))
                .map(Command::Method)
                .ok_or(CommandError::UnknownMethod)
        }
        "sweep" => {
            if args.first() == Some(&"default") {
                return arity(1).map(|_| Command::SweepDefault);
            }
            arity(6)?;
            let mut v = [0.0f32; 6];
            for (slot, w) in v.iter_mut().zip(args) {
                *slot = number(w)?;
            }
            let [start, stop, step, settle, integrate, drive] = v;
            let s = SweepSettings {
                start: Hz(start),
                stop: Hz(stop),
                step: Hz(step),
                settle: Seconds(settle),
                integrate: Seconds(integrate),
                drive: Volts(drive),
            };
            s.validate(scale).map_err(CommandError::Settings)?;
            Ok(Command::Sweep(s))
        }
        "calibrate" => {
            let (&sub, rest) = args.split_first().ok_or(CommandError::MissingArgument)?;
            let none = |c: Command| {
                if rest.is_empty() {
                    Ok(c)
                } else {
                    Err(CommandError::TooManyArguments)
                }
            };
            match sub {
                "add" => match rest {
                    [] => Err(CommandError::MissingArgument),
                    [w] => {
                        let e = number(w)?;
                        if (REFERENCE_KPA.0..=REFERENCE_KPA.1).contains(&e) {
                            Ok(Command::CalibrateAdd(KPa(e)))
                        } else {
                            Err(CommandError::OutOfRange)
                        }
                    }
                    _ => Err(CommandError::TooManyArguments),
                },
                "fit" => none(Command::CalibrateFit),
                "clear" => none(Command::CalibrateClear),
                "paper" => none(Command::CalibratePaper),
                _ => Err(CommandError::UnknownSubcommand),
            }
        }
        _ => Err(CommandError::UnknownCommand),
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

    fn scale() -> FrontEndScale {
        FrontEndScale {
            sample_rate: Hz(10_000.0),
            drive_volts_per_code: 5.0 * 3.3 / 4096.0,
            amps_per_code: 3.3 / 4096.0 / 300e3,
            monitor_volts_per_code: 3.3 / 4096.0 / 0.15,
        }
    }

    fn p(s: &str) -> Result<Command, CommandError> {
        parse(s.as_bytes(), &scale())
    }

    #[test]
    fn commands() {
        assert_eq!(p("measure"), Ok(Command::Measure));
        assert_eq!(p("  measure \t"), Ok(Command::Measure));
        assert_eq!(p("status"), Ok(Command::Status));
        assert_eq!(p("store"), Ok(Command::Store));
        assert_eq!(p("air"), Ok(Command::Air));
        assert_eq!(p("method sweep-g"), Ok(Command::Method(Method::SweepG)));
        assert_eq!(p("method paper"), Ok(Command::Method(Method::Paper)));
        assert_eq!(p("sweep default"), Ok(Command::SweepDefault));
        assert_eq!(
            p("sweep 200 260 2 0.02 0.03 5"),
            Ok(Command::Sweep(SweepSettings {
                start: Hz(200.0),
                stop: Hz(260.0),
                step: Hz(2.0),
                settle: Seconds(0.02),
                integrate: Seconds(0.03),
                drive: Volts(5.0),
            }))
        );
        assert_eq!(
            p("calibrate add 279"),
            Ok(Command::CalibrateAdd(KPa(279.0)))
        );
        assert_eq!(p("calibrate fit"), Ok(Command::CalibrateFit));
        assert_eq!(p("calibrate clear"), Ok(Command::CalibrateClear));
        assert_eq!(p("calibrate paper"), Ok(Command::CalibratePaper));
    }

    #[test]
    fn errors() {
        use CommandError::*;
        assert_eq!(p(""), Err(Empty));
        assert_eq!(p("   "), Err(Empty));
        assert_eq!(p("measur"), Err(UnknownCommand));
        assert_eq!(p("MEASURE"), Err(UnknownCommand));
        assert_eq!(p("measure now"), Err(TooManyArguments));
        assert_eq!(p("method"), Err(MissingArgument));
        assert_eq!(p("method fft"), Err(UnknownMethod));
        assert_eq!(p("method paper sweep-g"), Err(TooManyArguments));
        assert_eq!(p("sweep 200 260 2 0.02 0.03"), Err(MissingArgument));
        assert_eq!(p("sweep 200 260 2 0.02 0.03 5 6"), Err(TooManyArguments));
        assert_eq!(
            p("sweep 200 260 2 0.02 0.03 5 6 7 8"),
            Err(TooManyArguments)
        );
        assert_eq!(p("sweep default x"), Err(TooManyArguments));
        assert_eq!(p("sweep 200 260 2 0.02 0.03 five"), Err(BadNumber));
        assert_eq!(p("sweep 200 NaN 2 0.02 0.03 5"), Err(BadNumber));
        assert_eq!(p("sweep 200 inf 2 0.02 0.03 5"), Err(BadNumber));
        assert_eq!(p("sweep 200 1e39 2 0.02 0.03 5"), Err(BadNumber));
        assert_eq!(
            p("sweep 260 200 2 0.02 0.03 5"),
            Err(Settings(SettingsError::EmptyBand))
        );
        assert_eq!(
            p("sweep 200 260 0 0.02 0.03 5"),
            Err(Settings(SettingsError::StepNotPositive))
        );
        assert_eq!(
            p("sweep 200 260 2 0.02 0.03 500"),
            Err(Settings(SettingsError::DriveOutOfRange))
        );
        assert_eq!(
            p("sweep 200 3000 2 0.02 0.03 5"),
            Err(Settings(SettingsError::TooManyPoints))
        );
        assert_eq!(
            p("sweep 200 260 2 -1 0.03 5"),
            Err(Settings(SettingsError::SettleNegative))
        );
        assert_eq!(p("calibrate"), Err(MissingArgument));
        assert_eq!(p("calibrate add"), Err(MissingArgument));
        assert_eq!(p("calibrate add 0"), Err(OutOfRange));
        assert_eq!(p("calibrate add -5"), Err(OutOfRange));
        assert_eq!(p("calibrate add 1e6"), Err(OutOfRange));
        assert_eq!(p("calibrate add 5 6"), Err(TooManyArguments));
        assert_eq!(p("calibrate fit now"), Err(TooManyArguments));
        assert_eq!(p("calibrate undo"), Err(UnknownSubcommand));
        assert_eq!(parse(b"meas\xffure", &scale()), Err(NotUtf8));
        assert_eq!(parse(b"\xc3", &scale()), Err(NotUtf8));
        assert_eq!(parse(&[b'a'; MAX_LINE + 1], &scale()), Err(Oversized));
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
        let alphabet = b"measure method sweep calibrate add fit status store air paper sweep-g default 0123456789.-e+ \n\r\xff\xc3\x80NaNinf";
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
                let _ = parse(line, &scale());
                lines += 1;
            }
        }
        assert!(lines > 1000);
    }
}
