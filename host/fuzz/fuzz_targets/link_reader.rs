//! The host's link reader (fois-link) on arbitrary bytes from a serial port: whatever a
//! broken cable, a wrong baud rate or a hostile device sends, `Link::poll`
//! never panics, counts every frame it hands out or rejects exactly as its
//! decoder does, and every decoded frame renders as the monitor prints it
//! and as the CSV logger writes it.
//!
//! Input: the first 8 bytes choose the sizes of the reads the fake port
//! returns (1–64 bytes; 0 makes that read time out, as a real port does
//! between bursts, never twice in a row); the rest, cut at each 0xFE, gives the byte stream: a
//! piece that reads as a postcard `DeviceFrame` goes out as that frame,
//! properly framed (COBS + CRC: random bytes almost never carry a valid
//! CRC, and this way every renderer sees arbitrary field values), any
//! other piece raw. The port then ends, which the link reports as a lost
//! port.
#![no_main]

use std::io::{self, Read, Write};

use fois_host::csvlog;
use fois_host::monitor::{MonitorSummary, status_lines};
use fois_link::{Incoming, Link, LinkError, text};
use fois_protocol::{DeviceFrame, DeviceMsg, encode_to_vec};
use libfuzzer_sys::fuzz_target;

/// A serial port that hands out `data` in reads of the chosen sizes.
struct Port<'a> {
    data: &'a [u8],
    sizes: &'a [u8],
    reads: usize,
    timed_out: bool,
}

impl Read for Port<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.data.is_empty() {
            return Ok(0);
        }
        let size = match self.sizes.get(self.reads % self.sizes.len().max(1)) {
            Some(&s) => usize::from(s % 65),
            None => 64,
        };
        self.reads += 1;
        // Never two timeouts in a row: every second read makes progress.
        if size == 0 && !self.timed_out {
            self.timed_out = true;
            return Err(io::ErrorKind::TimedOut.into());
        }
        self.timed_out = false;
        let n = size.max(1).min(buf.len()).min(self.data.len());
        let (now, rest) = self.data.split_at(n);
        buf[..n].copy_from_slice(now);
        self.data = rest;
        Ok(n)
    }
}

impl Write for Port<'_> {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        Ok(bytes.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Everything the host prints or logs about one frame.
fn render(seq: u32, msg: &DeviceMsg, summary: &MonitorSummary) -> usize {
    let mut len = csvlog::format_row(0, &csvlog::Row::device(seq, msg)).len();
    len += match msg {
        DeviceMsg::Hello(h) => text::hello_text(h).len(),
        DeviceMsg::Ack(a) => text::ack_text(a).len(),
        DeviceMsg::Error(e) => text::error_text(e).len(),
        DeviceMsg::Event(e) => text::event_name(&e.kind).len(),
        DeviceMsg::Measurement(_)
        | DeviceMsg::MeasurementV2(_)
        | DeviceMsg::MeasurementV3(_)
        | DeviceMsg::MeasurementV5(_) => 0,
    };
    if let Some((m, _)) = msg.measurement() {
        len += status_lines(Some(m), summary)
            .iter()
            .map(String::len)
            .sum::<usize>();
    }
    len
}

fuzz_target!(|input: &[u8]| {
    let (sizes, rest) = input.split_at(input.len().min(8));
    let mut data = Vec::with_capacity(rest.len() * 2);
    let (mut framed, mut raw_bytes) = (0u64, 0usize);
    for piece in rest.split(|&b| b == 0xFE) {
        match postcard::from_bytes::<DeviceFrame>(piece) {
            Ok(f) => {
                data.extend(encode_to_vec(&f));
                framed += 1;
            }
            Err(_) => {
                data.extend_from_slice(piece);
                raw_bytes += piece.len();
            }
        }
    }
    let data = data.as_slice();
    let port = Port {
        data,
        sizes,
        reads: 0,
        timed_out: false,
    };
    let mut link = Link::new(port, "fuzz");
    let mut summary = MonitorSummary::default();
    let (mut frames, mut rejected) = (0u64, 0u64);
    // Every second read takes at least one byte: the stream ends within a
    // bounded number of polls (a poll may also hand out a kept backlog).
    for _ in 0..(data.len() + 1) * 2 + 16 {
        match link.poll() {
            Ok(items) => {
                for item in items {
                    match item {
                        Incoming::Frame(f, _) => {
                            frames += 1;
                            summary.frames += 1;
                            assert!(render(f.seq, &f.msg, &summary) > 0);
                        }
                        Incoming::Rejected(_) => rejected += 1,
                    }
                }
            }
            Err(LinkError::Lost(..)) => break,
            Err(e) => panic!("poll: {e}"),
        }
    }
    let stats = link.stats();
    assert_eq!(u64::from(stats.frames), frames, "decoded frames");
    assert_eq!(u64::from(stats.rejected()), rejected, "rejected frames");
    // With no raw bytes in between, every well-framed frame comes through.
    if raw_bytes == 0 {
        assert_eq!(frames, framed, "well-framed frames decoded");
    }
});
