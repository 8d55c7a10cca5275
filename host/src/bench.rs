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
