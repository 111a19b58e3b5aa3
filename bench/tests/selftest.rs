//! `probe-bench selftest`: the firmware's self-test on the simulated probe from the command
//! line — the nominal probe passes (its capacitance the plate's 210 pF less the motional
//! remainder, against the factory air reference), each fault exits non-zero with its code.

mod common;

use common::{bin, run_fails_one_line, run_json};
use std::process::Stdio;

#[test]
fn nominal_passes_and_each_fault_fails_with_its_code() {
    let v = run_json(bin().args(["selftest", "--phantom", "B", "--json"]));
    assert_eq!(v["status"], "passed", "{v}");
    assert_eq!(v["reference"], "air");
    // hal-sim's plate: 210 pF; the motional branch takes at most 0.35 % off at 1010 Hz.
    let c = v["c_pf"].as_f64().unwrap();
    assert!((c / 210.0 - 1.0).abs() < 0.0035 + 0.002, "{c} pF");
    let fresh = run_json(bin().args(["selftest", "--fresh", "--json"]));
    assert_eq!(fresh["status"], "passed");
    assert_eq!(fresh["reference"], "nominal");
    for (fault, code) in [
        ("open", "open_pzt"),
        ("short", "shorted_pzt"),
        ("dac-stuck", "no_drive"),
        ("adc-rail", "adc_rail_current"),
    ] {
        let out = bin()
            .args(["selftest", "--phantom", "B", "--json", "--fault", fault])
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        assert!(!out.status.success(), "{fault}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["status"], code, "{fault}: {v}");
        assert!(v["message"].as_str().is_some_and(|m| !m.is_empty()));
        assert!(String::from_utf8_lossy(&out.stderr).contains(code));
    }
    let e = run_fails_one_line(bin().args(["selftest", "--fault", "melted"]));
    assert!(e.contains("unknown fault"), "{e}");
}
