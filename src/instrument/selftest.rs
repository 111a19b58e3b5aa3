//! The power-on self-test of the analog chain: DAC and drive amplifier, PZT and wiring, sense
//! and monitor ADC channels.
//!
//! The PZT is driven at [`TEST_HZ`], far above every resonance the probe can have (free 232 Hz;
//! loaded 136–267 Hz over 1 kPa to rigid contact at any preload, `hal-sim`), where the plate is
//! its static capacitance: `Y = G0 + j 2 pi f C0` plus a motional remainder of at most
//! [`MOTIONAL_BOUND`] of `C0`. Four gap-free windows of one plan go through the one plan loop
//! ([`crate::reading::driver::run_plans`], the readings' stall rule); each is converted by the readings'
//! [`point_from_raw`] and the four points pass the readings' [`screen`] (clipping, no current,
//! knocks). What the screen cannot tell apart is told from the raw demodulator sums, which
//! carry both channels' rail counts and offsets: a channel that reads one rail throughout is a
//! stuck ADC; no drive voltage with current flowing is a short that pulls the drive down; a
//! clipped or unclipped current that is mostly in phase with the voltage is a resistive path
//! (short, leak). The capacitance is then compared with the unit's air reference `C0`
//! (`profile::AirReference::static_capacitance`), or, for a unit without one, with the nominal
//! plate ([`NOMINAL_C0`]) under its manufacturing tolerance.
//!
//! The session runs it at power-on and on the `selftest` command; while its last run failed,
//! every reading is refused with the fault's message ([`crate::instrument::session`]). Allocation free,
//! panic free; host-tested on `hal-sim`'s fault scenes (`tests/selftest.rs`).

use crate::dsp::lockin::solve;
use crate::engine::sweep::{
    amplitude_codes, check_frequency, point_from_raw, PointError, SweepPoint,
};
use crate::engine::{PointPlan, PointRaw};
use crate::estimate::{screen, OPEN_CIRCUIT_A};
use crate::hal::FrontEndScale;
use crate::reading::driver::{run_plans, Plans, PointSource, Stop};
use crate::status::Failure;
use crate::unit::profile::UnitProfile;
use crate::units::bounded;
use crate::units::{Farads, Hz, Seconds, Siemens, Volts};

/// The test frequency: 3.8 times the highest loaded resonance (267 Hz, rigid contact) and 4.3
/// times the free one, a multiple of 10 Hz but of neither 50 nor 60 Hz. Each window is a whole
/// number of 10 Hz periods ([`WINDOW_CYCLES`]), so every mains harmonic (50 or 60 Hz: all on
/// the 10 Hz grid) falls on a null of the sine fit, and the drive is not one of them.
pub const TEST_HZ: f32 = 1010.0;
/// Drive cycles per window: 0.1 s at [`TEST_HZ`] (1000 samples at 10 kHz).
pub const WINDOW_CYCLES: u32 = 101;
/// Gap-free windows: four, the fewest [`screen`]'s knock check (a window against its two
/// neighbours, from the second on) can judge.
pub const WINDOWS: usize = 4;
/// Commanded drive amplitude (peak). The sense current of the nominal plate at this voltage,
/// `2 pi 1010 Hz x 210 pF x 2 V = 2.7 uA`, is half the transimpedance stage's full scale
/// (`1.65 V / 300 kOhm = 5.5 uA`) before any filter attenuation: a plate of up to twice the
/// nominal capacitance is still measured unclipped.
pub const DRIVE: Volts = Volts(2.0);
/// Tag of the self-test's plan (readings count theirs from 1).
pub const TAG: u16 = u16::MAX;
/// Settling before the first window, in free-probe time constants `Q / (pi f0)`: a ring-down
/// of a reading just ended (the mode rings at its own resonance, 0.8 kHz from the drive) decays
/// to 5 % of its amplitude, which the sine fit at [`TEST_HZ`] rejects by another factor of
/// about `pi x 780 Hz x 0.1 s = 240`.
pub const SETTLE_TAUS: f32 = 3.0;

