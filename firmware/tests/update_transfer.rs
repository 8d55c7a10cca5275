//! The firmware transfer on the updater over the board's partitions (a RAM
//! flash) and embassy-boot's bootloader: a whole update, each refusal with
//! its reason and nothing changed, resuming after a link drop and after a
//! power cut.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod update_common;

use fois_firmware::update::UpdateSlots;
use fois_protocol::{ImageSignature, ImageState, UpdatePhase, UpdateRefusal};
use update_common::*;

const RUNNING: [u8; 3] = [0, 1, 0];

fn board() -> [u8; 16] {
    fois_protocol::Hello::board_from_str(BOARD)
}

/// Begin and send every chunk of `img` (chunks of `size` bytes).
fn send_all(u: &mut Updater, img: &Image, size: usize) {
    let st = u.begin_transfer(&img.begin()).unwrap();
    let mut at = st.next_offset as usize;
    while at < img.bytes.len() {
        let st = u.write_chunk(&chunk(img, at, size)).unwrap();
        at = st.next_offset as usize;
    }
}

#[test]
fn an_update_goes_over_swaps_into_a_trial_and_confirms() {
    let a = image(9_000, 1, RUNNING);
    let b = image(10_000, 2, [0, 2, 0]);
    let flash = board_flash(&a);
    assert_eq!(format!("{:?}", run_bootloader(&flash)), "Boot");
    let mut u = updater(&flash, RUNNING);
    assert_eq!(u.image_state(), ImageState::Confirmed);
    assert_eq!(u.slot_bytes(), ACTIVE_LEN - (64 + 4 + 64 * 4));
    // Unaligned chunks (100 bytes) as well as the protocol's 256.
    send_all(&mut u, &b, 100);
    let st = u.verify_image(&b.signature, &board()).unwrap();
    assert_eq!(st.phase, UpdatePhase::Verified);
    assert_eq!(u.commit_image(), Ok([0, 2, 0]));
    assert_eq!(u.status().unwrap().phase, UpdatePhase::Idle);
    drop(u);
    // The reset: the bootloader swaps, the new image runs on trial.
    assert_eq!(format!("{:?}", run_bootloader(&flash)), "Swap");
    assert_eq!(active_image(&flash, &[&a, &b]), Some([0, 2, 0]));
    let mut u = updater(&flash, [0, 2, 0]);
    assert_eq!(u.image_state(), ImageState::Trial);
    // On trial it takes no update.
    assert_eq!(u.begin_transfer(&a.begin()), Err(UpdateRefusal::OnTrial));
    u.mark_booted().unwrap();
    assert_eq!(u.image_state(), ImageState::Confirmed);
    drop(u);
    assert_eq!(format!("{:?}", run_bootloader(&flash)), "Boot");
    assert_eq!(active_image(&flash, &[&a, &b]), Some([0, 2, 0]));
    assert!(config_untouched(&flash));
}

#[test]
fn an_unconfirmed_trial_is_rolled_back_and_reported() {
    let a = image(9_000, 1, RUNNING);
    let b = image(10_000, 2, [0, 2, 0]);
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    send_all(&mut u, &b, 256);
    u.verify_image(&b.signature, &board()).unwrap();
    u.commit_image().unwrap();
    drop(u);
    run_bootloader(&flash);
    assert_eq!(active_image(&flash, &[&a, &b]), Some([0, 2, 0]));
    // The new image never confirms: the next reset rolls back.
    run_bootloader(&flash);
    assert_eq!(active_image(&flash, &[&a, &b]), Some(RUNNING));
    let mut u = updater(&flash, RUNNING);
    assert_eq!(
        u.image_state(),
        ImageState::RolledBack { failed: [0, 2, 0] }
    );
    // A rolled-back node takes a new update (after confirming itself).
    u.mark_booted().unwrap();
    send_all(&mut u, &b, 256);
    assert!(u.verify_image(&b.signature, &board()).is_ok());
    assert!(config_untouched(&flash));
}

