//! The host end of the probe's serial link (`docs/protocol.md`, crate `probe_proto`): a
//! connection to a real probe's serial port (115 200 Bd) or to the QEMU image serving its UART
//! on a TCP socket, the frames decoded on a reader thread into [`Received`] values.

use anyhow::{bail, Context, Result};
use probe_proto::{
    decode_device, encode_host, Decoder, DeviceFrame, DeviceMsg, FrameError, HostMsg, Outcome,
    ReadingMsg, StreamEndMsg, MAX_DEVICE_FRAME, MAX_HOST_FRAME, MAX_LINE, VERSION,
};
use pzt_probe::instrument::continuous::StreamReading;
use pzt_probe::reading::Reading;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Baud rate of the probe's LPUART1 (ST-LINK virtual COM port).
pub const BAUD: u32 = 115_200;

/// What a received frame holds, typed where the bench uses it.
#[derive(Clone, Debug)]
pub enum Kind {
    /// The probe's handshake.
    Hello {
        /// Its protocol version.
        version: u8,
        /// Its board.
        board: String,
    },
    /// A command's reply: `Ok` accepted, `Err((code, cause, message))` rejected.
    Reply {
        /// The command's id.
        id: u32,
        /// The outcome.
        outcome: Result<(), (String, Option<String>, String)>,
    },
    /// A reading.
    Reading(Reading),
    /// A stream's reading (`t_s` as the probe sends it: probe time since power-on).
    Stream(StreamReading),
    /// A stream ended: its start (probe time, s) and its counts.
    StreamEnd(StreamEndMsg),
    /// Any other message.
    Other,
}

/// One frame from the probe.
#[derive(Clone, Debug)]
pub struct Frame {
    /// The link's sequence number.
    pub seq: u32,
    /// Messages the probe dropped just before this one.
    pub dropped: u32,
    /// The whole frame as JSON (serde's form of [`DeviceFrame`]).
    pub json: serde_json::Value,
    /// What the bench uses of it.
    pub kind: Kind,
}

/// What the reader thread hands on.
#[derive(Clone, Debug)]
pub enum Received {
    /// A frame.
    Frame(Frame),
    /// Bytes that were no frame.
    Error(FrameError),
    /// The line closed (the probe or QEMU went away).
    Closed,
}

/// A reading of the link as the bench's [`Reading`] (`None`: an unknown status or method).
pub fn reading_of<S: AsRef<str>>(m: &ReadingMsg<S>) -> Option<Reading> {
    use pzt_probe::units::{Hz, KPa, Newtons, Seconds};
    let status = match m.status.as_ref() {
        "ok" => pzt_probe::Status::Ok,
        code => pzt_probe::Status::Failed(pzt_probe::Failure::from_code(code)?),
    };
    Some(Reading {
        status,
        method: pzt_probe::Method::from_name(m.method.as_ref())?,
        resonance: m.f_hz.map(Hz),
        resonance_sigma: m.f_sigma_hz.map(Hz),
        modulus: m.e_kpa.map(KPa),
        modulus_sigma: m.e_sigma_kpa.map(KPa),
        modulus_sigma_repeat: m.e_repeat_kpa.map(KPa),
        q: m.q,
        loss_tangent: m.loss_tangent,
        loss_tangent_sigma: m.loss_tangent_sigma,
        probe_time: Seconds(m.probe_time_s),
        points: m.points,
        force: m.force_n.map(|f| pzt_probe::loadcell::ContactForce {
            mean: Newtons(f),
            sigma: Newtons(m.force_sigma_n.unwrap_or(f32::NAN)),
            change: Newtons(f32::NAN),
            samples: 0,
        }),
    })
}

