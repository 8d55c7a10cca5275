//! The roll-out command's parser, and the sequencing with real node
//! readers running the real update driver against scripted nodes
//! (`fois_link::update_fake`): one node at a time, stopping at the first
//! failure, an offline node failing by the pickup time. The end-to-end
//! roll-out against virtual nodes uses [`spawn_reader`] with their ports.

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use fois_link::LinkError;
use fois_link::signed_image::SignedImage;
use fois_link::update::{UpdateEvent, UpdateOptions};
use fois_link::update_fake::{FakeNode, Script};
use fois_protocol::{Hello, ImageState, ImageTrailer};

use super::*;
use crate::command::NodeCommand;
use crate::reader::{NodeMsg, NodeUpdate, ReaderTimings, run_reader};

#[test]
fn the_command_is_an_update_naming_an_image_and_perhaps_nodes() {
    assert_eq!(
        RolloutCommand::parse(br#"{"command": "update", "image": "fois-0.7.0.fois"}"#),
        Ok(RolloutCommand {
            image: "fois-0.7.0.fois".into(),
            nodes: None
        })
    );
    assert_eq!(
        RolloutCommand::parse(br#"{"command":"update","image":"a.fois","nodes":["m1","m2"]}"#)
            .unwrap()
            .nodes,
        Some(vec!["m1".to_string(), "m2".to_string()])
    );
    for (bad, why) in [
        (
            &br#"{"command": "erase", "image": "a.fois"}"#[..],
            "unknown command",
        ),
        (br#"{"command": "update"}"#, "not a roll-out command"),
        (
            br#"{"command": "update", "image": "a", "colour": 1}"#,
            "not a roll-out command",
        ),
        (br#"update a.fois"#, "not a roll-out command"),
        (
            br#"{"command": "update", "image": "a", "nodes": []}"#,
            "`nodes` is empty",
        ),
    ] {
        let e = RolloutCommand::parse(bad).unwrap_err();
        assert!(e.contains(why), "{}: {e}", String::from_utf8_lossy(bad));
    }
    let big = vec![b' '; MAX_ROLLOUT_COMMAND_BYTES + 1];
    assert!(RolloutCommand::parse(&big).unwrap_err().contains("at most"));
}

const BOARD: &str = "NUCLEO-F446RE";

fn image(version: [u8; 3]) -> Arc<SignedImage> {
    let body: Vec<u8> = (0..20_000u32).map(|i| (i * 13 + 5) as u8).collect();
    let trailer = ImageTrailer {
        body_len: body.len() as u32,
        version,
        flags: 0,
        board: Hello::board_from_str(BOARD),
    };
    Arc::new(SignedImage::assemble(&body, &trailer, &[0x5A; 64]).unwrap())
}

fn fake(signatures_ok: bool) -> FakeNode {
    FakeNode::new(
        BOARD,
        [0, 6, 0],
        128 * 1024,
        Script::default(),
        Box::new(move |_, sig| signatures_ok && *sig == [0x5A; 64]),
    )
}

fn opts() -> UpdateOptions {
    UpdateOptions {
        reply_timeout: Duration::from_millis(300),
        garbled_wait: Duration::from_millis(50),
        attempts: 3,
        resume_timeout: Duration::from_secs(2),
        boot_timeout: Duration::from_secs(2),
        confirm_timeout: Duration::from_secs(2),
        status_poll: Duration::from_millis(200),
        max_resumes: 5,
        quiet_stream: true,
    }
}

/// A node reader on any `Read + Write` port `open` gives (a scripted node
/// here, a virtual node's pty in the end-to-end test), reporting into
/// `sink`, taking update jobs from `slot`, until `stop`.
pub fn spawn_reader<P, O>(
    k: usize,
    open: O,
    mut sink: std::sync::mpsc::Sender<NodeMsg>,
    slot: UpdateSlot,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()>
where
    P: Read + Write + 'static,
    O: FnMut() -> Result<P, LinkError> + Send + 'static,
{
    std::thread::spawn(move || {
        let (_cmd_tx, cmd_rx) = std::sync::mpsc::channel::<NodeCommand>();
        let timings = ReaderTimings {
            silence_timeout: Duration::from_secs(60),
            retry: Duration::from_millis(50),
            handshake: Duration::from_secs(1),
        };
        run_reader(k, "fake", open, &mut sink, &cmd_rx, &slot, timings, &stop);
    })
}

#[test]
fn nodes_are_updated_one_at_a_time_and_the_roll_out_stops_at_the_first_failure() {
    // The second node's key does not verify the image: it refuses at verify.
    let nodes = [fake(true), fake(false), fake(true)];
    let slots: Vec<UpdateSlot> = nodes.iter().map(|_| UpdateSlot::default()).collect();
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::channel();
    let threads: Vec<_> = nodes
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let n = n.clone();
            spawn_reader(
                k,
                move || Ok(n.port()),
                tx.clone(),
                slots[k].clone(),
                stop.clone(),
            )
        })
        .collect();
    drop(tx);
    let mut seen = Vec::new();
    let outcome = run_rollout(
        &[0, 1, 2],
        &image([0, 7, 0]),
        &opts(),
        &slots,
        Duration::from_secs(5),
        &AtomicBool::new(false),
        &mut |k, o| seen.push((k, matches!(o, NodeOutcome::Updated(_)))),
    );
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    for t in threads {
        t.join().unwrap();
    }
    assert_eq!(seen, vec![(0, true), (1, false)]);
    assert!(!outcome.ok());
    assert_eq!(outcome.not_reached, vec![2]);
    match &outcome.results[1].1 {
        NodeOutcome::Failed(why) => assert!(why.contains("signature"), "{why}"),
        other => panic!("{other:?}"),
    }
    let NodeOutcome::Updated(r) = &outcome.results[0].1 else {
        panic!("{:?}", outcome.results[0]);
    };
    assert!(
        update_text(r).contains("0.6.0 -> 0.7.0"),
        "{}",
        update_text(r)
    );
    // The first runs the image; the second and third the old one.
    assert_eq!(nodes[0].image_info().version, [0, 7, 0]);
    assert_eq!(nodes[0].image_info().state, ImageState::Confirmed);
    assert_eq!(nodes[1].image_info().version, [0, 6, 0]);
    assert_eq!(nodes[2].image_info().version, [0, 6, 0]);
    assert_eq!(nodes[2].traffic().chunks_written, 0);
    // The readers reported progress, and node 0 came back with its new
    // version (the reader connected again after the update).
    let msgs: Vec<NodeMsg> = rx.try_iter().collect();
    let progress = |k| {
        msgs.iter()
            .filter(|m| {
                m.node == k && matches!(m.update, NodeUpdate::Update(UpdateEvent::Progress { .. }))
            })
            .count()
    };
    assert!(progress(0) >= 2, "{}", progress(0));
    assert_eq!(progress(2), 0);
    let ups: Vec<[u8; 3]> = msgs
        .iter()
        .filter_map(|m| match &m.update {
            NodeUpdate::Up(h) if m.node == 0 => Some(h.firmware_version),
            _ => None,
        })
        .collect();
    assert_eq!(ups.first(), Some(&[0, 6, 0]));
    assert_eq!(ups.last(), Some(&[0, 7, 0]));
}

#[test]
fn an_offline_node_fails_by_the_pickup_time_and_stops_the_roll_out() {
    // No reader takes node 0's job.
    let slots = vec![UpdateSlot::default(), UpdateSlot::default()];
    let start = std::time::Instant::now();
    let outcome = run_rollout(
        &[0, 1],
        &image([0, 7, 0]),
        &opts(),
        &slots,
        Duration::from_millis(300),
        &AtomicBool::new(false),
        &mut |_, _| {},
    );
    assert!(start.elapsed() < Duration::from_secs(2));
    match &outcome.results[..] {
        [(0, NodeOutcome::Failed(why))] => assert!(why.contains("offline"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(outcome.not_reached, vec![1]);
    // The job was taken back: nothing is left for a reader to find later.
    assert!(slots[0].take().is_none());
    assert!(slots[1].take().is_none());
}