/// Run `f` on a fresh updater with `b` fully sent; the refusal it gives,
/// and whether the flash changed.
fn refused_after_send(
    b: &Image,
    f: impl FnOnce(&mut Updater) -> Result<fois_protocol::UpdateStatus, UpdateRefusal>,
) -> (UpdateRefusal, bool) {
    let a = image(9_000, 1, RUNNING);
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    send_all(&mut u, b, 256);
    let before = flash.borrow().bytes().to_vec();
    let status = u.status().unwrap();
    let r = f(&mut u).unwrap_err();
    let changed = flash.borrow().bytes() != &before[..];
    assert_eq!(
        u.status().unwrap(),
        status,
        "the refusal moved the transfer"
    );
    assert_eq!(u.commit_image(), Err(UpdateRefusal::NotVerified));
    (r, changed)
}

#[test]
fn bad_images_are_refused_with_their_reason_and_nothing_changes() {
    let good = image(10_000, 2, [0, 2, 0]);
    let board = board();
    // One bit changed in the slot, the begin's digest the original's.
    let mut flipped = good.clone();
    flipped.bytes[4_321] ^= 0x08;
    let (r, changed) = refused_after_send(&flipped, |u| u.verify_image(&good.signature, &board));
    assert_eq!((r, changed), (UpdateRefusal::DigestMismatch, false));
    // One bit changed and the digest made to match: the signature fails.
    let forged = Image {
        signature: good.signature,
        ..sign(flipped.bytes.clone(), [0, 2, 0], &keypair())
    };
    let (r, changed) = refused_after_send(&forged, |u| u.verify_image(&forged.signature, &board));
    assert_eq!((r, changed), (UpdateRefusal::BadSignature, false));
    // Signed with another key.
    let other = salty::Keypair::from(&[9u8; 32]);
    let foreign = image_for(10_000, 2, [0, 2, 0], 0, BOARD, &other);
    let (r, changed) = refused_after_send(&foreign, |u| u.verify_image(&foreign.signature, &board));
    assert_eq!((r, changed), (UpdateRefusal::BadSignature, false));
    // A signature of zeros.
    let zero = ImageSignature {
        r: [0; 32],
        s: [0; 32],
    };
    let (r, changed) = refused_after_send(&good, |u| u.verify_image(&zero, &board));
    assert_eq!((r, changed), (UpdateRefusal::BadSignature, false));
    // Truncated: the last 100 bytes missing (its own digest): no trailer.
    let truncated = sign(
        good.bytes[..good.bytes.len() - 100].to_vec(),
        [0, 2, 0],
        &keypair(),
    );
    let (r, changed) = refused_after_send(&truncated, |u| u.verify_image(&good.signature, &board));
    assert_eq!((r, changed), (UpdateRefusal::BadTrailer, false));
    // Older than the running image, without the downgrade flag.
    let older = image(10_000, 3, [0, 0, 9]);
    let (r, changed) = refused_after_send(&older, |u| u.verify_image(&older.signature, &board));
    assert_eq!(
        (r, changed),
        (
            UpdateRefusal::OlderVersion {
                running: RUNNING,
                image: [0, 0, 9]
            },
            false
        )
    );
    // The same version again is a downgrade too.
    let same = image(10_000, 3, RUNNING);
    let (r, _) = refused_after_send(&same, |u| u.verify_image(&same.signature, &board));
    assert!(matches!(r, UpdateRefusal::OlderVersion { .. }));
    // For another board.
    let foreign_board = image_for(10_000, 4, [0, 2, 0], 0, "NUCLEO-F446RE", &keypair());
    let (r, changed) = refused_after_send(&foreign_board, |u| {
        u.verify_image(&foreign_board.signature, &board)
    });
    assert_eq!((r, changed), (UpdateRefusal::WrongBoard, false));
    // A begin whose version is not the trailer's.
    let mut lying = good.clone();
    lying.version = [9, 9, 9];
    let (r, _) = refused_after_send(&lying, |u| u.verify_image(&good.signature, &board));
    assert_eq!(r, UpdateRefusal::BadTrailer);
}

