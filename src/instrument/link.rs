//! The host link (`docs/protocol.md`, crate `probe_proto`): received bytes to commands for the
//! session, and the report task's reports to frames for the UART.
//!
//! * [`HostLink`]: bytes → frames ([`probe_proto::Decoder`], 128-byte buffer) → [`Incoming`]:
//!   a handshake, a command line parsed by the one command parser ([`parse`]), or a typed
//!   frame error. Total on any input.
//! * [`Outgoing`]: each [`Report`] → zero or more [`DeviceMsg`]s, framed with the link's `seq`
//!   and `dropped` count and handed to the board's transmit queue, which may refuse a frame
//!   (full): it is then dropped and counted, never waited for. A command's [`DeviceMsg::Reply`]
//!   follows everything it caused: the command task reports [`LinkEvent::Queued`] before it
//!   hands the command on, the measurement task [`LinkEvent::Served`] after serving it; a
//!   refusal the session emitted in between becomes the reply's `Rejected`.

use crate::boot::BootError;
use crate::hal::FrontEndScale;
use crate::instrument::command::{parse, Command, CommandError};
use crate::instrument::selftest::{outcome_code, SelfTestReport};
use crate::instrument::session::{Event, Refusal};
use crate::reading::Reading;
use crate::reading::Settings;
use crate::unit::store::{LoadSource, SlotState, StoreError};
use probe_proto::{
    encode_device, Decoder, DeviceFrame, DeviceMsg, FrameError, HostMsg, Outcome, PointMsg,
    ReadingMsg, StreamEndMsg, MAX_DEVICE_FRAME, MAX_HOST_FRAME, MAX_LINE, VERSION,
};

/// What the link's receive side made of a frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Incoming {
    /// The host's handshake, of this version.
    Hello,
    /// A command line: its id, the line, and what the parser made of it.
    Command {
        /// The host's number for it.
        id: u32,
        /// The line as received (a board may serve lines of its own, as the QEMU image's
        /// `sim` lines).
        line: heapless::String<MAX_LINE>,
        /// The command, or why the line is none.
        parsed: Result<Command, CommandError>,
    },
    /// A frame that is no message (or a `Hello` of another version).
    Error(FrameError),
}

/// The link's receive side: a frame decoder over the host's bytes.
#[derive(Clone, Debug, Default)]
pub struct HostLink {
    decoder: Decoder<MAX_HOST_FRAME>,
}

impl HostLink {
    /// Nothing received yet.
    pub const fn new() -> Self {
        Self {
            decoder: Decoder::new(),
        }
    }

    /// Take one received byte; at the end of a frame, what it was (command lines parsed
    /// against `scale`).
    pub fn push(&mut self, byte: u8, scale: &FrontEndScale) -> Option<Incoming> {
        let body = match self.decoder.feed(byte)? {
            Ok(body) => body,
            Err(e) => return Some(Incoming::Error(e)),
        };
        Some(match probe_proto::decode_host(body) {
            Ok(HostMsg::Hello { version }) if version == VERSION => Incoming::Hello,
            Ok(HostMsg::Hello { version }) => {
                Incoming::Error(FrameError::WrongVersion { got: version })
            }
            Ok(HostMsg::Command { id, line }) => Incoming::Command {
                id,
                parsed: parse(line.as_bytes(), scale),
                line,
            },
            Err(e) => Incoming::Error(e),
        })
    }
}

/// The link's own reports (beside the session's events), through the report channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LinkEvent {
    /// The host said hello: answer with the probe's.
    Hello,
    /// A received frame was no message.
    FrameError(FrameError),
    /// Command `id`'s line is no command.
    Rejected {
        /// The command's id.
        id: u32,
        /// Why.
        error: CommandError,
    },
    /// Command `id` was handed to the measurement task (its events and reply follow).
    Queued(u32),
    /// Command `id` found the request queue full: refused, not run.
    Busy(u32),
    /// Board line `id` (the QEMU image's `sim` lines) was served by the command task itself:
    /// accepted, or refused with this message.
    BoardLine {
        /// The line's id.
        id: u32,
        /// Why it was refused.
        error: Option<&'static str>,
    },
    /// The measurement task served the oldest queued command (`ok`: as it returned).
    Served(bool),
}

/// Ids the link keeps of commands not yet answered: each is queued or in service (at most the
/// request channel's 4 and one) or its [`LinkEvent::Served`] waits in the report channel (at
/// most its 11): 16 bound them all (asserted with the capacities, [`crate::instrument::tasks`]).
pub const PENDING: usize = 16;

