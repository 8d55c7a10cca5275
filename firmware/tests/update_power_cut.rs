//! A power cut at every erase and program of a whole update — the
//! transfer, the commit, embassy-boot's swap (its `prepare_boot` run on the
//! RAM flash), the trial's confirmation and, when a cut lands in it, the
//! bootloader's revert: after every cut the node boots an image, the old
//! or the new, never neither; the config store is never touched; and the
//! host, resuming, gets the new image confirmed in the end.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod update_common;

use fois_firmware::storage::ram_flash::PowerCut;
use fois_firmware::update::UpdateSlots;
use fois_protocol::{ImageState, UpdatePhase};
use update_common::*;

const OLD: [u8; 3] = [0, 1, 0];
const NEW: [u8; 3] = [0, 2, 0];

fn board() -> [u8; 16] {
    fois_protocol::Hello::board_from_str(BOARD)
}

/// What one scenario went through.
#[derive(Debug, Default)]
struct Outcome {
    boots: u32,
    rollbacks: u32,
}

/// The node's life and the host's persistence: boot (the bootloader),
/// check the image, confirm a trial, then (re)run the update from where the
/// node says it stands, until the new image runs confirmed. Every flash
/// failure is the cut: the node resets.
fn live(flash: &Shared, a: &Image, b: &Image, cut: Option<PowerCut>) -> Outcome {
    if let Some(cut) = cut {
        flash.borrow_mut().cut_power(cut);
    }
    let mut out = Outcome::default();
    for _ in 0..12 {
        run_bootloader(flash);
        out.boots += 1;
        let running = active_image(flash, &[a, b]);
        assert!(running.is_some(), "the node boots neither image ({cut:?})");
        assert!(
            config_untouched(flash),
            "the config store changed ({cut:?})"
        );
        let running = running.unwrap_or(OLD);
        let mut u = updater(flash, running);
        match u.image_state() {
            ImageState::Trial => {
                assert_eq!(running, NEW);
                // The self-test passes: confirm.
                if u.mark_booted().is_err() {
                    continue;
                }
            }
            ImageState::RolledBack { failed } => {
                assert_eq!((running, failed), (OLD, NEW));
                out.rollbacks += 1;
                if u.mark_booted().is_err() {
                    continue;
                }
            }
            ImageState::Confirmed => {}
        }
        if running == NEW {
            return out;
        }
        // The host: begin (or resume), chunks, verify, commit.
        let Ok(st) = u.begin_transfer(&b.begin()) else {
            continue;
        };
        let mut at = st.next_offset as usize;
        let mut failed = false;
        while at < b.bytes.len() {
            match u.write_chunk(&chunk(b, at, 256)) {
                Ok(st) => at = st.next_offset as usize,
                Err(_) => {
                    failed = true;
                    break;
                }
            }
        }
        if failed || u.verify_image(&b.signature, &board()).is_err() {
            continue;
        }
        let _ = u.commit_image();
        // The reset after the commit's answer (or after the cut).
    }
    panic!("the update never finished ({cut:?})");
}

fn fresh() -> (Shared, Image, Image) {
    let a = image(9_000, 1, OLD);
    let b = image(10_000, 2, NEW);
    (board_flash(&a), a, b)
}

#[test]
fn a_cut_at_every_flash_operation_leaves_a_bootable_node() {
    // The uncut run: how many operations and bytes the whole update takes.
    let (flash, a, b) = fresh();
    let out = live(&flash, &a, &b, None);
    assert_eq!((out.boots, out.rollbacks), (2, 0));
    let total = flash.borrow().counters();
    // The figures firmware/README.md states.
    assert_eq!((total.ops, total.bytes), (140, 100_452), "{total:?}");
    eprintln!(
        "whole update: {} flash operations, {} bytes programmed or erased",
        total.ops, total.bytes
    );
    let mut rolled_back = 0;
    // Every operation: the (n+1)-th never starts.
    for n in 0..total.ops {
        let (flash, a, b) = fresh();
        let out = live(&flash, &a, &b, Some(PowerCut::AfterOps(n)));
        rolled_back += out.rollbacks;
        let last = updater(&flash, NEW);
        assert_eq!(last.image_state(), ImageState::Confirmed);
        assert_eq!(last.status().unwrap().phase, UpdatePhase::Idle);
    }
    // A cut in the trial's confirmation makes the bootloader roll back; the
    // host then updates again.
    assert!(rolled_back >= 1, "no cut rolled back");
    eprintln!(
        "{rolled_back} of {} operation cuts rolled back first",
        total.ops
    );
    // Mid-operation: a cut every 509 bytes of work (a partly programmed
    // chunk, mark, header or state word; a partly erased page).
    let mut cuts = 0;
    for k in (1..total.bytes).step_by(509) {
        let (flash, a, b) = fresh();
        live(&flash, &a, &b, Some(PowerCut::AfterBytes(k)));
        cuts += 1;
    }
    assert_eq!(cuts, 198);
}
