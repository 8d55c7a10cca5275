//! The node reader: one thread per node that opens its serial port, does the
//! handshake (`GetInfo` / `Hello`: `fois_link`, as `foisctl monitor` does),
//! starts the stream and hands every decoded frame to the gateway. When the port goes away, or
//! the node stays silent for the silence timeout, it says so and reconnects
//! on its own, every [`RETRY_INTERVAL`]. A node that resets in place (the
//! port stays, a `Hello` arrives while streaming) is told to stream again.
//!
//! [`run_reader`] works on any `Read + Write` stream through an opener, so
//! tests and the load benchmark can feed byte streams through the same code.

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

use fois_link::text::{ack_text, error_text};
use fois_link::timefmt::unix_ms_now;
use fois_link::{Incoming, Link, LinkError, open_port};
use fois_protocol::{Command, DeviceFrame, DeviceMsg, Hello, SeqEvent, SeqTracker};

use fois_link::update::{UpdateEvent, update};

use crate::command::NodeCommand;
use crate::config::NodeSpec;
use crate::rollout::{UpdateJob, UpdateSlot};

/// Wait between reconnection attempts.
pub const RETRY_INTERVAL: Duration = Duration::from_millis(500);
/// Time allowed for the handshake: the node's `GetInfo` answer can queue
/// behind its longest frame and a flash erase (3.4 s).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_millis(fois_protocol::REPLY_TIMEOUT_MS);
/// Time a node has to answer a command from MQTT: the protocol's
/// `REPLY_TIMEOUT_MS` (8 s), over the node's worst answer (5.829 s, a dark
/// calibration behind the longest frame and an erasing save).
pub const COMMAND_TIMEOUT: Duration = Duration::from_millis(fois_protocol::REPLY_TIMEOUT_MS);

/// A node silent this long is declared offline and reconnected: the
/// protocol's `REPLY_TIMEOUT_MS` (8 s), over the longest a healthy node is
/// silent: its worst answer, 5.829 s (its longest frame, a sector erase,
/// then a dark calibration; firmware/README.md "Answer time").
pub const SILENCE_TIMEOUT: Duration = Duration::from_millis(fois_protocol::REPLY_TIMEOUT_MS);

/// What a reader reports.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeUpdate {
    /// Connected (after the handshake).
    Up(Hello),
    /// A decoded frame and what its sequence number says.
    Frame(DeviceFrame, SeqEvent),
    /// A frame the decoder rejected.
    Rejected,
    /// The link was lost (port gone, silent, handshake failed after it was up).
    Down(String),
    /// The port cannot be opened or the handshake failed (reported once per
    /// outage, while it lasts).
    Unreachable(String),
    /// A firmware update's progress (the reader runs it on its link, its
    /// stream paused: [`crate::rollout`]).
    Update(UpdateEvent),
    /// A roll-out ended (sent by the roll-out itself; `node` is the last
    /// node it tried).
    RolloutEnd(crate::rollout::RolloutOutcome),
    /// A node's firmware update ended (sent by the roll-out).
    UpdateDone {
        /// The node runs the image, confirmed.
        ok: bool,
        /// The version it runs, or why it failed.
        detail: String,
    },
    /// The node's answer to an MQTT command.
    CommandResult {
        /// The command.
        command: NodeCommand,
        /// Carried out.
        ok: bool,
        /// The answer as text.
        detail: String,
    },
}

/// One report of a reader.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeMsg {
    /// The node's index in the config.
    pub node: usize,
    /// Host time of the report, Unix ms.
    pub host_unix_ms: u64,
    /// What happened.
    pub update: NodeUpdate,
}

/// Where a reader's reports go. Returns false when the publisher is gone.
pub trait Sink {
    /// Deliver one report (may block: backpressure).
    fn send(&mut self, msg: NodeMsg) -> bool;
}

impl Sink for tokio::sync::mpsc::Sender<NodeMsg> {
    fn send(&mut self, msg: NodeMsg) -> bool {
        self.blocking_send(msg).is_ok()
    }
}

impl Sink for std::sync::mpsc::Sender<NodeMsg> {
    fn send(&mut self, msg: NodeMsg) -> bool {
        std::sync::mpsc::Sender::send(self, msg).is_ok()
    }
}

/// Timings of a reader.
#[derive(Debug, Clone, Copy)]
pub struct ReaderTimings {
    /// Declare the node offline after this long without a frame.
    pub silence_timeout: Duration,
    /// Wait between reconnection attempts.
    pub retry: Duration,
    /// Time allowed for the handshake.
    pub handshake: Duration,
}

impl Default for ReaderTimings {
    fn default() -> Self {
        ReaderTimings {
            silence_timeout: SILENCE_TIMEOUT,
            retry: RETRY_INTERVAL,
            handshake: HANDSHAKE_TIMEOUT,
        }
    }
}