/// The rejection's message of a failed `store` (the store's error code is its cause).
const STORE_FAILED: &str = "storing the profile in flash failed";

/// A rejection for the next reply: code, cause and message.
type Rejection = (&'static str, Option<&'static str>, &'static str);

/// The link's transmit side: sequence, drop count, the ids of queued commands and the
/// refusal waiting for its reply.
#[derive(Clone, Debug)]
pub struct Outgoing {
    board: &'static str,
    unit: &'static str,
    boot: Option<BootError>,
    seq: u32,
    dropped: u32,
    pending: heapless::Deque<u32, PENDING>,
    rejection: Option<Rejection>,
}

/// The buffer a frame is encoded in (the longest frame and its delimiter).
pub type FrameBuf = [u8; MAX_DEVICE_FRAME + 1];

impl Outgoing {
    /// The link of board `board` (`qemu`, `stm32`), whose interrupt's work is counted in `unit`
    /// and whose first failed bring-up step is `boot`.
    pub const fn new(board: &'static str, unit: &'static str, boot: Option<BootError>) -> Self {
        Self {
            board,
            unit,
            boot,
            seq: 0,
            dropped: 0,
            pending: heapless::Deque::new(),
            rejection: None,
        }
    }

    /// Messages made since power-on (the next frame's `seq`).
    pub fn seq(&self) -> u32 {
        self.seq
    }

    /// Frame `r`'s messages in `buf` and offer each to `send`, which queues a whole frame and
    /// returns true, or refuses it (the queue is full) and returns false: the message is then
    /// dropped and counted in the next frame. Returns the messages dropped by this call.
    pub fn report(
        &mut self,
        r: &Report,
        buf: &mut FrameBuf,
        mut send: impl FnMut(&[u8]) -> bool,
    ) -> u32 {
        let mut lost = 0;
        let mut out = |o: &mut Self, msg: DeviceMsg<'_>| {
            if !o.send(msg, buf, &mut send) {
                lost += 1;
            }
        };
        match *r {
            Report::Event(ref e) => {
                match *e {
                    Event::Refused(why) => self.rejection = Some(refusal(why)),
                    Event::StoreFailed(f) => {
                        self.rejection = Some(("store", Some(store_error_name(f)), STORE_FAILED))
                    }
                    _ => {}
                }
                if let Some(m) = event_msg(e) {
                    out(self, m);
                }
            }
            Report::Counters => out(self, counters_msg(self.unit)),
            Report::Rejected(_) | Report::Exit(_) => {}
            Report::Link(l) => match l {
                LinkEvent::Hello => {
                    out(
                        self,
                        DeviceMsg::Hello {
                            version: VERSION,
                            board: self.board,
                            firmware: env!("CARGO_PKG_VERSION"),
                            max_line_bytes: MAX_LINE as u16,
                            max_host_frame_bytes: MAX_HOST_FRAME as u16,
                            max_device_frame_bytes: MAX_DEVICE_FRAME as u16,
                        },
                    );
                    if let Some(b) = self.boot {
                        out(
                            self,
                            DeviceMsg::BootError {
                                fault: b.code(),
                                message: b.message(),
                            },
                        );
                    }
                }
                LinkEvent::FrameError(error) => out(self, DeviceMsg::LinkError { error }),
                LinkEvent::Rejected { id, error } => out(
                    self,
                    DeviceMsg::Reply {
                        id,
                        outcome: Outcome::Rejected {
                            code: "parse",
                            cause: Some(error.code()),
                            message: error.message(),
                        },
                    },
                ),
                LinkEvent::Busy(id) => out(
                    self,
                    DeviceMsg::Reply {
                        id,
                        outcome: Outcome::Rejected {
                            code: "busy",
                            cause: None,
                            message: "command queue full: wait for a reply before sending more",
                        },
                    },
                ),
                LinkEvent::BoardLine { id, error } => out(
                    self,
                    DeviceMsg::Reply {
                        id,
                        outcome: match error {
                            None => Outcome::Accepted,
                            Some(message) => Outcome::Rejected {
                                code: "sim",
                                cause: None,
                                message,
                            },
                        },
                    },
                ),
                LinkEvent::Queued(id) => {
                    // The command task queues no more than the request channel holds plus the
                    // one in service; an id beyond that could never be answered.
                    let _ = self.pending.push_back(id);
                }
                LinkEvent::Served(_) => {
                    let rejection = self.rejection.take();
                    // A request of the QEMU script has no id: no reply.
                    if let Some(id) = self.pending.pop_front() {
                        let outcome = match rejection {
                            Some((code, cause, message)) => Outcome::Rejected {
                                code,
                                cause,
                                message,
                            },
                            None => Outcome::Accepted,
                        };
                        out(self, DeviceMsg::Reply { id, outcome });
                    }
                }
            },
        }
        lost
    }

    /// One message: framed with the next `seq` and the drops before it, offered to `send`.
    fn send(
        &mut self,
        msg: DeviceMsg<'_>,
        buf: &mut FrameBuf,
        send: &mut impl FnMut(&[u8]) -> bool,
    ) -> bool {
        let frame = DeviceFrame {
            seq: self.seq,
            dropped: self.dropped,
            msg,
        };
        self.seq = self.seq.wrapping_add(1);
        // Every message fits the buffer (host-tested at its longest); one that did not would
        // be dropped and counted like one the queue refused.
        let sent = encode_device(&frame, buf).is_ok_and(send);
        if sent {
            self.dropped = 0;
        } else {
            self.dropped = self.dropped.saturating_add(1);
        }
        sent
    }
}

