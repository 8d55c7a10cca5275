//! The node with update slots: the whole update over its commands, the
//! reset into the trial, the self-test that confirms it, the self-test that
//! fails and is rolled back without a person, and a node without slots.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod update_common;

use std::rc::Rc;

use fois_firmware::sim_board::{self, SimBoard, SimNode};
use fois_firmware::storage::MemStorage;
use fois_firmware::update::{UpdateSlots, trial};
use fois_protocol::{
    AckResult, Command, DeviceFrame, DeviceMsg, ErrorCode, EventKind, HostFrame, ImageInfo,
    ImageState, UpdatePhase, encode_to_vec,
};
use update_common::*;

const OLD: [u8; 3] = [0, 1, 0];
const NEW: [u8; 3] = [0, 2, 0];

type World = Rc<SimBoard>;
type UpNode = SimNode<World, MemStorage, Updater>;

fn boot(flash: &Shared, w: &World, images: &[&Image]) -> UpNode {
    run_bootloader(flash);
    let running = active_image(flash, images).expect("no image to boot");
    sim_board::sim_node_with_updates(w.clone(), MemStorage::new(), BOARD, updater(flash, running))
}

fn send(node: &mut UpNode, w: &World, cmd: Command) -> Vec<DeviceFrame> {
    let mut bytes = Vec::new();
    let wire = encode_to_vec(&HostFrame { id: 7, cmd });
    node.handle_rx(&wire, w.now_ms(), &mut |b| bytes.extend_from_slice(b));
    common::frames(&bytes)
}

fn answer(node: &mut UpNode, w: &World, cmd: Command) -> Result<AckResult, ErrorCode> {
    match send(node, w, cmd).pop().map(|f| f.msg) {
        Some(DeviceMsg::Ack(a)) => Ok(a.result),
        Some(DeviceMsg::Error(e)) => Err(e.code),
        other => panic!("no answer: {other:?}"),
    }
}

/// The image events one frame sent.
fn frame_events(node: &mut UpNode, w: &World) -> Vec<EventKind> {
    let mut bytes = Vec::new();
    w.run_frame(node, &mut |b| bytes.extend_from_slice(b));
    common::frames(&bytes)
        .into_iter()
        .filter_map(|f| match f.msg {
            DeviceMsg::Event(e) => match e.kind {
                k @ (EventKind::ImageConfirmed { .. } | EventKind::ImageRolledBack { .. }) => {
                    Some(k)
                }
                _ => None,
            },
            _ => None,
        })
        .collect()
}

/// The host's update over the node's commands; the node asks for its reset.
fn update_over_commands(node: &mut UpNode, w: &World, b: &Image) {
    let Ok(AckResult::UpdateStatus(st)) = answer(node, w, Command::UpdateBegin(b.begin())) else {
        panic!("begin refused");
    };
    let mut at = st.next_offset as usize;
    while at < b.bytes.len() {
        // Frames go on between the chunks.
        if at.is_multiple_of(2_048) {
            node.run_frame(w.now_ms(), &mut |_| {});
        }
        match answer(node, w, Command::UpdateChunk(chunk(b, at, 256))) {
            Ok(AckResult::UpdateStatus(st)) => at = st.next_offset as usize,
            other => panic!("chunk at {at}: {other:?}"),
        }
    }
    let verified = answer(node, w, Command::UpdateVerify(b.signature));
    assert!(
        matches!(verified, Ok(AckResult::UpdateStatus(st)) if st.phase == UpdatePhase::Verified),
        "{verified:?}"
    );
    assert!(!node.take_reset_request());
    assert_eq!(
        answer(node, w, Command::UpdateCommit),
        Ok(AckResult::UpdateCommitted { version: NEW })
    );
    assert!(node.take_reset_request(), "no reset after the commit");
}