/// A decoded frame as the bench's [`Frame`].
pub fn frame_of(f: &DeviceFrame) -> Frame {
    let kind = match &f.msg {
        DeviceMsg::Hello { version, board, .. } => Kind::Hello {
            version: *version,
            board: (*board).to_owned(),
        },
        DeviceMsg::Reply { id, outcome } => Kind::Reply {
            id: *id,
            outcome: match outcome {
                Outcome::Accepted => Ok(()),
                Outcome::Rejected {
                    code,
                    cause,
                    message,
                } => Err((
                    (*code).to_owned(),
                    cause.map(str::to_owned),
                    (*message).to_owned(),
                )),
            },
        },
        DeviceMsg::Reading(r) => reading_of(r).map_or(Kind::Other, Kind::Reading),
        DeviceMsg::Stream {
            stream_seq,
            t_s,
            locked,
            reading,
        } => reading_of(reading).map_or(Kind::Other, |r| {
            Kind::Stream(StreamReading {
                seq: *stream_seq,
                t_s: pzt_probe::Seconds(*t_s),
                locked: *locked,
                reading: r,
            })
        }),
        DeviceMsg::StreamEnd(e) => Kind::StreamEnd(*e),
        _ => Kind::Other,
    };
    Frame {
        seq: f.seq,
        dropped: f.dropped,
        json: serde_json::to_value(f).unwrap_or(serde_json::Value::Null),
        kind,
    }
}

/// Decode `bytes` from the probe into `out`, frame by frame (the decoder keeps a frame cut
/// between calls).
pub fn decode_into(dec: &mut Decoder<MAX_DEVICE_FRAME>, bytes: &[u8], out: &mut Vec<Received>) {
    for &b in bytes {
        match dec.feed(b) {
            None => {}
            Some(Err(e)) => out.push(Received::Error(e)),
            Some(Ok(body)) => out.push(match decode_device(body) {
                Ok(f) => Received::Frame(frame_of(&f)),
                Err(e) => Received::Error(e),
            }),
        }
    }
}

/// A host message as bytes on the line: a leading delimiter (it ends whatever an earlier host
/// left half-sent), then the frame.
pub fn host_bytes(msg: &HostMsg) -> Vec<u8> {
    let mut buf = [0u8; MAX_HOST_FRAME + 1];
    let mut v = vec![0u8];
    // Every HostMsg fits (a command line is at most MAX_LINE bytes).
    if let Ok(f) = encode_host(msg, &mut buf) {
        v.extend_from_slice(f);
    }
    v
}

/// A command line as a [`HostMsg::Command`], or why it cannot be one.
pub fn command(id: u32, line: &str) -> Result<HostMsg> {
    let line = heapless::String::<MAX_LINE>::try_from(line)
        .map_err(|_| anyhow::anyhow!("a command line is at most {MAX_LINE} bytes"))?;
    Ok(HostMsg::Command { id, line })
}

/// The QEMU image serving its UART on a TCP socket of this host (killed when dropped).
pub struct QemuProbe {
    child: Child,
    /// The TCP port of its first serial port.
    pub port: u16,
}

impl Drop for QemuProbe {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl QemuProbe {
    /// Start `elf` on `script` (its `sim` lines, then `serve`, added here) with its UART on a
    /// free TCP port, QEMU waiting for the connection before it runs; its defmt stream
    /// (semihosting) goes to `defmt_log` if given.
    pub fn start(
        elf: &std::path::Path,
        scene: &[String],
        defmt_log: Option<PathBuf>,
    ) -> Result<Self> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .context("no free TCP port")?
            .port();
        let mut lines = scene.to_vec();
        lines.push(pzt_probe::board::sim_script::SERVE.to_owned());
        let script = lines.join(";");
        let stdout = match defmt_log {
            Some(p) => Stdio::from(
                std::fs::File::create(&p)
                    .with_context(|| format!("cannot write {}", p.display()))?,
            ),
            None => Stdio::null(),
        };
        let child = Command::new("qemu-system-arm")
            .args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
            .args(["-icount", "shift=0,sleep=off"])
            .args(["-nographic", "-monitor", "none"])
            .arg("-serial")
            .arg(format!("tcp:127.0.0.1:{port},server=on,wait=on"))
            .arg("-semihosting-config")
            .arg(format!(
                "enable=on,target=native,arg=script:{}",
                script.replace(',', ",,")
            ))
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(Stdio::null())
            .spawn()
            .context("cannot start qemu-system-arm (is it installed?)")?;
        Ok(Self { child, port })
    }

