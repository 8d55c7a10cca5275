//! A firmware update carried out on the virtual node in process: the
//! firmware's updater on the RAM slots, embassy-boot's swap at the reset
//! after the commit, the new node running the image's version on trial and
//! confirming itself after its self-test; refusals leave the version alone.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use fois_firmware::update::{FIRMWARE_VERSION, UpdateKey};

use fois_protocol::{
    AckResult, ChunkData, Command, ErrorCode, FirmwareVersion, ImageSignature, ImageState,
    ImageTrailer, UPDATE_CHUNK_MAX, UpdateBegin, UpdateChunk, UpdateRefusal,
};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

const BOARD: &str = "virtual-f446";

fn keypair() -> salty::Keypair {
    let hex = include_str!("../../firmware/tests/keys/test-update-ed25519.seed").trim();
    let mut seed = [0u8; 32];
    for (i, b) in seed.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap();
    }
    salty::Keypair::from(&seed)
}

struct Image {
    bytes: Vec<u8>,
    sha512: [u8; 64],
    signature: ImageSignature,
    version: FirmwareVersion,
}

fn image(body_len: usize, seed: u32, version: FirmwareVersion) -> Image {
    let mut bytes: Vec<u8> = (0..body_len as u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) ^ seed).rotate_left(seed % 31) as u8)
        .collect();
    bytes.extend_from_slice(
        &ImageTrailer {
            body_len: body_len as u32,
            version,
            flags: 0,
            board: fois_protocol::Hello::board_from_str(BOARD),
        }
        .to_bytes(),
    );
    let sha512 = salty::Sha512::new().updated(&bytes).finalize();
    let signature = ImageSignature::from_bytes(&keypair().sign(&sha512).to_bytes());
    Image {
        bytes,
        sha512,
        signature,
        version,
    }
}

fn newer() -> FirmwareVersion {
    [FIRMWARE_VERSION[0], FIRMWARE_VERSION[1].wrapping_add(1), 0]
}

fn node() -> VirtualNode {
    node_in(Segment::new(3_600.0, Cover::Dry))
}

fn node_in(segment: Segment) -> VirtualNode {
    let env = Arc::new(Environment::new(
        Timeline::new(vec![segment]),
        fois_sim::SensorKind::B,
        1,
    ));
    let mut vn = VirtualNode::new(
        env,
        NodeOptions {
            calibrate_at_s: None,
            update_key: UpdateKey::from_bytes(keypair().public.to_bytes()),
            ..NodeOptions::default()
        },
    );
    vn.run_until_s(1.0, &mut |_: &[u8]| {});
    vn
}

/// Begin, every chunk, verify: the verify's answer.
fn send(vn: &mut VirtualNode, img: &Image) -> Result<AckResult, ErrorCode> {
    let mut digest = [0u8; 32];
    digest.copy_from_slice(&img.sha512[..32]);
    let mut quiet = |_: &[u8]| {};
    vn.command(
        Command::UpdateBegin(UpdateBegin {
            image_len: img.bytes.len() as u32,
            version: img.version,
            image_digest: digest,
        }),
        &mut quiet,
    )?;
    for (i, data) in img.bytes.chunks(UPDATE_CHUNK_MAX).enumerate() {
        vn.command(
            Command::UpdateChunk(UpdateChunk {
                offset: (i * UPDATE_CHUNK_MAX) as u32,
                crc32: fois_protocol::framing::CRC.checksum(data),
                data: ChunkData::new(data).unwrap(),
            }),
            &mut quiet,
        )?;
    }
    vn.command(Command::UpdateVerify(img.signature), &mut quiet)
}