struct Reporter<'a, S: Sink> {
    node: usize,
    sink: &'a mut S,
}

impl<S: Sink> Reporter<'_, S> {
    fn send(&mut self, update: NodeUpdate) -> bool {
        self.sink.send(NodeMsg {
            node: self.node,
            host_unix_ms: unix_ms_now(),
            update,
        })
    }
}

fn sleep_unless_stopped(d: Duration, stop: &AtomicBool) {
    let end = Instant::now() + d;
    while !stop.load(Ordering::Relaxed) {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        std::thread::sleep(left.min(Duration::from_millis(50)));
    }
}

/// Read one node until `stop`: open with `open`, handshake, stream, report;
/// reconnect on loss. Returns when `stop` is set or the sink is gone. A
/// job left in `updates` pauses the stream: the reader runs the update on
/// its link, reports it, and connects again (the node has reset).
#[allow(clippy::too_many_arguments)]
pub fn run_reader<P, O, S>(
    node: usize,
    name: &str,
    mut open: O,
    sink: &mut S,
    commands: &Receiver<NodeCommand>,
    updates: &UpdateSlot,
    timings: ReaderTimings,
    stop: &AtomicBool,
) where
    P: Read + Write,
    O: FnMut() -> Result<P, LinkError>,
    S: Sink,
{
    let mut rep = Reporter { node, sink };
    let mut tracker = SeqTracker::default();
    let mut unreachable_said = false;
    while !stop.load(Ordering::Relaxed) {
        let connected = open().and_then(|port| {
            let mut link = Link::new(port, name.to_string());
            link.seq = tracker.clone();
            let hello = link.handshake(timings.handshake)?;
            Ok((link, hello))
        });
        let (mut link, hello) = match connected {
            Ok(c) => c,
            Err(e) => {
                if !unreachable_said {
                    unreachable_said = true;
                    if !rep.send(NodeUpdate::Unreachable(e.to_string())) {
                        return;
                    }
                }
                sleep_unless_stopped(timings.retry, stop);
                continue;
            }
        };
        unreachable_said = false;
        let node_version = hello.protocol_version;
        if !rep.send(NodeUpdate::Up(hello)) {
            return;
        }
        let end = stream(
            &mut link,
            &mut rep,
            commands,
            updates,
            node_version,
            timings,
            stop,
        );
        match end {
            StreamEnd::SinkGone => return,
            StreamEnd::Stopped => {}
            StreamEnd::Update(job) => {
                if !run_job(&mut link, &mut open, &job, &mut rep) {
                    return;
                }
            }
            StreamEnd::LinkLost(reason) => {
                if !rep.send(NodeUpdate::Down(reason)) {
                    return;
                }
                sleep_unless_stopped(timings.retry, stop);
            }
        }
        tracker = link.seq.clone();
    }
}

/// Run an update job on the reader's link (reopening the port with `open`
/// if it goes away), report its progress (at most once a second), and
/// tell the roll-out how it ended. False when the sink is gone.
fn run_job<P, O, S>(
    link: &mut Link<P>,
    open: &mut O,
    job: &UpdateJob,
    rep: &mut Reporter<'_, S>,
) -> bool
where
    P: Read + Write,
    O: FnMut() -> Result<P, LinkError>,
    S: Sink,
{
    let mut sink_ok = true;
    let mut last_progress: Option<Instant> = None;
    let result = update(link, &job.image, &job.opts, Some(open), &mut |e| {
        if let UpdateEvent::Progress { done, total } = e
            && done < total
            && last_progress.is_some_and(|t| t.elapsed() < Duration::from_secs(1))
        {
            return;
        }
        if matches!(e, UpdateEvent::Progress { .. }) {
            last_progress = Some(Instant::now());
        }
        sink_ok &= rep.send(NodeUpdate::Update(e));
    });
    let _ = job.done.send(result.map_err(|e| e.to_string()));
    sink_ok
}

/// Why [`stream`] returned.
enum StreamEnd {
    /// The link was lost: why.
    LinkLost(String),
    /// `stop` was set.
    Stopped,
    /// The gateway no longer listens (the sink is gone).
    SinkGone,
    /// A firmware update waits in the reader's slot.
    Update(UpdateJob),
}

