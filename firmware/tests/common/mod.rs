//! The node tests' board: the firmware's scripted simulated board
//! (`fois_firmware::sim_board`, shared with the QEMU harness) behind an
//! `Rc`, and helpers that decode what the node sent.
#![allow(dead_code)]

use std::rc::Rc;

use fois_firmware::sim_board::{self, SimBoard};
use fois_firmware::storage::{MemStorage, Storage};
use fois_protocol::{DeviceFrame, FrameDecoder, HostFrame, encode_to_vec};

/// The board a test drives: clock, output levels, scene.
pub type World = Rc<SimBoard>;

/// The node on a [`World`] with [`MemStorage`].
pub type SimNode = NodeOn<MemStorage>;
/// The node on a [`World`] with storage `S`.
pub type NodeOn<S> = sim_board::SimNode<World, S>;

/// A node on a fresh world with this storage.
pub fn node_with(storage: MemStorage) -> (SimNode, World) {
    node_on(storage)
}

/// A node on a fresh world with any storage.
pub fn node_on<S: Storage>(storage: S) -> (NodeOn<S>, World) {
    let w = World::default();
    (sim_board::sim_node(w.clone(), storage, "sim"), w)
}

pub fn node() -> (SimNode, World) {
    node_with(MemStorage::new())
}

/// Decode everything a call sent.
pub fn frames(bytes: &[u8]) -> Vec<DeviceFrame> {
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut out = Vec::new();
    dec.feed::<DeviceFrame>(bytes, |r| out.push(r.expect("node sent a bad frame")));
    out
}

/// Run frames until the node has saved what it had pending (at most 90 s of
/// frames: the shortest save interval is a minute); returns the frames sent.
pub fn run_until_saved<S: Storage>(node: &mut NodeOn<S>, w: &World) -> Vec<DeviceFrame> {
    let mut out = Vec::new();
    for _ in 0..900 {
        if !node.save_pending() {
            break;
        }
        out.extend(step(node, w));
    }
    assert!(!node.save_pending(), "the save never came");
    out
}

/// Run one frame and return the frames it sent; the clock then moves to the
/// end of the frame period.
pub fn step<S: Storage>(node: &mut NodeOn<S>, w: &World) -> Vec<DeviceFrame> {
    let mut bytes = Vec::new();
    w.run_frame(node, &mut |b| bytes.extend_from_slice(b));
    frames(&bytes)
}

/// Send one command; return the frames answered.
pub fn command<S: Storage>(
    node: &mut NodeOn<S>,
    w: &World,
    id: u16,
    cmd: fois_protocol::Command,
) -> Vec<DeviceFrame> {
    let mut bytes = Vec::new();
    let wire = encode_to_vec(&HostFrame { id, cmd });
    node.handle_rx(&wire, w.now_ms(), &mut |b| bytes.extend_from_slice(b));
    frames(&bytes)
}
