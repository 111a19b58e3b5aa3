//! Fuzz the host command interface: arbitrary bytes through the line buffer and the parser.
//! Nothing may panic, loop or overflow; every line is either a command or a typed error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pzt_probe::instrument::command::{parse, LineBuffer};
use pzt_probe::hal::FrontEndScale;

fuzz_target!(|data: &[u8]| {
    let scale = FrontEndScale::PROBE;
    // The whole input as one line.
    let _ = parse(data, &scale);
    // And as a byte stream through the UART line buffer.
    let mut lb = LineBuffer::new();
    for &b in data {
        if let Some(Ok(line)) = lb.push(b) {
            let _ = parse(line, &scale);
        }
    }
});
