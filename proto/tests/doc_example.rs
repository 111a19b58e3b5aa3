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

fn examples() -> Vec<(&'static str, Vec<u8>)> {
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_DEVICE_FRAME];
    let host = HostMsg::Command {
        id: 1,
        line: heapless::String::try_from("measure").unwrap(),
    };
    out.push((
        "<!-- example: command -->",
        encode_host(&host, &mut buf).unwrap().to_vec(),
    ));
    let hello = HostMsg::Hello { version: VERSION };
    out.push((
        "<!-- example: hello -->",
        encode_host(&hello, &mut buf).unwrap().to_vec(),
    ));
    let reading = DeviceFrame {
        seq: 300,
        dropped: 0,
        msg: DeviceMsg::Reading(ReadingMsg {
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
        }),
    };
    out.push((
        "<!-- example: reading -->",
        encode_device(&reading, &mut buf).unwrap().to_vec(),
    ));
    let reply = DeviceFrame {
        seq: 301,
        dropped: 0,
        msg: DeviceMsg::Reply {
            id: 1,
            outcome: Outcome::Accepted,
        },
    };
    out.push((
        "<!-- example: reply -->",
        encode_device(&reply, &mut buf).unwrap().to_vec(),
    ));
    out
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
