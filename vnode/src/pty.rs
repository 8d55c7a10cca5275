//! Serving a [`VirtualNode`] on a pseudo-terminal (feature `pty`), so any
//! serial tool, `foisctl monitor` and the fleet gateway talk to it as to a
//! board: what `foisctl virtual-node` and `foisctl demo` run, and what the
//! gateway's tests and load benchmark serve their nodes with.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::VirtualNode;
use crate::line::Line;
use crate::modbus_link::ModbusLink;

/// How to serve a virtual node on a pseudo-terminal.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// Virtual seconds per real second.
    pub speed: f64,
    /// Stop after this much real time.
    pub duration: Option<Duration>,
}

/// A pseudo-terminal: the node writes to the master, clients open `path`.
pub struct Pty {
    master: serialport::TTYPort,
    // Held open so the master never sees a hang-up while no client is there.
    _slave: serialport::TTYPort,
    path: PathBuf,
}

impl Pty {
    /// Open a pty pair (raw mode).
    pub fn open() -> anyhow::Result<Pty> {
        use anyhow::Context;
        use serialport::SerialPort;
        let (mut master, slave) =
            serialport::TTYPort::pair().context("cannot create a pseudo-terminal")?;
        let path = PathBuf::from(slave.name().context("the pty has no name")?);
        master.set_timeout(Duration::ZERO)?;
        // A program started later (a gateway under test, a shell) must not
        // inherit the pair: a copy of the master in another process would
        // keep the pty alive after this one closes it, and its clients
        // would never see the hang-up of an unplugged node.
        #[cfg(unix)]
        for fd in [
            std::os::fd::AsRawFd::as_raw_fd(&master),
            std::os::fd::AsRawFd::as_raw_fd(&slave),
        ] {
            // SAFETY: fcntl on a descriptor this process owns and keeps
            // open; F_SETFD only changes its close-on-exec flag.
            if unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) } != 0 {
                anyhow::bail!(
                    "cannot mark the pseudo-terminal close-on-exec: {}",
                    std::io::Error::last_os_error()
                );
            }
        }
        Ok(Pty {
            master,
            _slave: slave,
            path,
        })
    }

    /// The client side's path (/dev/pts/N).
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Bytes the node wrote that no reader took (pty buffer full).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServeStats {
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames dropped (pty buffer full: nobody reading).
    pub frames_dropped: u64,
    /// Bytes received from clients.
    pub bytes_received: u64,
}

fn write_frame(master: &mut serialport::TTYPort, bytes: &[u8], stats: &mut ServeStats) {
    // Like a UART with nobody listening: what does not fit is lost.
    let mut off = 0;
    while off < bytes.len() {
        match master.write(&bytes[off..]) {
            Ok(0) => break,
            Ok(n) => off += n,
            Err(_) => break,
        }
    }
    if off == bytes.len() {
        stats.frames_sent += 1;
    } else {
        stats.frames_dropped += 1;
    }
}

/// The Modbus RTU side of a served node (used while its link settings say
/// Modbus RTU).
#[derive(Debug, Clone)]
pub struct ModbusOptions {
    /// The emulated link rate, Bd: it sets the silences that end a frame
    /// (`fois_firmware::modbus::Silences`).
    pub baud: u32,
    /// Append the node's own frames (COBS frames, as it would stream them
    /// on the framed link) to this file: the log to check the registers
    /// against. Without it they are dropped.
    pub frame_log: Option<PathBuf>,
}

impl Default for ModbusOptions {
    /// 19 200 Bd (the field link's long-cable rate), no log.
    fn default() -> Self {
        ModbusOptions {
            baud: 19_200,
            frame_log: None,
        }
    }
}

