//! The store's move from the layout before the bootloader (two 128 KiB
//! pages, F446 sectors 6–7) to sectors 2–3 (two 16 KiB pages):
//! `storage::migrate` on `RamFlash` in both geometries, with golden records
//! of every record layout (1–4) as the firmware of that layout wrote them,
//! and a power cut at every operation (and at bytes through the writes) of
//! the move.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::Storage;
use fois_firmware::storage::flash_store::{BOARD_SECTOR_BYTES, FlashStore, OLD_BOARD_SECTOR_BYTES};
use fois_firmware::storage::migrate::{Migration, migrate};
use fois_firmware::storage::ram_flash::{PowerCut, RamFlash};
use fois_firmware::storage::record::{self, MAX_RECORD};
use fois_protocol::*;

/// The new store: two 16 KiB pages (sectors 2 and 3).
const NEW: usize = BOARD_SECTOR_BYTES;
/// The old store: two 128 KiB pages (sectors 6 and 7, now the DFU slot).
const OLD: usize = OLD_BOARD_SECTOR_BYTES;
type NewFlash = RamFlash<Vec<u8>, NEW, 2>;
type OldFlash = RamFlash<Vec<u8>, OLD, 2>;
const OLD_RANGE: core::ops::Range<u32> = 0..(2 * OLD) as u32;

/// Layout 1 (protocol 1–2 firmware): the version-1 config (onset 1 500 nA)
/// and a baseline (310, −7) nA (the same bytes as `record.rs`'s test).
const GOLDEN_V1: [u8; 35] = [
    0x46, 0x4f, 0x49, 0x53, 0x01, 0x00, 0x17, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90, 0x4e,
    0xdc, 0x0b, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0x01, 0xec, 0x04, 0x0d, 0x3b,
    0xf4, 0xd5, 0xa0,
];
/// Layout 2: the version-3 config (onset 1 500 nA, gain tempco −4 000
/// ppm/K) and the baseline (310, −7) nA.
const GOLDEN_V2: [u8; 43] = [
    0x46, 0x4f, 0x49, 0x53, 0x02, 0x00, 0x1f, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90, 0x4e,
    0xdc, 0x0b, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0xbf, 0x3e, 0xa0, 0x1f, 0xd8,
    0x04, 0xdc, 0x0b, 0x01, 0xec, 0x04, 0x0d, 0x79, 0x6b, 0x3d, 0x21,
];
/// Layout 3: the default config, the baseline (310, −7) nA and the learned
/// gain 1 050 000 ± 20 000 ppm.
const GOLDEN_V3: [u8; 50] = [
    0x46, 0x4f, 0x49, 0x53, 0x03, 0x00, 0x26, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90, 0x4e,
    0xe8, 0x07, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0x00, 0xa0, 0x1f, 0xd8, 0x04,
    0xdc, 0x0b, 0x01, 0xec, 0x04, 0x0d, 0x01, 0x90, 0x8b, 0x40, 0xa0, 0x9c, 0x01, 0x00, 0x96, 0x38,
    0x2b, 0x2f,
];
/// Layout 4 (today's): onset 1 234 nA, baseline (−40, 12) nA, learned gain
/// 870 000 ± 26 100 ppm, calibrated gain 850 000 ± 17 000 ppm, Modbus RTU
/// at address 17 with 8N1.
const GOLDEN_V4: [u8; 58] = [
    0x46, 0x4f, 0x49, 0x53, 0x04, 0x00, 0x2e, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90, 0x4e,
    0xd2, 0x09, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0x00, 0xa0, 0x1f, 0xd8, 0x04,
    0xdc, 0x0b, 0x01, 0x4f, 0x18, 0x01, 0xf0, 0x8c, 0x35, 0xf4, 0xcb, 0x01, 0x01, 0xd0, 0xf0, 0x33,
    0xe8, 0x84, 0x01, 0x01, 0x11, 0x02, 0x9e, 0xbc, 0xfe, 0xac,
];

/// What each golden record must come back as after the move.
struct Expect {
    layout: u16,
    onset_rise_na: u32,
    baseline: Option<Baseline>,
    gain: Option<GainEstimate>,
    link: LinkSettings,
}

