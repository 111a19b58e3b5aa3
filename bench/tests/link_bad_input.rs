//! Bad input on the host link against the running QEMU image (issue #27): random bytes,
//! truncated, oversized, malformed and wrong-version frames, a host that vanishes mid-stream,
//! and a command flood during a stream. Each bad frame gets a typed `LinkError`, each command
//! exactly one reply (`busy` when the queue is full), the link's `seq` moves by one plus the
//! drops it announces, and a stream's reading is either delivered or missing from `stream_seq`
//! and counted in its end. Needs qemu-system-arm and the thumbv7em-none-eabihf target.

use probe_bench::link::{host_bytes, Frame, Kind, Link, QemuProbe, Received};
use probe_proto::{cobs, crc32, HostMsg};
use serde_json::Value;
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(300);

fn start(scene: &[&str]) -> (QemuProbe, Link) {
    let elf = probe_bench::qemu::build_image().unwrap();
    let scene: Vec<String> = scene.iter().map(|s| s.to_string()).collect();
    let mut q = QemuProbe::start(&elf, &scene, None).unwrap();
    let s = q.connect(Duration::from_secs(20)).unwrap();
    (q, Link::tcp(s, None).unwrap())
}

/// Everything received until `done` says so (the link must not close or go quiet).
fn until(link: &Link, got: &mut Vec<Received>, mut done: impl FnMut(&[Received]) -> bool) {
    let t0 = Instant::now();
    while !done(got) {
        assert!(t0.elapsed() < WAIT, "timed out; got {got:?}");
        match link.recv(Duration::from_millis(200)) {
            Some(Received::Closed) => panic!("the link closed; got {got:?}"),
            Some(r) => got.push(r),
            None => {}
        }
    }
}

fn frames(got: &[Received]) -> Vec<&Frame> {
    got.iter()
        .filter_map(|r| match r {
            Received::Frame(f) => Some(f),
            _ => None,
        })
        .collect()
}

fn link_errors(got: &[Received]) -> Vec<Value> {
    frames(got)
        .iter()
        .filter_map(|f| f.json["msg"].get("LinkError").map(|e| e["error"].clone()))
        .collect()
}

fn reply(got: &[Received], id: u32) -> Option<Result<(), String>> {
    frames(got).iter().find_map(|f| match &f.kind {
        Kind::Reply { id: r, outcome } if *r == id => {
            Some(outcome.clone().map_err(|(code, _, _)| code))
        }
        _ => None,
    })
}

/// Consecutive frames: `seq` moves by one plus the drops the later one announces.
fn assert_seq_accounts_for_every_message(fs: &[&Frame]) {
    for w in fs.windows(2) {
        assert_eq!(
            w[1].seq,
            w[0].seq + 1 + w[1].dropped,
            "{} then {}",
            w[0].json,
            w[1].json
        );
    }
}

fn hello(link: &mut Link) -> Vec<Received> {
    link.hello().unwrap();
    let mut got = Vec::new();
    until(link, &mut got, |g| {
        frames(g)
            .iter()
            .any(|f| matches!(f.kind, Kind::Hello { .. }))
    });
    got
}

/// A frame of `content` (version byte first), CRC and COBS as the protocol has them.
fn raw_frame(content: &[u8]) -> Vec<u8> {
    let mut c = content.to_vec();
    c.extend_from_slice(&crc32(content).to_le_bytes());
    let mut enc = vec![0u8; c.len() + 8];
    let n = cobs::encode(&c, &mut enc).unwrap();
    let mut v = vec![0u8];
    v.extend_from_slice(&enc[..n]);
    v.push(0);
    v
}

#[test]
fn every_bad_frame_gets_a_typed_error_and_the_next_good_frame_is_served() {
    let (_q, mut link) = start(&["sim phantom B"]);
    let mut got = hello(&mut link);
    let mut expected = Vec::new();

    // Random bytes: every non-empty run between delimiters is one bad frame.
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let garbage: Vec<u8> = (0..3000)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // One byte in 40 a delimiter.
            if x.is_multiple_of(40) {
                0
            } else {
                (x >> 24) as u8
            }
        })
        .collect();
    let runs = garbage.split(|&b| b == 0).filter(|r| !r.is_empty()).count();
    link.send_raw(&garbage).unwrap();
    // A truncated frame, then (its leading delimiter ends the cut one) a good one.
    let good = host_bytes(&probe_bench::link::command(100, "status").unwrap());
    link.send_raw(&good[..good.len() / 2]).unwrap();
    link.send_raw(&good).unwrap();
    // An oversized frame.
    let mut long = vec![0x55u8; 400];
    long.push(0);
    link.send_raw(&long).unwrap();
    expected.push(serde_json::json!("TooLong"));
    // A frame of another version, and a Hello of another version.
    link.send_raw(&raw_frame(&[2, 1, 7, 1, b'x'])).unwrap();
    expected.push(serde_json::json!({"WrongVersion": {"got": 2}}));
    link.send(&HostMsg::Hello { version: 9 }).unwrap();
    expected.push(serde_json::json!({"WrongVersion": {"got": 9}}));
    // A valid frame whose body is no message, and a bit flip.
    link.send_raw(&raw_frame(&[1, 9])).unwrap();
    expected.push(serde_json::json!("Malformed"));
    let mut flipped = host_bytes(&probe_bench::link::command(101, "status").unwrap());
    flipped[5] ^= 0x04;
    link.send_raw(&flipped).unwrap();
    // A line that is no command, then a good command.
    link.command("frobnicate 3").unwrap(); // id 1
    link.command("status").unwrap(); // id 2
    until(&link, &mut got, |g| reply(g, 2).is_some());

    let errors = link_errors(&got);
    // The garbage's runs and the truncated frame, then the listed ones, then the bit flip.
    assert_eq!(errors.len(), runs + 1 + expected.len() + 1, "{errors:?}");
    let tail = &errors[runs + 1..runs + 1 + expected.len()];
    assert_eq!(tail, expected.as_slice());
    for e in &errors[..runs + 1] {
        assert!(
            ["BadCobs", "BadCrc", "TooShort", "TooLong"].contains(&e.as_str().unwrap_or("")),
            "{e}"
        );
    }
    assert_eq!(
        reply(&got, 100),
        Some(Ok(())),
        "the frame after the cut one"
    );
    assert_eq!(reply(&got, 101), None, "the flipped frame ran nothing");
    assert_eq!(reply(&got, 1), Some(Err("parse".to_owned())));
    assert_eq!(reply(&got, 2), Some(Ok(())));
    assert!(
        got.iter().all(|r| !matches!(r, Received::Error(_))),
        "the probe's frames are good"
    );
    let fs = frames(&got);
    assert_seq_accounts_for_every_message(&fs);
    assert!(fs.iter().all(|f| f.dropped == 0));
    eprintln!(
        "{} garbage runs, {} link errors, {} frames from the probe",
        runs,
        errors.len(),
        fs.len()
    );
}