/// Stream until the link is lost, `stop`, or the sink is gone. Commands
/// take the shape of the node's protocol `node_version`.
fn stream<P: Read + Write, S: Sink>(
    link: &mut Link<P>,
    rep: &mut Reporter<'_, S>,
    commands: &Receiver<NodeCommand>,
    updates: &UpdateSlot,
    node_version: u16,
    timings: ReaderTimings,
    stop: &AtomicBool,
) -> StreamEnd {
    let start = Command::StartStream {
        frame_period_ms: None,
    };
    if let Err(e) = link.send(start.clone()) {
        return StreamEnd::LinkLost(e.to_string());
    }
    let mut last_frame = Instant::now();
    let mut last_start = Instant::now();
    let mut pending: Vec<(u16, NodeCommand, Instant)> = Vec::new();
    loop {
        if stop.load(Ordering::Relaxed) {
            return StreamEnd::Stopped;
        }
        if let Some(job) = updates.take() {
            return StreamEnd::Update(job);
        }
        match commands.try_recv() {
            Ok(cmd) => match link.send(cmd.wire_command(node_version)) {
                Ok(id) => pending.push((id, cmd, Instant::now())),
                Err(e) => {
                    let detail = format!("not sent: {e}");
                    if !rep.send(NodeUpdate::CommandResult {
                        command: cmd,
                        ok: false,
                        detail,
                    }) {
                        return StreamEnd::SinkGone;
                    }
                    return StreamEnd::LinkLost(e.to_string());
                }
            },
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => {}
        }
        let incs = match link.poll() {
            Ok(v) => v,
            Err(e) => return StreamEnd::LinkLost(e.to_string()),
        };
        if !incs.is_empty() {
            last_frame = Instant::now();
        } else if last_frame.elapsed() >= timings.silence_timeout {
            return StreamEnd::LinkLost(format!(
                "no frame for {:.1} s",
                last_frame.elapsed().as_secs_f64()
            ));
        }
        for inc in incs {
            let update = match inc {
                Incoming::Rejected(_) => NodeUpdate::Rejected,
                Incoming::Frame(f, ev) => {
                    let answer = match &f.msg {
                        DeviceMsg::Ack(a) => Some((a.id, true, ack_text(a))),
                        DeviceMsg::Error(e) => e.id.map(|id| (id, false, error_text(e))),
                        _ => None,
                    };
                    if let Some((id, ok, detail)) = answer
                        && let Some(k) = pending.iter().position(|p| p.0 == id)
                    {
                        let (_, command, _) = pending.remove(k);
                        if !rep.send(NodeUpdate::CommandResult {
                            command,
                            ok,
                            detail,
                        }) {
                            return StreamEnd::SinkGone;
                        }
                    }
                    // A node sends `Hello` only while it does not stream:
                    // it reset in place (watchdog, brown-out) or missed the
                    // request. Ask again, at most twice a second.
                    if matches!(f.msg, DeviceMsg::Hello(_))
                        && last_start.elapsed() >= Duration::from_millis(500)
                    {
                        last_start = Instant::now();
                        if let Err(e) = link.send(start.clone()) {
                            return StreamEnd::LinkLost(e.to_string());
                        }
                    }
                    NodeUpdate::Frame(f, ev)
                }
            };
            if !rep.send(update) {
                return StreamEnd::SinkGone;
            }
        }
        let mut k = 0;
        while k < pending.len() {
            if pending[k].2.elapsed() >= COMMAND_TIMEOUT {
                let (_, command, _) = pending.remove(k);
                if !rep.send(NodeUpdate::CommandResult {
                    command,
                    ok: false,
                    detail: format!("no answer within {} s", COMMAND_TIMEOUT.as_secs()),
                }) {
                    return StreamEnd::SinkGone;
                }
            } else {
                k += 1;
            }
        }
    }
}

