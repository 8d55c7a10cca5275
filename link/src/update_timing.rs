//! How long a transfer takes on the line: the update driver's throughput
//! model. One chunk in flight (the node answers each before the next goes
//! out), so per chunk the line carries the command and its answer and the
//! node takes its own time to write it; the node's other frames share the
//! line (on the half-duplex RS-485 field link every byte does):
//!
//! ```text
//! T = N · ((B_cmd + B_ans) · 10 / baud + t_node) / (1 − s)
//! N = ceil(image_len / 256),   s = r_stream · B_stream · 10 / baud
//! ```
//!
//! 10 bits a byte (8N1), `B_cmd` a full chunk's frame with the leading
//! 0x00 the link sends, `B_ans` its `UpdateStatus` answer, `t_node` from the
//! command's last byte to the answer's first (programming 256 B, the frame
//! work it may wait behind, the driver-enable turnaround), `s` the share of
//! the line the node's own frames take (its 10 Hz measurements, or its 1 Hz
//! `Hello` once the driver has stopped the stream). The sizes come from
//! encoding the real frames ([`chunk_frame_bytes`]); `update_tests` checks
//! them against the bytes the driver sends to the scripted node.

use fois_protocol::{
    Ack, AckResult, ChunkData, Command, DeviceFrame, DeviceMsg, HostFrame, UPDATE_CHUNK_MAX,
    UpdateChunk, UpdatePhase, UpdateStatus, encode_to_vec,
};

/// One transfer's line.
#[derive(Debug, Clone, Copy)]
pub struct LineModel {
    /// Baud rate, 8N1.
    pub baud: u32,
    /// Bytes of body and trailer.
    pub image_len: u32,
    /// Bytes on the line per chunk command (leading 0x00 included).
    pub command_bytes: usize,
    /// Bytes of the node's answer.
    pub answer_bytes: usize,
    /// The node's time per chunk between command and answer, ms.
    pub node_ms: f64,
    /// The node's own frames per second during the transfer.
    pub stream_hz: f64,
    /// Bytes of one of them.
    pub stream_bytes: usize,
}

impl LineModel {
    /// Chunks of the transfer.
    pub fn chunks(&self) -> u32 {
        self.image_len.div_ceil(UPDATE_CHUNK_MAX as u32)
    }

    /// The share of the line the node's own frames take.
    pub fn stream_share(&self) -> f64 {
        self.stream_hz * self.stream_bytes as f64 * 10.0 / f64::from(self.baud)
    }

    /// Seconds for every chunk, begin and verify not counted.
    pub fn transfer_s(&self) -> f64 {
        let wire_s = (self.command_bytes + self.answer_bytes) as f64 * 10.0 / f64::from(self.baud);
        f64::from(self.chunks()) * (wire_s + self.node_ms / 1000.0) / (1.0 - self.stream_share())
    }

    /// The most node time per chunk (ms) that still meets `goal_s`.
    pub fn node_ms_budget(&self, goal_s: f64) -> f64 {
        let wire_s = (self.command_bytes + self.answer_bytes) as f64 * 10.0 / f64::from(self.baud);
        (goal_s * (1.0 - self.stream_share()) / f64::from(self.chunks()) - wire_s) * 1000.0
    }
}

/// Bytes on the line of a full chunk's command (with the link's leading
/// 0x00) and of its answer, with field values at their widest for an
/// image of `image_len` (offset and length near the end, a CRC of
/// 32 bits, ids and sequence numbers past 16 384).
pub fn chunk_frame_bytes(image_len: u32) -> (usize, usize) {
    // A full chunk always fits: (0, 0) is never returned.
    let Some(data) = ChunkData::new(&[0xFF; UPDATE_CHUNK_MAX]) else {
        return (0, 0);
    };
    let offset = image_len.saturating_sub(UPDATE_CHUNK_MAX as u32);
    let cmd = HostFrame {
        id: u16::MAX,
        cmd: Command::UpdateChunk(UpdateChunk {
            offset,
            crc32: u32::MAX,
            data,
        }),
    };
    let answer = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::Ack(Ack {
            id: u16::MAX,
            result: AckResult::UpdateStatus(UpdateStatus {
                phase: UpdatePhase::Receiving,
                image_len,
                next_offset: image_len,
            }),
        }),
    };
    (1 + encode_to_vec(&cmd).len(), encode_to_vec(&answer).len())
}
