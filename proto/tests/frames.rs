//! The link's frames against every bad input of issue #27: round trips of every message,
//! random bytes, truncated and oversized frames, bit flips (the CRC catches them), a wrong
//! version, and resynchronisation after garbage (the next good frame decodes).

use probe_proto::*;

/// xorshift64*: a reproducible byte source without dependencies.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn byte(&mut self) -> u8 {
        (self.next() >> 56) as u8
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn reading(status: &str) -> ReadingMsg<&str> {
    ReadingMsg {
        status,
        method: "auto",
        f_hz: Some(241.25),
        f_sigma_hz: Some(0.03),
        e_kpa: Some(279.5),
        e_sigma_kpa: Some(4.25),
        e_repeat_kpa: Some(1.5),
        q: Some(11.5),
        loss_tangent: None,
        loss_tangent_sigma: None,
        force_n: Some(0.03),
        force_sigma_n: Some(0.0004),
        probe_time_s: 0.37,
        points: 12,
    }
}

/// One of each probe message.
fn every_device_msg() -> Vec<DeviceMsg<'static>> {
    vec![
        DeviceMsg::Hello {
            version: VERSION,
            board: "qemu",
            firmware: "0.1.0",
            max_line_bytes: 96,
            max_host_frame_bytes: MAX_HOST_FRAME as u16,
            max_device_frame_bytes: MAX_DEVICE_FRAME as u16,
        },
        DeviceMsg::Reply {
            id: 7,
            outcome: Outcome::Accepted,
        },
        DeviceMsg::Reply {
            id: u32::MAX,
            outcome: Outcome::Rejected {
                code: "selftest",
                cause: Some("open_pzt"),
                message: "self-test: no current through the PZT",
            },
        },
        DeviceMsg::LinkError {
            error: FrameError::WrongVersion { got: 9 },
        },
        DeviceMsg::LinkError {
            error: FrameError::BadCrc,
        },
        DeviceMsg::Reading(reading("ok")),
        DeviceMsg::Stream {
            stream_seq: 300,
            t_s: 2.5,
            locked: true,
            reading: reading("too_light"),
        },
        DeviceMsg::StreamEnd(StreamEndMsg {
            start_s: 1.25,
            readings: 80,
            ok: 79,
            dropped: 0,
        }),
        DeviceMsg::Hint {
            code: "too_light",
            message: "pressed too lightly",
        },
        DeviceMsg::Status {
            method: "auto",
            calibration: "fitted",
            fallback: false,
            air: true,
            q_model: true,
            references: 0,
            selftest: "passed",
            boot: None,
        },
        DeviceMsg::SelfTest {
            result: "passed",
            message: None,
            f_hz: 1010.0,
            c_pf: 209.2,
            c_sigma_pf: 0.05,
            ref_c_pf: 210.1,
            tol: 0.0535,
            reference: "air",
            g_s: 1e-8,
            i_a: 2.7e-6,
            v: 2.0,
            probe_time_s: 0.58,
        },
        DeviceMsg::BootError {
            fault: "boot_clock",
            message: "clock failed",
        },
        DeviceMsg::Settings {
            method: "fit",
            start_hz: Some(180.0),
            stop_hz: Some(280.0),
            step_hz: None,
            settle_s: Some(0.02),
            integrate_s: Some(0.03),
            drive_v: Some(5.0),
        },
        DeviceMsg::Point(PointMsg {
            tag: 3,
            f_hz: 230.0,
            g_s: 1e-6,
            b_s: 2e-6,
            sigma_s: 1e-9,
        }),
        DeviceMsg::Air {
            f_hz: 232.1,
            q: 40.0,
        },
        DeviceMsg::Reference {
            e_kpa: 279.0,
            f_hz: 241.0,
            f_sigma_hz: 0.1,
            n: 3,
        },
        DeviceMsg::Calibration {
            source: "fitted",
            a: 1.0,
            b: 2.0,
            c: 3.0,
            min_kpa: 10.0,
            max_kpa: 3000.0,
        },
        DeviceMsg::LoadCell {
            present: true,
            newtons_per_count: Some(1e-6),
            tare_counts: Some(-1200),
            min_n: 0.012,
            max_n: 0.055,
        },
        DeviceMsg::Store {
            event: "saved",
            slot: Some(1),
            seq: Some(4),
        },
        DeviceMsg::Stalled { tag: 9 },
        DeviceMsg::Help {
            commands: "measure,stream",
            methods: "auto,hold",
            default_method: "auto",
        },
        DeviceMsg::Counters {
            batches: 1199,
            late: 0,
            ring: 0,
            dropped: 0,
            isr_mean: 3879,
            isr_max: 7160,
            unit: "instructions",
            load_cell_errors: 0,
        },
    ]
}

