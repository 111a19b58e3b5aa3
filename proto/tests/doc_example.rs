//! The example frames of `docs/protocol.md` are this encoder's: the test reads the doc's hex
//! lines and checks them byte for byte, so the document cannot go stale.

use probe_proto::*;

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The doc's line after `label`: the hex bytes in its code block.
fn doc_bytes(doc: &str, label: &str) -> String {
    let at = doc
        .find(label)
        .unwrap_or_else(|| panic!("docs/protocol.md has no `{label}`"));
    let rest = &doc[at + label.len()..];
    let line = rest
        .lines()
        .find(|l| l.trim_start().starts_with("frame:"))
        .expect("a `frame:` line after the label");
    line.trim_start()["frame:".len()..].trim().to_owned()
}

/// A host message's frame.
fn host(m: &HostMsg) -> Vec<u8> {
    encode_host(m, &mut [0u8; MAX_DEVICE_FRAME])
        .unwrap()
        .to_vec()
}

/// A probe message's frame, as the `seq`th sent, none dropped before it.
fn device(seq: u32, msg: DeviceMsg) -> Vec<u8> {
    let f = DeviceFrame {
        seq,
        dropped: 0,
        msg,
    };
    encode_device(&f, &mut [0u8; MAX_DEVICE_FRAME])
        .unwrap()
        .to_vec()
}

fn examples() -> Vec<(&'static str, Vec<u8>)> {
    let command = HostMsg::Command {
        id: 1,
        line: heapless::String::try_from("measure").unwrap(),
    };
    let reading = ReadingMsg {
        status: "ok",
        method: "auto",
        f_hz: Some(241.5),
        f_sigma_hz: Some(0.03125),
        e_kpa: Some(279.0),
        e_sigma_kpa: Some(4.5),
        e_repeat_kpa: Some(1.25),
        q: Some(11.5),
        loss_tangent: None,
        loss_tangent_sigma: None,
        force_n: Some(0.03125),
        force_sigma_n: Some(0.0005),
        probe_time_s: 0.375,
        points: 12,
    };
    let reply = DeviceMsg::Reply {
        id: 1,
        outcome: Outcome::Accepted,
    };
    vec![
        ("<!-- example: command -->", host(&command)),
        (
            "<!-- example: hello -->",
            host(&HostMsg::Hello { version: VERSION }),
        ),
        (
            "<!-- example: reading -->",
            device(300, DeviceMsg::Reading(reading)),
        ),
        ("<!-- example: reply -->", device(301, reply)),
    ]
}

#[test]
fn the_documents_example_frames_are_the_encoders() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/protocol.md"))
        .expect("docs/protocol.md");
    for (label, bytes) in examples() {
        assert_eq!(
            doc_bytes(&doc, label),
            hex(&bytes),
            "docs/protocol.md's {label} is stale"
        );
    }
}

/// Prints the examples (`cargo test -p probe-proto --test doc_example -- --nocapture print`).
#[test]
fn print_examples() {
    for (label, bytes) in examples() {
        println!("{label}\nframe: {}", hex(&bytes));
    }
}
