//! The SEGGER RTT up-buffer 0 of the image, read from emulated RAM as a debug probe reads it
//! (probe-rs): the control block at the ELF symbol `_SEGGER_RTT` ("SEGGER RTT" id, the buffer
//! counts, then per up-buffer: name pointer, buffer pointer, size, write offset, read offset,
//! flags); the bytes between the read and the write offset are taken and the read offset is
//! written back, so the target sees them consumed.

use crate::machine::Machine;

/// Core cycles between two drains: an emulated millisecond at 170 MHz, in which the image's
/// 1 KiB up-buffer does not fill.
pub const DRAIN_CYCLES: u64 = 170_000;

/// Offset of up-buffer 0's descriptor in the control block (16-byte id, two counts).
const UP0: u32 = 24;

/// Drain up-buffer 0 of the control block at `cb`: its new bytes, or an error if the control
/// block is not (yet) initialised.
pub fn drain(m: &mut Machine, cb: u32) -> Result<Vec<u8>, String> {
    let head = m
        .read_memory(cb, 16)
        .ok_or("RTT control block not in RAM")?;
    if &head[..10] != b"SEGGER RTT" {
        return Err("RTT control block not initialised".into());
    }
    let d = m
        .read_memory(cb + UP0, 24)
        .ok_or("RTT descriptor unreadable")?;
    let w = |i: usize| u32::from_le_bytes(d[4 * i..4 * i + 4].try_into().unwrap());
    let (buf, size, wr, rd) = (w(1), w(2), w(3), w(4));
    if size == 0 || wr >= size || rd >= size {
        return Err(format!(
            "RTT up-buffer 0 inconsistent: size {size}, write {wr}, read {rd}"
        ));
    }
    let mut out = Vec::new();
    let mut r = rd;
    while r != wr {
        let end = if wr > r { wr } else { size };
        out.extend(
            m.read_memory(buf + r, (end - r) as usize)
                .ok_or("RTT buffer unreadable")?,
        );
        r = if end == size { 0 } else { end };
    }
    if r != rd {
        let addr = cb + UP0 + 16;
        m.board_mut().mem_write(addr, 4, r);
    }
    Ok(out)
}