/// The nominal plate of a unit without an air reference: 7 x 1 mm PZT-5A, 0.5 mm thick,
/// `eps33 = 1700 eps0`: `C0 = 1700 x 8.854e-12 x 7e-6 / 0.5e-3 = 210.7 pF` (`hal-sim`'s
/// `Pzt::default`, 210 pF).
pub const NOMINAL_C0: Farads = Farads(210e-12);
/// The nominal plate's free resonance and Q (`hal-sim`'s free probe), for the settling time of
/// a unit without an air reference.
const NOMINAL_FREE: (f32, f32) = (232.3, 40.0);

/// Largest motional share of the susceptance at [`TEST_HZ`], as a fraction of `2 pi f C0`:
/// `|Im(alpha^2 / (c + j w m + k / (j w)))| / (w C0)` over every contact the probe can be in
/// at power-on (free; 1 kPa to rigid at 0.03–1 N). Above resonance the mode is mass-like and
/// its susceptance negative; the worst case is the stiffest contact (267 Hz), 0.324 %.
/// `tests/selftest.rs` recomputes it from `hal-sim`'s closed-form admittance and checks this
/// bound within 10 % of it.
pub const MOTIONAL_BOUND: f32 = 0.0035;
/// Drift of `C0` the test allows since the air reference: PZT-5A's permittivity changes by
/// 0.1–0.5 %/K (`docs/methods.md`); 0.5 %/K over 10 K between the air reference and power-on.
pub const TEMPERATURE_ALLOWANCE: f32 = 0.05;
/// Manufacturing tolerance of the nominal plate (no air reference): permittivity of PZT-5A
/// ±10 % (vendors' K33 tolerance), thickness 0.5 ± 0.025 mm (5 %), the transimpedance and
/// monitor resistors 1 % each; the temperature allowance and the motional bound on top.
pub const NOMINAL_TOLERANCE: f32 = 0.10 + 0.05 + 0.02 + TEMPERATURE_ALLOWANCE + MOTIONAL_BOUND;
/// Standard uncertainties of the measured capacitance added to its tolerance.
pub const SIGMAS: f32 = 5.0;

/// What the self-test compares with.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Expected {
    /// The plate's static capacitance.
    pub capacitance: Farads,
    /// Its static conductance.
    pub conductance: Siemens,
    /// Allowed relative deviation of the capacitance (before the measurement's own `SIGMAS`).
    pub tolerance: f32,
    /// True when from the unit's air reference, false for the nominal plate.
    pub from_air: bool,
    /// The free probe's resonance and Q (the settling time).
    free: (f32, f32),
}

/// The reference of `unit`: its air reference with [`MOTIONAL_BOUND`] and
/// [`TEMPERATURE_ALLOWANCE`], or the nominal plate with [`NOMINAL_TOLERANCE`].
pub fn expected(unit: &UnitProfile) -> Expected {
    match unit
        .air
        .filter(|a| a.is_valid() && a.static_capacitance.0 > 0.0)
    {
        Some(a) => Expected {
            capacitance: a.static_capacitance,
            conductance: a.static_conductance,
            tolerance: MOTIONAL_BOUND + TEMPERATURE_ALLOWANCE,
            from_air: true,
            free: (a.free_resonance.0, a.free_q),
        },
        None => Expected {
            capacitance: NOMINAL_C0,
            conductance: Siemens(0.0),
            tolerance: NOMINAL_TOLERANCE,
            from_air: false,
            free: NOMINAL_FREE,
        },
    }
}

/// Which ADC channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    /// The sense current (transimpedance amplifier).
    Current,
    /// The drive monitor (PZT voltage divider).
    Monitor,
}

/// What the self-test found wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SelfTestFault {
    /// The self-test's plan does not fit this board's converters (sample rate or DAC range).
    Board,
    /// No window came from the converters within the stall rule: the sample stream is dead.
    NoSamples,
    /// An ADC channel reads one rail throughout, with no signal on it.
    AdcRail(Channel),
    /// No drive voltage at the PZT and no current: the DAC or the drive amplifier (a DAC stuck
    /// at one code).
    NoDrive,
    /// No current through the PZT (below [`OPEN_CIRCUIT_A`]): the plate or its wiring is open.
    OpenPzt,
    /// The PZT conducts: the in-phase current exceeds the plate's capacitive current (a short,
    /// or a leak a thousand times the plate's dielectric loss), or current flows while the
    /// drive voltage has collapsed.
    ShortedPzt,
    /// The sense current reaches a rail while mostly capacitive: a capacitance far above the
    /// plate's, or the sense gain is wrong.
    Clipped,
    /// A knock or interference disturbed the test.
    Interference,
    /// The capacitance is outside its tolerance around the reference.
    Capacitance,
}

