#!/usr/bin/env python3
"""A client of the probe's host link, written from docs/protocol.md (version 1) alone.

    python3 probe_client.py --url socket://127.0.0.1:PORT measure
    python3 probe_client.py --url /dev/ttyACM0 "stream 3"

Each argument is a command line; each is sent once the previous one's reply has come. Every
message from the probe is printed as one JSON line (readings as {"Reading": {...}}, and so on),
with the frame's link `seq` and `dropped`. Exits non-zero if a command was rejected or the link
failed. Needs pyserial (`python3 -m pip install pyserial`); `socket://` URLs reach the QEMU
image's TCP serial port.
"""

import argparse
import json
import struct
import sys
import time
import zlib

VERSION = 1


# --- Framing: COBS(version · body · CRC-32 LE) · 0x00 -------------------------------------

def cobs_encode(data: bytes) -> bytes:
    out = bytearray([0])
    code_at, code = 0, 1
    for b in data:
        if b == 0:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
        else:
            out.append(b)
            code += 1
            if code == 0xFF:
                out[code_at] = code
                code_at, code = len(out), 1
                out.append(0)
    out[code_at] = code
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    out = bytearray()
    i = 0
    while i < len(data):
        code = data[i]
        if code == 0:
            raise ValueError("bad_cobs")
        i += 1
        end = i + code - 1
        if end > len(data):
            raise ValueError("bad_cobs")
        out += data[i:end]
        i = end
        if code != 0xFF and i < len(data):
            out.append(0)
    return bytes(out)


def frame(body: bytes) -> bytes:
    """A host frame, with a leading delimiter that ends anything half-sent before it."""
    content = bytes([VERSION]) + body
    content += struct.pack("<I", zlib.crc32(content))
    return b"\x00" + cobs_encode(content) + b"\x00"


def unframe(raw: bytes) -> bytes:
    """The body of a received frame (without its delimiter), or ValueError with the error."""
    content = cobs_decode(raw)
    if len(content) < 5:
        raise ValueError("too_short")
    data, crc = content[:-4], struct.unpack("<I", content[-4:])[0]
    if zlib.crc32(data) != crc:
        raise ValueError("bad_crc")
    if data[0] != VERSION:
        raise ValueError(f"wrong_version {data[0]}")
    return data[1:]


# --- postcard ------------------------------------------------------------------------------

def varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


class Reader:
    def __init__(self, data: bytes):
        self.d, self.i = data, 0

    def byte(self) -> int:
        if self.i >= len(self.d):
            raise ValueError("malformed")
        b = self.d[self.i]
        self.i += 1
        return b

    def u8(self):
        return self.byte()

    def varint(self, max_bytes):
        n = shift = 0
        for _ in range(max_bytes):
            b = self.byte()
            n |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return n
        raise ValueError("malformed")

    def u16(self):
        return self.varint(3)

    def u32(self):
        return self.varint(5)

    def i32(self):
        z = self.varint(5)
        return (z >> 1) ^ -(z & 1)

    def f32(self):
        if self.i + 4 > len(self.d):
            raise ValueError("malformed")
        v = struct.unpack("<f", self.d[self.i:self.i + 4])[0]
        self.i += 4
        return v

    def bool(self):
        b = self.byte()
        if b > 1:
            raise ValueError("malformed")
        return b == 1

    def str(self):
        n = self.u32()
        if self.i + n > len(self.d):
            raise ValueError("malformed")
        s = self.d[self.i:self.i + n].decode("utf-8")
        self.i += n
        return s


def option(kind):
    def read(r):
        tag = r.byte()
        if tag == 0:
            return None
        if tag == 1:
            return kind(r)
        raise ValueError("malformed")
    return read


def struct_of(*fields):
    """A reader of the named fields in order: fields are (name, reader)."""
    def read(r):
        return {name: kind(r) for name, kind in fields}
    return read


U8, U16, U32, I32 = Reader.u8, Reader.u16, Reader.u32, Reader.i32
F32, BOOL, STR = Reader.f32, Reader.bool, Reader.str
OF32, OSTR = option(F32), option(STR)

READING = struct_of(
    ("status", STR), ("method", STR), ("f_hz", OF32), ("f_sigma_hz", OF32),
    ("e_kpa", OF32), ("e_sigma_kpa", OF32), ("e_repeat_kpa", OF32), ("q", OF32),
    ("loss_tangent", OF32), ("loss_tangent_sigma", OF32), ("force_n", OF32),
    ("force_sigma_n", OF32), ("probe_time_s", F32), ("points", U16),
)


def enum_of(*variants):
    """A reader of an enum: variants are (name, reader or None) by index."""
    def read(r):
        k = r.u32()
        if k >= len(variants):
            raise ValueError("malformed")
        name, kind = variants[k]
        return {name: kind(r)} if kind else name
    return read


