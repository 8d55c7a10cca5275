//! The node's record on NOR flash (`FlashStore` over a `RamFlash`): first
//! boot, damage, power cuts at every operation and byte of saves, wear.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::Storage;
use fois_firmware::storage::flash_store::FlashStore;
use fois_firmware::storage::ram_flash::{PowerCut, RamFlash};
use fois_firmware::storage::record::{self, MAX_RECORD, Record};
use fois_protocol::*;

/// The board's geometry: two 128 KiB sectors (F446 sectors 6 and 7).
const SECTOR: usize = fois_firmware::storage::flash_store::BOARD_SECTOR_BYTES;
type BoardFlash = RamFlash<Vec<u8>, SECTOR, 2>;
/// Small pages: a save changes page every few records (erase + move).
const SMALL: usize = 256;
type SmallFlash = RamFlash<Vec<u8>, SMALL, 2>;

fn board_flash() -> BoardFlash {
    RamFlash::new(vec![0xFF; 2 * SECTOR])
}

fn small_flash() -> SmallFlash {
    RamFlash::new(vec![0xFF; 2 * SMALL])
}

fn store<const P: usize>(flash: RamFlash<Vec<u8>, P, 2>) -> FlashStore<RamFlash<Vec<u8>, P, 2>> {
    FlashStore::new(flash, 0..(2 * P) as u32).expect("two pages")
}

/// Boot a node on this flash; its config, baseline and whether
/// CONFIG_DEFAULTED is raised on the first frame.
fn boot<const P: usize>(
    flash: RamFlash<Vec<u8>, P, 2>,
) -> (Config, Option<Baseline>, bool, RamFlash<Vec<u8>, P, 2>) {
    let (mut node, w) = node_on(store(flash));
    let fs = step(&mut node, &w);
    let defaulted = fs.iter().any(|f| {
        f.msg
            .measurement()
            .is_some_and(|(m, _)| m.flags & flags::CONFIG_DEFAULTED != 0)
    });
    let (config, baseline) = (node.config().clone(), node.baseline());
    let flash = node.into_parts().5.into_flash();
    (config, baseline, defaulted, flash)
}

/// The k-th record of a sequence (config and baseline both change).
fn record(k: u32) -> Record {
    Record {
        config: Config {
            onset_rise_na: 1_000 + k * 10,
            clear_frames: 300 + (k % 7) as u16,
            ..Config::default()
        },
        baseline: (!k.is_multiple_of(3)).then_some(Baseline {
            i1_na: -(k as i32),
            i2_na: k as i32 * 3,
        }),
        gain: None,
        gain_calibration: None,
        link: fois_protocol::LinkSettings::default(),
    }
}

fn encoded(r: &Record) -> Vec<u8> {
    let mut buf = [0u8; MAX_RECORD];
    let n = record::encode(r, &mut buf);
    buf[..n].to_vec()
}

/// Have a node save `r` (SetConfig, and a calibration when the record has
/// a baseline, then the coalesced save). Returns the flash and the record
/// the node saved (the calibrated baseline is what the node measured).
fn save_through_node<const P: usize>(
    flash: RamFlash<Vec<u8>, P, 2>,
    r: &Record,
) -> (RamFlash<Vec<u8>, P, 2>, Record) {
    let (mut node, w) = node_on(store(flash));
    // The baseline comes from a calibration on a face reading about it.
    if let Some(b) = r.baseline {
        w.set(|s| s.signal_na = [f64::from(b.i1_na), f64::from(b.i2_na)]);
    }
    command(&mut node, &w, 1, Command::SetConfigV3(r.config.clone()));
    if r.baseline.is_some() {
        command(&mut node, &w, 2, Command::CalibrateDark);
    }
    let saved = Record {
        config: node.config().clone(),
        baseline: node.baseline(),
        gain: node.gain_kept(),
        gain_calibration: None,
        link: fois_protocol::LinkSettings::default(),
    };
    // Straight to the due time: one poll, one save.
    if let Some(due) = node.save_due_ms() {
        node.poll_storage(due);
    }
    (node.into_parts().5.into_flash(), saved)
}

#[test]
fn erased_flash_is_a_first_boot_defaults_without_fault() {
    let (c, b, defaulted, flash) = boot(board_flash());
    assert_eq!(c, Config::default());
    assert_eq!(b, None);
    assert!(!defaulted, "erased flash is a first boot, not a fault");
    assert_eq!(flash.counters().ops, 0, "booting writes nothing");
}

#[test]
fn a_saved_record_survives_reboots_and_the_newest_wins() {
    let mut flash = board_flash();
    let mut st = store(flash);
    for k in 1..=5 {
        st.write(&encoded(&record(k))).unwrap();
    }
    assert_eq!(st.saves(), 5);
    flash = st.into_flash();
    let mut st = store(flash);
    let mut buf = [0u8; MAX_RECORD];
    let n = st.read(&mut buf).unwrap();
    assert_eq!(record::decode(&buf[..n]), Ok(record(5)));
    // Through the node: config and baseline back, no fault.
    let (c, b, defaulted, _) = boot(st.into_flash());
    assert_eq!((c, b), (record(5).config, record(5).baseline));
    assert!(!defaulted);
}

