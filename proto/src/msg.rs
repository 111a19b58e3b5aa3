//! The messages. Field order is wire order (postcard writes fields in declaration order and
//! enum variants by their index in declaration order): append, never reorder, and raise
//! [`crate::VERSION`] for any other change. Units are in the names; optional values are
//! `Option`s (a reading without a modulus has `e_kpa: None`).

use crate::MAX_LINE;
use serde::{Deserialize, Serialize};

/// Host → probe.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum HostMsg {
    /// Handshake: the host's protocol version. The probe answers [`DeviceMsg::Hello`], or
    /// [`DeviceMsg::LinkError`] with [`crate::FrameError::WrongVersion`] when it differs.
    Hello {
        /// The host's [`crate::VERSION`].
        version: u8,
    },
    /// A command line of the probe's command grammar (`measure`, `stream 3`, `method hold`,
    /// …; `docs/firmware.md`), without its terminator. The probe answers with a
    /// [`DeviceMsg::Reply`] of the same `id` once it has served it; the messages the command
    /// causes (readings, settings, status, …) come before the reply.
    Command {
        /// The host's number for the command, echoed in its reply.
        id: u32,
        /// The line, at most [`MAX_LINE`] bytes.
        line: heapless::String<MAX_LINE>,
    },
}

/// Probe → host: every message with the link's sequence number and the count of messages
/// dropped just before it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceFrame<'a> {
    /// Counts every message the probe made since power-on, sent or dropped (wraps at 2³²):
    /// consecutive frames differ by `1 + dropped`.
    pub seq: u32,
    /// Messages dropped since the last frame sent because the transmit queue was full.
    pub dropped: u32,
    /// The message.
    #[serde(borrow)]
    pub msg: DeviceMsg<'a>,
}

/// What the probe tells the host.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DeviceMsg<'a> {
    /// Answer to [`HostMsg::Hello`].
    Hello {
        /// The probe's [`crate::VERSION`].
        version: u8,
        /// The board: `qemu` or `stm32`.
        board: &'a str,
        /// The firmware's package version.
        firmware: &'a str,
        /// Longest command line, bytes.
        max_line_bytes: u16,
        /// Longest frame the probe accepts, bytes ([`crate::MAX_HOST_FRAME`]).
        max_host_frame_bytes: u16,
        /// Longest frame the probe sends, bytes ([`crate::MAX_DEVICE_FRAME`]).
        max_device_frame_bytes: u16,
    },
    /// A command was served (after everything it caused) or refused.
    Reply {
        /// The command's `id`.
        id: u32,
        /// Accepted, or why not.
        #[serde(borrow)]
        outcome: Outcome<'a>,
    },
    /// A received frame was not a message; no command of it was run.
    LinkError {
        /// Why.
        error: crate::FrameError,
    },
    /// A reading ended (`measure`, `calibrate add`).
    Reading(#[serde(borrow)] ReadingMsg<&'a str>),
    /// A reading of a stream (`stream <seconds>`).
    Stream {
        /// The stream's reading number from 0; a gap is a reading the probe could not queue.
        stream_seq: u32,
        /// Probe time (the sample clock since power-on) when the reading ended, s; the
        /// stream started at [`StreamEndMsg::start_s`].
        t_s: f32,
        /// The tracker held the resonance.
        locked: bool,
        /// The reading.
        #[serde(borrow)]
        reading: ReadingMsg<&'a str>,
    },
    /// A stream ended.
    StreamEnd(StreamEndMsg),
    /// What to do about the failed reading just sent.
    Hint {
        /// The failure's code.
        code: &'a str,
        /// One line for a human.
        message: &'a str,
    },
    /// The session's state (`status`).
    Status {
        /// Active method.
        method: &'a str,
        /// Source of the calibration in use.
        calibration: &'a str,
        /// No valid stored profile: the fallback calibration is in use.
        fallback: bool,
        /// An air reference is held.
        air: bool,
        /// A contact condition (Q model) is held.
        q_model: bool,
        /// Reference readings held.
        references: u16,
        /// The last self-test: `passed`, `not_run` or a fault code.
        selftest: &'a str,
        /// The board's failed bring-up step, if any.
        boot: Option<&'a str>,
    },
    /// A self-test ended (power-on, `selftest`).
    SelfTest {
        /// `passed` or a fault code.
        result: &'a str,
        /// The fault's message (`None` when passed).
        message: Option<&'a str>,
        /// Test frequency, Hz.
        f_hz: f32,
        /// Measured capacitance, pF.
        c_pf: f32,
        /// Its standard uncertainty, pF.
        c_sigma_pf: f32,
        /// The capacitance compared with, pF.
        ref_c_pf: f32,
        /// Relative tolerance.
        tol: f32,
        /// What `ref_c_pf` is: `air` (the air reference) or `nominal`.
        reference: &'a str,
        /// Conductance, S.
        g_s: f32,
        /// Current amplitude, A.
        i_a: f32,
        /// Drive amplitude, V.
        v: f32,
        /// Probe time the test took, s.
        probe_time_s: f32,
    },
    /// A bring-up step of the board failed (sent after `Hello` while it holds).
    BootError {
        /// The step's code.
        fault: &'a str,
        /// One line for a human.
        message: &'a str,
    },
    /// The active method and its settings (after `method`, `sweep`, `staged`).
    Settings {
        /// Method.
        method: &'a str,
        /// Band or sweep start, Hz.
        start_hz: Option<f32>,
        /// Band or sweep stop, Hz.
        stop_hz: Option<f32>,
        /// Sweep step, Hz.
        step_hz: Option<f32>,
        /// Settling, s.
        settle_s: Option<f32>,
        /// Integration, s.
        integrate_s: Option<f32>,
        /// Drive amplitude, V.
        drive_v: Option<f32>,
    },
    /// An admittance point of the reading in progress.
    Point(PointMsg),
    /// The air reference was taken.
    Air {
        /// Free resonance, Hz.
        f_hz: f32,
        /// Free quality factor.
        q: f32,
    },
    /// A reference reading was added (`calibrate add`).
    Reference {
        /// The reference's modulus, kPa.
        e_kpa: f32,
        /// Its resonance, Hz.
        f_hz: f32,
        /// The resonance's standard uncertainty, Hz.
        f_sigma_hz: f32,
        /// References held.
        n: u16,
    },
    /// A calibration is in use (`calibrate fit`, `calibrate paper`).
    Calibration {
        /// Its source.
        source: &'a str,
        /// Power law `E = a (f − c)^b`: `a`, kPa.
        a: f32,
        /// Exponent `b`.
        b: f32,
        /// Offset `c`, Hz.
        c: f32,
        /// Calibrated span, kPa.
        min_kpa: f32,
        /// Calibrated span, kPa.
        max_kpa: f32,
    },
    /// The load cell's calibration and the force window.
    LoadCell {
        /// The unit reads with a load cell.
        present: bool,
        /// Sensitivity, N per count.
        newtons_per_count: Option<f32>,
        /// Tare, counts.
        tare_counts: Option<i32>,
        /// Force window, N.
        min_n: f32,
        /// Force window, N.
        max_n: f32,
    },
    /// The flash store: `loaded`, `fallback`, `saved` or an error code.
    Store {
        /// What happened.
        event: &'a str,
        /// The slot, when one was loaded or saved.
        slot: Option<u8>,
        /// Its sequence number.
        seq: Option<u32>,
    },
    /// A window did not arrive in time.
    Stalled {
        /// The plan's tag.
        tag: u16,
    },
    /// The commands and methods (`help`).
    Help {
        /// Command words, comma separated.
        commands: &'a str,
        /// Method names, comma separated.
        methods: &'a str,
        /// The default method.
        default_method: &'a str,
    },
    /// The health counters.
    Counters {
        /// Sample batches.
        batches: u32,
        /// Batches whose interrupt came late.
        late: u32,
        /// DAC batches the engine's ring forgot.
        ring: u32,
        /// Points the interrupt could not hand on.
        dropped: u32,
        /// The interrupt's mean work per batch (`unit`).
        isr_mean: u32,
        /// Its most.
        isr_max: u32,
        /// `instructions` (QEMU) or `cycles` (STM32).
        unit: &'a str,
        /// Failed load-cell reads.
        load_cell_errors: u32,
    },
}

