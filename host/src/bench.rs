//! Decoder throughput and the long-run memory check, shared by
//! `foisctl bench-decode`, the benches and the tests.

use std::time::Instant;

use fois_protocol::{
    DetectorState, DeviceFrame, DeviceMsg, FrameDecoder, Measurement, encode_to_vec, flags,
};

/// A result of [`decode_throughput`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Throughput {
    /// Frames decoded.
    pub frames: u64,
    /// Bytes fed.
    pub bytes: u64,
    /// Wall time, s.
    pub seconds: f64,
}

impl Throughput {
    /// Frames per second.
    pub fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }
}

/// A realistic measurement frame with sequence number `seq`.
pub fn sample_frame(seq: u32) -> DeviceFrame {
    DeviceFrame {
        seq,
        msg: DeviceMsg::Measurement(Measurement {
            uptime_ms: u64::from(seq) * 100,
            i1_na: 25_000 + (seq % 977) as i32,
            i2_na: 8_000 - (seq % 313) as i32,
            ambient1_na: 1_200,
            ambient2_na: 900,
            temperature_centi_c: -512,
            vdda_mv: 3_301,
            flags: flags::ALARM,
            state: DetectorState::Ice,
        }),
    }
}

/// Encode `n` measurement frames into one byte stream and time decoding it
/// with the host's streaming decoder (in 4 KiB reads, as from a port).
pub fn decode_throughput(n: u32) -> Throughput {
    let mut stream = Vec::new();
    for seq in 0..n {
        stream.extend(encode_to_vec(&sample_frame(seq)));
    }
    let mut dec = Box::new(FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new());
    let start = Instant::now();
    let mut frames = 0u64;
    let mut check = 0u64;
    for chunk in stream.chunks(4096) {
        dec.feed::<DeviceFrame>(chunk, |r| {
            if let Ok(f) = r {
                frames += 1;
                check = check.wrapping_add(u64::from(f.seq));
            }
        });
    }
    let seconds = start.elapsed().as_secs_f64();
    std::hint::black_box(check);
    Throughput {
        frames,
        bytes: stream.len() as u64,
        seconds,
    }
}

/// Resident set size of this process, bytes (Linux; `None` elsewhere).
pub fn rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    Some(pages * u64::try_from(page).ok()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn throughput_counts_every_frame() {
        let r = decode_throughput(2_000);
        assert_eq!(r.frames, 2_000);
        assert!(r.bytes > 2_000 * 20);
        assert!(r.frames_per_s() > 0.0);
    }
}

/// Result of [`long_run`].
#[derive(Debug, Clone, PartialEq)]
pub struct LongRun {
    /// Frames the virtual node produced.
    pub frames: u64,
    /// What the monitor saw.
    pub summary: crate::monitor::MonitorSummary,
    /// (frames so far, resident set size in bytes) every tenth of the run.
    pub rss: Vec<(u64, u64)>,
    /// Wall time, s.
    pub seconds: f64,
}

impl LongRun {
    /// RSS growth from the first tenth of the run to its largest value, bytes.
    pub fn rss_growth(&self) -> i64 {
        let first = self.rss.first().map_or(0, |x| x.1);
        let max = self.rss.iter().map(|x| x.1).max().unwrap_or(first);
        max as i64 - first as i64
    }
}

/// How long the long run's feeder waits for the monitor to read the last
/// bytes, and then for it to stop.
const DRAIN_DEADLINE: std::time::Duration = std::time::Duration::from_secs(60);