/// A refusal as the reply's rejection.
fn refusal(why: Refusal) -> Rejection {
    let m = why.message();
    match why {
        Refusal::Settings(e) => ("settings", Some(e.code()), m),
        Refusal::Air(f) => ("air", Some(f.code()), m),
        Refusal::NoResonance => ("no_resonance", None, m),
        Refusal::BadReference(f) => ("bad_reference", Some(f.code()), m),
        Refusal::Weigh => ("weigh", None, m),
        Refusal::ReferencesFull => ("references_full", None, m),
        Refusal::Fit => ("fit", None, m),
        Refusal::SelfTest(f) => ("selftest", Some(f.code()), m),
        Refusal::Boot(e) => ("boot", Some(e.code()), m),
    }
}

/// `v` unless it is NaN (a value the firmware's log writes as NaN is `None` on the link).
fn some(v: f32) -> Option<f32> {
    (!v.is_nan()).then_some(v)
}

/// A reading's message: the fields of the bench's JSON.
pub fn reading_msg(r: &Reading) -> ReadingMsg<&'static str> {
    let fin = |v: Option<f32>| some(nan_or(v));
    ReadingMsg {
        status: r.status.code(),
        method: r.method.name(),
        f_hz: fin(r.resonance.map(|v| v.0)),
        f_sigma_hz: fin(r.resonance_sigma.map(|v| v.0)),
        e_kpa: fin(r.modulus.map(|v| v.0)),
        e_sigma_kpa: fin(r.modulus_sigma.map(|v| v.0)),
        e_repeat_kpa: fin(r.modulus_sigma_repeat.map(|v| v.0)),
        q: fin(r.q),
        loss_tangent: fin(r.loss_tangent),
        loss_tangent_sigma: fin(r.loss_tangent_sigma),
        force_n: fin(r.force.map(|w| w.mean.0)),
        force_sigma_n: fin(r.force.map(|w| w.sigma.0)),
        probe_time_s: r.probe_time.0,
        points: r.points,
    }
}

fn selftest_msg(r: &SelfTestReport) -> DeviceMsg<'static> {
    let e = &r.expected;
    DeviceMsg::SelfTest {
        result: outcome_code(Some(r.outcome)),
        message: r.outcome.err().map(|f| f.message()),
        f_hz: r.freq.0,
        c_pf: r.capacitance.0 * 1e12,
        c_sigma_pf: r.capacitance_sigma.0 * 1e12,
        ref_c_pf: e.capacitance.0 * 1e12,
        tol: e.tolerance,
        reference: if e.from_air { "air" } else { "nominal" },
        g_s: r.conductance.0,
        i_a: r.current_a,
        v: r.drive_v,
        probe_time_s: r.probe_time.0,
    }
}

