//! The Python client (`clients/python/probe_client.py`, written from docs/protocol.md) takes a
//! reading of phantom B from the QEMU image over its TCP serial port, and decodes the document's
//! example frames. Needs python3 with pyserial (`scripts/setup` installs it), qemu-system-arm
//! and the thumbv7em-none-eabihf target.

use probe_bench::link::QemuProbe;
use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn client() -> PathBuf {
    root().join("clients/python/probe_client.py")
}

#[test]
fn the_python_client_reads_phantom_b_from_the_qemu_image() {
    let elf = probe_bench::qemu::build_image().unwrap();
    let scene = ["sim phantom B".to_owned(), "sim seed 0".to_owned()];
    let q = QemuProbe::start(&elf, &scene, None).unwrap();
    let out = Command::new("python3")
        .arg(client())
        .args(["--url", &format!("socket://127.0.0.1:{}", q.port)])
        .args(["--timeout-s", "300", "measure"])
        .output()
        .expect("python3");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let frames: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // Link seq without gaps, nothing dropped.
    for w in frames.windows(2) {
        assert_eq!(
            w[1]["seq"].as_u64().unwrap(),
            w[0]["seq"].as_u64().unwrap() + 1
        );
    }
    let reading = frames
        .iter()
        .find_map(|f| f["msg"].get("Reading"))
        .expect("a reading");
    assert_eq!(reading["status"], "ok", "{reading}");
    let e = reading["e_kpa"].as_f64().unwrap();
    let s = reading["e_sigma_kpa"].as_f64().unwrap();
    assert!((e - 279.0).abs() <= 3.0 * s, "{reading}");
    let reply = &frames.last().unwrap()["msg"]["Reply"];
    assert_eq!(reply["id"], 1);
    assert_eq!(reply["outcome"], "Accepted");
    eprintln!("python client: {reading}");
}

#[test]
fn the_python_client_decodes_the_documents_examples() {
    let code = r#"
import re, sys
sys.path.insert(0, sys.argv[1])
import probe_client as p
doc = open(sys.argv[2]).read()
ex = dict(re.findall(r"<!-- example: (\w+) -->.*?frame: ([0-9a-f ]+)", doc, re.S))
raw = lambda k: bytes.fromhex(ex[k])[:-1]
f = p.decode_device(p.unframe(raw("reading")))
r = f["msg"]["Reading"]
assert f["seq"] == 300 and r["status"] == "ok" and r["e_kpa"] == 279.0 and r["loss_tangent"] is None, f
assert r["force_sigma_n"] == __import__("struct").unpack("<f", __import__("struct").pack("<f", 0.0005))[0]
f = p.decode_device(p.unframe(raw("reply")))
assert f == {"seq": 301, "dropped": 0, "msg": {"Reply": {"id": 1, "outcome": "Accepted"}}}, f
assert p.command(1, "measure") == b"\x00" + bytes.fromhex(ex["command"]), "command"
assert p.hello() == b"\x00" + bytes.fromhex(ex["hello"]), "hello"
for bad in [raw("reply")[:-1], bytes([raw("reply")[0] ^ 1]) + raw("reply")[1:]]:
    try:
        p.decode_device(p.unframe(bad))
        raise SystemExit("a bad frame decoded")
    except ValueError:
        pass
print("ok")
"#;
    let out = Command::new("python3")
        .args(["-c", code])
        .arg(root().join("clients/python"))
        .arg(root().join("docs/protocol.md"))
        .output()
        .expect("python3");
    assert!(
        out.status.success() && String::from_utf8_lossy(&out.stdout).trim() == "ok",
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