/// The host pipeline for `frames` frames of the firmware node at its
/// 10 Hz, in virtual time as fast as the machine goes: virtual node →
/// pty → `monitor::run` (decoder, sequence tracking, CSV log to `log`).
/// Samples this process's RSS every tenth of the run.
pub fn long_run(frames: u64, log: &std::path::Path) -> anyhow::Result<LongRun> {
    use std::io::{Read, Write};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;

    use fois_sim::{Curve, CurvePoint};
    use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};
    use serialport::SerialPort;

    let (mut master, slave) = serialport::TTYPort::pair()?;
    master.set_timeout(Duration::ZERO)?;
    let path = slave
        .name()
        .ok_or_else(|| anyhow::anyhow!("pty without a name"))?;
    // Dry for the first half of the run, then rime at 1 mm/h: the alarm
    // trips on the way (for a day: 12 h dry, 12 h of rime).
    let half_s = frames as f64 * 0.1 / 2.0;
    let curve = Curve {
        points: (0..=150)
            .map(|i| {
                let d = f64::from(i) * 0.1;
                CurvePoint {
                    thickness_mm: d,
                    i1_ua: 30.0 * (1.0 - (-d).exp()),
                    i2_ua: 10.0 * (1.0 - (-d / 3.0).exp()),
                    ..CurvePoint::default()
                }
            })
            .collect(),
    };
    let tl = Timeline::new(vec![
        Segment::new(half_s, Cover::Dry),
        Segment::new(f64::INFINITY, Cover::Rime).rate(1.0),
    ]);
    let env = Arc::new(Environment::with_curves(
        tl,
        [(Cover::Rime, curve)],
        [0.0; 2],
    ));
    // The feeder watches the slave's input queue to know when the monitor
    // has read every byte (the monitor opens the same pty by its path).
    let queue = slave.try_clone_native()?;
    let stop = Arc::new(AtomicBool::new(false));
    let feeder_stop = stop.clone();
    let monitor_done = Arc::new(AtomicBool::new(false));
    let feeder_done = monitor_done.clone();
    let start = Instant::now();
    let feeder = std::thread::spawn(move || -> Vec<(u64, u64)> {
        let mut node = VirtualNode::new(env, NodeOptions::default());
        let mut rss = Vec::new();
        let mut buf = [0u8; 512];
        let mut out: Vec<u8> = Vec::with_capacity(8192);
        let tenth = (frames / 10).max(1);
        // Blocking write: the reader (monitor) sets the pace.
        let writer = |m: &mut serialport::TTYPort, bytes: &[u8]| {
            let mut off = 0;
            let t = Instant::now();
            while off < bytes.len() && t.elapsed() < Duration::from_secs(10) {
                match m.write(&bytes[off..]) {
                    Ok(n) => off += n,
                    Err(_) => std::thread::sleep(Duration::from_micros(200)),
                }
            }
        };
        while node.frames() < frames {
            if let Ok(n) = master.read(&mut buf) {
                node.handle_rx(&buf[..n], &mut |b: &[u8]| out.extend_from_slice(b));
            }
            // A batch of frames per read check.
            for _ in 0..64 {
                node.step_frame(&mut |b: &[u8]| out.extend_from_slice(b));
                if node.frames().is_multiple_of(tenth) {
                    rss.push((node.frames(), rss_bytes().unwrap_or(0)));
                }
                if node.frames() >= frames {
                    break;
                }
            }
            writer(&mut master, &out);
            out.clear();
        }
        // Stop the monitor once it has read every byte: a fixed wait is not
        // enough on a loaded CI machine (2 s once left 125 frames unread).
        // The monitor handles what it read before it looks at `stop` again.
        let t = Instant::now();
        while t.elapsed() < DRAIN_DEADLINE && queue.bytes_to_read().is_ok_and(|n| n > 0) {
            std::thread::sleep(Duration::from_millis(20));
        }
        feeder_stop.store(true, Ordering::Relaxed);
        // Keep the master end open until the monitor has stopped: closing it
        // first reads as a lost link.
        while !feeder_done.load(Ordering::Relaxed) && t.elapsed() < DRAIN_DEADLINE {
            std::thread::sleep(Duration::from_millis(20));
        }
        rss
    });
    let mut opts = crate::monitor::MonitorOptions::new(path);
    opts.quiet = true;
    opts.log = Some(log.to_path_buf());
    let summary = crate::monitor::run(&opts, &stop);
    stop.store(true, Ordering::Relaxed);
    monitor_done.store(true, Ordering::Relaxed);
    let rss = feeder
        .join()
        .map_err(|_| anyhow::anyhow!("feeder thread panicked"))?;
    drop(slave);
    Ok(LongRun {
        frames,
        summary: summary?,
        rss,
        seconds: start.elapsed().as_secs_f64(),
    })
}