fn counters_msg(unit: &'static str) -> DeviceMsg<'static> {
    use crate::counters::*;
    use core::sync::atomic::Ordering::Relaxed;
    DeviceMsg::Counters {
        batches: BATCHES.load(Relaxed),
        late: LATE.load(Relaxed),
        ring: RING.load(Relaxed),
        dropped: DROPPED.load(Relaxed),
        isr_mean: ISR_MEAN.load(Relaxed),
        isr_max: ISR_MAX.load(Relaxed),
        unit,
        load_cell_errors: LOAD_CELL_ERRORS.load(Relaxed),
    }
}

/// A session event's message (`None`: a refusal, which goes into the command's reply).
pub fn event_msg(e: &Event) -> Option<DeviceMsg<'static>> {
    Some(match *e {
        Event::Loaded(LoadSource::Stored { slot, seq, .. }) => DeviceMsg::Store {
            event: "loaded",
            slot: Some(slot),
            seq: Some(seq),
        },
        Event::Loaded(LoadSource::Fallback { .. }) => DeviceMsg::Store {
            event: "fallback",
            slot: None,
            seq: None,
        },
        Event::Saved(v) => DeviceMsg::Store {
            event: "saved",
            slot: Some(v.slot),
            seq: Some(v.seq),
        },
        Event::StoreFailed(e) => DeviceMsg::Store {
            event: store_error_name(e),
            slot: None,
            seq: None,
        },
        Event::Settings(m, s) => {
            let [start, stop, step, settle, integrate, drive] = settings_fields(&s).map(some);
            DeviceMsg::Settings {
                method: m.name(),
                start_hz: start,
                stop_hz: stop,
                step_hz: step,
                settle_s: settle,
                integrate_s: integrate,
                drive_v: drive,
            }
        }
        Event::Point { tag, point } => DeviceMsg::Point(PointMsg {
            tag,
            f_hz: point.freq.0,
            g_s: point.g_s,
            b_s: point.b_s,
            sigma_s: point.sigma_s,
        }),
        Event::Reading(r) => DeviceMsg::Reading(reading_msg(&r)),
        Event::SelfTest(r) => selftest_msg(&r),
        Event::Hint(f) => DeviceMsg::Hint {
            code: f.code(),
            message: f.message(),
        },
        Event::Stalled(tag) => DeviceMsg::Stalled { tag },
        Event::Air(a) => DeviceMsg::Air {
            f_hz: a.free_resonance.0,
            q: a.free_q,
        },
        Event::Reference {
            modulus,
            reference,
            n,
        } => DeviceMsg::Reference {
            e_kpa: modulus.0,
            f_hz: reference.resonance_hz as f32,
            f_sigma_hz: reference.sigma_hz as f32,
            n,
        },
        Event::Calibration(c) => DeviceMsg::Calibration {
            source: c.source.name(),
            a: c.a as f32,
            b: c.b as f32,
            c: c.c as f32,
            min_kpa: c.min_kpa as f32,
            max_kpa: c.max_kpa as f32,
        },
        Event::LoadCell { cal, window } => DeviceMsg::LoadCell {
            present: cal.is_some(),
            newtons_per_count: cal.map(|c| c.newtons_per_count),
            tare_counts: cal.map(|c| c.tare.0),
            min_n: window.min.0,
            max_n: window.max.0,
        },
        Event::Refused(_) => return None,
        Event::Help => DeviceMsg::Help {
            commands: COMMANDS,
            methods: crate::reading::METHOD_NAMES,
            default_method: crate::reading::DEFAULT_METHOD.name(),
        },
        Event::Stream(x) => DeviceMsg::Stream {
            stream_seq: x.seq,
            t_s: x.t_s.0,
            locked: x.locked,
            reading: reading_msg(&x.reading),
        },
        Event::StreamEnd {
            start,
            readings,
            ok,
            dropped,
            ..
        } => DeviceMsg::StreamEnd(StreamEndMsg {
            start_s: start.0,
            readings,
            ok,
            dropped,
        }),
        Event::Status(s) => DeviceMsg::Status {
            method: s.method.name(),
            calibration: s.calibration.source.name(),
            fallback: s.fallback,
            air: s.air,
            q_model: s.q_model,
            references: s.references,
            selftest: outcome_code(s.selftest),
            boot: s.boot.map(|b| b.code()),
        },
    })
}

/// `v` or NaN (missing values are logged as NaN).
pub fn nan_or(v: Option<f32>) -> f32 {
    v.unwrap_or(f32::NAN)
}

