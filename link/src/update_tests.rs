//! The update driver against the scripted node ([`crate::update_fake`]):
//! a clean transfer, lost and garbled pieces, a cut port and a power cut
//! with resume, every refusal, the trial's outcomes, and the link's
//! throughput model from the bytes the driver really sends.

use std::time::Duration;

use fois_protocol::update::image_flags;
use fois_protocol::{Hello, ImageState, ImageTrailer, UpdateRefusal};

use crate::link::Link;
use crate::signed_image::SignedImage;
use crate::update::{Step, UpdateError, UpdateEvent, UpdateOptions, UpdateReport, update};
use crate::update_fake::{FakeNode, FakePort, Script, TrialOutcome};

const BOARD: &str = "NUCLEO-F446RE";
const SIGNATURE: [u8; 64] = [0x5A; 64];
const SLOT_BYTES: u32 = 128 * 1024;

/// A 90 KiB image (seeded bytes) of `version` for `board`.
fn image(version: [u8; 3], board: &str, flags: u8) -> SignedImage {
    let mut x: u32 = 0x1234_5678;
    let body: Vec<u8> = (0..90 * 1024)
        .map(|_| {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 24) as u8
        })
        .collect();
    let trailer = ImageTrailer {
        body_len: body.len() as u32,
        version,
        flags,
        board: Hello::board_from_str(board),
    };
    SignedImage::assemble(&body, &trailer, &SIGNATURE).unwrap()
}

fn fake(script: Script) -> FakeNode {
    FakeNode::new(
        BOARD,
        [0, 6, 0],
        SLOT_BYTES,
        script,
        Box::new(|_digest, sig| *sig == SIGNATURE),
    )
}

fn opts() -> UpdateOptions {
    UpdateOptions {
        reply_timeout: Duration::from_millis(150),
        garbled_wait: Duration::from_millis(30),
        attempts: 3,
        resume_timeout: Duration::from_millis(1_500),
        boot_timeout: Duration::from_millis(1_000),
        confirm_timeout: Duration::from_millis(600),
        status_poll: Duration::from_millis(100),
        max_resumes: 5,
        quiet_stream: true,
    }
}

struct Run {
    result: Result<UpdateReport, UpdateError>,
    events: Vec<UpdateEvent>,
}

fn run(node: &FakeNode, img: &SignedImage, reopen: bool) -> Run {
    let mut link = Link::new(node.port(), "fake");
    let mut events = Vec::new();
    let reopener = node.clone();
    let mut reopen_fn = move || -> Result<FakePort, crate::LinkError> { Ok(reopener.port()) };
    let result = update(
        &mut link,
        img,
        &opts(),
        if reopen { Some(&mut reopen_fn) } else { None },
        &mut |e| events.push(e),
    );
    Run { result, events }
}

fn chunks_of(img: &SignedImage) -> u64 {
    u64::from(img.image_len()).div_ceil(256)
}

#[test]
fn a_clean_transfer_writes_every_byte_once_and_follows_the_trial() {
    let node = fake(Script::default());
    let img = image([0, 7, 0], BOARD, 0);
    let r = run(&node, &img, false);
    let report = r.result.unwrap();
    assert_eq!(report.running, [0, 7, 0]);
    assert_eq!(report.from_version, [0, 6, 0]);
    assert_eq!(
        (report.retries, report.resumes, report.started_at),
        (0, 0, 0)
    );
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
    assert_eq!(chunks_of(&img), 361);
    assert_eq!(node.image_info().state, ImageState::Confirmed);
    // Progress: every chunk, in order, to the end.
    let done: Vec<u32> = r
        .events
        .iter()
        .filter_map(|e| match e {
            UpdateEvent::Progress { done, total } => {
                assert_eq!(*total, img.image_len());
                Some(*done)
            }
            _ => None,
        })
        .collect();
    assert_eq!(done.first(), Some(&0));
    assert_eq!(done.get(1), Some(&256));
    assert_eq!(done.last(), Some(&img.image_len()));
    assert!(
        done.windows(2)
            .all(|w| w[1] == w[0] + 256 || w[1] == img.image_len())
    );
    // Running it again: the node runs the image, nothing is sent.
    let again = run(&node, &img, false).result.unwrap();
    assert!(again.already_running);
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
}