impl SelfTestFault {
    /// Stable snake_case code, as logged.
    pub const fn code(self) -> &'static str {
        match self {
            SelfTestFault::Board => "board",
            SelfTestFault::NoSamples => "no_samples",
            SelfTestFault::AdcRail(Channel::Current) => "adc_rail_current",
            SelfTestFault::AdcRail(Channel::Monitor) => "adc_rail_monitor",
            SelfTestFault::NoDrive => "no_drive",
            SelfTestFault::OpenPzt => "open_pzt",
            SelfTestFault::ShortedPzt => "shorted_pzt",
            SelfTestFault::Clipped => "clipped",
            SelfTestFault::Interference => "interference",
            SelfTestFault::Capacitance => "capacitance",
        }
    }

    /// What is wrong and what to do, for a human.
    pub const fn message(self) -> &'static str {
        match self {
            SelfTestFault::Board => "self-test does not fit this board's converters: firmware and board do not match",
            SelfTestFault::NoSamples => "self-test: no samples from the converters (ADC/DMA stream stopped): service the probe",
            SelfTestFault::AdcRail(Channel::Current) => "self-test: the sense-current ADC reads a constant rail: sense amplifier or ADC fault, service the probe",
            SelfTestFault::AdcRail(Channel::Monitor) => "self-test: the drive-monitor ADC reads a constant rail: monitor divider or ADC fault, service the probe",
            SelfTestFault::NoDrive => "self-test: no drive voltage at the PZT: DAC or drive amplifier fault, service the probe",
            SelfTestFault::OpenPzt => "self-test: no current through the PZT: plate or wiring open, check the probe cable",
            SelfTestFault::ShortedPzt => "self-test: the PZT conducts like a resistor: plate or wiring shorted, check the probe cable",
            SelfTestFault::Clipped => "self-test: sense current at full scale: capacitance far too high or sense gain fault, check the probe cable",
            SelfTestFault::Interference => "self-test disturbed by a knock or interference: hold the probe still and run selftest",
            SelfTestFault::Capacitance => "self-test: PZT capacitance out of tolerance: cracked plate or another probe; in free air take air, then run selftest",
        }
    }

    /// Every fault, in declaration order.
    pub const ALL: [SelfTestFault; 10] = [
        SelfTestFault::Board,
        SelfTestFault::NoSamples,
        SelfTestFault::AdcRail(Channel::Current),
        SelfTestFault::AdcRail(Channel::Monitor),
        SelfTestFault::NoDrive,
        SelfTestFault::OpenPzt,
        SelfTestFault::ShortedPzt,
        SelfTestFault::Clipped,
        SelfTestFault::Interference,
        SelfTestFault::Capacitance,
    ];
}

/// A self-test's outcome as logged: `not_run` (`None`), `passed` or the fault's code.
pub fn outcome_code(o: Option<Result<(), SelfTestFault>>) -> &'static str {
    match o {
        None => "not_run",
        Some(Ok(())) => "passed",
        Some(Err(f)) => f.code(),
    }
}

/// The outcome of one self-test, with what it measured (`NaN` where it measured nothing).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SelfTestReport {
    /// Passed, or the fault.
    pub outcome: Result<(), SelfTestFault>,
    /// The drive frequency (from the tuning word).
    pub freq: Hz,
    /// Measured capacitance `Im(Y) / (2 pi f)`, mean of the windows.
    pub capacitance: Farads,
    /// Its standard uncertainty.
    pub capacitance_sigma: Farads,
    /// Measured conductance `Re(Y)`, mean of the windows.
    pub conductance: Siemens,
    /// Sense current amplitude (peak), mean of the windows.
    pub current_a: f32,
    /// Drive amplitude at the PZT (peak), mean of the windows.
    pub drive_v: f32,
    /// What it was compared with.
    pub expected: Expected,
    /// Probe time the test took.
    pub probe_time: Seconds,
}

impl SelfTestReport {
    fn fault(f: SelfTestFault, freq: Hz, expected: Expected) -> Self {
        Self {
            outcome: Err(f),
            freq,
            capacitance: Farads(f32::NAN),
            capacitance_sigma: Farads(f32::NAN),
            conductance: Siemens(f32::NAN),
            current_a: f32::NAN,
            drive_v: f32::NAN,
            expected,
            probe_time: Seconds(0.0),
        }
    }