/// Serve `node` on `pty` until `stop` is set or the duration ends. Virtual
/// time runs `speed` times faster than real time. The framed protocol, or
/// Modbus RTU (with the default [`ModbusOptions`]) while the node's link
/// settings say so.
pub fn serve(
    node: &mut VirtualNode,
    pty: &mut Pty,
    opts: &ServeOptions,
    stop: &AtomicBool,
) -> anyhow::Result<ServeStats> {
    serve_with(node, pty, opts, &ModbusOptions::default(), stop)
}

/// [`serve`] with these Modbus options. The protocol follows the node's
/// link settings at every pass (a `SetLinkSettings` or a Modbus write
/// switches it after its answer, as the board's reset does).
pub fn serve_with(
    node: &mut VirtualNode,
    pty: &mut Pty,
    opts: &ServeOptions,
    modbus: &ModbusOptions,
    stop: &AtomicBool,
) -> anyhow::Result<ServeStats> {
    serve_on_line(node, pty, opts, modbus, None, stop)
}

/// [`serve_with`], the framed link carried at `line_baud` by the byte-time
/// model of [`crate::line`] (one half-duplex line; an answer leaves after
/// the flash work it answers): `None`, as fast as the pty moves bytes.
pub fn serve_on_line(
    node: &mut VirtualNode,
    pty: &mut Pty,
    opts: &ServeOptions,
    modbus: &ModbusOptions,
    line_baud: Option<u32>,
    stop: &AtomicBool,
) -> anyhow::Result<ServeStats> {
    use anyhow::Context;
    let mut line = line_baud.map(Line::new);
    let mut log = match &modbus.frame_log {
        Some(p) => Some(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .with_context(|| format!("cannot open the frame log {}", p.display()))?,
        ),
        None => None,
    };
    let mut to_log = |b: &[u8]| {
        if let Some(f) = log.as_mut() {
            let _ = f.write_all(b);
        }
    };
    let mut rtu: Option<ModbusLink> = None;
    let mut stats = ServeStats::default();
    let start = Instant::now();
    let t0 = node.clock().now_ns();
    let speed = if opts.speed.is_finite() && opts.speed > 0.0 {
        opts.speed
    } else {
        1.0
    };
    let mut buf = [0u8; 1024];
    while !stop.load(Ordering::Relaxed) {
        let elapsed = start.elapsed();
        if opts.duration.is_some_and(|d| elapsed >= d) {
            break;
        }
        let target = t0 + (elapsed.as_secs_f64() * speed * 1e9) as u64;
        if ModbusLink::active(node) {
            if rtu.is_none() {
                rtu = Some(ModbusLink::new(modbus.baud, node.node().link_settings()));
            }
        } else {
            rtu = None;
        }
        if let (None, Some(line)) = (rtu.as_ref(), line.as_mut()) {
            let wait = framed_on_line(
                node, pty, line, &mut stats, &mut buf, start, t0, target, speed,
            );
            std::thread::sleep(wait);
            continue;
        }
        let master = &mut pty.master;
        // Host → node.
        loop {
            match master.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    stats.bytes_received += n as u64;
                    let now_us = start.elapsed().as_micros() as u64;
                    let mut tx = |b: &[u8]| write_frame(master, b, &mut stats);
                    match rtu.as_mut() {
                        Some(link) => link.receive(node, &buf[..n], now_us, &mut tx, &mut to_log),
                        None => node.handle_rx(&buf[..n], &mut tx),
                    }
                }
                Err(_) => break,
            }
        }
        let master = &mut pty.master;
        let mut tx = |b: &[u8]| write_frame(master, b, &mut stats);
        match rtu.as_mut() {
            Some(link) => {
                let now_us = start.elapsed().as_micros() as u64;
                link.poll(node, now_us, &mut tx, &mut to_log);
                node.advance_to(target, &mut to_log);
            }
            None => node.advance_to(target, &mut tx),
        }
        // Sleep until the next frame is due in real time (≤ 5 ms, so
        // commands are answered promptly), or until a Modbus frame's
        // silence ends.
        let now_s = start.elapsed().as_secs_f64();
        let due = node.next_due_ns().saturating_sub(t0) as f64 / speed / 1e9;
        let mut wait = (due - now_s).clamp(0.0, 0.005).max(0.0005);
        if let Some(link) = &rtu {
            wait = wait.min(0.000_2);
            if let Some(d) = link.deadline_us() {
                wait = wait.min((d as f64 * 1e-6 - now_s).max(0.000_05));
            }
        }
        std::thread::sleep(Duration::from_secs_f64(wait));
    }
    Ok(stats)
}