#[test]
fn lost_and_garbled_pieces_are_sent_again_without_writing_twice() {
    let script = Script {
        lose_command_at: [2_560].into(),
        lose_answer_at: [5_120].into(),
        garble_answer_at: [7_680].into(),
        ..Script::default()
    };
    let node = fake(script);
    let img = image([0, 7, 0], BOARD, 0);
    let report = run(&node, &img, false).result.unwrap();
    assert_eq!(report.retries, 3);
    // The lost answer's chunk was written; its resend was answered
    // OutOfOrder with the next offset, which the driver took.
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
    assert_eq!(report.running, [0, 7, 0]);
}

#[test]
fn a_cut_port_is_reopened_and_the_transfer_resumes_where_the_node_is() {
    let node = fake(Script {
        cut_port_at: Some(40 * 256),
        ..Script::default()
    });
    let img = image([0, 7, 0], BOARD, 0);
    let r = run(&node, &img, true);
    let report = r.result.unwrap();
    assert_eq!(report.resumes, 1);
    assert!(r.events.contains(&UpdateEvent::Resumed { from: 40 * 256 }));
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
}

#[test]
fn without_a_way_to_reopen_the_update_stops_and_a_second_run_continues() {
    let node = fake(Script {
        cut_port_at: Some(40 * 256),
        ..Script::default()
    });
    let img = image([0, 7, 0], BOARD, 0);
    match run(&node, &img, false).result {
        Err(UpdateError::LinkDown {
            step: Step::Transfer,
            offset,
            total,
            ..
        }) => assert_eq!((offset, total), (40 * 256, img.image_len())),
        other => panic!("{other:?}"),
    }
    let r = run(&node, &img, false);
    let report = r.result.unwrap();
    assert_eq!(report.started_at, 40 * 256);
    assert!(r.events.contains(&UpdateEvent::Resumed { from: 40 * 256 }));
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
}

#[test]
fn a_power_cut_mid_transfer_is_picked_up_from_the_bytes_the_node_kept() {
    let node = fake(Script {
        power_cut_at: Some(100 * 256),
        ..Script::default()
    });
    let img = image([0, 7, 0], BOARD, 0);
    let r = run(&node, &img, false);
    let report = r.result.unwrap();
    assert_eq!(report.resumes, 1);
    assert!(r.events.contains(&UpdateEvent::Resumed { from: 100 * 256 }));
    assert_eq!(node.traffic().chunks_written, chunks_of(&img));
}

fn refused(r: Run) -> (Step, UpdateRefusal, bool) {
    match r.result {
        Err(UpdateError::Refused {
            step,
            refusal,
            by_host,
        }) => (step, refusal, by_host),
        other => panic!("{other:?}"),
    }
}

#[test]
fn wrong_images_are_refused_on_the_host_before_a_byte_is_sent() {
    let node = fake(Script::default());
    let r = run(&node, &image([0, 7, 0], "OTHER-BOARD", 0), false);
    assert_eq!(refused(r), (Step::Connect, UpdateRefusal::WrongBoard, true));
    let r = run(&node, &image([0, 5, 9], BOARD, 0), false);
    assert_eq!(
        refused(r),
        (
            Step::Connect,
            UpdateRefusal::OlderVersion {
                running: [0, 6, 0],
                image: [0, 5, 9]
            },
            true
        )
    );
    let small = FakeNode::new(
        BOARD,
        [0, 6, 0],
        64 * 1024,
        Script::default(),
        Box::new(|_, _| true),
    );
    let r = run(&small, &image([0, 7, 0], BOARD, 0), false);
    assert_eq!(
        refused(r),
        (
            Step::Connect,
            UpdateRefusal::BadLength {
                max_bytes: 64 * 1024
            },
            true
        )
    );
    assert_eq!(
        node.traffic().chunks_written + small.traffic().chunks_written,
        0
    );
    // A signed downgrade passes the host's check (and the node's).
    let report = run(
        &node,
        &image([0, 5, 9], BOARD, image_flags::DOWNGRADE),
        false,
    )
    .result
    .unwrap();
    assert_eq!(report.running, [0, 5, 9]);
}