#[test]
fn a_signed_downgrade_passes_and_a_node_without_a_key_refuses_everything() {
    let a = image(9_000, 1, RUNNING);
    let older = downgrade(10_000, 3, [0, 0, 9]);
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    send_all(&mut u, &older, 256);
    assert!(u.verify_image(&older.signature, &board()).is_ok());
    // The same image on a build without a key.
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = fois_firmware::update::FlashUpdater::new(
        part(&flash, DFU_AT, DFU_LEN),
        part(&flash, STATE_AT, STATE_LEN),
        fois_firmware::update::transfer::UpdaterConfig {
            active_len: ACTIVE_LEN,
            running: RUNNING,
            key: fois_firmware::update::UpdateKey::NONE,
        },
    );
    send_all(&mut u, &older, 256);
    assert_eq!(
        u.verify_image(&older.signature, &board()),
        Err(UpdateRefusal::BadSignature)
    );
    assert_eq!(u.commit_image(), Err(UpdateRefusal::NotVerified));
}

#[test]
fn bad_pieces_are_refused_with_their_reason_and_nothing_changes() {
    let a = image(9_000, 1, RUNNING);
    let b = image(10_000, 2, [0, 2, 0]);
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    let max = u.slot_bytes();
    let unchanged = |u: &mut Updater, r: Result<_, UpdateRefusal>, want: UpdateRefusal| {
        let _ = u;
        assert_eq!(r.map(|_: fois_protocol::UpdateStatus| ()), Err(want));
    };
    let before = flash.borrow().bytes().to_vec();
    // Nothing begun.
    let r = u.write_chunk(&chunk(&b, 0, 256));
    unchanged(&mut u, r, UpdateRefusal::NoTransfer);
    let r = u.verify_image(&b.signature, &board());
    unchanged(&mut u, r, UpdateRefusal::NoTransfer);
    assert_eq!(u.commit_image(), Err(UpdateRefusal::NoTransfer));
    // Oversized, and shorter than a trailer.
    let mut big = b.begin();
    big.image_len = max + 1;
    let r = u.begin_transfer(&big);
    unchanged(&mut u, r, UpdateRefusal::BadLength { max_bytes: max });
    let mut short = b.begin();
    short.image_len = TRAILER as u32 - 1;
    let r = u.begin_transfer(&short);
    unchanged(&mut u, r, UpdateRefusal::BadLength { max_bytes: max });
    assert!(
        flash.borrow().bytes() == &before[..],
        "a refused begin wrote"
    );
    // A transfer under way.
    u.begin_transfer(&b.begin()).unwrap();
    u.write_chunk(&chunk(&b, 0, 256)).unwrap();
    let before = flash.borrow().bytes().to_vec();
    // Out of order: ahead, behind.
    let r = u.write_chunk(&chunk(&b, 512, 256));
    unchanged(
        &mut u,
        r,
        UpdateRefusal::OutOfOrder {
            expected_offset: 256,
        },
    );
    let r = u.write_chunk(&chunk(&b, 0, 256));
    unchanged(
        &mut u,
        r,
        UpdateRefusal::OutOfOrder {
            expected_offset: 256,
        },
    );
    // A bad CRC.
    let mut bad = chunk(&b, 256, 256);
    bad.crc32 ^= 1;
    let r = u.write_chunk(&bad);
    unchanged(&mut u, r, UpdateRefusal::ChunkCrc);
    // Verify before every byte is in; commit before verify.
    let r = u.verify_image(&b.signature, &board());
    unchanged(&mut u, r, UpdateRefusal::Incomplete { next_offset: 256 });
    assert_eq!(u.commit_image(), Err(UpdateRefusal::NotVerified));
    assert!(
        flash.borrow().bytes() == &before[..],
        "a refused piece wrote"
    );
    // Past the image's end.
    let mut at = 256;
    while at + 256 < b.bytes.len() {
        at = u.write_chunk(&chunk(&b, at, 256)).unwrap().next_offset as usize;
    }
    let mut longer = b.bytes.clone();
    longer.extend_from_slice(&[0; 256]);
    let over = sign(longer, b.version, &keypair());
    let r = u.write_chunk(&chunk(&over, at, 256));
    unchanged(
        &mut u,
        r,
        UpdateRefusal::OutOfOrder {
            expected_offset: at as u32,
        },
    );
    u.write_chunk(&chunk(&b, at, 256)).unwrap();
    assert!(u.verify_image(&b.signature, &board()).is_ok());
    // An abort ends it: nothing to commit.
    assert_eq!(u.abort_transfer().unwrap().phase, UpdatePhase::Idle);
    assert_eq!(u.commit_image(), Err(UpdateRefusal::NoTransfer));
    drop(u);
    let u = updater(&flash, RUNNING);
    assert_eq!(
        u.status().unwrap().phase,
        UpdatePhase::Idle,
        "the abort is kept"
    );
}