fn goldens() -> Vec<(&'static [u8], Expect)> {
    let b = Some(Baseline {
        i1_na: 310,
        i2_na: -7,
    });
    vec![
        (
            &GOLDEN_V1[..],
            Expect {
                layout: 1,
                onset_rise_na: 1_500,
                baseline: b,
                gain: None,
                link: LinkSettings::default(),
            },
        ),
        (
            &GOLDEN_V2[..],
            Expect {
                layout: 2,
                onset_rise_na: 1_500,
                baseline: b,
                gain: None,
                link: LinkSettings::default(),
            },
        ),
        (
            &GOLDEN_V3[..],
            Expect {
                layout: 3,
                onset_rise_na: Config::default().onset_rise_na,
                baseline: b,
                gain: Some(GainEstimate {
                    gain_ppm: 1_050_000,
                    sigma_ppm: 20_000,
                }),
                link: LinkSettings::default(),
            },
        ),
        (
            &GOLDEN_V4[..],
            Expect {
                layout: 4,
                onset_rise_na: 1_234,
                baseline: Some(Baseline {
                    i1_na: -40,
                    i2_na: 12,
                }),
                gain: Some(GainEstimate {
                    gain_ppm: 870_000,
                    sigma_ppm: 26_100,
                }),
                link: v4_link(),
            },
        ),
    ]
}

fn v4_link() -> LinkSettings {
    LinkSettings {
        protocol: LinkProtocol::ModbusRtu,
        modbus_address: 17,
        parity: Parity::None8N1,
    }
}

/// An older record than the golden one (the store keeps the newest).
fn older_record() -> Vec<u8> {
    let r = record::Record {
        config: Config {
            onset_rise_na: 2_222,
            ..Config::default()
        },
        baseline: None,
        gain: None,
        gain_calibration: None,
        link: LinkSettings::default(),
    };
    let mut buf = [0u8; MAX_RECORD];
    let n = record::encode(&r, &mut buf);
    buf[..n].to_vec()
}

fn new_flash() -> NewFlash {
    RamFlash::new(vec![0xFF; 2 * NEW])
}

/// The old store as the firmware of that layout left it: a few older
/// records, then `golden` as the newest, written by sequential-storage (the
/// same pinned version) on the old geometry.
fn old_flash_with(golden: &[u8], older: usize) -> OldFlash {
    let mut st = FlashStore::new(RamFlash::new(vec![0xFF; 2 * OLD]), OLD_RANGE).unwrap();
    for _ in 0..older {
        st.write(&older_record()).unwrap();
    }
    st.write(golden).unwrap();
    st.into_flash()
}

fn new_store(flash: NewFlash) -> FlashStore<NewFlash> {
    FlashStore::new(flash, 0..(2 * NEW) as u32).unwrap()
}

/// The record the new store holds (empty: none).
fn stored(flash: NewFlash) -> (Vec<u8>, NewFlash) {
    let mut st = new_store(flash);
    let mut buf = [0u8; MAX_RECORD];
    let n = st.read(&mut buf).unwrap_or(0);
    (buf[..n].to_vec(), st.into_flash())
}

fn old_holds(flash: &mut OldFlash, golden: &[u8]) -> bool {
    let copy = RamFlash::<Vec<u8>, OLD, 2>::new(flash.bytes().to_vec());
    let mut st = FlashStore::new(copy, OLD_RANGE).unwrap();
    let mut buf = [0u8; MAX_RECORD];
    st.read(&mut buf).is_ok_and(|n| &buf[..n] == golden)
}

/// The V4 golden's bytes are what today's encoder writes for that record.
#[test]
fn the_layout_4_golden_is_todays_encoding() {
    let r = record::Record {
        config: Config {
            onset_rise_na: 1_234,
            ..Config::default()
        },
        baseline: Some(Baseline {
            i1_na: -40,
            i2_na: 12,
        }),
        gain: Some(GainEstimate {
            gain_ppm: 870_000,
            sigma_ppm: 26_100,
        }),
        gain_calibration: Some(GainEstimate {
            gain_ppm: 850_000,
            sigma_ppm: 17_000,
        }),
        link: v4_link(),
    };
    let mut buf = [0u8; MAX_RECORD];
    let n = record::encode(&r, &mut buf);
    assert_eq!(&buf[..n], &GOLDEN_V4[..], "{:#04x?}", &buf[..n]);
}

