//! The firmware's other tasks apart from RTIC, beside the measurement task
//! ([`crate::instrument::measure`]): what each decides, over links its RTIC side implements
//! (`src/board/tasks.rs`: the channels, the monotonic, the board), tested here on the host.
//!
//! * [`batch`]: the sample interrupt's work on one batch, given the ADC half just captured and
//!   the DAC half just played.
//! * [`receive`]: the UART's receive interrupt: host bytes into the command task's channel while
//!   it has room, then the board holds the rest.
//! * [`serve_link`]: the command task's host link: bytes → frames → requests for the
//!   measurement task, each answered (`docs/protocol.md`).
//! * [`conversion`]: the load-cell task's read, its errors counted.
//!
//! The channels between the tasks are sized here ([`PLAN_CAP`] … [`RX_CAP`]).

use crate::counters::{DROPPED, LOAD_CELL_ERRORS};
use crate::engine::{PointPlan, PointRaw, SampleEngine};
use crate::hal::{AdcFrame, FrontEndScale};
use crate::instrument::command::Command;
use crate::instrument::link::{HostLink, Incoming, LinkEvent, Report, PENDING};
use crate::loadcell::LoadCellCounts;
use crate::units::DacCode;
use core::sync::atomic::Ordering;

/// What the measurement task asks of the sample interrupt: a plan to load, or `None` to stop.
pub type EngineCmd = Option<PointPlan>;

/// Plans queued for the sample interrupt (the double buffer of its settings, validated before
/// they reach it).
pub const PLAN_CAP: usize = 2;
/// Finished points queued for the measurement task.
pub const POINT_CAP: usize = 4;
/// Requests queued for the measurement task.
pub const REQUEST_CAP: usize = 4;
/// Reports buffered between the tasks and the report task (11: the static RAM budget of
/// 55 KiB, scripts/ci-firmware, keeps the stack 41 KiB; a stream's reading that finds the
/// channel full is dropped and counted, never waited for).
pub const REPORT_CAP: usize = 11;
/// Completions: every request queued and the one in service, so none is lost while the host
/// link's receive side reads bytes.
pub const DONE_CAP: usize = REQUEST_CAP + 1;
/// Received bytes buffered between the UART interrupt and the command task.
pub const RX_CAP: usize = 64;
/// The load-cell task looks for a conversion this often (ms): above the HX711's 80 a second,
/// so each is read before the next overwrites it.
pub const LOAD_CELL_POLL_MS: u32 = 5;

// The host link keeps the id of every command queued, in service, or whose completion waits
// in the report channel.
const _: () = assert!(PENDING >= REQUEST_CAP + 1 + REPORT_CAP);

/// The sample interrupt's work on one batch: every queued plan taken from `plan` (`Load` or
/// `Stop`), the ADC half `adc` demodulated with each finished point offered to `point` as its
/// window closes ([`SampleEngine::demodulate_into`]), which never waits: a point it refuses (a
/// full channel) is counted in [`DROPPED`]; then the DAC half `dac` refilled (the plan applied
/// phase-continuously). Returns the points refused. Bounded:
/// no logging, no allocation, no wait.
#[inline(always)]
pub fn batch(
    engine: &mut SampleEngine,
    adc: &[AdcFrame],
    dac: &mut [DacCode],
    mut plan: impl FnMut() -> Option<EngineCmd>,
    mut point: impl FnMut(PointRaw) -> bool,
) -> u32 {
    while let Some(cmd) = plan() {
        match cmd {
            Some(p) => engine.load(p),
            None => engine.stop(),
        }
    }
    let mut refused = 0;
    engine.demodulate_into(adc, |p| {
        if !point(p) {
            DROPPED.fetch_add(1, Ordering::Relaxed);
            refused += 1;
        }
    });
    engine.generate(dac);
    refused
}

/// A UART's receive side, as the receive interrupt drains it.
pub trait RxPort {
    /// No room for more bytes: leave them to the board (QEMU keeps the host's stream back in
    /// its receive register; the STM32 drops what its DMA ring holds, the frame then fails
    /// and is reported) and acknowledge the interrupt.
    fn hold(&mut self);
    /// The next received byte, if any.
    fn read_byte(&mut self) -> Option<u8>;
}

