//! Replays the host link's fuzz corpus (`fuzz/corpus/frame`, grown by `cargo fuzz run frame`)
//! through the frame decoders of both ends and the firmware's `HostLink`, as the fuzz target
//! does: no input may panic, and a decoded message re-encodes to itself. The hand-written seeds
//! decode to what they are.

use probe_proto::{
    decode_device, decode_host, encode_device, encode_host, Decoder, FrameError, HostMsg,
    MAX_DEVICE_FRAME, MAX_HOST_FRAME,
};
use pzt_probe::hal::FrontEndScale;
use pzt_probe::instrument::command::Command;
use pzt_probe::instrument::link::{HostLink, Incoming};

/// The body of the one valid frame `f` (an encoder's output).
fn body_of<const N: usize>(f: &[u8]) -> Vec<u8> {
    let mut d = Decoder::<N>::new();
    for &x in f {
        if let Some(r) = d.feed(x) {
            return r.expect("the encoder's frame is valid").to_vec();
        }
    }
    panic!("the encoder's frame has no delimiter")
}

/// What the fuzz target does with one input; the firmware link's outcomes.
fn feed(data: &[u8]) -> Vec<Incoming> {
    let scale = FrontEndScale::PROBE;
    let mut host = Decoder::<MAX_HOST_FRAME>::new();
    let mut device = Decoder::<MAX_DEVICE_FRAME>::new();
    let mut link = HostLink::new();
    let mut buf = [0u8; MAX_DEVICE_FRAME + 1];
    let mut out = Vec::new();
    for &b in data {
        if let Some(Ok(body)) = host.feed(b) {
            if let Ok(m) = decode_host(body) {
                let f = encode_host(&m, &mut buf).unwrap();
                assert_eq!(decode_host(&body_of::<MAX_HOST_FRAME>(f)), Ok(m));
            }
        }
        if let Some(Ok(body)) = device.feed(b) {
            let body = body.to_vec();
            if let Ok(m) = decode_device(&body) {
                let mut o = [0u8; MAX_DEVICE_FRAME + 1];
                if let Ok(f) = encode_device(&m, &mut o) {
                    let again = body_of::<MAX_DEVICE_FRAME>(f);
                    assert_eq!(decode_device(&again).as_ref(), Ok(&m));
                }
            }
        }
        if let Some(i) = link.push(b, &scale) {
            out.push(i);
        }
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