    /// True when the test passed.
    pub fn passed(&self) -> bool {
        self.outcome.is_ok()
    }
}

/// The self-test as a measurement of the plan loop: one plan of [`WINDOWS`] gap-free windows.
#[derive(Clone, Debug)]
pub struct SelfTest {
    plan: PointPlan,
    issued: bool,
    raws: heapless::Vec<PointRaw, WINDOWS>,
}

impl SelfTest {
    /// The test's plan on `scale` for a unit expected as `e` (the settling from its free
    /// probe); `Board` when [`TEST_HZ`] or [`DRIVE`] do not fit the converters.
    pub fn new(scale: &FrontEndScale, e: &Expected) -> Result<Self, SelfTestFault> {
        let ftw = check_frequency(TEST_HZ, scale).map_err(|_| SelfTestFault::Board)?;
        let drive = Volts(DRIVE.0.min(scale.max_drive_volts()));
        let amplitude_codes = amplitude_codes(drive, scale).map_err(|_| SelfTestFault::Board)?;
        let (f0, q) = e.free;
        let tau = if f0 > 0.0 && q > 0.0 {
            q / (core::f32::consts::PI * f0)
        } else {
            NOMINAL_FREE.1 / (core::f32::consts::PI * NOMINAL_FREE.0)
        };
        let settle = bounded(SETTLE_TAUS * tau * scale.sample_rate.0, 0.0, 1e6);
        Ok(Self {
            plan: PointPlan {
                ftw,
                amplitude_codes,
                settle_samples: settle as u32,
                cycles: WINDOW_CYCLES,
                windows: WINDOWS as u16,
                open: false,
                aligned: false,
                tag: TAG,
            },
            issued: false,
            raws: heapless::Vec::new(),
        })
    }

    /// The plan it asks for.
    pub fn plan(&self) -> PointPlan {
        self.plan
    }

    /// The windows received so far.
    pub fn windows(&self) -> &[PointRaw] {
        &self.raws
    }
}

impl Plans for SelfTest {
    fn next_plan(&mut self) -> Option<PointPlan> {
        if self.issued {
            return None;
        }
        self.issued = true;
        Some(self.plan)
    }
    /// Keeps the raw window (both channels' sums and rail counts); the test's windows are no
    /// admittance points of a reading.
    fn accept(&mut self, raw: &PointRaw) -> Option<SweepPoint> {
        let _ = self.raws.push(*raw);
        None
    }
    fn is_complete(&self) -> bool {
        self.issued && self.raws.is_full()
    }
}

/// A channel of `raw` that sat on a converter rail for every sample, with no signal on it (a
/// signal clipped at both rails still has its fundamental).
fn stuck_at_rail(raw: &PointRaw, ch: Channel) -> bool {
    let n = raw.sums.reference.n;
    let (sums, hits) = match ch {
        Channel::Current => (&raw.sums.current, raw.sums.current_rail_hits),
        Channel::Monitor => (&raw.sums.monitor, raw.sums.monitor_rail_hits),
    };
    n > 0 && hits >= n && solve(sums, &raw.sums.reference).is_none_or(|p| !(p.value.norm() >= 1.0))
}

/// Sense current amplitude (A, peak) of `raw`, and whether it touched a rail.
fn current_of(raw: &PointRaw, scale: &FrontEndScale) -> (f32, bool) {
    let a = solve(&raw.sums.current, &raw.sums.reference).map_or(0.0, |p| {
        (p.value.norm() * scale.amps_per_code as f64) as f32
    });
    (a, raw.sums.current_rail_hits > 0)
}