/// The `settings` line's fields `[start_hz, stop_hz, step_hz, settle_s, integrate_s,
/// drive_v]` of any method's settings: a sweep's own; for the staged methods the band, no
/// step (`NaN`), the coarse settling, the integration and the drive; for ring-down the
/// band, no step, the burst as settling, the ring as integration and the drive; `NaN` for
/// settings of other kinds.
pub fn settings_fields(s: &Settings) -> [f32; 6] {
    match s {
        Settings::Sweep(s) => [
            s.start.0,
            s.stop.0,
            s.step.0,
            s.settle.0,
            s.integrate.0,
            s.drive.0,
        ],
        Settings::Staged(s) => [
            s.band_start.0,
            s.band_stop.0,
            f32::NAN,
            s.coarse_settle.0,
            s.integrate.0,
            s.drive.0,
        ],
        Settings::Hold(_) => [f32::NAN; 6],
    }
}

/// A store slot's state, as logged.
pub fn slot_name(s: SlotState) -> &'static str {
    match s {
        SlotState::Valid(_) => "valid",
        SlotState::Empty => "empty",
        SlotState::Corrupt => "corrupt",
        SlotState::Unreadable => "unreadable",
    }
}

/// A store error, as logged.
pub fn store_error_name(e: StoreError) -> &'static str {
    match e {
        StoreError::Geometry => "geometry",
        StoreError::InvalidRecord => "invalid_record",
        StoreError::Erase => "erase",
        StoreError::Program => "program",
        StoreError::Verify => "verify",
    }
}

/// The command words `help` lists.
pub const COMMANDS: &str =
    "measure,stream,method,sweep,staged,air,calibrate,force,weigh,store,reload,status,selftest,help";