fn frame(seq: u32, msg: DeviceMsg<'static>) -> DeviceFrame<'static> {
    DeviceFrame {
        seq,
        dropped: seq % 3,
        msg,
    }
}

fn encode_d(f: &DeviceFrame) -> Vec<u8> {
    let mut out = [0u8; MAX_DEVICE_FRAME + 8];
    encode_device(f, &mut out).unwrap().to_vec()
}

fn encode_h(m: &HostMsg) -> Vec<u8> {
    let mut out = [0u8; MAX_HOST_FRAME + 8];
    encode_host(m, &mut out).unwrap().to_vec()
}

fn command(id: u32, line: &str) -> HostMsg {
    HostMsg::Command {
        id,
        line: heapless::String::try_from(line).unwrap(),
    }
}

/// A whole frame around `data` (version and body, unchecked): its CRC appended, COBS-encoded,
/// delimited.
fn frame_around(data: &[u8]) -> Vec<u8> {
    let mut content = data.to_vec();
    content.extend_from_slice(&crc32(data).to_le_bytes());
    let mut enc = [0u8; 64];
    let n = cobs::encode(&content, &mut enc).unwrap();
    let mut s = enc[..n].to_vec();
    s.push(0);
    s
}

/// Every outcome of feeding `bytes` to a device-side decoder, bodies decoded as probe frames.
fn device_outcomes(bytes: &[u8]) -> Vec<Result<DeviceFrame<'static>, FrameError>> {
    let mut d = Decoder::<MAX_DEVICE_FRAME>::new();
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(r) = d.feed(b) {
            out.push(r.and_then(|body| {
                // Leak: the test keeps the borrowed strings past the decoder's buffer.
                let body: &'static [u8] = Box::leak(body.to_vec().into_boxed_slice());
                decode_device(body)
            }));
        }
    }
    out
}

fn host_outcomes(bytes: &[u8]) -> Vec<Result<HostMsg, FrameError>> {
    let mut d = Decoder::<MAX_HOST_FRAME>::new();
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(r) = d.feed(b) {
            out.push(r.and_then(decode_host));
        }
    }
    out
}

#[test]
fn every_message_round_trips_and_fits() {
    for (i, m) in every_device_msg().into_iter().enumerate() {
        let f = frame(i as u32 * 1000, m);
        let bytes = encode_d(&f);
        assert!(bytes.len() <= MAX_DEVICE_FRAME + 1);
        assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1);
        assert_eq!(*bytes.last().unwrap(), 0);
        assert_eq!(device_outcomes(&bytes), vec![Ok(f)]);
    }
    for m in [
        HostMsg::Hello { version: VERSION },
        command(0, "measure"),
        command(u32::MAX, &"x".repeat(MAX_LINE)),
    ] {
        let bytes = encode_h(&m);
        assert!(bytes.len() <= MAX_HOST_FRAME + 1, "{} bytes", bytes.len());
        assert_eq!(host_outcomes(&bytes), vec![Ok(m)]);
    }
}

#[test]
fn a_message_too_large_for_the_buffer_is_an_error_not_a_panic() {
    let long = "y".repeat(600);
    let long: &'static str = Box::leak(long.into_boxed_str());
    let f = DeviceFrame {
        seq: 0,
        dropped: 0,
        msg: DeviceMsg::Hint {
            code: "x",
            message: long,
        },
    };
    let mut out = [0u8; MAX_DEVICE_FRAME];
    assert_eq!(encode_device(&f, &mut out), Err(EncodeError));
    for n in 0..8 {
        let mut small = vec![0u8; n];
        assert_eq!(encode_device(&f, &mut small), Err(EncodeError));
    }
}

#[test]
fn random_bytes_never_panic_and_never_pass() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let mut good = 0;
    for _ in 0..2000 {
        let n = rng.below(700);
        let bytes: Vec<u8> = (0..n).map(|_| rng.byte()).collect();
        for r in host_outcomes(&bytes) {
            good += r.is_ok() as u32;
        }
        for r in device_outcomes(&bytes) {
            good += r.is_ok() as u32;
        }
    }
    // A CRC-32 lets one random frame in 2³² through: none in these.
    assert_eq!(good, 0);
}

#[test]
fn truncated_frames_are_refused_and_the_next_frame_decodes() {
    let m = command(42, "stream 3");
    let bytes = encode_h(&m);
    for cut in 1..bytes.len() - 1 {
        // The host vanished mid-frame, then a new host starts each frame with a delimiter.
        let mut s = bytes[..cut].to_vec();
        s.push(0);
        s.extend_from_slice(&bytes);
        let out = host_outcomes(&s);
        assert_eq!(out.len(), 2, "cut at {cut}");
        assert!(out[0].is_err(), "cut at {cut}: {:?}", out[0]);
        assert_eq!(out[1], Ok(m.clone()));
    }
}