    /// Connect to its serial port (QEMU starts the image then), retrying for `within`.
    pub fn connect(&mut self, within: Duration) -> Result<TcpStream> {
        let t0 = Instant::now();
        loop {
            match TcpStream::connect(("127.0.0.1", self.port)) {
                Ok(s) => {
                    s.set_nodelay(true).ok();
                    return Ok(s);
                }
                Err(e) => {
                    if let Some(status) = self.child.try_wait()? {
                        bail!("qemu-system-arm ended ({status}) before the link connected");
                    }
                    if t0.elapsed() > within {
                        return Err(e).context("cannot connect to the QEMU image's serial port");
                    }
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }
}

/// A link to a probe: bytes out, decoded frames in (from a reader thread).
pub struct Link {
    writer: Box<dyn Write + Send>,
    tcp: Option<TcpStream>,
    rx: mpsc::Receiver<Received>,
    /// Ids of commands sent so far (the next one's).
    pub next_id: u32,
    _qemu: Option<QemuProbe>,
}

impl Link {
    /// A link over `reader`/`writer` (the same byte stream); `qemu` is kept alive with it.
    pub fn new(
        mut reader: Box<dyn Read + Send>,
        writer: Box<dyn Write + Send>,
        qemu: Option<QemuProbe>,
    ) -> Self {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut dec = Decoder::<MAX_DEVICE_FRAME>::new();
            let mut buf = [0u8; 4096];
            let mut out = Vec::new();
            loop {
                match reader.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => {
                        decode_into(&mut dec, &buf[..n], &mut out);
                        for r in out.drain(..) {
                            if tx.send(r).is_err() {
                                return;
                            }
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(_) => break,
                }
            }
            let _ = tx.send(Received::Closed);
        });
        Self {
            writer,
            tcp: None,
            rx,
            next_id: 1,
            _qemu: qemu,
        }
    }

    /// A link over TCP connection `s` (the QEMU image's serial port); `qemu` is kept alive
    /// with it.
    pub fn tcp(s: TcpStream, qemu: Option<QemuProbe>) -> Result<Self> {
        let r = s.try_clone()?;
        let w = s.try_clone()?;
        let mut link = Self::new(Box::new(r), Box::new(w), qemu);
        link.tcp = Some(s);
        Ok(link)
    }

    /// Close a TCP link at once, as a host that vanishes (nothing more is read or sent).
    pub fn vanish(&self) {
        if let Some(s) = &self.tcp {
            let _ = s.shutdown(std::net::Shutdown::Both);
        }
    }

    /// The QEMU image on `scene` (its `sim` lines), connected.
    pub fn qemu(
        elf: &std::path::Path,
        scene: &[String],
        defmt_log: Option<PathBuf>,
    ) -> Result<Self> {
        let mut q = QemuProbe::start(elf, scene, defmt_log)?;
        let s = q.connect(Duration::from_secs(20))?;
        Self::tcp(s, Some(q))
    }

    /// A real probe on serial port `path` at [`BAUD`].
    pub fn serial(path: &str) -> Result<Self> {
        let port = serialport::new(path, BAUD)
            .timeout(Duration::from_millis(200))
            .open()
            .with_context(|| format!("cannot open serial port {path}"))?;
        let r = port.try_clone().context("cannot clone the serial port")?;
        Ok(Self::new(Box::new(r), Box::new(port), None))
    }

    /// Send raw bytes (tests of bad input).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<()> {
        self.writer.write_all(bytes)?;
        self.writer.flush()?;
        Ok(())
    }

    /// Send a message.
    pub fn send(&mut self, msg: &HostMsg) -> Result<()> {
        self.send_raw(&host_bytes(msg))
    }

    /// Send the handshake.
    pub fn hello(&mut self) -> Result<()> {
        self.send(&HostMsg::Hello { version: VERSION })
    }

    /// Send command `line` with the next id: the id.
    pub fn command(&mut self, line: &str) -> Result<u32> {
        let id = self.next_id;
        self.send(&command(id, line)?)?;
        self.next_id = self.next_id.wrapping_add(1);
        Ok(id)
    }

    /// The next thing received, waiting at most `within` (`None`: nothing came).
    pub fn recv(&self, within: Duration) -> Option<Received> {
        self.rx.recv_timeout(within).ok()
    }
}