#[test]
fn an_update_over_the_commands_boots_on_trial_and_confirms_after_its_self_test() {
    let a = image(9_000, 1, OLD);
    let b = image(10_000, 2, NEW);
    let flash = board_flash(&a);
    let w = World::default();
    let mut node = boot(&flash, &w, &[&a, &b]);
    assert_eq!(node.hello().firmware_version, OLD);
    assert_eq!(
        answer(&mut node, &w, Command::GetImageInfo),
        Ok(AckResult::ImageInfo(ImageInfo {
            version: OLD,
            state: ImageState::Confirmed,
            slot_bytes: ACTIVE_LEN - 324,
        }))
    );
    update_over_commands(&mut node, &w, &b);
    // The reset: the new image on trial.
    let mut node = boot(&flash, &w, &[&a, &b]);
    assert_eq!(node.hello().firmware_version, NEW);
    assert!(node.on_trial());
    assert_eq!(
        answer(&mut node, &w, Command::UpdateBegin(a.begin())),
        Err(ErrorCode::UpdateRefused(
            fois_protocol::UpdateRefusal::OnTrial
        ))
    );
    // The host asked (the link answers); three plausible frames confirm.
    let mut events = Vec::new();
    for _ in 0..trial::TRIAL_FRAMES {
        events.extend(frame_events(&mut node, &w));
    }
    assert_eq!(events, vec![EventKind::ImageConfirmed { version: NEW }]);
    assert!(!node.on_trial());
    assert!(matches!(
        answer(&mut node, &w, Command::GetImageInfo),
        Ok(AckResult::ImageInfo(ImageInfo {
            state: ImageState::Confirmed,
            version: NEW,
            ..
        }))
    ));
    // And it stays: the next boot is the new image, confirmed.
    drop(node);
    let node = boot(&flash, &w, &[&a, &b]);
    assert_eq!(node.updates().image_state(), ImageState::Confirmed);
    assert_eq!(node.hello().firmware_version, NEW);
    assert!(config_untouched(&flash));
}

#[test]
fn an_image_that_fails_its_self_test_is_rolled_back_without_a_person() {
    let a = image(9_000, 1, OLD);
    let b = image(10_000, 2, NEW);
    let flash = board_flash(&a);
    let w = World::default();
    let mut node = boot(&flash, &w, &[&a, &b]);
    update_over_commands(&mut node, &w, &b);
    // The new image streams, but every frame it measures is saturated (as
    // a new image that drives its ADC wrong would): the deadline passes, it
    // asks for the reset.
    let mut node = boot(&flash, &w, &[&a, &b]);
    w.set(|s| s.ambient_na = [1.0e6, 1.0e6]);
    let start = w.now_ms();
    let mut frames = 0;
    while !node.take_reset_request() {
        assert!(frame_events(&mut node, &w).is_empty());
        frames += 1;
        assert!(frames < 10_000, "no rollback");
    }
    let waited = w.now_ms() - start;
    let deadline = trial::trial_deadline_ms(node.frame_period_ms());
    assert!(
        waited >= deadline && waited <= deadline + 200,
        "{waited} ms for a {deadline} ms deadline"
    );
    // The bootloader rolls back; the old image reports it with its first
    // frame, says so when asked, and takes a new update.
    drop(node);
    w.set(|s| s.ambient_na = [0.0, 0.0]);
    let mut node = boot(&flash, &w, &[&a, &b]);
    assert_eq!(node.hello().firmware_version, OLD);
    let rolled_back = ImageState::RolledBack { failed: NEW };
    assert_eq!(node.updates().image_state(), rolled_back);
    assert_eq!(
        frame_events(&mut node, &w),
        vec![EventKind::ImageRolledBack {
            failed: NEW,
            running: OLD
        }]
    );
    assert!(frame_events(&mut node, &w).is_empty(), "reported twice");
    assert!(matches!(
        answer(&mut node, &w, Command::GetImageInfo),
        Ok(AckResult::ImageInfo(ImageInfo { state, version: OLD, .. })) if state == rolled_back
    ));
    assert!(matches!(
        answer(&mut node, &w, Command::UpdateBegin(b.begin())),
        Ok(AckResult::UpdateStatus(_))
    ));
    assert!(config_untouched(&flash));
}

#[test]
fn a_node_without_update_slots_knows_no_transfer() {
    let (mut node, w) = common::node();
    for cmd in [
        Command::UpdateBegin(image(100, 1, NEW).begin()),
        Command::GetUpdateStatus,
        Command::UpdateCommit,
        Command::UpdateAbort,
    ] {
        let out = common::command(&mut node, &w, 3, cmd.clone());
        assert!(
            matches!(&out[0].msg, DeviceMsg::Error(e) if e.code == ErrorCode::UnknownCommand),
            "{cmd:?}: {out:?}"
        );
    }
    let out = common::command(&mut node, &w, 4, Command::GetImageInfo);
    assert!(matches!(
        &out[0].msg,
        DeviceMsg::Ack(a) if a.result == AckResult::ImageInfo(ImageInfo {
            version: fois_firmware::node::FIRMWARE_VERSION,
            state: ImageState::Confirmed,
            slot_bytes: 0,
        })
    ));
}
