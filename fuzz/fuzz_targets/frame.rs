//! Fuzz the host link's receive side: arbitrary bytes through `probe_proto::roundtrip` (the
//! frame decoders of both ends, each body decoded as a host and a probe message) and the
//! firmware's `HostLink` (decoder, then the command parser). Nothing may panic, loop or
//! overflow; a body that decodes re-encodes to a frame that decodes to the same message.
#![no_main]

use libfuzzer_sys::fuzz_target;
use probe_proto::roundtrip::RoundTrip;
use pzt_probe::hal::FrontEndScale;
use pzt_probe::instrument::link::HostLink;

fuzz_target!(|data: &[u8]| {
    let scale = FrontEndScale::PROBE;
    let mut check = RoundTrip::new();
    let mut link = HostLink::new();
    for &b in data {
        assert_eq!(check.feed(b), Ok(()));
        let _ = link.push(b, &scale);
    }
});