fn info(vn: &mut VirtualNode) -> fois_protocol::ImageInfo {
    match vn.command(Command::GetImageInfo, &mut |_: &[u8]| {}) {
        Ok(AckResult::ImageInfo(i)) => i,
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_update_swaps_in_at_the_reset_and_the_new_version_confirms_itself() {
    let mut vn = node();
    let before = info(&mut vn);
    assert_eq!(
        (before.version, before.state),
        (FIRMWARE_VERSION, ImageState::Confirmed)
    );
    // The board's 128 KiB active slot, less the transfer's record.
    assert!((120 * 1024..=128 * 1024).contains(&before.slot_bytes));
    let img = image(90 * 1024, 7, newer());
    send(&mut vn, &img).unwrap();
    let t_commit = vn.clock().now_s();
    let r = vn.command(Command::UpdateCommit, &mut |_: &[u8]| {});
    assert_eq!(
        r,
        Ok(AckResult::UpdateCommitted {
            version: img.version
        })
    );
    assert_eq!(vn.resets(), 1);
    // The swap ran at the reset: the active slot holds the image, and the
    // board's swap took its erases' time (three 128 KiB sectors at least).
    let swap_s = vn.clock().now_s() - t_commit;
    assert!(swap_s >= 6.0, "swap took {swap_s} s");
    let head = vn
        .update_partitions()
        .active
        .with(|f| f.bytes()[..img.bytes.len()].to_vec());
    assert_eq!(head, img.bytes);
    assert_eq!(vn.node().hello().firmware_version, img.version);
    let trial = info(&mut vn);
    assert_eq!(
        (trial.version, trial.state),
        (img.version, ImageState::Trial)
    );
    // Frames, the store, the link answered (the GetImageInfo): confirmed.
    let now = vn.clock().now_s();
    vn.run_until_s(now + 3.0, &mut |_: &[u8]| {});
    let after = info(&mut vn);
    assert_eq!(
        (after.version, after.state),
        (img.version, ImageState::Confirmed)
    );
    // A later reset boots the same, confirmed image.
    vn.command(Command::Reset, &mut |_: &[u8]| {}).unwrap();
    let again = info(&mut vn);
    assert_eq!(
        (again.version, again.state),
        (img.version, ImageState::Confirmed)
    );
}

#[test]
fn refused_images_leave_the_running_version() {
    let mut vn = node();
    // One bit changed after signing.
    let mut flipped = image(20 * 1024, 3, newer());
    flipped.bytes[5_000] ^= 0x10;
    flipped.sha512 = salty::Sha512::new().updated(&flipped.bytes).finalize();
    assert_eq!(
        send(&mut vn, &flipped),
        Err(ErrorCode::UpdateRefused(UpdateRefusal::BadSignature))
    );
    // Older than the running version, not signed as a downgrade.
    let older = image(20 * 1024, 4, [0, 0, 1]);
    assert!(matches!(
        send(&mut vn, &older),
        Err(ErrorCode::UpdateRefused(UpdateRefusal::OlderVersion { .. }))
    ));
    assert_eq!(
        vn.command(Command::UpdateCommit, &mut |_: &[u8]| {})
            .map(|_| ()),
        Err(ErrorCode::UpdateRefused(UpdateRefusal::NotVerified))
    );
    // Without a key every image is refused.
    let env = Arc::new(Environment::new(
        Timeline::new(vec![Segment::new(60.0, Cover::Dry)]),
        fois_sim::SensorKind::B,
        1,
    ));
    let mut keyless = VirtualNode::new(env, NodeOptions::default());
    assert_eq!(
        send(&mut keyless, &image(4 * 1024, 5, newer())),
        Err(ErrorCode::UpdateRefused(UpdateRefusal::BadSignature))
    );
    assert_eq!(info(&mut vn).version, FIRMWARE_VERSION);
    assert_eq!(vn.resets(), 0);
}

#[test]
fn an_image_that_fails_its_self_test_is_rolled_back_by_the_bootloader() {
    // Every frame invalid (both channels saturated by sunlight far beyond
    // the phototransistors' clip): the new image's self-test
    // cannot pass; at its deadline it resets, the bootloader swaps the old
    // image back, and the node reports the rollback.
    let mut vn = node_in(Segment::new(3_600.0, Cover::Dry).ambient([1_000.0, 1_000.0]));
    let img = image(30 * 1024, 9, newer());
    send(&mut vn, &img).unwrap();
    vn.command(Command::UpdateCommit, &mut |_: &[u8]| {})
        .unwrap();
    assert_eq!(vn.resets(), 1);
    let trial = info(&mut vn);
    assert_eq!(
        (trial.version, trial.state),
        (img.version, ImageState::Trial)
    );
    let now = vn.clock().now_s();
    let mut events = Vec::new();
    let mut dec = fois_protocol::FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    vn.run_until_s(now + 90.0, &mut |b: &[u8]| {
        dec.feed::<fois_protocol::DeviceFrame>(b, |r| {
            if let Ok(fois_protocol::DeviceFrame {
                msg: fois_protocol::DeviceMsg::Event(e),
                ..
            }) = r
            {
                events.push(e.kind);
            }
        })
    });
    assert_eq!(
        vn.resets(),
        2,
        "no rollback reset: {events:?} {:?}",
        info(&mut vn)
    );
    let after = info(&mut vn);
    assert_eq!(after.version, FIRMWARE_VERSION);
    assert!(
        events.contains(&fois_protocol::EventKind::ImageRolledBack {
            failed: img.version,
            running: FIRMWARE_VERSION,
        }),
        "{events:?}"
    );
    // How this boot went (read at boot), and marked: a new update may begin.
    assert_eq!(
        after.state,
        ImageState::RolledBack {
            failed: img.version
        }
    );
    let mut digest = [0u8; 32];
    digest.copy_from_slice(&img.sha512[..32]);
    let begin = vn.command(
        Command::UpdateBegin(UpdateBegin {
            image_len: img.bytes.len() as u32,
            version: img.version,
            image_digest: digest,
        }),
        &mut |_: &[u8]| {},
    );
    assert!(matches!(begin, Ok(AckResult::UpdateStatus(_))), "{begin:?}");
}

/// During a transfer the node goes on measuring: rime on the face (the
/// alarm on), streaming at 10 Hz, every command of a 90 KiB update with
/// the line's time between the chunks (a 279-byte frame at 115 200 Bd):
/// the alarm output never drops, and the longest gap between two
/// measurement frames is one 128 KiB sector's worst-case erase (a command
/// erases at most one sector), its record's programming and a frame
/// period. The DFU slot holds an
/// older image (a first update went before), so the transfer erases.
#[test]
fn during_a_transfer_the_alarm_holds_and_frames_keep_coming() {
    use fois_firmware::platform::watchdog::ERASE_128K_X32_MAX_MS;
    use fois_protocol::framing::FrameDecoder;
    use fois_protocol::{DeviceFrame, DeviceMsg};

    let env = Arc::new(Environment::new(
        Timeline::new(vec![
            Segment::new(20.0, Cover::Dry),
            Segment::new(3_600.0, Cover::Rime).rate(10.0),
        ]),
        fois_sim::SensorKind::B,
        1,
    ));
    let mut vn = VirtualNode::new(
        env,
        NodeOptions {
            update_key: UpdateKey::from_bytes(keypair().public.to_bytes()),
            ..NodeOptions::default()
        },
    );
    // Calibrated on the dry face at 1 s; ice from 20 s. A first update
    // (committed, swapped, confirmed) leaves the old image in the DFU
    // slot, so the measured one must erase its sectors as it goes.
    vn.run_until_s(60.0, &mut |_: &[u8]| {});
    let first = image(90 * 1024, 10, newer());
    send(&mut vn, &first).unwrap();
    vn.command(Command::UpdateCommit, &mut |_: &[u8]| {})
        .unwrap();
    let now = vn.clock().now_s();
    vn.run_until_s(now.max(300.0), &mut |_: &[u8]| {});
    assert_eq!(info(&mut vn).state, ImageState::Confirmed);
    assert!(vn.alarm_on(), "no alarm on 0.8 mm of rime");
    let r = vn.command(
        Command::StartStream {
            frame_period_ms: None,
        },
        &mut |_: &[u8]| {},
    );
    assert!(r.is_ok(), "{r:?}");

    // The time of every measurement frame the node sends.
    let clock = vn.clock().clone();
    let mut decoder = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut frame_ns: Vec<u64> = Vec::new();
    let mut tx = |b: &[u8]| {
        decoder.feed::<DeviceFrame>(b, |r| {
            if let Ok(DeviceFrame {
                msg: DeviceMsg::Measurement(..) | DeviceMsg::MeasurementV5(..),
                ..
            }) = r
            {
                frame_ns.push(clock.now_ns());
            }
        })
    };
    // A second of streaming before the transfer: the frame before the
    // begin's erase is seen.
    let now = vn.clock().now_ns();
    vn.advance_to(now + 1_000_000_000, &mut tx);
    let edges_before = vn.alarm_pin().edges().len();
    let start_ns = vn.clock().now_ns();

    let next = [FIRMWARE_VERSION[0], FIRMWARE_VERSION[1].wrapping_add(2), 0];
    let img = image(90 * 1024, 11, next);
    let mut digest = [0u8; 32];
    digest.copy_from_slice(&img.sha512[..32]);
    let chunk_line_ns = 279 * 10 * 1_000_000_000 / 115_200;
    let t0 = vn.clock().now_ns();
    let r = vn.command(
        Command::UpdateBegin(UpdateBegin {
            image_len: img.bytes.len() as u32,
            version: img.version,
            image_digest: digest,
        }),
        &mut tx,
    );
    assert!(r.is_ok(), "{r:?}");
    let begin_ns = vn.clock().now_ns() - t0;
    for (i, data) in img.bytes.chunks(UPDATE_CHUNK_MAX).enumerate() {
        let now = vn.clock().now_ns();
        vn.advance_to(now + chunk_line_ns, &mut tx);
        let r = vn.command(
            Command::UpdateChunk(UpdateChunk {
                offset: (i * UPDATE_CHUNK_MAX) as u32,
                crc32: fois_protocol::framing::CRC.checksum(data),
                data: ChunkData::new(data).unwrap(),
            }),
            &mut tx,
        );
        assert!(r.is_ok(), "chunk {i}: {r:?}");
    }
    let r = vn.command(Command::UpdateVerify(img.signature), &mut tx);
    assert!(r.is_ok(), "{r:?}");
    let end_ns = vn.clock().now_ns();
    vn.advance_to(end_ns + 1_000_000_000, &mut tx);

    // The alarm output: no edge at all while the update went over.
    assert!(vn.alarm_on());
    assert_eq!(
        vn.alarm_pin().edges().len(),
        edges_before,
        "the alarm moved"
    );
    // Frames: from the first command to the verify's end, with the
    // longest gap one erase and a frame period.
    let transfer_s = (end_ns - start_ns) as f64 / 1e9;
    assert!(
        frame_ns.len() as f64 >= 0.8 * 10.0 * transfer_s,
        "{} frames in {transfer_s:.1} s",
        frame_ns.len()
    );
    let worst_gap_ns = frame_ns
        .windows(2)
        .map(|w| w[1] - w[0])
        .max()
        .unwrap_or(u64::MAX);
    // One erase, the record's programming, and a frame period.
    let bound_ns = u64::from(ERASE_128K_X32_MAX_MS) * 1_000_000 + 150_000_000;
    println!(
        "transfer {transfer_s:.1} s, {} frames, longest gap {} ms (bound {} ms; the begin took {} ms)",
        frame_ns.len(),
        worst_gap_ns / 1_000_000,
        bound_ns / 1_000_000,
        begin_ns / 1_000_000
    );
    assert!(
        worst_gap_ns <= bound_ns,
        "longest gap {} ms",
        worst_gap_ns / 1_000_000
    );
    // A gap as long as an erase happened: the bound is met, not vacuous.
    assert!(worst_gap_ns >= u64::from(ERASE_128K_X32_MAX_MS) * 1_000_000 / 2);
}
