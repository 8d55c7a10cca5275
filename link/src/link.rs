//! The serial link to a node: open a port, decode frames as they come,
//! send commands, count lost (sequence gaps) and rejected (decoder) frames,
//! handshake on `Hello` and refuse another protocol version.
//!
//! [`Link`] works on any `Read + Write` byte stream, so tests and the
//! virtual node can use pipes or pseudo-terminals.

use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use fois_protocol::{
    Ack, AckResult, Command, DecodeStats, DeviceFrame, DeviceMsg, ErrorReply, FrameDecoder,
    FrameError, Hello, HostFrame, PROTOCOL_VERSION, SeqEvent, SeqTracker, encode_to_vec,
};

/// Errors of the link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The port could not be opened.
    #[error("cannot open serial port {port}: {reason}")]
    Open {
        /// Port path.
        port: String,
        /// Why.
        reason: String,
    },
    /// The port went away (unplugged, node process ended).
    #[error("serial port {0} disappeared ({1})")]
    Lost(String, String),
    /// No answer in time.
    #[error("no answer from the node on {port} within {waited_ms} ms{hint}")]
    Timeout {
        /// Port path.
        port: String,
        /// How long we waited.
        waited_ms: u64,
        /// Extra explanation.
        hint: String,
    },
    /// The node speaks another protocol version.
    #[error(
        "the node speaks protocol version {node}, this program reads versions {oldest} to {host}: \
         update it or the firmware so both match ({hello})"
    )]
    Incompatible {
        /// The node's version.
        node: u16,
        /// Ours (the newest we read).
        host: u16,
        /// The oldest version we read.
        oldest: u16,
        /// The node's hello, as text.
        hello: String,
    },
}

/// Something that came over the link.
#[derive(Debug, Clone, PartialEq)]
pub enum Incoming {
    /// A decoded frame and what its sequence number says.
    Frame(DeviceFrame, SeqEvent),
    /// A frame the decoder skipped.
    Rejected(FrameError),
}

/// A link over any byte stream.
pub struct Link<P> {
    port: P,
    name: String,
    decoder: Box<FrameDecoder>,
    next_id: u16,
    /// Sequence tracking.
    pub seq: SeqTracker,
    rx: Vec<u8>,
    /// Frames read while waiting for an answer, not yet handed out.
    backlog: std::collections::VecDeque<Incoming>,
}

