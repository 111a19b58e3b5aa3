//! Replays the host link's fuzz corpus (`fuzz/corpus/frame`, grown by `cargo fuzz run frame`)
//! through `probe_proto::roundtrip` and the firmware's `HostLink`, as the fuzz target does: no
//! input may panic, and a decoded message re-encodes to itself. The hand-written seeds
//! decode to what they are.

use probe_proto::roundtrip::RoundTrip;
use probe_proto::{decode_device, decode_host, Decoder, FrameError, HostMsg, MAX_DEVICE_FRAME};
use pzt_probe::hal::FrontEndScale;
use pzt_probe::instrument::command::Command;
use pzt_probe::instrument::link::{HostLink, Incoming};

/// What the fuzz target does with one input; the firmware link's outcomes.
fn feed(data: &[u8]) -> Vec<Incoming> {
    let scale = FrontEndScale::PROBE;
    let mut check = RoundTrip::new();
    let mut link = HostLink::new();
    let mut out = Vec::new();
    for &b in data {
        assert_eq!(check.feed(b), Ok(()));
        out.extend(link.push(b, &scale));
    }
    out
}

fn read(name: &str) -> Vec<u8> {
    std::fs::read(format!(
        "{}/fuzz/corpus/frame/{name}",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

#[test]
fn corpus_replays_without_panic_and_the_seeds_decode() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/fuzz/corpus/frame");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).expect("corpus directory") {
        feed(&std::fs::read(entry.unwrap().path()).unwrap());
        n += 1;
    }
    assert!(n >= 12, "corpus has only {n} inputs");
    assert_eq!(feed(&read("hello")), [Incoming::Hello]);
    let cmd = |id: u32, line: &str, c| Incoming::Command {
        id,
        line: heapless::String::try_from(line).unwrap(),
        parsed: c,
    };
    assert_eq!(
        feed(&read("measure")),
        [cmd(1, "measure", Ok(Command::Measure))]
    );
    assert!(matches!(
        feed(&read("stream")).as_slice(),
        [Incoming::Command {
            id: 2,
            parsed: Ok(Command::Stream(_)),
            ..
        }]
    ));
    assert_eq!(
        feed(&read("wrong-version")),
        [Incoming::Error(FrameError::WrongVersion { got: 2 })]
    );
    assert_eq!(
        feed(&read("oversized")),
        [
            Incoming::Error(FrameError::TooLong),
            cmd(7, "status", Ok(Command::Status))
        ]
    );
    assert!(
        feed(&read("truncated")).is_empty(),
        "no delimiter: nothing yet"
    );
    // The probe's own frames are probe messages, not host ones.
    let mut d = Decoder::<MAX_DEVICE_FRAME>::new();
    let body = read("device-reading")
        .into_iter()
        .find_map(|b| d.feed(b).map(|r| r.unwrap().to_vec()))
        .unwrap();
    assert!(decode_device(&body).is_ok());
    assert!(decode_host(&body).is_err());
    let _ = HostMsg::Hello { version: 1 };
}