#[test]
fn oversized_frames_are_too_long_and_the_decoder_recovers() {
    let mut s = vec![0x55u8; MAX_HOST_FRAME * 3];
    s.push(0);
    let good = command(1, "status");
    s.extend_from_slice(&encode_h(&good));
    let out = host_outcomes(&s);
    assert_eq!(out, vec![Err(FrameError::TooLong), Ok(good)]);
    // A line longer than MAX_LINE cannot be sent (the type refuses it).
    assert!(heapless::String::<MAX_LINE>::try_from("z".repeat(MAX_LINE + 1).as_str()).is_err());
}

#[test]
fn every_single_bit_flip_is_caught() {
    let bytes = encode_h(&command(77, "sweep 200 260 2 0.02 0.03 5"));
    let body_len = bytes.len() - 1;
    for i in 0..body_len {
        for bit in 0..8 {
            let mut s = bytes.clone();
            s[i] ^= 1 << bit;
            let out = host_outcomes(&s);
            assert!(
                out.iter().all(|r| r.is_err()),
                "flip of bit {bit} of byte {i} passed: {out:?}"
            );
        }
    }
    // Two flips anywhere in a probe frame, many times.
    let mut rng = Rng(99);
    let f = frame(5, DeviceMsg::Reading(reading("ok")));
    let bytes = encode_d(&f);
    for _ in 0..5000 {
        let mut s = bytes.clone();
        for _ in 0..2 {
            let i = rng.below(bytes.len() - 1);
            s[i] ^= 1 << rng.below(8);
        }
        if s == bytes {
            continue;
        }
        assert!(device_outcomes(&s).iter().all(|r| r.is_err()));
    }
}

#[test]
fn a_wrong_version_is_told_as_such() {
    // A version-2 frame: a valid CRC over version 2's bytes.
    assert_eq!(
        host_outcomes(&frame_around(&[2, 0x00, 0x01])),
        vec![Err(FrameError::WrongVersion { got: 2 })]
    );
    // A Hello of another version in a frame of this one decodes: the firmware answers it.
    let hello = HostMsg::Hello { version: 3 };
    assert_eq!(host_outcomes(&encode_h(&hello)), vec![Ok(hello)]);
}

#[test]
fn a_valid_frame_with_a_body_of_no_message_is_malformed() {
    for body in [&[9u8][..], &[1, 5], &[0, 1, 2], &[1, 0, 200]] {
        let data = [&[VERSION][..], body].concat();
        assert_eq!(
            host_outcomes(&frame_around(&data)),
            vec![Err(FrameError::Malformed)],
            "{body:?}"
        );
    }
    // Trailing bytes after a whole message are malformed too.
    assert_eq!(
        host_outcomes(&frame_around(&[VERSION, 0, VERSION, 0xAA])),
        vec![Err(FrameError::Malformed)]
    );
    // Too short for a version and a CRC.
    assert_eq!(
        host_outcomes(&[0x03, 0x01, 0x02, 0x00]),
        vec![Err(FrameError::TooShort)]
    );
}

#[test]
fn garbage_then_good_frames_resynchronise() {
    let mut rng = Rng(7);
    let msgs: Vec<DeviceFrame> = every_device_msg()
        .into_iter()
        .enumerate()
        .map(|(i, m)| frame(i as u32, m))
        .collect();
    for _ in 0..300 {
        let mut s = Vec::new();
        for f in &msgs {
            // Garbage (no delimiter inside, so it joins the next frame), a delimiter, a frame.
            let n = rng.below(40);
            s.extend((0..n).map(|_| rng.byte() | 1));
            s.push(0);
            s.extend_from_slice(&encode_d(f));
        }
        let got: Vec<_> = device_outcomes(&s)
            .into_iter()
            .filter_map(Result::ok)
            .collect();
        assert_eq!(got, msgs);
    }
}

/// A point's body is its fields in the order `docs/protocol.md` gives them (the frame's `seq`
/// and `dropped`, variant index 11, then `tag`, `f_hz`, `g_s`, `b_s`, `sigma_s`), built here by
/// hand from postcard's rules: unsigned integers as LEB128 varints, `f32` little-endian.
#[test]
fn a_point_is_its_documented_fields_in_order() {
    let p = PointMsg {
        tag: 300,
        f_hz: 230.5,
        g_s: 1e-6,
        b_s: -2e-6,
        sigma_s: 1e-9,
    };
    let f = DeviceFrame {
        seq: 5,
        dropped: 0,
        msg: DeviceMsg::Point(p),
    };
    // seq 5, dropped 0, variant 11, tag 300 = 0b10_0101100 → 0xAC 0x02.
    let mut want = vec![5, 0, 11, 0xAC, 0x02];
    for x in [p.f_hz, p.g_s, p.b_s, p.sigma_s] {
        want.extend_from_slice(&x.to_le_bytes());
    }
    let mut buf = [0u8; MAX_DEVICE_FRAME];
    assert_eq!(postcard::to_slice(&f, &mut buf).unwrap(), &want[..]);
    assert_eq!(decode_device(&want), Ok(f));
}