/// Where the receive interrupt puts the host's bytes: the command task's channel.
pub trait ByteSink {
    /// No room for another byte.
    fn is_full(&self) -> bool;
    /// One byte (room seen).
    fn put(&mut self, byte: u8);
}

/// The receive interrupt: bytes from `port` into `sink` while it has room; then the port holds
/// the rest, and the command task pends the interrupt again after each byte it takes.
pub fn receive(port: &mut impl RxPort, sink: &mut impl ByteSink) {
    loop {
        if sink.is_full() {
            port.hold();
            break;
        }
        let Some(b) = port.read_byte() else {
            break;
        };
        sink.put(b);
    }
}

/// The load-cell task's read: a conversion for the force log if one was ready; a driver error
/// is counted ([`LOAD_CELL_ERRORS`]), never logged from the task.
pub fn conversion<E>(read: Result<Option<LoadCellCounts>, E>) -> Option<LoadCellCounts> {
    match read {
        Ok(c) => c,
        Err(_) => {
            LOAD_CELL_ERRORS.fetch_add(1, Ordering::Relaxed);
            None
        }
    }
}

/// The command task's links: the UART's bytes, the request and completion channels of the
/// measurement task, the report channel, and the board's own lines.
#[allow(async_fn_in_trait)] // used with concrete types only, in one task
pub trait CommandLink {
    /// The host's next byte (`None`: the receive side is gone).
    async fn byte(&mut self) -> Option<u8>;
    /// Hand a request to the measurement task, waiting for room; false when it is gone.
    async fn request(&mut self, c: Command) -> bool;
    /// The request queue has room now.
    fn has_room(&self) -> bool;
    /// Hand a request on if there is room now; false when it was not.
    fn try_request(&mut self, c: Command) -> bool;
    /// The measurement task's next completion (`ok` as it served the request), waiting for
    /// it; `None` when none can come.
    async fn done(&mut self) -> Option<bool>;
    /// A completion that came, without waiting.
    fn try_done(&mut self) -> Option<bool>;
    /// A report for the report task, waiting for room.
    async fn report(&mut self, r: Report);
    /// `line` is the board's own (the QEMU image's `sim` lines), served by
    /// [`CommandLink::board_line`] rather than parsed. None by default.
    fn is_board_line(&self, _line: &str) -> bool {
        false
    }
    /// Serve a board line once every command before it has been served: `None` when it was
    /// accepted, or why it was refused.
    async fn board_line(&mut self, _line: &str) -> Option<&'static str> {
        None
    }
}