#[test]
fn a_transfer_resumes_after_a_link_drop_and_after_a_reset() {
    let a = image(9_000, 1, RUNNING);
    let b = image(10_000, 2, [0, 2, 0]);
    let flash = board_flash(&a);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    u.begin_transfer(&b.begin()).unwrap();
    let mut at = 0;
    for _ in 0..10 {
        at = u.write_chunk(&chunk(&b, at, 200)).unwrap().next_offset as usize;
    }
    assert_eq!(at, 2_000);
    // The link drops: the same begin resumes where it was.
    let st = u.begin_transfer(&b.begin()).unwrap();
    assert_eq!((st.phase, st.next_offset), (UpdatePhase::Receiving, 2_000));
    // A reset: the record vouches for the whole granules written (7 × 256).
    drop(u);
    run_bootloader(&flash);
    let mut u = updater(&flash, RUNNING);
    let st = u.status().unwrap();
    assert_eq!(
        (st.phase, st.image_len, st.next_offset),
        (UpdatePhase::Receiving, 10_064, 1_792)
    );
    let st = u.begin_transfer(&b.begin()).unwrap();
    assert_eq!(st.next_offset, 1_792);
    let mut at = 1_792;
    while at < b.bytes.len() {
        at = u.write_chunk(&chunk(&b, at, 256)).unwrap().next_offset as usize;
    }
    assert!(u.verify_image(&b.signature, &board()).is_ok());
    // Another image's begin starts afresh.
    let c = image(5_000, 5, [0, 3, 0]);
    let st = u.begin_transfer(&c.begin()).unwrap();
    assert_eq!((st.next_offset, st.image_len), (0, 5_064));
}

#[test]
fn a_chunk_cut_mid_programming_is_not_vouched_for() {
    use fois_firmware::storage::ram_flash::PowerCut;
    let a = image(9_000, 1, RUNNING);
    let b = image(10_000, 2, [0, 2, 0]);
    for cut_bytes in [1u32, 100, 255, 256, 259] {
        let flash = board_flash(&a);
        run_bootloader(&flash);
        let mut u = updater(&flash, RUNNING);
        u.begin_transfer(&b.begin()).unwrap();
        for at in (0..1_024).step_by(256) {
            u.write_chunk(&chunk(&b, at, 256)).unwrap();
        }
        // The fifth chunk (256 bytes, then its 4-byte mark) loses power.
        flash
            .borrow_mut()
            .cut_power(PowerCut::AfterBytes(cut_bytes));
        assert_eq!(
            u.write_chunk(&chunk(&b, 1_024, 256)),
            Err(UpdateRefusal::FlashFailed)
        );
        drop(u);
        run_bootloader(&flash);
        let u = updater(&flash, RUNNING);
        assert_eq!(
            u.status().unwrap().next_offset,
            1_024,
            "cut after {cut_bytes} B"
        );
    }
}