/// Anything in the range that is not a readable record: defaults WITH the
/// CONFIG_DEFAULTED flag, never silently.
#[test]
fn a_damaged_store_is_defaults_with_the_flag() {
    // (1) Garbage over both sectors (e.g. another program's data), seeded.
    let mut flash = board_flash();
    let mut x: u32 = 0x1234_5678;
    for b in flash.bytes_mut() {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        *b = x as u8;
    }
    let (c, b, defaulted, flash) = boot(flash);
    assert_eq!((c, b), (Config::default(), None));
    assert!(defaulted, "garbage must raise CONFIG_DEFAULTED");
    // The store repaired itself: the next save is read back.
    let (flash, _) = save_through_node(flash, &record(1));
    let (c, _, defaulted, _) = boot(flash);
    assert_eq!(c, record(1).config);
    assert!(!defaulted);

    // (2) The single stored record's bytes damaged (a bit flipped in each
    // byte of the item in turn): the item's CRC fails, nothing readable.
    let mut good = store(board_flash());
    good.write(&encoded(&record(2))).unwrap();
    let good = good.into_flash();
    let used: Vec<usize> = (0..2 * SECTOR)
        .filter(|&i| good.bytes()[i] != 0xFF)
        .collect();
    assert!(used.len() > 20, "{}", used.len());
    for &i in &used {
        let mut f = good.clone();
        f.bytes_mut()[i] ^= 0x01;
        let (c, _, defaulted, _) = boot(f);
        assert!(
            c == record(2).config && !defaulted || c == Config::default() && defaulted,
            "byte {i}: config {c:?}, defaulted {defaulted}"
        );
    }

    // (3) An intact item whose record is of another layout version or whose
    // config breaks the rule.
    for bytes in [
        {
            let mut v = encoded(&record(3));
            v[4] = 0; // version 0 (CRC of the record now fails too)
            v
        },
        {
            let bad = Record {
                config: Config {
                    clear_rise_na: 5_000,
                    ..Config::default()
                },
                baseline: None,
                gain: None,
                gain_calibration: None,
                link: fois_protocol::LinkSettings::default(),
            };
            encoded(&bad)
        },
    ] {
        let mut st = store(board_flash());
        st.write(&bytes).unwrap();
        let (c, _, defaulted, _) = boot(st.into_flash());
        assert_eq!(c, Config::default());
        assert!(defaulted);
    }
}

/// After a cut and a reboot the node holds the old or the new record; it
/// never holds defaults without the flag, and the next save works.
fn check_cut<const P: usize>(
    before: &RamFlash<Vec<u8>, P, 2>,
    old: Option<&Record>,
    new: &Record,
    cut: PowerCut,
) -> bool {
    let mut f = before.clone();
    f.cut_power(cut);
    let (mut f, _) = save_through_node(f, new);
    let was_cut = !f.is_powered();
    f.power_on();
    let (c, b, defaulted, f) = boot(f);
    let got = (c.clone(), b);
    let is_new = got == (new.config.clone(), new.baseline);
    let is_old = match old {
        Some(o) => got == (o.config.clone(), o.baseline) && !defaulted,
        // Nothing stored before: defaults, and after a cut mid-way through
        // the very first save the flag says the setting was lost.
        None => got == (Config::default(), None),
    };
    assert!(
        is_new && !defaulted || is_old,
        "{cut:?}: got {got:?} defaulted={defaulted}, old {old:?}, new {new:?}"
    );
    assert!(!was_cut || !is_new || !defaulted);
    // The store is usable after the cut: one more save reads back.
    let (f, probe) = save_through_node(f, &record(998));
    let (c, b, defaulted, _) = boot(f);
    assert_eq!(
        (c, b, defaulted),
        (probe.config, probe.baseline, false),
        "{cut:?}: after recovery"
    );
    was_cut
}

/// Sweep one save: every op count and every byte count up to what the save
/// uses uncut. Returns the flash after the uncut save, the record saved and
/// (ops, bytes, erases) of the save.
fn sweep_save<const P: usize>(
    before: &RamFlash<Vec<u8>, P, 2>,
    old: Option<&Record>,
    wanted: &Record,
) -> (RamFlash<Vec<u8>, P, 2>, Record, (u32, u32, u32)) {
    let c0 = before.counters();
    let (after, new) = save_through_node(before.clone(), wanted);
    let new = &new;
    let c1 = after.counters();
    let (ops, bytes, erases) = (c1.ops - c0.ops, c1.bytes - c0.bytes, c1.erases - c0.erases);
    assert!(ops > 0, "the save wrote nothing");
    for n in 0..ops {
        assert!(
            check_cut(before, old, new, PowerCut::AfterOps(n)),
            "ops {n}"
        );
    }
    for n in 0..bytes {
        assert!(
            check_cut(before, old, new, PowerCut::AfterBytes(n)),
            "bytes {n}"
        );
    }
    // At the full count nothing is cut: the new record.
    assert!(!check_cut(before, old, new, PowerCut::AfterBytes(bytes)));
    (after, new.clone(), (ops, bytes, erases))
}