/// Open a serial port with a short read timeout (so loops stay responsive).
pub fn open_port(path: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>, LinkError> {
    let builder = serialport::new(path, baud).timeout(Duration::from_millis(50));
    // Pseudo-terminals (virtual nodes) are opened shared: TIOCEXCL would stay
    // on the pty if a monitor were killed, locking the next client out.
    let resolved = std::fs::canonicalize(path).unwrap_or_else(|_| path.into());
    let shared = resolved.starts_with("/dev/pts");
    #[cfg(unix)]
    {
        let mut port = builder.open_native().map_err(|e| LinkError::Open {
            port: path.to_string(),
            reason: e.to_string(),
        })?;
        if shared {
            let _ = port.set_exclusive(false);
        }
        Ok(Box::new(port))
    }
    #[cfg(not(unix))]
    {
        let _ = shared;
        builder.open().map_err(|e| LinkError::Open {
            port: path.to_string(),
            reason: e.to_string(),
        })
    }
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

impl<P: Read + Write> Link<P> {
    /// A link over `port`; `name` is used in messages.
    pub fn new(port: P, name: impl Into<String>) -> Self {
        Link {
            port,
            name: name.into(),
            decoder: Box::default(),
            next_id: 1,
            seq: SeqTracker::default(),
            rx: vec![0; 4096],
            backlog: Default::default(),
        }
    }

    /// The port's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Decoder counts (frames decoded, rejected by reason).
    pub fn stats(&self) -> DecodeStats {
        self.decoder.stats()
    }

    /// The underlying port.
    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// Drop the frames read while waiting for an answer, not yet handed
    /// out (a caller that reads none of them).
    pub fn discard_backlog(&mut self) {
        self.backlog.clear();
    }

    /// Hand `frames` out again on the next [`Link::poll`] (a caller that
    /// stopped reading in the middle of a batch).
    pub fn keep(&mut self, frames: impl IntoIterator<Item = Incoming>) {
        self.backlog.extend(frames);
    }

    /// Forget a partial frame and the sequence history (after a reconnect
    /// the caller decides how to count the gap).
    pub fn reset_decoder(&mut self) {
        self.decoder.reset();
    }

    /// Send a command; returns its id.
    pub fn send(&mut self, cmd: Command) -> Result<u16, LinkError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        // A leading 0x00 ends any partial frame in the node's decoder.
        let mut bytes = vec![0u8];
        bytes.extend(encode_to_vec(&HostFrame { id, cmd }));
        self.write_raw(&bytes)?;
        Ok(id)
    }

    /// Write raw bytes (tests inject garbage with it).
    pub fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.port
            .write_all(bytes)
            .and_then(|_| self.port.flush().or(Ok(())))
            .map_err(|e| LinkError::Lost(self.name.clone(), e.to_string()))
    }

    /// Read what is there (waiting at most the port's timeout) and return
    /// the frames completed. `Err(Lost)` when the port is gone.
    pub fn poll(&mut self) -> Result<Vec<Incoming>, LinkError> {
        let mut out: Vec<Incoming> = self.backlog.drain(..).collect();
        if !out.is_empty() {
            return Ok(out);
        }
        let n = match self.port.read(&mut self.rx) {
            Ok(0) => {
                return Err(LinkError::Lost(self.name.clone(), "end of stream".into()));
            }
            Ok(n) => n,
            Err(e) if is_timeout(&e) => return Ok(out),
            Err(e) => return Err(LinkError::Lost(self.name.clone(), e.to_string())),
        };
        let seq = &mut self.seq;
        self.decoder.feed::<DeviceFrame>(&self.rx[..n], |r| {
            out.push(match r {
                Ok(frame) => {
                    let ev = seq.observe(frame.seq);
                    Incoming::Frame(frame, ev)
                }
                Err(e) => Incoming::Rejected(e),
            })
        });
        Ok(out)
    }

    /// Send `cmd` and wait for its `Ack` or `Error` (other frames are kept
    /// for the next [`Link::poll`]).
    pub fn request(&mut self, cmd: Command, timeout: Duration) -> Result<Reply, LinkError> {
        let id = self.send(cmd)?;
        self.wait_reply(id, timeout)
    }

    /// Wait for the answer to command `id`.
    pub fn wait_reply(&mut self, id: u16, timeout: Duration) -> Result<Reply, LinkError> {
        let start = Instant::now();
        let mut kept = Vec::new();
        let mut malformed = 0u32;
        let result = loop {
            if start.elapsed() > timeout {
                break Err(self.timeout_error(timeout, malformed));
            }
            let frames = match self.poll() {
                Ok(f) => f,
                Err(e) => break Err(e),
            };
            let mut found = None;
            for inc in frames {
                match &inc {
                    Incoming::Frame(f, _) if found.is_none() => match &f.msg {
                        DeviceMsg::Ack(a) if a.id == id => found = Some(Reply::Ack(a.clone())),
                        DeviceMsg::Error(e) if e.id == Some(id) => {
                            found = Some(Reply::Error(e.clone()))
                        }
                        DeviceMsg::Hello(h) if !readable(h) => {
                            self.backlog.extend(kept);
                            return Err(incompatible(h));
                        }
                        _ => {}
                    },
                    Incoming::Rejected(FrameError::Malformed) => malformed += 1,
                    _ => {}
                }
                kept.push(inc);
            }
            if let Some(r) = found {
                break Ok(r);
            }
        };
        self.backlog.extend(kept);
        result
    }

    fn timeout_error(&self, timeout: Duration, malformed: u32) -> LinkError {
        let hint = if malformed > 0 {
            format!(
                "; {malformed} frame(s) passed their CRC but could not be read: \
                 the node probably speaks another protocol version"
            )
        } else {
            "; is a FOIS node on this port, powered, at this baud rate?".into()
        };
        LinkError::Timeout {
            port: self.name.clone(),
            waited_ms: timeout.as_millis() as u64,
            hint,
        }
    }

    /// Handshake: ask the node who it is (`GetInfo`) and also accept the
    /// `Hello` it sends at boot. Refuses another protocol version.
    pub fn handshake(&mut self, timeout: Duration) -> Result<Hello, LinkError> {
        let id = self.send(Command::GetInfo)?;
        let start = Instant::now();
        let mut kept = Vec::new();
        let mut malformed = 0;
        let mut resent = false;
        let result = loop {
            if start.elapsed() > timeout {
                break Err(self.timeout_error(timeout, malformed));
            }
            // A node that was booting may have missed the first request.
            if !resent && start.elapsed() > timeout / 2 {
                resent = true;
                if let Err(e) = self.send(Command::GetInfo) {
                    break Err(e);
                }
            }
            let frames = match self.poll() {
                Ok(f) => f,
                Err(e) => break Err(e),
            };
            let mut hello = None;
            for inc in frames {
                match &inc {
                    Incoming::Frame(f, _) if hello.is_none() => match &f.msg {
                        DeviceMsg::Hello(h) => hello = Some(h.clone()),
                        DeviceMsg::Ack(Ack {
                            id: aid,
                            result: AckResult::Info(h),
                        }) if *aid == id || resent => hello = Some(h.clone()),
                        _ => {}
                    },
                    Incoming::Rejected(FrameError::Malformed) => malformed += 1,
                    _ => {}
                }
                kept.push(inc);
            }
            if let Some(h) = hello {
                if !readable(&h) {
                    break Err(incompatible(&h));
                }
                break Ok(h);
            }
        };
        self.backlog.extend(kept);
        result
    }
}