#[test]
fn a_host_that_vanishes_mid_stream_leaves_the_probe_serving_the_next() {
    let (mut q, mut link) = start(&["sim phantom C"]);
    let mut got = hello(&mut link);
    link.command("stream 2").unwrap();
    until(&link, &mut got, |g| {
        frames(g)
            .iter()
            .filter(|f| matches!(f.kind, Kind::Stream(_)))
            .count()
            >= 5
    });
    let last_seq = frames(&got).last().unwrap().seq;
    // Mid-frame, even: half a command, then gone.
    let cut = host_bytes(&probe_bench::link::command(50, "status").unwrap());
    link.send_raw(&cut[..cut.len() / 2]).unwrap();
    link.vanish();
    drop(link);

    // A new host: the probe finished the stream into the void and serves it.
    let s = q.connect(Duration::from_secs(20)).unwrap();
    let mut link = Link::tcp(s, None).unwrap();
    let mut got = hello(&mut link);
    link.next_id = 7;
    link.command("status").unwrap();
    until(&link, &mut got, |g| reply(g, 7).is_some());
    assert_eq!(reply(&got, 7), Some(Ok(())));
    let fs = frames(&got);
    assert!(fs[0].seq > last_seq, "the link's seq goes on");
    assert_seq_accounts_for_every_message(&fs);
    let status = fs
        .iter()
        .find_map(|f| f.json["msg"].get("Status"))
        .expect("a status");
    assert_eq!(status["selftest"], "passed");
    // The half frame of the old host ended at the new host's first delimiter: one error.
    assert!(link_errors(&got).len() <= 1, "{:?}", link_errors(&got));
}

#[test]
fn a_command_flood_during_a_stream_gets_one_reply_each_and_no_reading_vanishes() {
    let (_q, mut link) = start(&["sim phantom C", "sim seed 3"]);
    let mut got = hello(&mut link);
    let stream = link.command("stream 2").unwrap();
    // 40 commands at once, while the stream runs.
    let mut flood = Vec::new();
    let mut ids = Vec::new();
    for k in 0..40u32 {
        let id = 1000 + k;
        ids.push(id);
        let line = if k % 3 == 0 { "help" } else { "status" };
        flood.extend(host_bytes(&probe_bench::link::command(id, line).unwrap()));
    }
    link.send_raw(&flood).unwrap();
    until(&link, &mut got, |g| {
        reply(g, stream).is_some() && ids.iter().all(|&id| reply(g, id).is_some())
    });
    let fs = frames(&got);
    assert_seq_accounts_for_every_message(&fs);
    // Exactly one reply per command.
    for &id in ids.iter().chain([stream].iter()) {
        let n = fs
            .iter()
            .filter(|f| matches!(f.kind, Kind::Reply { id: r, .. } if r == id))
            .count();
        assert_eq!(n, 1, "replies to {id}");
    }
    let busy = ids
        .iter()
        .filter(|&&id| reply(&got, id) == Some(Err("busy".to_owned())))
        .count();
    let accepted = ids
        .iter()
        .filter(|&&id| reply(&got, id) == Some(Ok(())))
        .count();
    assert_eq!(busy + accepted, ids.len(), "accepted or busy, nothing else");
    assert!(busy > 0 && accepted > 0, "busy {busy}, accepted {accepted}");
    // The stream: every reading it made arrived or is a gap its end counts.
    let seqs: Vec<u32> = fs
        .iter()
        .filter_map(|f| match &f.kind {
            Kind::Stream(s) => Some(s.seq),
            _ => None,
        })
        .collect();
    let (made, dropped) = fs
        .iter()
        .find_map(|f| match f.kind {
            Kind::StreamEnd(e) => Some((e.readings, e.dropped)),
            _ => None,
        })
        .expect("a stream end");
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "in order");
    assert!(seqs.iter().all(|&s| s < made));
    assert_eq!(
        made - seqs.len() as u32,
        dropped,
        "gaps in stream_seq = the end's drops"
    );
    let link_drops: u32 = fs.iter().map(|f| f.dropped).sum();
    eprintln!(
        "flood: {accepted} accepted, {busy} busy; stream {made} readings, {} delivered, {dropped} dropped by the report queue; link drops {link_drops}; {} frames",
        seqs.len(),
        fs.len()
    );
}
