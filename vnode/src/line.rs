//! A byte-time model of the node's framed serial link (optional; a pty by
//! itself carries bytes as fast as the processes move them): one
//! half-duplex line (RS-485) at `baud`, 10 bit times a byte (8N1), shared
//! by both directions. A host byte reaches the node when its stop bit has
//! gone over the line; the node's answer starts once the line is free and
//! the node has finished the work it answers (its flash stalls: how far the
//! virtual clock ran ahead of real time), and reaches the host after its
//! last byte. Times are real-time nanoseconds since the serve loop began.

use std::collections::VecDeque;

/// Bits per byte on the line (start, 8 data, stop).
pub const BITS_PER_BYTE: u64 = 10;

/// The line between host and node.
#[derive(Debug, Clone)]
pub struct Line {
    byte_ns: u64,
    /// The line is busy until then.
    free_at_ns: u64,
    /// Host bytes on their way, with the time their stop bit arrives.
    to_node: VecDeque<(u64, u8)>,
    /// Node frames on their way, with the time their last byte arrives.
    to_host: VecDeque<(u64, Vec<u8>)>,
}

impl Line {
    /// A line at `baud` (clamped to ≥ 1 Bd).
    pub fn new(baud: u32) -> Self {
        Line {
            byte_ns: BITS_PER_BYTE * 1_000_000_000 / u64::from(baud.max(1)),
            free_at_ns: 0,
            to_node: VecDeque::new(),
            to_host: VecDeque::new(),
        }
    }

    /// One byte's time on the line, ns.
    pub fn byte_ns(&self) -> u64 {
        self.byte_ns
    }

    /// The host wrote `bytes` at `now_ns`.
    pub fn host_sent(&mut self, bytes: &[u8], now_ns: u64) {
        for &b in bytes {
            self.free_at_ns = self.free_at_ns.max(now_ns) + self.byte_ns;
            self.to_node.push_back((self.free_at_ns, b));
        }
    }

    /// The host's bytes that have arrived at the node by `now_ns`.
    pub fn arrived_at_node(&mut self, now_ns: u64) -> Vec<u8> {
        let mut out = Vec::new();
        while let Some(&(at, b)) = self.to_node.front() {
            if at > now_ns {
                break;
            }
            out.push(b);
            self.to_node.pop_front();
        }
        out
    }

    /// The node sends `frame`, ready (its work done) at `ready_ns`.
    pub fn node_sent(&mut self, frame: &[u8], ready_ns: u64) {
        let start = self.free_at_ns.max(ready_ns);
        self.free_at_ns = start + self.byte_ns * frame.len() as u64;
        self.to_host.push_back((self.free_at_ns, frame.to_vec()));
    }

    /// The node's frames that have arrived at the host by `now_ns`.
    pub fn arrived_at_host(&mut self, now_ns: u64) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        while let Some((at, _)) = self.to_host.front() {
            if *at > now_ns {
                break;
            }
            if let Some((_, f)) = self.to_host.pop_front() {
                out.push(f);
            }
        }
        out
    }

    /// The next arrival in either direction, ns.
    pub fn next_event_ns(&self) -> Option<u64> {
        let a = self.to_node.front().map(|(t, _)| *t);
        let b = self.to_host.front().map(|(t, _)| *t);
        match (a, b) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_take_ten_bit_times_and_the_line_is_shared() {
        let mut line = Line::new(19_200);
        assert_eq!(line.byte_ns(), 520_833);
        line.host_sent(&[1, 2, 3], 0);
        assert_eq!(line.arrived_at_node(520_832), Vec::<u8>::new());
        assert_eq!(line.arrived_at_node(1_041_666), vec![1, 2]);
        assert_eq!(line.arrived_at_node(1_562_499), vec![3]);
        // The node answers at once, but the line is its own again only
        // after the host's last byte; a node busy longer answers later.
        line.node_sent(&[9; 4], 1_000_000);
        assert_eq!(line.next_event_ns(), Some(1_562_499 + 4 * 520_833));
        assert!(line.arrived_at_host(3_645_830).is_empty());
        assert_eq!(line.arrived_at_host(3_645_831), vec![vec![9; 4]]);
        line.node_sent(&[7], 10_000_000);
        assert_eq!(line.next_event_ns(), Some(10_520_833));
        // 115 200 Bd: 86.8 µs a byte.
        assert_eq!(Line::new(115_200).byte_ns(), 86_805);
    }
}