/// Every layout moves: the new store then holds the golden bytes, the old
/// region is erased, a node booted on the new store has the config, the
/// baseline, the learned gain and the link settings, and no fault.
#[test]
fn every_record_layout_moves_and_the_node_keeps_it() {
    for (golden, want) in goldens() {
        let mut old = old_flash_with(golden, 3);
        let mut new = new_store(new_flash());
        let done = migrate(&mut new, &mut old, OLD_RANGE).unwrap();
        assert_eq!(
            done,
            Migration::Moved {
                layout: want.layout,
                old_erased: true
            }
        );
        assert!(old.bytes().iter().all(|&b| b == 0xFF), "old region erased");
        let (bytes, flash) = stored(new.into_flash());
        assert_eq!(bytes, golden, "layout {}", want.layout);
        // Once moved, never again: the old region is not even read.
        let mut new = new_store(flash);
        let reads_before = old.counters();
        assert_eq!(
            migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
            Migration::NotNeeded
        );
        assert_eq!(old.counters(), reads_before);
        // The node boots on it with everything kept.
        let (mut node, w) = node_on(new);
        let fs = step(&mut node, &w);
        let defaulted = fs.iter().any(|f| {
            f.msg
                .measurement()
                .is_some_and(|(m, _)| m.flags & flags::CONFIG_DEFAULTED != 0)
        });
        assert!(!defaulted, "layout {}", want.layout);
        assert_eq!(node.config().onset_rise_na, want.onset_rise_na);
        assert_eq!(node.baseline(), want.baseline);
        assert_eq!(node.gain_kept(), want.gain, "layout {}", want.layout);
        assert_eq!(node.link_settings(), want.link);
    }
}

/// A store that changed pages on the old geometry (thousands of saves):
/// the newest record is the one moved.
#[test]
fn the_newest_record_moves_after_old_page_changes() {
    let mut st = FlashStore::new(
        RamFlash::<Vec<u8>, OLD, 2>::new(vec![0xFF; 2 * OLD]),
        OLD_RANGE,
    )
    .unwrap();
    let mut k = 0;
    while st.flash_mut().counters().erases < 3 {
        let r = record::Record {
            config: Config {
                onset_rise_na: 1_000 + k % 500,
                ..Config::default()
            },
            baseline: None,
            gain: None,
            gain_calibration: None,
            link: LinkSettings::default(),
        };
        let mut buf = [0u8; MAX_RECORD];
        let n = record::encode(&r, &mut buf);
        st.write(&buf[..n]).unwrap();
        k += 1;
    }
    st.write(&GOLDEN_V3).unwrap();
    let mut old = st.into_flash();
    let mut new = new_store(new_flash());
    assert!(matches!(
        migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
        Migration::Moved { layout: 3, .. }
    ));
    assert_eq!(stored(new.into_flash()).0, GOLDEN_V3);
}

/// Nothing to move: an erased old region, an update's image in the DFU
/// slot, a corrupt newest record; the new store stays empty and the old
/// region is not changed (not even by sequential-storage's repair).
#[test]
fn nothing_moves_from_an_empty_region_an_image_or_a_bad_record() {
    // Erased.
    let mut old: OldFlash = RamFlash::new(vec![0xFF; 2 * OLD]);
    let mut new = new_store(new_flash());
    assert_eq!(
        migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
        Migration::NothingToMove
    );
    // An image being downloaded (pseudo-random bytes in the first page).
    let mut image = vec![0xFF; 2 * OLD];
    let mut x: u32 = 0x1234_5678;
    for b in image.iter_mut().take(90 * 1024) {
        x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *b = (x >> 24) as u8;
    }
    let mut old: OldFlash = RamFlash::new(image.clone());
    assert_eq!(
        migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
        Migration::NothingToMove
    );
    assert_eq!(old.bytes(), &image[..], "the image is untouched");
    assert_eq!(old.counters().ops, 0, "no erase or write in the DFU slot");
    // A newest record that fails its CRC (an intact sequential-storage item).
    let mut bad = GOLDEN_V3;
    bad[20] ^= 0x01;
    let mut old = old_flash_with(&bad, 0);
    assert_eq!(
        migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
        Migration::NothingToMove
    );
    assert!(old_holds(&mut old, &bad));
    assert!(stored(new.into_flash()).0.is_empty());
}