/// Whether this host reads the node's protocol version: every version
/// from `OLDEST_READABLE_VERSION` (1) to `PROTOCOL_VERSION` (a fleet is never
/// upgraded at once; a version-1 node streams `Measurement` without an
/// estimate, which the monitor and the log show as empty).
fn readable(h: &Hello) -> bool {
    (fois_protocol::OLDEST_READABLE_VERSION..=PROTOCOL_VERSION).contains(&h.protocol_version)
}

fn incompatible(h: &Hello) -> LinkError {
    LinkError::Incompatible {
        node: h.protocol_version,
        host: PROTOCOL_VERSION,
        oldest: fois_protocol::OLDEST_READABLE_VERSION,
        hello: crate::text::hello_text(h),
    }
}

/// A node's answer to a command.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// Carried out.
    Ack(Ack),
    /// Refused.
    Error(ErrorReply),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fake port: reads come from a script, writes are recorded.
    struct Script {
        chunks: std::collections::VecDeque<Vec<u8>>,
        written: Vec<u8>,
    }
    impl Read for Script {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            match self.chunks.pop_front() {
                Some(c) => {
                    buf[..c.len()].copy_from_slice(&c);
                    Ok(c.len())
                }
                None => Err(io::ErrorKind::TimedOut.into()),
            }
        }
    }
    impl Write for Script {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            self.written.extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    fn hello(version: u16) -> Hello {
        Hello {
            protocol_version: version,
            firmware_version: [0, 1, 0],
            board: Hello::board_from_str("test"),
            unique_id: [7; 12],
            reset_reason: fois_protocol::ResetReason::PowerOn,
        }
    }

    #[test]
    fn handshake_refuses_other_version_and_accepts_ours() {
        let frame = |v| {
            encode_to_vec(&DeviceFrame {
                seq: 0,
                msg: DeviceMsg::Hello(hello(v)),
            })
        };
        let mut link = Link::new(
            Script {
                chunks: [vec![1, 2, 3, 0], frame(PROTOCOL_VERSION + 1)].into(),
                written: vec![],
            },
            "script",
        );
        let err = link.handshake(Duration::from_millis(200)).unwrap_err();
        assert!(
            matches!(err, LinkError::Incompatible { node, .. } if node == PROTOCOL_VERSION + 1)
        );
        let text = err.to_string();
        assert!(
            text.contains(&format!("version {}", PROTOCOL_VERSION + 1)),
            "{text}"
        );
        assert_eq!(link.stats().rejected(), 1);
        // The request went out as a HostFrame GetInfo after a 0x00.
        let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
        let mut got = vec![];
        dec.feed::<HostFrame>(&link.port_mut().written, |r| got.push(r));
        assert_eq!(
            got,
            vec![Ok(HostFrame {
                id: 1,
                cmd: Command::GetInfo
            })]
        );

        let mut link = Link::new(
            Script {
                chunks: [frame(PROTOCOL_VERSION)].into(),
                written: vec![],
            },
            "script",
        );
        assert_eq!(
            link.handshake(Duration::from_millis(200)).unwrap(),
            hello(PROTOCOL_VERSION)
        );
        // Every version from the oldest readable one is read; older ones are
        // refused like newer ones.
        for v in [fois_protocol::OLDEST_READABLE_VERSION, 0] {
            let mut link = Link::new(
                Script {
                    chunks: [frame(v)].into(),
                    written: vec![],
                },
                "script",
            );
            let got = link.handshake(Duration::from_millis(200));
            if v == 0 {
                assert!(matches!(got, Err(LinkError::Incompatible { node: 0, .. })));
            } else {
                assert_eq!(got.unwrap(), hello(v));
            }
        }
    }

    #[test]
    fn silent_port_times_out() {
        let mut link = Link::new(
            Script {
                chunks: Default::default(),
                written: vec![],
            },
            "silent",
        );
        let err = link
            .request(Command::AckAlarm, Duration::from_millis(30))
            .unwrap_err();
        assert!(
            matches!(err, LinkError::Timeout { waited_ms: 30, .. }),
            "{err}"
        );
    }
}
