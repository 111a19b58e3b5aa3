//! Fuzz the host link's receive side: arbitrary bytes through the frame decoders of both ends
//! (`probe_proto::Decoder` with the probe's and the host's buffers), each body decoded as a
//! host and a probe message, and the firmware's `HostLink` (decoder, then the command parser).
//! Nothing may panic, loop or overflow; a body that decodes re-encodes to a frame that decodes
//! to the same message.
#![no_main]

use libfuzzer_sys::fuzz_target;
use probe_proto::{
    decode_device, decode_host, encode_device, encode_host, Decoder, MAX_DEVICE_FRAME,
    MAX_HOST_FRAME,
};
use pzt_probe::hal::FrontEndScale;
use pzt_probe::instrument::link::HostLink;

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

fuzz_target!(|data: &[u8]| {
    let scale = FrontEndScale::PROBE;
    let mut host = Decoder::<MAX_HOST_FRAME>::new();
    let mut device = Decoder::<MAX_DEVICE_FRAME>::new();
    let mut link = HostLink::new();
    let mut buf = [0u8; MAX_DEVICE_FRAME + 1];
    for &b in data {
        if let Some(Ok(body)) = host.feed(b) {
            if let Ok(m) = decode_host(body) {
                let f = encode_host(&m, &mut buf).expect("a decoded host message re-encodes");
                assert_eq!(decode_host(&body_of::<MAX_HOST_FRAME>(f)), Ok(m));
            }
        }
        if let Some(Ok(body)) = device.feed(b) {
            let body = body.to_vec();
            if let Ok(m) = decode_device(&body) {
                let mut out = [0u8; MAX_DEVICE_FRAME + 1];
                // A decoded message may be longer than the probe ever sends: no frame then.
                if let Ok(f) = encode_device(&m, &mut out) {
                    let again = body_of::<MAX_DEVICE_FRAME>(f);
                    assert_eq!(decode_device(&again).as_ref(), Ok(&m));
                }
            }
        }
        let _ = link.push(b, &scale);
    }
});