/// A new store with a valid record wins: the old one is not read.
#[test]
fn a_valid_new_record_is_kept() {
    let mut old = old_flash_with(&GOLDEN_V2, 0);
    let mut new = new_store(new_flash());
    new.write(&GOLDEN_V4).unwrap();
    let before = old.counters();
    assert_eq!(
        migrate(&mut new, &mut old, OLD_RANGE).unwrap(),
        Migration::NotNeeded
    );
    assert_eq!(old.counters(), before);
    assert_eq!(stored(new.into_flash()).0, GOLDEN_V4);
    assert!(old_holds(&mut old, &GOLDEN_V2));
}

/// Run the move with the power cut at `cut_new` in the new store's flash
/// (ops or bytes) or, once that finished, after `cut_old` operations in the
/// old region's; then check: the old record is intact unless the new one is
/// complete; a reboot's move ends with the golden record in the new store.
/// Returns whether the cut hit.
fn cut_and_reboot(golden: &[u8], cut_new: Option<PowerCut>, cut_old: Option<u32>) -> bool {
    let mut old = old_flash_with(golden, 2);
    let mut new_raw = new_flash();
    if let Some(c) = cut_new {
        new_raw.cut_power(c);
    }
    if let Some(n) = cut_old {
        old.cut_power(PowerCut::AfterOps(n));
    }
    let mut new = new_store(new_raw);
    let first = migrate(&mut new, &mut old, OLD_RANGE);
    let mut new_raw = new.into_flash();
    let hit = !new_raw.is_powered() || !old.is_powered();
    new_raw.power_on();
    old.power_on();
    let (bytes, new_raw) = stored(new_raw);
    let new_complete = bytes == golden;
    assert!(
        new_complete || old_holds(&mut old, golden),
        "cut {cut_new:?}/{cut_old:?}: neither the new nor the old record ({first:?})"
    );
    // The reboot.
    let mut new = new_store(new_raw);
    let second = migrate(&mut new, &mut old, OLD_RANGE).unwrap();
    if new_complete {
        assert_eq!(second, Migration::NotNeeded);
    }
    assert_eq!(
        stored(new.into_flash()).0,
        golden,
        "cut {cut_new:?}/{cut_old:?}"
    );
    hit
}

#[test]
fn a_power_cut_at_every_operation_of_the_move_loses_nothing() {
    for (golden, want) in goldens() {
        // The move's operations in the new store: count them on a clean run.
        let mut probe = new_store(new_flash());
        let mut old = old_flash_with(golden, 2);
        migrate(&mut probe, &mut old, OLD_RANGE).unwrap();
        let new_ops = probe.flash_mut().counters().ops;
        let new_bytes = probe.flash_mut().counters().bytes;
        let old_ops = old.counters().ops - old_flash_with(golden, 2).counters().ops;
        assert!(new_ops >= 3, "erase both pages, write the item: {new_ops}");
        assert_eq!(old_ops, 2, "the old region's two page erases");
        let mut hits = 0;
        for n in 0..new_ops {
            hits += u32::from(cut_and_reboot(golden, Some(PowerCut::AfterOps(n)), None));
        }
        for n in 0..old_ops {
            hits += u32::from(cut_and_reboot(golden, None, Some(n)));
        }
        assert_eq!(hits, new_ops + old_ops, "layout {}", want.layout);
        // Inside the operations: through the erases in steps, through the
        // record's bytes one by one.
        let erase_bytes = 2 * NEW as u32;
        let mut at = 0;
        while at < new_bytes {
            assert!(cut_and_reboot(golden, Some(PowerCut::AfterBytes(at)), None));
            at += if at < erase_bytes { 4_099 } else { 1 };
        }
    }
}
