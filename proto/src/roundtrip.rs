//! The receive side's self-check, which the fuzz target `frame` runs on arbitrary bytes and
//! `tests/fuzz_frame_corpus.rs` replays on its corpus: bytes through the frame decoders of both
//! ends, each body decoded as a host and as a probe message, and each decoded message
//! re-encoded to a frame that decodes to the same message.

use crate::{
    decode_device, decode_host, encode_device, encode_host, Decoder, MAX_DEVICE_FRAME,
    MAX_HOST_FRAME,
};

/// A decoded message that did not come back from its own frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mismatch {
    /// A host message did not re-encode (every host message must: the probe's replies quote
    /// nothing longer).
    HostEncode,
    /// A host message's frame decoded to another message or to none.
    Host,
    /// A probe message's frame decoded to another message or to none.
    Device,
}

/// Both ends' decoders over one byte stream.
pub struct RoundTrip {
    host: Decoder<MAX_HOST_FRAME>,
    device: Decoder<MAX_DEVICE_FRAME>,
}

impl Default for RoundTrip {
    fn default() -> Self {
        Self::new()
    }
}

impl RoundTrip {
    /// Both decoders empty.
    pub const fn new() -> Self {
        Self {
            host: Decoder::new(),
            device: Decoder::new(),
        }
    }

    /// The next received byte: `Err` when it ends a frame whose message does not survive
    /// re-encoding. A probe message longer than the probe ever sends has no frame and is let
    /// be.
    pub fn feed(&mut self, b: u8) -> Result<(), Mismatch> {
        let mut buf = [0u8; MAX_DEVICE_FRAME + 1];
        if let Some(Ok(body)) = self.host.feed(b) {
            if let Ok(m) = decode_host(body) {
                let f = encode_host(&m, &mut buf).map_err(|_| Mismatch::HostEncode)?;
                let mut d = Decoder::<MAX_HOST_FRAME>::new();
                if body_of(&mut d, f).map(decode_host) != Some(Ok(m)) {
                    return Err(Mismatch::Host);
                }
            }
        }
        if let Some(Ok(body)) = self.device.feed(b) {
            if let Ok(m) = decode_device(body) {
                if let Ok(f) = encode_device(&m, &mut buf) {
                    let mut d = Decoder::<MAX_DEVICE_FRAME>::new();
                    if body_of(&mut d, f).map(decode_device) != Some(Ok(m)) {
                        return Err(Mismatch::Device);
                    }
                }
            }
        }
        Ok(())
    }
}

/// The body of frame `f` (one frame, its delimiter last) through decoder `d`: `None` unless
/// its last byte, and only that, ends a valid frame.
fn body_of<'d, const N: usize>(d: &'d mut Decoder<N>, f: &[u8]) -> Option<&'d [u8]> {
    let (&last, rest) = f.split_last()?;
    for &x in rest {
        if d.feed(x).is_some() {
            return None;
        }
    }
    d.feed(last)?.ok()
}
