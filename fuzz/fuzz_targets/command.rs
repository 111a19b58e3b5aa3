//! Fuzz the host command interface: arbitrary bytes through the line buffer and the parser.
//! Nothing may panic, loop or overflow; every line is either a command or a typed error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pzt_probe::instrument::command::{parse, LineBuffer};
use pzt_probe::hal::FrontEndScale;
use pzt_probe::Hz;

fuzz_target!(|data: &[u8]| {
    let scale = FrontEndScale {
        sample_rate: Hz(10_000.0),
        drive_volts_per_code: 5.0 * 3.3 / 4096.0,
        amps_per_code: 3.3 / 4096.0 / 300e3,
        monitor_volts_per_code: 3.3 / 4096.0 / 0.15,
        reconstruction_corner: Hz(1_000.0),
        antialias_corner: Hz(1_000.0),
    };
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
