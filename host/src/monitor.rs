//! `foisctl monitor`: live view of a node, durable CSV log, reconnects when
//! the port comes back.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use fois_protocol::{Command, DeviceMsg};

use crate::csvlog::{CsvLog, Row};
use crate::exit;
pub use crate::status::{fault_line, icing_line, status_line, status_lines};
use fois_link::advice::{Calibration, calibration_advice};
use fois_link::reading::EventReading;
use fois_link::text::{ack_text, error_text, event_name, hello_text};
use fois_link::{Incoming, Link, LinkError, open_port};
use fois_protocol::{SeqEvent, SeqTracker};

/// What `monitor` does.
#[derive(Debug, Clone)]
pub struct MonitorOptions {
    /// Serial port path.
    pub port: String,
    /// Baud rate.
    pub baud: u32,
    /// CSV log file (appended).
    pub log: Option<PathBuf>,
    /// Stop after this long (None: until Ctrl-C).
    pub duration: Option<Duration>,
    /// Time allowed for the handshake.
    pub handshake_timeout: Duration,
    /// Print plain status lines even on a terminal.
    pub plain: bool,
    /// Print nothing but errors and the summary.
    pub quiet: bool,
    /// Also print the protocol's chatter: the node's `Hello` in full (its
    /// 24-hex-digit unique id, reset reason), every `Ack`.
    pub verbose: bool,
    /// Print the legend of the status lines before the first one.
    pub legend: bool,
    /// What is really on the face, as one status line (the demo knows it
    /// from the virtual node's environment); `None` for a real node.
    pub truth: Option<TruthFn>,
}

/// A source of the "truth" status line (the demo's virtual environment).
#[derive(Clone)]
pub struct TruthFn(pub Arc<dyn Fn() -> String + Send + Sync>);

impl std::fmt::Debug for TruthFn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TruthFn")
    }
}

impl MonitorOptions {
    /// Defaults for a port.
    pub fn new(port: impl Into<String>) -> Self {
        MonitorOptions {
            port: port.into(),
            baud: fois_protocol::BAUD_RATE,
            log: None,
            duration: None,
            // The node's `GetInfo` answer can wait behind its longest frame
            // and a flash erase (3.4 s): the host's command timeout covers it.
            handshake_timeout: Duration::from_millis(fois_protocol::REPLY_TIMEOUT_MS),
            plain: false,
            quiet: false,
            verbose: false,
            legend: true,
            truth: None,
        }
    }
}

pub use crate::status::MonitorSummary;

/// The live view: a redrawn status line on a terminal, periodic lines
/// otherwise; events as lines above it.
struct View {
    bar: Option<indicatif::ProgressBar>,
    quiet: bool,
    last_line: Instant,
}