/// An overwrite after the store was read (its cache filled) lands where the
/// next boot finds it: sequential-storage's `erase_all` keeps its cache, and
/// a record stored through the stale cache (without its page's marker) was
/// found by the read-back but not after a reboot.
#[test]
fn an_overwrite_after_a_read_survives_the_reboot() {
    for k in 1..=3 {
        let mut st = store(board_flash());
        for j in 0..k {
            st.write(&encoded(&record(j + 1))).unwrap();
        }
        let mut buf = [0u8; MAX_RECORD];
        assert!(st.read(&mut buf).unwrap() > 0);
        let newest = encoded(&record(40 + k));
        st.overwrite(&newest).unwrap();
        let mut again = store(st.into_flash());
        let n = again.read(&mut buf).unwrap();
        assert_eq!(&buf[..n], &newest[..], "after {k} records");
    }
}

#[test]
fn power_cut_at_every_operation_and_byte_of_a_save_on_the_board_geometry() {
    let mut flash = board_flash();
    let mut old = None;
    let mut total = (0, 0);
    for k in 1..=3 {
        let (after, new, (ops, bytes, erases)) = sweep_save(&flash, old.as_ref(), &record(k));
        assert_eq!(erases, 0, "no erase while the sector has room");
        total = (total.0 + ops, total.1 + bytes);
        flash = after;
        old = Some(new);
    }
    // Tens of cut points per save (the item and its page marker).
    assert!(total.1 > 3 * 40, "{total:?}");
}

#[test]
fn power_cut_at_every_operation_and_byte_of_saves_across_page_changes() {
    let mut flash = small_flash();
    let mut old = None;
    let mut erasing_saves = 0;
    let mut cut_points = 0;
    for k in 1..=20 {
        let (after, new, (ops, bytes, erases)) = sweep_save(&flash, old.as_ref(), &record(k));
        if erases > 0 {
            erasing_saves += 1;
        }
        cut_points += ops + bytes;
        flash = after;
        old = Some(new);
    }
    // The sequence went round the two pages several times: saves that
    // erased a page and moved the record were swept too.
    assert!(erasing_saves >= 3, "{erasing_saves}");
    assert!(
        flash.page_erases().iter().all(|&e| e >= 2),
        "{:?}",
        flash.page_erases()
    );
    println!(
        "small pages: {cut_points} cut points over 20 saves, {erasing_saves} saves erased a page"
    );
}

/// Hourly dark calibration for ten years on the board's geometry (two
/// 16 KiB sectors): how often is each sector erased? And the worst a host
/// can force — a change every second, saved at the node's shortest
/// interval (`node::saving::SAVE_MIN_INTERVAL_MS`) — against the F446's
/// 10 000 cycles (datasheet N_END). (`cargo test -p fois-firmware --test
/// storage -- --nocapture wear` prints the figures.)
#[test]
fn wear_of_hourly_saves_for_ten_years() {
    const SAVES: u32 = 24 * 365 * 10 + 2 * 24; // 87 648 (two leap days)
    const TEN_YEARS_S: u64 = (365 * 10 + 2) * 86_400;
    const ENDURANCE_CYCLES: u64 = 10_000;
    let mut st = store(board_flash());
    for k in 0..SAVES {
        st.write(&encoded(&record(k % 1_000 + 1))).unwrap();
    }
    let f = st.into_flash();
    let per_sector = f.page_erases();
    let per_erase = u64::from(SAVES / f.counters().erases.max(1));
    // Forced: one save per shortest interval for ten years.
    let interval_s = fois_firmware::node::saving::SAVE_MIN_INTERVAL_MS / 1_000;
    let forced = TEN_YEARS_S / interval_s / per_erase / 2;
    // The shortest interval that keeps the forced case within the endurance.
    let safe_interval_s = TEN_YEARS_S.div_ceil(ENDURANCE_CYCLES * 2 * per_erase);
    println!(
        "{SAVES} saves: sector erases {per_sector:?}, {per_erase} records per erase; \
         forced (a save every {interval_s} s): {forced} erases per sector; \
         within {ENDURANCE_CYCLES} cycles from a save every {safe_interval_s} s"
    );
    // sequential-storage uses the pages in turn: even wear.
    assert!(per_sector[0].abs_diff(per_sector[1]) <= 1);
    // Hourly saves: far below the endurance.
    assert!(
        per_sector.iter().all(|&e| (100..1_000).contains(&e)),
        "{per_sector:?}"
    );
    // A 16 KiB page holds a few hundred records.
    assert!((200..400).contains(&per_erase), "{per_erase}");
    // The forced case needs a save interval of about a minute, and the
    // node's shortest interval keeps it within the endurance.
    assert!((30..=60).contains(&safe_interval_s), "{safe_interval_s}");
    assert!(forced <= ENDURANCE_CYCLES, "{forced}");
}