/// The host link's receive side (QEMU: after the script's `serve`): bytes → frames →
/// commands for the measurement task, each answered (`docs/protocol.md`). A command that finds
/// the request queue full is rejected (`busy`), so the byte path never waits on a command in
/// service; a frame that is no message is answered with its error. A board line
/// ([`CommandLink::is_board_line`]) waits until every command before it has been served.
/// Command lines are parsed against `scale`. Returns when the bytes end.
pub async fn serve_link(link: &mut impl CommandLink, scale: &FrontEndScale) {
    let mut host = HostLink::new();
    // Requests queued and not yet served.
    let mut outstanding = 0u32;
    while let Some(b) = link.byte().await {
        while link.try_done().is_some() {
            outstanding = outstanding.saturating_sub(1);
        }
        let report = match host.push(b, scale) {
            None => continue,
            Some(Incoming::Hello) => LinkEvent::Hello,
            Some(Incoming::Error(e)) => LinkEvent::FrameError(e),
            Some(Incoming::Command { id, line, .. }) if link.is_board_line(&line) => {
                while outstanding > 0 && link.done().await.is_some() {
                    outstanding -= 1;
                }
                let error = link.board_line(&line).await;
                LinkEvent::BoardLine { id, error }
            }
            Some(Incoming::Command {
                id,
                parsed: Err(error),
                ..
            }) => LinkEvent::Rejected { id, error },
            Some(Incoming::Command {
                id, parsed: Ok(c), ..
            }) if link.has_room() => {
                // Queued before it is handed on: the reply's id waits in the report task
                // before any event of the command reaches it. This task alone sends requests,
                // so the room seen stays.
                link.report(Report::Link(LinkEvent::Queued(id))).await;
                outstanding += link.try_request(c) as u32;
                continue;
            }
            Some(Incoming::Command { id, .. }) => LinkEvent::Busy(id),
        };
        link.report(Report::Link(report)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::instrument::command::CommandError;
    use crate::reading::driver::block_on;
    use probe_proto::{encode_host, FrameError, HostMsg, VERSION};
    use std::collections::VecDeque;
    use std::format;
    use std::string::String;
    use std::vec::Vec;

    fn frame(m: &HostMsg) -> Vec<u8> {
        let mut buf = [0u8; 160];
        encode_host(m, &mut buf).unwrap().to_vec()
    }

    fn command(id: u32, line: &str) -> Vec<u8> {
        frame(&HostMsg::Command {
            id,
            line: heapless::String::try_from(line).unwrap(),
        })
    }

    /// A scripted command link: the host's bytes, the request queue's room, completions the
    /// measurement task sends (`early`: already there at the next byte; `later`: when waited
    /// for), and everything the task did, in order.
    #[derive(Default)]
    struct Script {
        bytes: VecDeque<u8>,
        room: usize,
        early: usize,
        later: VecDeque<bool>,
        log: Vec<String>,
    }

    impl CommandLink for Script {
        async fn byte(&mut self) -> Option<u8> {
            self.bytes.pop_front()
        }
        async fn request(&mut self, c: Command) -> bool {
            self.log.push(format!("request {c:?}"));
            true
        }
        fn has_room(&self) -> bool {
            self.room > 0
        }
        fn try_request(&mut self, c: Command) -> bool {
            self.room -= 1;
            self.log.push(format!("request {c:?}"));
            true
        }
        async fn done(&mut self) -> Option<bool> {
            let d = self.later.pop_front();
            self.log.push(format!("done {d:?}"));
            d
        }
        fn try_done(&mut self) -> Option<bool> {
            (self.early > 0).then(|| {
                self.early -= 1;
                self.log.push("early done".into());
                true
            })
        }
        async fn report(&mut self, r: Report) {
            self.log.push(match r {
                Report::Link(l) => format!("{l:?}"),
                r => format!("{r:?}"),
            });
        }
        fn is_board_line(&self, line: &str) -> bool {
            line.starts_with("sim ")
        }
        async fn board_line(&mut self, line: &str) -> Option<&'static str> {
            self.log.push(format!("board {line}"));
            (line != "sim ok").then_some("refused")
        }
    }

    fn serve(link: &mut Script, frames: &[Vec<u8>]) {
        link.bytes = frames.concat().into();
        block_on(serve_link(link, &FrontEndScale::PROBE));
    }

    #[test]
    fn each_frame_is_answered_or_queued() {
        let mut link = Script {
            room: 1,
            ..Default::default()
        };
        let mut bad = command(4, "status");
        bad[3] ^= 0x10;
        serve(
            &mut link,
            &[
                frame(&HostMsg::Hello { version: VERSION }),
                command(1, "measure"),
                command(2, "status"),
                command(3, "frobnicate"),
                bad,
            ],
        );
        let unknown = CommandError::UnknownCommand;
        assert_eq!(
            link.log,
            [
                "Hello".into(),
                "Queued(1)".into(),
                "request Measure".into(),
                "Busy(2)".into(),
                format!("Rejected {{ id: 3, error: {unknown:?} }}"),
                format!("FrameError({:?})", FrameError::BadCrc),
            ]
        );
    }

    #[test]
    fn a_board_line_waits_for_every_command_before_it() {
        let mut link = Script {
            room: 3,
            later: [true, false].into(),
            ..Default::default()
        };
        // Two commands queued: the board line waits for both completions.
        serve(
            &mut link,
            &[
                command(1, "status"),
                command(2, "status"),
                command(3, "sim ok"),
            ],
        );
        assert_eq!(
            link.log[4..],
            [
                "done Some(true)",
                "done Some(false)",
                "board sim ok",
                "BoardLine { id: 3, error: None }"
            ]
        );
        // A completion that came before the next byte is counted: nothing left to wait for.
        let mut link = Script {
            room: 3,
            ..Default::default()
        };
        link.bytes = command(1, "status").into();
        block_on(serve_link(&mut link, &FrontEndScale::PROBE));
        link.early = 1;
        serve(&mut link, &[command(2, "sim bad")]);
        assert_eq!(
            link.log[2..],
            [
                "early done",
                "board sim bad",
                "BoardLine { id: 2, error: Some(\"refused\") }"
            ]
        );
    }

    #[test]
    fn a_board_line_is_a_command_where_the_board_has_none() {
        /// The STM32's link: no board lines.
        struct Plain(Script);
        impl CommandLink for Plain {
            async fn byte(&mut self) -> Option<u8> {
                self.0.byte().await
            }
            async fn request(&mut self, c: Command) -> bool {
                self.0.request(c).await
            }
            fn has_room(&self) -> bool {
                self.0.has_room()
            }
            fn try_request(&mut self, c: Command) -> bool {
                self.0.try_request(c)
            }
            async fn done(&mut self) -> Option<bool> {
                self.0.done().await
            }
            fn try_done(&mut self) -> Option<bool> {
                self.0.try_done()
            }
            async fn report(&mut self, r: Report) {
                self.0.report(r).await
            }
        }
        let mut link = Plain(Script {
            bytes: command(7, "sim phantom B").into(),
            ..Default::default()
        });
        block_on(serve_link(&mut link, &FrontEndScale::PROBE));
        assert_eq!(link.0.log.len(), 1);
        assert!(link.0.log[0].starts_with("Rejected { id: 7"));
    }

    /// A port with `n` bytes waiting, and a sink of `room` bytes.
    struct Port {
        waiting: VecDeque<u8>,
        held: u32,
    }
    impl RxPort for Port {
        fn hold(&mut self) {
            self.held += 1;
        }
        fn read_byte(&mut self) -> Option<u8> {
            self.waiting.pop_front()
        }
    }
    struct Sink {
        room: usize,
        got: Vec<u8>,
    }
    impl ByteSink for Sink {
        fn is_full(&self) -> bool {
            self.got.len() == self.room
        }
        fn put(&mut self, b: u8) {
            self.got.push(b);
        }
    }

    #[test]
    fn the_receive_interrupt_moves_bytes_while_there_is_room_then_holds() {
        let mut port = Port {
            waiting: (1..=5).collect(),
            held: 0,
        };
        let mut sink = Sink {
            room: 3,
            got: Vec::new(),
        };
        receive(&mut port, &mut sink);
        assert_eq!((sink.got.as_slice(), port.held), (&[1, 2, 3][..], 1));
        assert_eq!(port.waiting, [4, 5], "left to the board");
        sink.room = 10;
        receive(&mut port, &mut sink);
        assert_eq!((sink.got.len(), port.held), (5, 1), "drained, not held");
    }

    #[test]
    fn a_load_cell_error_is_counted_not_passed_on() {
        let before = LOAD_CELL_ERRORS.load(Ordering::Relaxed);
        assert_eq!(
            conversion::<()>(Ok(Some(LoadCellCounts(7)))),
            Some(LoadCellCounts(7))
        );
        assert_eq!(conversion::<()>(Ok(None)), None);
        assert_eq!(conversion(Err(())), None);
        assert!(LOAD_CELL_ERRORS.load(Ordering::Relaxed) > before);
    }

    #[test]
    fn a_batch_takes_every_plan_and_counts_the_points_refused() {
        use crate::engine::BATCH;
        let plan = PointPlan {
            ftw: crate::dsp::dds::tuning_word(240.0, 10_000.0),
            amplitude_codes: 800,
            settle_samples: 0,
            cycles: 1,
            windows: 4,
            open: false,
            aligned: false,
            tag: 9,
        };
        let mut engine = SampleEngine::new();
        let mut plans: VecDeque<EngineCmd> = [None, Some(plan)].into();
        let adc = [AdcFrame::default(); BATCH];
        let mut dac = [DacCode::MID; BATCH];
        let mut taken = Vec::new();
        let mut refused = 0;
        for _ in 0..40 {
            refused += batch(
                &mut engine,
                &adc,
                &mut dac,
                || plans.pop_front(),
                |p| {
                    taken.push(p.plan.tag);
                    taken.len() % 2 == 0
                },
            );
        }
        assert!(plans.is_empty(), "every plan taken in the first batch");
        assert!(dac.iter().any(|c| *c != DacCode::MID), "the drive plays");
        assert!(taken.len() >= 2 && taken.iter().all(|t| *t == 9));
        assert_eq!(refused as usize, taken.len().div_ceil(2));
    }
}