impl View {
    fn new(plain: bool, quiet: bool) -> View {
        let bar = (!plain && !quiet && std::io::stdout().is_terminal()).then(|| {
            let b = indicatif::ProgressBar::new_spinner();
            b.set_style(
                indicatif::ProgressStyle::with_template("{spinner:.cyan} {msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
            );
            b.enable_steady_tick(Duration::from_millis(200));
            b
        });
        View {
            bar,
            quiet,
            last_line: Instant::now() - Duration::from_secs(10),
        }
    }

    fn say(&self, text: &str) {
        if self.quiet {
            return;
        }
        match &self.bar {
            Some(b) => b.println(text),
            None => println!("{text}"),
        }
    }

    fn status(&mut self, lines: &[String]) {
        if self.quiet {
            return;
        }
        match &self.bar {
            Some(bar) => bar.set_message(lines.join("\n  ")),
            None => {
                if self.last_line.elapsed() >= Duration::from_secs(1) {
                    self.last_line = Instant::now();
                    println!("{}", lines.join("  | "));
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

struct Session<'a> {
    log: Option<CsvLog>,
    view: View,
    verbose: bool,
    truth: Option<TruthFn>,
    /// Lines typed on the terminal ([`crate::keys`]).
    keys: Option<std::sync::mpsc::Receiver<Result<crate::keys::Key, String>>>,
    /// Ids of the commands sent from typed keys, awaiting their answer.
    pending: Vec<u16>,
    /// The protocol version of the node connected (the keys' commands take
    /// its shape).
    node_version: u16,
    sum: MonitorSummary,
    stop: &'a AtomicBool,
    /// Node uptime of the last measurement or event, ms.
    last_uptime_ms: Option<u64>,
}

impl Session<'_> {
    fn row(&mut self, row: Row) -> anyhow::Result<()> {
        if let Some(log) = &mut self.log {
            log.write(&row)?;
        }
        Ok(())
    }

    fn handle(&mut self, inc: Incoming) -> anyhow::Result<()> {
        match inc {
            Incoming::Rejected(e) => {
                self.sum.rejected += 1;
                self.row(Row::note("rejected", format!("{e:?}")))?;
            }
            Incoming::Frame(f, ev) => {
                self.sum.frames += 1;
                match ev {
                    SeqEvent::Gap(n) => {
                        self.sum.lost += n;
                        self.view
                            .say(&format!("! {n} frame(s) lost before seq {}", f.seq));
                        self.row(Row::gap(f.seq, n))?;
                    }
                    SeqEvent::Restart => {
                        self.last_uptime_ms = None;
                        self.view.say(&format!(
                            "! node restarted (sequence went back to {})",
                            f.seq
                        ));
                        self.row(Row {
                            seq: Some(f.seq),
                            ..Row::note("node_restart", "sequence number went backwards")
                        })?;
                    }
                    _ => {}
                }
                // A node that reset while we were away may have sent more
                // frames than before: its uptime going back tells.
                let uptime = match &f.msg {
                    DeviceMsg::Event(e) => Some(e.uptime_ms),
                    msg => msg.measurement().map(|(m, _)| m.uptime_ms),
                };
                if let Some(u) = uptime {
                    if let Some(last) = self.last_uptime_ms
                        && u < last
                        && ev != SeqEvent::Restart
                    {
                        self.view.say(&format!(
                            "! node restarted (uptime went back from {last} to {u} ms)"
                        ));
                        self.row(Row {
                            seq: Some(f.seq),
                            uptime_ms: Some(u),
                            ..Row::note("node_restart", format!("uptime went back from {last} ms"))
                        })?;
                    }
                    self.last_uptime_ms = Some(u);
                }
                match &f.msg {
                    DeviceMsg::Measurement(_)
                    | DeviceMsg::MeasurementV2(_)
                    | DeviceMsg::MeasurementV3(_)
                    | DeviceMsg::MeasurementV5(_) => {
                        if let Some((m, estimate)) = f.msg.measurement() {
                            self.sum.measurements += 1;
                            self.sum.last = Some(m.clone());
                            self.sum.last_estimate = estimate.copied();
                            self.sum.last_gain = f.msg.gain().copied();
                            self.sum.last_icing = f.msg.icing().copied();
                        }
                    }
                    DeviceMsg::Event(e) => {
                        if e.kind == fois_protocol::EventKind::IceOnset {
                            self.sum.ice_onsets += 1;
                        }
                        let r = EventReading::new(e);
                        let faults = if r.faults.is_empty() {
                            String::new()
                        } else {
                            format!(" [{}]", r.faults.join(", "))
                        };
                        self.view.say(&format!(
                            "* event {}{faults} at uptime {:.1} s: I1 {:.3} µA, rise {:.3} µA, {:.2} °C",
                            event_name(&e.kind),
                            e.uptime_ms as f64 / 1000.0,
                            r.i1_ua,
                            r.rise1_ua,
                            r.temperature_c
                        ));
                    }
                    DeviceMsg::Ack(a) => {
                        let asked = self.pending.contains(&a.id);
                        self.pending.retain(|&id| id != a.id);
                        if self.verbose || asked {
                            self.view.say(&format!("  ack {}", ack_text(a)));
                        }
                    }
                    DeviceMsg::Error(e) => {
                        self.view.say(&format!("! error {}", error_text(e)));
                        // A refusal of a typed `d`: what to do next.
                        let asked = e.id.is_some_and(|id| self.pending.contains(&id));
                        if let Some(id) = e.id {
                            self.pending.retain(|&p| p != id);
                        }
                        if let Some(advice) = asked
                            .then(|| calibration_advice(Calibration::Dark, &e.code))
                            .flatten()
                        {
                            self.view.say(&format!("  {advice}"));
                        }
                    }
                    DeviceMsg::Hello(h) => {
                        if self.verbose {
                            self.view.say(&format!("  hello {}", hello_text(h)));
                        }
                    }
                }
                self.row(Row::device(f.seq, &f.msg))?;
            }
        }
        Ok(())
    }

    /// Send the commands typed since the last call.
    fn typed(&mut self, link: &mut Link<Box<dyn serialport::SerialPort>>) -> anyhow::Result<()> {
        let Some(rx) = &self.keys else { return Ok(()) };
        let typed: Vec<_> = rx.try_iter().collect();
        for k in typed {
            match k {
                Ok(key) => match key.command(self.node_version) {
                    Some(cmd) => {
                        let name = format!("{cmd:?}");
                        let id = link.send(cmd)?;
                        self.pending.push(id);
                        self.view.say(&format!("> {name} sent"));
                    }
                    None => self.view.say(crate::legend::LEGEND),
                },
                Err(line) => self.view.say(&format!(
                    "> `{}` is no key; {}",
                    line.trim(),
                    crate::keys::HELP
                )),
            }
        }
        Ok(())
    }

    fn tick(&mut self) -> anyhow::Result<()> {
        if let Some(log) = &mut self.log {
            log.tick()?;
        }
        let mut lines = status_lines(self.sum.last.as_ref(), &self.sum).to_vec();
        // The icing rate below the estimate (protocol v5 nodes).
        if let Some(i) = icing_line(&self.sum) {
            lines.insert(2, i);
        }
        // The demo's truth right below the estimate it is to be compared with.
        if let Some(t) = &self.truth {
            lines.insert(2, (t.0)());
        }
        if let Some(f) = self.sum.last.as_ref().and_then(fault_line) {
            lines.push(f);
        }
        self.view.status(&lines);
        Ok(())
    }
}

/// Run the monitor until `stop` is set, the duration ends, or an error
/// that reconnecting cannot fix (bad port at start, incompatible node).
pub fn run(opts: &MonitorOptions, stop: &AtomicBool) -> anyhow::Result<MonitorSummary> {
    let log = match &opts.log {
        Some(p) => Some(CsvLog::open(p)?),
        None => None,
    };
    if opts.legend && !opts.quiet {
        println!("{}", crate::legend::LEGEND);
    }
    if !opts.quiet && std::io::stdin().is_terminal() {
        println!("{}", crate::keys::HELP);
    }
    let mut s = Session {
        log,
        view: View::new(opts.plain, opts.quiet),
        verbose: opts.verbose,
        truth: opts.truth.clone(),
        keys: if opts.quiet {
            None
        } else {
            crate::keys::spawn()
        },
        pending: Vec::new(),
        node_version: fois_protocol::PROTOCOL_VERSION,
        sum: MonitorSummary::default(),
        stop,
        last_uptime_ms: None,
    };
    let result = run_session(opts, &mut s);
    s.view.finish();
    let mut sum = s.sum.clone();
    if let Some(log) = s.log.take() {
        sum.log_rows = log.rows();
        let path = log.path().display().to_string();
        log.close()
            .with_context(|| format!("closing the log {path}"))?;
    }
    result.map(|_| sum)
}

fn run_session(opts: &MonitorOptions, s: &mut Session) -> anyhow::Result<()> {
    let start = Instant::now();
    let done = |s: &Session| {
        s.stop.load(Ordering::Relaxed) || opts.duration.is_some_and(|d| start.elapsed() >= d)
    };
    let mut tracker = SeqTracker::default();
    let mut connected_once = false;
    let mut waiting_said = false;
    while !done(s) {
        let port = match open_port(&opts.port, opts.baud) {
            Ok(p) => p,
            Err(e) if !connected_once => return Err(e.into()),
            Err(e) => {
                if !waiting_said {
                    s.view
                        .say(&format!("  waiting for {} to come back ({e})", opts.port));
                    waiting_said = true;
                }
                s.tick()?;
                std::thread::sleep(Duration::from_millis(200));
                continue;
            }
        };
        let mut link = Link::new(port, opts.port.clone());
        let _ = link.port_mut().clear(serialport::ClearBuffer::Input);
        link.seq = tracker.clone();
        let hello = match link.handshake(opts.handshake_timeout) {
            Ok(h) => h,
            Err(e @ LinkError::Incompatible { .. }) => return Err(e.into()),
            Err(e) if !connected_once => return Err(e.into()),
            Err(e) => {
                if !waiting_said {
                    s.view.say(&format!("  reconnect failed, retrying: {e}"));
                    waiting_said = true;
                }
                s.tick()?;
                std::thread::sleep(Duration::from_millis(200));
                continue;
            }
        };
        waiting_said = false;
        s.node_version = hello.protocol_version;
        let text = hello_text(&hello);
        let shown = if s.verbose {
            text.clone()
        } else {
            format!(
                "{}, protocol {}",
                hello.board_name(),
                hello.protocol_version
            )
        };
        s.view.say(&format!(
            "{} {} ({shown})",
            if connected_once {
                "reconnected to"
            } else {
                "connected to"
            },
            opts.port
        ));
        s.row(Row::note("link_up", format!("port={} {text}", opts.port)))?;
        connected_once = true;
        link.send(Command::StartStream {
            frame_period_ms: None,
        })?;
        let lost = loop {
            if done(s) {
                break None;
            }
            match link.poll() {
                Ok(incs) => {
                    for inc in incs {
                        s.handle(inc)?;
                    }
                }
                Err(e) => break Some(e),
            }
            s.typed(&mut link)?;
            s.tick()?;
        };
        tracker = link.seq.clone();
        if let Some(e) = lost {
            s.sum.disconnects += 1;
            s.view
                .say(&format!("! {e}; waiting for it to return (Ctrl-C to quit)"));
            s.row(Row::note("link_lost", e.to_string()))?;
            if let Some(log) = &mut s.log {
                log.flush()?;
            }
        }
    }
    Ok(())
}

/// Map errors of `monitor` to exit codes (see [`exit`]).
pub fn exit_code(err: &anyhow::Error) -> i32 {
    exit::code_of(err)
}
