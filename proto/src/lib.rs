//! The probe's host link on its serial line (`docs/protocol.md` is the specification).
//!
//! * **Messages**: [`HostMsg`] (host → probe) and [`DeviceFrame`] around a [`DeviceMsg`]
//!   (probe → host), encoded with postcard (serde's compact binary format: varints, `f32`
//!   little-endian, enums by variant index).
//! * **Frame**: `COBS(version · postcard body · CRC-32 of both, little-endian) · 0x00`
//!   ([`encode_host`], [`encode_device`]); the CRC is CRC-32/ISO-HDLC (zlib's, [`crc32`]).
//! * **Decoder**: [`Decoder`] takes bytes one at a time and returns each frame's postcard body
//!   or a typed [`FrameError`]; its buffer is fixed, it never panics, and a delimiter always
//!   resynchronises it.
//! * **Self-check**: [`roundtrip::RoundTrip`], both decoders over one byte stream, each
//!   decoded message re-encoded and decoded again (the fuzz target's check).
//!
//! `no_std`, allocation free; every function is total on any input.
#![no_std]
#![deny(missing_docs)]

pub mod cobs;
mod crc;
mod msg;
pub mod roundtrip;

pub use crc::crc32;
pub use msg::*;

use serde::{Deserialize, Serialize};

/// The protocol's version: the first byte of every frame's content. A frame of another version
/// is refused with [`FrameError::WrongVersion`].
pub const VERSION: u8 = 1;

/// Longest frame the probe accepts from the host, COBS-encoded, without the delimiter, bytes.
pub const MAX_HOST_FRAME: usize = 128;
/// Longest frame the probe sends, COBS-encoded, without the delimiter, bytes.
pub const MAX_DEVICE_FRAME: usize = 512;
/// Longest command line a [`HostMsg::Command`] carries, bytes (the firmware's `MAX_LINE`).
pub const MAX_LINE: usize = 96;

/// Bytes of the CRC at the end of a frame's content.
pub const CRC_BYTES: usize = 4;

/// Why received bytes are not a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameError {
    /// The bytes between two delimiters are not a COBS encoding.
    BadCobs,
    /// The frame's CRC-32 does not match its content (a corrupted or truncated frame).
    BadCrc,
    /// Longer than the receiver's buffer; discarded up to the next delimiter.
    TooLong,
    /// Shorter than a version byte and a CRC.
    TooShort,
    /// The version byte is not [`VERSION`] (`got`: the frame's).
    WrongVersion {
        /// The frame's version byte.
        got: u8,
    },
    /// The CRC holds but the body is no message of this version (unknown variant, a field
    /// cut short, bytes left over, a string not UTF-8 or too long).
    Malformed,
}

impl FrameError {
    /// Stable snake_case code.
    pub const fn code(self) -> &'static str {
        match self {
            FrameError::BadCobs => "bad_cobs",
            FrameError::BadCrc => "bad_crc",
            FrameError::TooLong => "too_long",
            FrameError::TooShort => "too_short",
            FrameError::WrongVersion { .. } => "wrong_version",
            FrameError::Malformed => "malformed",
        }
    }
}

/// Why a message could not be encoded into the buffer given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncodeError;

/// A streaming frame decoder with an `N`-byte buffer: bytes in, one frame's body (the postcard
/// bytes after the version byte, without the CRC) or a [`FrameError`] out at each delimiter.
///
/// Empty frames (two delimiters in a row) are ignored, so a sender may also start each frame
/// with a delimiter to end whatever a vanished peer left half-sent.
#[derive(Clone, Debug)]
pub struct Decoder<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
        }
    }

    /// Bytes held of a frame not yet ended.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Take one received byte: at a delimiter, the frame it ends (its body, checked) or why it
    /// is none; `None` otherwise and for empty frames.
    pub fn feed(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        if byte != 0 {
            if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if overflow {
            return Some(Err(FrameError::TooLong));
        }
        if len == 0 {
            return None;
        }
        let content = &mut self.buf[..len];
        Some(match cobs::decode_in_place(content) {
            Some(n) => check(&content[..n]),
            None => Err(FrameError::BadCobs),
        })
    }
}

/// A decoded frame's content (`version · body · crc`) checked: its body.
fn check(content: &[u8]) -> Result<&[u8], FrameError> {
    if content.len() < 1 + CRC_BYTES {
        return Err(FrameError::TooShort);
    }
    let (data, crc) = content.split_at(content.len() - CRC_BYTES);
    let mut want = [0u8; CRC_BYTES];
    want.copy_from_slice(crc);
    if crc32(data) != u32::from_le_bytes(want) {
        return Err(FrameError::BadCrc);
    }
    match data.split_first() {
        Some((&VERSION, body)) => Ok(body),
        Some((&got, _)) => Err(FrameError::WrongVersion { got }),
        None => Err(FrameError::TooShort),
    }
}

/// A frame body decoded as `T`; every byte must belong to it.
pub fn decode<'a, T: Deserialize<'a>>(body: &'a [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes::<T>(body) {
        Ok((v, [])) => Ok(v),
        _ => Err(FrameError::Malformed),
    }
}

/// `msg` as a whole frame into `out`, delimiter included: the written bytes.
///
/// The content (version, postcard body, CRC) is built at the end of `out` and COBS-encoded
/// to its start, so `out` needs the frame's length plus the content's.
pub fn encode<'o, T: Serialize>(msg: &T, out: &'o mut [u8]) -> Result<&'o [u8], EncodeError> {
    // COBS adds one byte per 254 and the delimiter: the content starts far enough back.
    let cap = out.len();
    let room = cap.checked_sub(2).ok_or(EncodeError)? * 254 / 255;
    let start = cap - room;
    let content = &mut out[start..];
    let (version, rest) = content.split_first_mut().ok_or(EncodeError)?;
    *version = VERSION;
    let body = postcard::to_slice(msg, rest)
        .map_err(|_| EncodeError)?
        .len();
    let data_end = 1 + body;
    let crc = crc32(&content[..data_end]).to_le_bytes();
    content
        .get_mut(data_end..data_end + CRC_BYTES)
        .ok_or(EncodeError)?
        .copy_from_slice(&crc);
    let n = cobs::encode_within(out, start, data_end + CRC_BYTES).ok_or(EncodeError)?;
    *out.get_mut(n).ok_or(EncodeError)? = 0;
    Ok(&out[..n + 1])
}

/// A host message as a frame into `out` ([`encode`]).
pub fn encode_host<'o>(msg: &HostMsg, out: &'o mut [u8]) -> Result<&'o [u8], EncodeError> {
    encode(msg, out)
}

/// A probe message as a frame into `out` ([`encode`]).
pub fn encode_device<'o>(
    frame: &DeviceFrame<'_>,
    out: &'o mut [u8],
) -> Result<&'o [u8], EncodeError> {
    encode(frame, out)
}

/// A received body as a host message.
pub fn decode_host(body: &[u8]) -> Result<HostMsg, FrameError> {
    decode(body)
}

/// A received body as a probe message (strings borrowed from `body`).
pub fn decode_device(body: &[u8]) -> Result<DeviceFrame<'_>, FrameError> {
    decode(body)
}