/// Judge the windows of a self-test on `scale` against `e`.
pub fn classify(raws: &[PointRaw], scale: &FrontEndScale, e: &Expected) -> SelfTestReport {
    let freq = raws.first().map_or(Hz(TEST_HZ), |r| {
        Hz(crate::dsp::dds::frequency_hz(r.plan.ftw, scale.sample_rate.0 as f64) as f32)
    });
    let fault = |f| SelfTestReport::fault(f, freq, *e);
    if raws.is_empty() {
        return fault(SelfTestFault::NoSamples);
    }
    for ch in [Channel::Current, Channel::Monitor] {
        if raws.iter().all(|r| stuck_at_rail(r, ch)) {
            return fault(SelfTestFault::AdcRail(ch));
        }
    }
    let mut points: heapless::Vec<SweepPoint, WINDOWS> = heapless::Vec::new();
    for r in raws {
        match point_from_raw(r, scale) {
            Ok(p) => {
                let _ = points.push(p);
            }
            Err(PointError::NoDrive) => {
                // No drive voltage: a DAC or amplifier that does not drive, or a short that
                // pulls the drive down while current flows.
                let (i, rail) = current_of(r, scale);
                let f = if rail || i >= OPEN_CIRCUIT_A {
                    SelfTestFault::ShortedPzt
                } else {
                    SelfTestFault::NoDrive
                };
                return fault(f);
            }
            Err(PointError::Degenerate) => return fault(SelfTestFault::NoSamples),
        }
    }
    let n = points.len() as f32;
    let mean = |k: fn(&SweepPoint) -> f32| points.iter().map(k).sum::<f32>() / n;
    let (g, b) = (mean(|p| p.g_s), mean(|p| p.b_s));
    let w = 2.0 * core::f32::consts::PI * freq.0;
    // The standard uncertainty of the mean susceptance: the points' own (from the sine fits'
    // residuals) or their scatter, whichever is larger.
    let own = libm::sqrtf(points.iter().map(|p| p.sigma_s * p.sigma_s).sum::<f32>()) / n;
    let scatter = libm::sqrtf(
        points
            .iter()
            .map(|p| (p.b_s - b) * (p.b_s - b))
            .sum::<f32>()
            / (n - 1.0).max(1.0)
            / n,
    );
    let sigma_c = own.max(scatter) / w;
    let c = b / w;
    let measured = |outcome| SelfTestReport {
        outcome,
        freq,
        capacitance: Farads(c),
        capacitance_sigma: Farads(sigma_c),
        conductance: Siemens(g),
        current_a: mean(|p| p.current_a),
        drive_v: mean(|p| p.drive_v),
        expected: *e,
        probe_time: Seconds(0.0),
    };
    // The capacitive current the reference plate carries per volt.
    let b_ref = w * e.capacitance.0;
    // Resistive: the in-phase admittance beyond the reference's exceeds the reference plate's
    // capacitive one (loss angle above 45 degrees; PZT-5A's dielectric loss is tan d <= 0.02).
    let resistive = g - e.conductance.0 > b_ref;
    if let Err(f) = screen(&points) {
        return measured(Err(match f {
            Failure::Clipped if resistive => SelfTestFault::ShortedPzt,
            Failure::Clipped => SelfTestFault::Clipped,
            Failure::OpenCircuit => SelfTestFault::OpenPzt,
            Failure::Interference => SelfTestFault::Interference,
            _ => SelfTestFault::NoSamples,
        }));
    }
    let outcome = if resistive {
        Err(SelfTestFault::ShortedPzt)
    } else if !(libm::fabsf(c - e.capacitance.0)
        <= e.tolerance * e.capacitance.0 + SIGMAS * sigma_c)
    {
        Err(SelfTestFault::Capacitance)
    } else {
        Ok(())
    };
    measured(outcome)
}

/// Run the self-test against `src` for `unit`: the plan through the one plan loop, the windows
/// judged by [`classify`]. A stall is reported to `on_stop` and ends as `NoSamples`.
pub async fn run<S: PointSource>(
    src: &mut S,
    unit: &UnitProfile,
    mut on_stop: impl FnMut(Stop),
) -> SelfTestReport {
    let e = expected(unit);
    let scale = src.scale();
    let start = src.now_sample();
    let mut t = match SelfTest::new(&scale, &e) {
        Ok(t) => t,
        Err(f) => return SelfTestReport::fault(f, Hz(TEST_HZ), e),
    };
    let mut report = match run_plans(src, &mut t, |_, _| {}).await {
        Ok(_) => classify(t.windows(), &scale, &e),
        Err((stop, _)) => {
            on_stop(stop);
            classify(&[], &scale, &e)
        }
    };
    report.probe_time =
        Seconds(src.now_sample().saturating_sub(start) as f32 / scale.sample_rate.0);
    report
}