FRAME_ERROR = enum_of(
    ("BadCobs", None), ("BadCrc", None), ("TooLong", None), ("TooShort", None),
    ("WrongVersion", struct_of(("got", U8))), ("Malformed", None),
)
OUTCOME = enum_of(
    ("Accepted", None),
    ("Rejected", struct_of(("code", STR), ("cause", OSTR), ("message", STR))),
)
DEVICE_MSG = enum_of(
    ("Hello", struct_of(("version", U8), ("board", STR), ("firmware", STR),
                        ("max_line_bytes", U16), ("max_host_frame_bytes", U16),
                        ("max_device_frame_bytes", U16))),
    ("Reply", struct_of(("id", U32), ("outcome", OUTCOME))),
    ("LinkError", struct_of(("error", FRAME_ERROR))),
    ("Reading", READING),
    ("Stream", struct_of(("stream_seq", U32), ("t_s", F32), ("locked", BOOL),
                         ("reading", READING))),
    ("StreamEnd", struct_of(("start_s", F32), ("readings", U32), ("ok", U32),
                            ("dropped", U32))),
    ("Hint", struct_of(("code", STR), ("message", STR))),
    ("Status", struct_of(("method", STR), ("calibration", STR), ("fallback", BOOL),
                         ("air", BOOL), ("q_model", BOOL), ("references", U16),
                         ("selftest", STR), ("boot", OSTR))),
    ("SelfTest", struct_of(("result", STR), ("message", OSTR), ("f_hz", F32), ("c_pf", F32),
                           ("c_sigma_pf", F32), ("ref_c_pf", F32), ("tol", F32),
                           ("reference", STR), ("g_s", F32), ("i_a", F32), ("v", F32),
                           ("probe_time_s", F32))),
    ("BootError", struct_of(("fault", STR), ("message", STR))),
    ("Settings", struct_of(("method", STR), ("start_hz", OF32), ("stop_hz", OF32),
                           ("step_hz", OF32), ("settle_s", OF32), ("integrate_s", OF32),
                           ("drive_v", OF32))),
    ("Point", struct_of(("tag", U16), ("f_hz", F32), ("g_s", F32), ("b_s", F32),
                        ("sigma_s", F32))),
    ("Air", struct_of(("f_hz", F32), ("q", F32))),
    ("Reference", struct_of(("e_kpa", F32), ("f_hz", F32), ("f_sigma_hz", F32), ("n", U16))),
    ("Calibration", struct_of(("source", STR), ("a", F32), ("b", F32), ("c", F32),
                              ("min_kpa", F32), ("max_kpa", F32))),
    ("LoadCell", struct_of(("present", BOOL), ("newtons_per_count", OF32),
                           ("tare_counts", option(I32)), ("min_n", F32), ("max_n", F32))),
    ("Store", struct_of(("event", STR), ("slot", option(U8)), ("seq", option(U32)))),
    ("Stalled", struct_of(("tag", U16))),
    ("Help", struct_of(("commands", STR), ("methods", STR), ("default_method", STR))),
    ("Counters", struct_of(("batches", U32), ("late", U32), ("ring", U32), ("dropped", U32),
                           ("isr_mean", U32), ("isr_max", U32), ("unit", STR),
                           ("load_cell_errors", U32))),
)


def decode_device(body: bytes) -> dict:
    r = Reader(body)
    out = {"seq": r.u32(), "dropped": r.u32(), "msg": DEVICE_MSG(r)}
    if r.i != len(body):
        raise ValueError("malformed")
    return out


def hello() -> bytes:
    return frame(varint(0) + bytes([VERSION]))


def command(cmd_id: int, line: str) -> bytes:
    b = line.encode("utf-8")
    if len(b) > 96:
        raise ValueError("a command line is at most 96 bytes")
    return frame(varint(1) + varint(cmd_id) + varint(len(b)) + b)


# --- The link ------------------------------------------------------------------------------

class Link:
    """Frames in and out over a pyserial port."""

    def __init__(self, url: str):
        import serial  # pyserial
        self.port = serial.serial_for_url(url, baudrate=115200, timeout=0.2)
        self.buf = bytearray()
        self.next_seq = None
        self.lost = 0

    def send(self, data: bytes):
        self.port.write(data)
        self.port.flush()

    def messages(self, deadline: float):
        """Received frames (as dicts) until the deadline; link errors as {"error": ...}."""
        while time.monotonic() < deadline:
            chunk = self.port.read(4096)
            if not chunk:
                continue
            self.buf += chunk
            while 0 in self.buf:
                i = self.buf.index(0)
                raw, self.buf = bytes(self.buf[:i]), self.buf[i + 1:]
                if not raw:
                    continue
                try:
                    f = decode_device(unframe(raw))
                except (ValueError, UnicodeDecodeError) as e:
                    yield {"error": str(e)}
                    continue
                if self.next_seq is not None:
                    self.lost += max(0, f["seq"] - self.next_seq - f["dropped"])
                self.next_seq = f["seq"] + 1
                yield f


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--url", required=True,
                    help="pyserial URL: a port (/dev/ttyACM0) or socket://HOST:PORT")
    ap.add_argument("--timeout-s", type=float, default=600.0,
                    help="most wall time to wait for each reply, s")
    ap.add_argument("commands", nargs="*", help="command lines, e.g. measure, 'stream 3'")
    a = ap.parse_args()
    link = Link(a.url)
    link.send(hello())
    rejected = 0
    for f in link.messages(time.monotonic() + a.timeout_s):
        print(json.dumps(f), flush=True)
        if isinstance(f.get("msg"), dict) and "Hello" in f["msg"]:
            break
    else:
        print("probe_client: no hello from the probe", file=sys.stderr)
        return 1
    for cmd_id, line in enumerate(a.commands, start=1):
        link.send(command(cmd_id, line))
        for f in link.messages(time.monotonic() + a.timeout_s):
            print(json.dumps(f), flush=True)
            reply = f.get("msg", {}).get("Reply") if isinstance(f.get("msg"), dict) else None
            if reply and reply["id"] == cmd_id:
                if reply["outcome"] != "Accepted":
                    rejected += 1
                break
        else:
            print(f"probe_client: no reply to {line!r}", file=sys.stderr)
            return 1
    if link.lost:
        print(f"probe_client: {link.lost} messages lost on the line", file=sys.stderr)
    return 1 if rejected or link.lost else 0


if __name__ == "__main__":
    sys.exit(main())