/// A command's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Outcome<'a> {
    /// Parsed and served (a reading that failed is still served: its code is in the reading).
    Accepted,
    /// Not served.
    Rejected {
        /// Why, as a code: `busy` (the command queue is full), `parse` (the line is no
        /// command), `sim` (QEMU: a bad `sim` line), `settings`, `selftest`, `boot`, `air`,
        /// `no_resonance`, `bad_reference`, `weigh`, `references_full`, `fit`, `store`.
        code: &'a str,
        /// The detail's code: the parse error, the self-test fault, the reading failure, …
        /// (`None` when the code says it all).
        cause: Option<&'a str>,
        /// One line for a human.
        message: &'a str,
    },
}

/// The end of a stream: its start and its counts. The bench keeps it as the link delivered it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StreamEndMsg {
    /// Probe time when the stream started, s.
    pub start_s: f32,
    /// Readings the stream made.
    pub readings: u32,
    /// Of those, `ok`.
    pub ok: u32,
    /// Of those, dropped before the link (the probe's report queue was full).
    pub dropped: u32,
}

/// An admittance point of a reading in progress. The bench keeps the points parsed from the
/// firmware's log, whose `point` line carries the same fields, as this.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointMsg {
    /// The plan's tag.
    pub tag: u16,
    /// Frequency, Hz.
    pub f_hz: f32,
    /// Conductance, S.
    pub g_s: f32,
    /// Susceptance, S.
    pub b_s: f32,
    /// Standard uncertainty of each, S.
    pub sigma_s: f32,
}

/// A reading: the fields of `probe-bench`'s JSON, named by unit. `S` is its text: `&str` on
/// the link (borrowed from the frame); the bench keeps a reading parsed from the firmware's
/// log, whose `reading` line carries the same fields, with `String`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadingMsg<S> {
    /// `ok` or a failure code.
    pub status: S,
    /// The method that read it.
    pub method: S,
    /// Resonance, Hz.
    pub f_hz: Option<f32>,
    /// Its standard uncertainty, Hz.
    pub f_sigma_hz: Option<f32>,
    /// Storage modulus, kPa.
    pub e_kpa: Option<f32>,
    /// Its combined standard uncertainty, kPa.
    pub e_sigma_kpa: Option<f32>,
    /// Its repeatability standard uncertainty, kPa.
    pub e_repeat_kpa: Option<f32>,
    /// Quality factor.
    pub q: Option<f32>,
    /// The tissue's loss tangent.
    pub loss_tangent: Option<f32>,
    /// Its standard uncertainty.
    pub loss_tangent_sigma: Option<f32>,
    /// Mean contact force over the reading, N.
    pub force_n: Option<f32>,
    /// Its standard deviation, N.
    pub force_sigma_n: Option<f32>,
    /// Probe time the reading took, s.
    pub probe_time_s: f32,
    /// Admittance points it used.
    pub points: u16,
}
