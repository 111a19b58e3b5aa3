//! Replays the fuzzer's regression corpus (`fuzz/corpus/command`, grown by
//! `cargo fuzz run command`) through the command parser and the UART line buffer, as the fuzz
//! target does: no input may panic. The hand-written seeds must parse to commands.

use pzt_probe::hal::FrontEndScale;
use pzt_probe::instrument::command::{parse, LineBuffer};

fn feed(data: &[u8]) -> usize {
    let s = FrontEndScale::PROBE;
    let _ = parse(data, &s);
    let mut lb = LineBuffer::new();
    let mut lines = 0;
    for &b in data {
        if let Some(r) = lb.push(b) {
            lines += 1;
            if let Ok(line) = r {
                let _ = parse(line, &s);
            }
        }
    }
    lines
}

#[test]
fn corpus_replays_without_panic() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/fuzz/corpus/command");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).expect("corpus directory") {
        let path = entry.unwrap().path();
        let data = std::fs::read(&path).unwrap();
        feed(&data);
        n += 1;
    }
    assert!(n >= 6, "corpus has only {n} inputs");
    // The seeds are valid commands.
    for seed in ["measure", "method", "sweep", "status", "store"] {
        let data = std::fs::read(format!("{dir}/{seed}")).unwrap();
        assert_eq!(feed(&data), 1);
        let line = data.strip_suffix(b"\n").unwrap();
        assert!(
            parse(line, &FrontEndScale::PROBE).is_ok(),
            "seed {seed} must parse"
        );
    }
}