/// Spawn the reader thread of a node on its serial port.
pub fn spawn_serial_reader<S: Sink + Send + 'static>(
    node: usize,
    spec: NodeSpec,
    mut sink: S,
    commands: Receiver<NodeCommand>,
    updates: UpdateSlot,
    timings: ReaderTimings,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new()
        .name(format!("node-{node}"))
        .spawn(move || {
            let open = || open_port(&spec.port, spec.baud);
            run_reader(
                node, &spec.port, open, &mut sink, &commands, &updates, timings, &stop,
            );
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::{
        Ack, AckResult, DetectorState, FrameDecoder, HostFrame, Measurement, PROTOCOL_VERSION,
        ResetReason, encode_to_vec,
    };
    use std::collections::VecDeque;
    use std::sync::Mutex;

    /// A scripted node: answers GetInfo, then serves queued frames; records
    /// every command it got.
    #[derive(Clone, Default)]
    struct FakeNode {
        inner: Arc<Mutex<FakeInner>>,
    }
    #[derive(Default)]
    struct FakeInner {
        out: VecDeque<u8>,
        got: Vec<Command>,
        seq: u32,
        dead: bool,
    }
    impl FakeNode {
        fn frame(&self, msg: DeviceMsg) {
            let mut i = self.inner.lock().unwrap();
            let seq = i.seq;
            i.seq += 1;
            i.out.extend(encode_to_vec(&DeviceFrame { seq, msg }));
        }
    }
    fn hello() -> Hello {
        Hello {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: [1, 2, 3],
            board: Hello::board_from_str("fake"),
            unique_id: [0xab; 12],
            reset_reason: ResetReason::PowerOn,
        }
    }
    fn meas(uptime_ms: u64) -> DeviceMsg {
        DeviceMsg::Measurement(Measurement {
            uptime_ms,
            i1_na: 0,
            i2_na: 0,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: -500,
            vdda_mv: 3300,
            flags: 0,
            state: DetectorState::Dry,
        })
    }
    impl Read for FakeNode {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let mut i = self.inner.lock().unwrap();
            if i.dead {
                return Err(std::io::Error::other("gone"));
            }
            if i.out.is_empty() {
                drop(i);
                std::thread::sleep(Duration::from_millis(2));
                return Err(std::io::ErrorKind::TimedOut.into());
            }
            let n = buf.len().min(i.out.len());
            for b in buf.iter_mut().take(n) {
                *b = i.out.pop_front().unwrap();
            }
            Ok(n)
        }
    }
    impl Write for FakeNode {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
            let mut cmds = vec![];
            dec.feed::<HostFrame>(b, |r| cmds.extend(r.ok()));
            for c in cmds {
                let reply = match c.cmd {
                    Command::GetInfo => Some(AckResult::Info(hello())),
                    Command::AckAlarm => Some(AckResult::AlarmAcknowledged),
                    Command::AckAlarmV4 => Some(AckResult::NoAlarm),
                    Command::StartStream { .. } => Some(AckResult::Streaming {
                        frame_period_ms: 100,
                    }),
                    _ => None,
                };
                self.inner.lock().unwrap().got.push(c.cmd.clone());
                if let Some(result) = reply {
                    self.frame(DeviceMsg::Ack(Ack { id: c.id, result }));
                }
            }
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn reader_handshakes_streams_forwards_commands_and_reports_loss() {
        let fake = FakeNode::default();
        let (tx, rx) = std::sync::mpsc::channel();
        let (cmd_tx, cmd_rx) = std::sync::mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let (f2, s2) = (fake.clone(), stop.clone());
        let t = std::thread::spawn(move || {
            let mut tx = tx;
            let timings = ReaderTimings {
                silence_timeout: Duration::from_millis(400),
                retry: Duration::from_millis(20),
                handshake: Duration::from_millis(500),
            };
            let updates = UpdateSlot::default();
            run_reader(
                3,
                "fake",
                || Ok(f2.clone()),
                &mut tx,
                &cmd_rx,
                &updates,
                timings,
                &s2,
            );
        });
        let next = || rx.recv_timeout(Duration::from_secs(2)).unwrap();
        let m = next();
        assert_eq!(m.node, 3);
        assert_eq!(m.update, NodeUpdate::Up(hello()));
        for u in [100, 200, 300] {
            fake.frame(meas(u));
        }
        let mut uptimes = vec![];
        while uptimes.len() < 3 {
            if let NodeUpdate::Frame(f, _) = next().update
                && let DeviceMsg::Measurement(m) = f.msg
            {
                uptimes.push(m.uptime_ms);
            }
        }
        assert_eq!(uptimes, vec![100, 200, 300]);
        cmd_tx.send(NodeCommand::AckAlarm).unwrap();
        let result = loop {
            if let NodeUpdate::CommandResult {
                command,
                ok,
                detail,
            } = next().update
            {
                break (command, ok, detail);
            }
        };
        assert_eq!(result.0, NodeCommand::AckAlarm);
        assert!(result.1);
        // A version-4 node without an alarm says there is none.
        assert!(result.2.contains("NoAlarm"), "{}", result.2);
        // Silence: declared down within the timeout, then reconnected.
        let down = loop {
            if let NodeUpdate::Down(r) = next().update {
                break r;
            }
        };
        assert!(down.contains("no frame"), "{down}");
        let up = loop {
            if let NodeUpdate::Up(_) = next().update {
                break true;
            }
        };
        assert!(up);
        fake.inner.lock().unwrap().dead = true;
        let down = loop {
            match next().update {
                NodeUpdate::Down(r) | NodeUpdate::Unreachable(r) if r.contains("gone") => break r,
                _ => {}
            }
        };
        assert!(down.contains("gone"), "{down}");
        stop.store(true, Ordering::Relaxed);
        t.join().unwrap();
        let got = fake.inner.lock().unwrap().got.clone();
        assert!(got.contains(&Command::AckAlarmV4));
        assert!(got.contains(&Command::StartStream {
            frame_period_ms: None
        }));
    }
}