#[test]
fn the_node_s_refusals_end_the_update_with_their_reason() {
    let img = image([0, 7, 0], BOARD, 0);
    for refusal in [
        UpdateRefusal::Busy,
        UpdateRefusal::OnTrial,
        UpdateRefusal::FlashFailed,
    ] {
        let node = fake(Script {
            refuse_begin: Some(refusal),
            ..Script::default()
        });
        assert_eq!(
            refused(run(&node, &img, false)),
            (Step::Begin, refusal, false)
        );
    }
    // A bad signature: refused at verify, the slot abandoned (a later run
    // starts afresh).
    let node = FakeNode::new(
        BOARD,
        [0, 6, 0],
        SLOT_BYTES,
        Script::default(),
        Box::new(|_, _| false),
    );
    assert_eq!(
        refused(run(&node, &img, false)),
        (Step::Verify, UpdateRefusal::BadSignature, false)
    );
    let r = run(&node, &img, false);
    assert_eq!(
        r.events
            .iter()
            .filter(|e| matches!(e, UpdateEvent::Resumed { .. }))
            .count(),
        0
    );
    for refusal in [UpdateRefusal::DigestMismatch, UpdateRefusal::BadTrailer] {
        let node = fake(Script {
            refuse_verify: Some(refusal),
            ..Script::default()
        });
        assert_eq!(
            refused(run(&node, &img, false)),
            (Step::Verify, refusal, false)
        );
        assert_eq!(node.image_info().version, [0, 6, 0]);
    }
}