/// Everything the firmware's report task logs: the session's events and the board's own.
#[derive(Clone, Copy, Debug)]
pub enum Report {
    /// A session event.
    Event(Event),
    /// A host line the parser refused, or a `sim` line of the QEMU image's script: the
    /// refusal's message.
    Rejected(&'static str),
    /// The health counters.
    Counters,
    /// The end of the QEMU image's script, with its overall success.
    Exit(bool),
    /// The host link's own report ([`crate::instrument::link`]); in the log only a command
    /// line the parser refused (`rejected error=`, as from the line-mode UART).
    Link(LinkEvent),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::instrument::selftest::SelfTestFault;
    use probe_proto::{decode_device, encode_host, Decoder};

    /// The messages `reports` make, as (seq, dropped, message debug text), with `room`
    /// deciding per frame whether the transmit queue takes it.
    fn run(reports: &[Report], mut room: impl FnMut(usize) -> bool) -> Vec<(u32, u32, String)> {
        let mut o = Outgoing::new("qemu", "instructions", Some(BootError::ALL[0]));
        let mut buf = [0u8; MAX_DEVICE_FRAME + 1];
        let mut wire = Vec::new();
        let mut n = 0;
        for r in reports {
            o.report(r, &mut buf, |f| {
                n += 1;
                let ok = room(n);
                if ok {
                    wire.extend_from_slice(f);
                }
                ok
            });
        }
        let mut d = Decoder::<{ MAX_DEVICE_FRAME }>::new();
        let mut out = Vec::new();
        for b in wire {
            if let Some(body) = d.feed(b) {
                let f = decode_device(body.unwrap()).unwrap();
                out.push((f.seq, f.dropped, format!("{:?}", f.msg)));
            }
        }
        out
    }

    #[test]
    fn each_command_gets_one_reply_after_its_events_with_the_refusal_inside() {
        let refused = Event::Refused(Refusal::SelfTest(SelfTestFault::OpenPzt));
        let got = run(
            &[
                Report::Link(LinkEvent::Hello),
                Report::Link(LinkEvent::Queued(10)),
                Report::Link(LinkEvent::Queued(11)),
                Report::Event(Event::Help),
                Report::Link(LinkEvent::Served(true)),
                Report::Event(refused),
                Report::Link(LinkEvent::Served(false)),
                Report::Link(LinkEvent::Rejected {
                    id: 12,
                    error: CommandError::UnknownCommand,
                }),
                Report::Link(LinkEvent::Busy(13)),
                // A script request (no id): no reply, and its refusal does not leak.
                Report::Event(refused),
                Report::Link(LinkEvent::Served(false)),
                Report::Link(LinkEvent::Queued(14)),
                Report::Link(LinkEvent::Served(true)),
            ],
            |_| true,
        );
        let msgs: Vec<&str> = got.iter().map(|(_, _, m)| m.as_str()).collect();
        assert!(msgs[0].starts_with("Hello { version: 1, board: \"qemu\""));
        assert!(msgs[1].starts_with("BootError"));
        assert!(msgs[2].starts_with("Help"));
        assert_eq!(msgs[3], "Reply { id: 10, outcome: Accepted }");
        assert!(msgs[4].starts_with(
            "Reply { id: 11, outcome: Rejected { code: \"selftest\", cause: Some(\"open_pzt\")"
        ));
        assert!(msgs[5].starts_with(
            "Reply { id: 12, outcome: Rejected { code: \"parse\", cause: Some(\"unknown_command\")"
        ));
        assert!(msgs[6].starts_with("Reply { id: 13, outcome: Rejected { code: \"busy\""));
        assert_eq!(msgs[7], "Reply { id: 14, outcome: Accepted }");
        assert_eq!(msgs.len(), 8);
        let seqs: Vec<u32> = got.iter().map(|g| g.0).collect();
        assert_eq!(seqs, (0..8).collect::<Vec<_>>());
    }

    #[test]
    fn a_full_queue_drops_and_the_next_frame_counts_it() {
        let e = Report::Event(Event::Stalled(1));
        // Frames 2, 3 and 5 find no room.
        let got = run(&[e; 6], |n| !matches!(n, 2 | 3 | 5));
        let meta: Vec<(u32, u32)> = got.iter().map(|g| (g.0, g.1)).collect();
        assert_eq!(meta, [(0, 0), (3, 2), (5, 1)]);
        for w in got.windows(2) {
            assert_eq!(w[1].0, w[0].0 + 1 + w[1].1, "seq jumps by the drops");
        }
    }

    #[test]
    fn host_frames_become_commands_or_typed_errors() {
        let scale = FrontEndScale::PROBE;
        let mut link = HostLink::new();
        let mut feed = |bytes: &[u8]| -> Vec<Incoming> {
            bytes.iter().filter_map(|&b| link.push(b, &scale)).collect()
        };
        let mut buf = [0u8; 160];
        let cmd = |id, line: &str, buf: &mut [u8; 160]| {
            let m = HostMsg::Command {
                id,
                line: heapless::String::try_from(line).unwrap(),
            };
            encode_host(&m, buf).unwrap().to_vec()
        };
        // Command `id`'s frame of `line` comes in as that command, parsed to `parsed`.
        let mut command_in = |id, line: &str, parsed| {
            let want = Incoming::Command {
                id,
                line: heapless::String::try_from(line).unwrap(),
                parsed,
            };
            assert_eq!(feed(&cmd(id, line, &mut buf)), [want]);
        };
        command_in(3, "measure", Ok(Command::Measure));
        command_in(4, "stream 0.01", Err(CommandError::OutOfRange));
        let hello = encode_host(&HostMsg::Hello { version: 2 }, &mut buf)
            .unwrap()
            .to_vec();
        assert_eq!(
            feed(&hello),
            [Incoming::Error(FrameError::WrongVersion { got: 2 })]
        );
        let hello = encode_host(&HostMsg::Hello { version: VERSION }, &mut buf)
            .unwrap()
            .to_vec();
        assert_eq!(feed(&hello), [Incoming::Hello]);
        let mut bad = cmd(5, "status", &mut buf);
        bad[3] ^= 0x10;
        assert_eq!(feed(&bad), [Incoming::Error(FrameError::BadCrc)]);
    }

    #[test]
    fn the_longest_messages_fit_a_frame() {
        let mut reports = Vec::new();
        for f in crate::status::Failure::ALL {
            reports.push(Report::Event(Event::Hint(f)));
            reports.push(Report::Link(LinkEvent::Queued(u32::MAX)));
            reports.push(Report::Event(Event::Refused(Refusal::BadReference(f))));
            reports.push(Report::Link(LinkEvent::Served(false)));
        }
        for f in SelfTestFault::ALL {
            reports.push(Report::Link(LinkEvent::Queued(u32::MAX)));
            reports.push(Report::Event(Event::Refused(Refusal::SelfTest(f))));
            reports.push(Report::Link(LinkEvent::Served(false)));
        }
        for b in BootError::ALL {
            reports.push(Report::Link(LinkEvent::Queued(u32::MAX)));
            reports.push(Report::Event(Event::Refused(Refusal::Boot(b))));
            reports.push(Report::Link(LinkEvent::Served(false)));
        }
        let n =
            crate::status::Failure::ALL.len() * 2 + SelfTestFault::ALL.len() + BootError::ALL.len();
        let got = run(&reports, |_| true);
        assert_eq!(got.len(), n, "every message encoded");
        assert!(got.iter().all(|g| g.1 == 0));
    }
}