/// Replace `link` by a symlink to `target` (removed by [`LinkGuard`]'s drop).
pub fn make_link(link: &Path, target: &Path) -> anyhow::Result<LinkGuard> {
    use anyhow::Context;
    if let Ok(meta) = std::fs::symlink_metadata(link) {
        if meta.file_type().is_symlink() {
            std::fs::remove_file(link)?;
        } else {
            anyhow::bail!(
                "{} exists and is not a symlink; choose another --link path",
                link.display()
            );
        }
    }
    #[cfg(unix)]
    std::os::unix::fs::symlink(target, link)
        .with_context(|| format!("cannot create the link {}", link.display()))?;
    Ok(LinkGuard {
        link: link.to_path_buf(),
        target: target.to_path_buf(),
    })
}

/// Removes the symlink on drop (if it still points to our pty).
pub struct LinkGuard {
    link: PathBuf,
    target: PathBuf,
}

impl Drop for LinkGuard {
    fn drop(&mut self) {
        if std::fs::read_link(&self.link).is_ok_and(|t| t == self.target) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}

/// One pass of the framed link over the byte-time model: host bytes onto
/// the line, those arrived handed to the node (unless it is still busy
/// with flash work: its virtual clock ahead of real time), the node's
/// frames onto the line, those arrived written to the pty. Returns how
/// long to sleep.
#[allow(clippy::too_many_arguments)]
fn framed_on_line(
    node: &mut VirtualNode,
    pty: &mut Pty,
    line: &mut Line,
    stats: &mut ServeStats,
    buf: &mut [u8],
    start: Instant,
    t0: u64,
    target: u64,
    speed: f64,
) -> Duration {
    let master = &mut pty.master;
    let now_ns = start.elapsed().as_nanos() as u64;
    while let Ok(n) = master.read(buf) {
        if n == 0 {
            break;
        }
        stats.bytes_received += n as u64;
        line.host_sent(buf.get(..n).unwrap_or(&[]), now_ns);
    }
    // How far the node's work runs ahead of real time, real ns.
    let lead =
        |node: &VirtualNode| (node.clock().now_ns().saturating_sub(target) as f64 / speed) as u64;
    let mut frames: Vec<Vec<u8>> = Vec::new();
    if lead(node) == 0 {
        let bytes = line.arrived_at_node(now_ns);
        if !bytes.is_empty() {
            node.handle_rx(&bytes, &mut |b: &[u8]| frames.push(b.to_vec()));
        }
    }
    node.advance_to(target, &mut |b: &[u8]| frames.push(b.to_vec()));
    let ready = now_ns + lead(node);
    for f in &frames {
        line.node_sent(f, ready);
    }
    for f in line.arrived_at_host(now_ns) {
        write_frame(master, &f, stats);
    }
    // Until the next byte or frame arrives, the node is free again, or the
    // next frame is due (≤ 5 ms, ≥ 50 µs).
    let now_ns = start.elapsed().as_nanos() as u64;
    let frame_due = (node.next_due_ns().saturating_sub(t0) as f64 / speed) as u64;
    let mut until = frame_due.min(now_ns + 5_000_000);
    if let Some(t) = line.next_event_ns() {
        until = until.min(t);
    }
    let busy = lead(node);
    if busy > 0 {
        until = until.min(now_ns + busy);
    }
    Duration::from_nanos(until.saturating_sub(now_ns).max(50_000))
}