#[test]
fn a_node_older_than_protocol_6_is_refused_by_name() {
    let node = fake(Script::default());
    node.set_protocol_version(5);
    match run(&node, &image([0, 7, 0], BOARD, 0), false).result {
        Err(UpdateError::NodeTooOld { node: 5, since: 6 }) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_failed_trial_is_reported_as_a_rollback_and_a_silent_one_as_unconfirmed() {
    let node = fake(Script {
        trial: TrialOutcome::RollBack,
        ..Script::default()
    });
    match run(&node, &image([0, 7, 0], BOARD, 0), false).result {
        Err(UpdateError::RolledBack { failed, running }) => {
            assert_eq!((failed, running), ([0, 7, 0], [0, 6, 0]))
        }
        other => panic!("{other:?}"),
    }
    let node = fake(Script {
        trial: TrialOutcome::Silent,
        ..Script::default()
    });
    match run(&node, &image([0, 7, 0], BOARD, 0), false).result {
        Err(UpdateError::NotConfirmed { running, state, .. }) => {
            assert_eq!((running, state), ([0, 7, 0], ImageState::Trial))
        }
        other => panic!("{other:?}"),
    }
    // On trial, the node refuses another image until it confirms.
    let r = run(&node, &image([0, 8, 0], BOARD, 0), false);
    assert_eq!(refused(r), (Step::Begin, UpdateRefusal::OnTrial, false));
}

/// The throughput model with the frame sizes the driver really sends: a
/// 90 KiB image at 115 200 and 19 200 Bd (`cargo test -p fois-link
/// throughput -- --nocapture` prints the table README.md quotes).
#[test]
fn throughput_of_a_90_kib_image_at_both_rates() {
    use crate::update_timing::{LineModel, chunk_frame_bytes};
    use fois_protocol::{DeviceFrame, DeviceMsg, ResetReason, encode_to_vec};

    let img = image([0, 7, 0], BOARD, 0);
    let (command_bytes, answer_bytes) = chunk_frame_bytes(img.image_len());
    assert_eq!((command_bytes, answer_bytes), (278, 23));
    assert!(command_bytes <= fois_protocol::MAX_FRAME + 1);

    // The driver's own bytes: the chunks and a handful of other commands.
    let node = fake(Script {
        stream_every: 0,
        ..Script::default()
    });
    run(&node, &img, false).result.unwrap();
    let t = node.traffic();
    let chunks = chunks_of(&img);
    let per_chunk = t.host_bytes as f64 / chunks as f64;
    assert!(
        per_chunk <= command_bytes as f64 + 2.0 && per_chunk >= command_bytes as f64 - 8.0,
        "{per_chunk} B a chunk sent"
    );
    assert!(t.answer_bytes as f64 / (t.answers as f64) <= answer_bytes as f64);

    // The node's frames: its 10 Hz measurement (the widest of the fixture's
    // node) or, with the stream stopped, its Hello once a second.
    let measurement = encode_to_vec(&DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::MeasurementV5(fois_protocol::MeasurementV5 {
            measurement: crate::fixtures::iced_measurement(),
            estimate: Some(crate::fixtures::rime_estimate()),
            gain: Some(crate::fixtures::gain_estimate()),
            icing: Some(fois_protocol::IcingEstimate {
                rate_um_per_h: 5_000,
                sigma_um_per_h: 400,
                accreting_permille: 950,
                accreting: true,
            }),
        }),
    })
    .len();
    let hello = encode_to_vec(&DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::Hello(Hello {
            protocol_version: 6,
            firmware_version: [0, 7, 0],
            board: Hello::board_from_str(BOARD),
            unique_id: [0xFF; 12],
            reset_reason: ResetReason::PowerOn,
        }),
    })
    .len();
    let model = |baud, node_ms, stream_hz, stream_bytes| LineModel {
        baud,
        image_len: img.image_len(),
        command_bytes,
        answer_bytes,
        node_ms,
        stream_hz,
        stream_bytes,
    };
    println!(
        "90 KiB + trailer = {} B, {} chunks; command {command_bytes} B, answer \
         {answer_bytes} B; measurement {measurement} B at 10 Hz, hello {hello} B at 1 Hz",
        img.image_len(),
        chunks
    );
    println!("| baud | node ms/chunk | stream | transfer s | node ms budget for the goal |");
    let mut quiet = Vec::new();
    for (baud, goal_s) in [(115_200, 20.0), (19_200, 90.0)] {
        for node_ms in [5.0, 20.0] {
            for (label, hz, bytes) in [
                ("10 Hz measurements", 10.0, measurement),
                ("stopped (1 Hz hello)", 1.0, hello),
            ] {
                let m = model(baud, node_ms, hz, bytes);
                println!(
                    "| {baud} | {node_ms} | {label} | {:.1} | {:.1} |",
                    m.transfer_s(),
                    m.node_ms_budget(goal_s)
                );
                if hz == 1.0 {
                    quiet.push((baud, node_ms, m.transfer_s(), goal_s));
                }
            }
        }
    }
    // With the stream stopped (the driver's default) and the node answering
    // a chunk within 20 ms, both goals hold with one chunk in flight.
    for (baud, node_ms, s, goal_s) in quiet {
        assert!(
            s <= goal_s,
            "{baud} Bd, {node_ms} ms: {s:.1} s > {goal_s} s"
        );
    }
    // With the 10 Hz stream on the half-duplex line, 19 200 Bd leaves the
    // node 26 ms a chunk; stopped, 86 ms (the driver's default).
    let streaming = model(19_200, 0.0, 10.0, measurement).node_ms_budget(90.0);
    let stopped = model(19_200, 0.0, 1.0, hello).node_ms_budget(90.0);
    assert!((25.0..28.0).contains(&streaming), "{streaming}");
    assert!((85.0..88.0).contains(&stopped), "{stopped}");
}
