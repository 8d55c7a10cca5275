//! The boot and fault hardening the board relies on, on the simulated
//! board: a panic reset reported once, the store skipped after panic resets
//! in a row, the brown-out fault, the rule's state resumed after a reset
//! (not after a power-on), saves that wait for a healthy supply.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::MemStorage;
use fois_firmware::platform::boot::{self, RuleSnapshot, SkippableStorage};
use fois_firmware::sim_board;
use fois_firmware::storage::Storage;
use fois_protocol::*;

fn events(fs: &[DeviceFrame]) -> Vec<EventKind> {
    fs.iter()
        .filter_map(|f| match &f.msg {
            DeviceMsg::Event(e) => Some(e.kind),
            _ => None,
        })
        .collect()
}

fn flags_of(fs: &[DeviceFrame]) -> u16 {
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::MeasurementV5(m) => Some(m.measurement.flags),
            _ => None,
        })
        .expect("a measurement")
}

/// A record holding a non-default config.
fn stored_config() -> (MemStorage, Config) {
    let (mut node, w) = node();
    let c = Config {
        onset_frames: 12,
        ..Config::default()
    };
    command(&mut node, &w, 1, Command::SetConfigV3(c.clone()));
    run_until_saved(&mut node, &w);
    (node.into_parts().5, c)
}

#[test]
fn a_panic_reset_is_reported_once_and_the_third_in_a_row_skips_the_store() {
    let (storage, stored) = stored_config();
    // The panic handler recorded three panics at line 412, resetting each time.
    let mut words = [0u32; boot::PANIC_WORDS];
    let mut storage = Some(storage);
    for n in 1..=3u8 {
        words = boot::record_panic(words, 412);
        let plan = boot::plan_boot(words, false);
        words = plan.words;
        let w = World::default();
        let skip = plan.skip_store;
        let store = SkippableStorage(if skip { None } else { storage.take() });
        let mut node = sim_board::sim_node(w.clone(), store, "sim");
        node.set_boot_faults(false, skip);
        if let Some((line, resets)) = plan.panic_reset {
            node.report_panic_reset(line, resets);
        }
        let mut bytes = Vec::new();
        w.run_frame(&mut node, &mut |b| bytes.extend_from_slice(b));
        let fs = frames(&bytes);
        let panic = EventKind::PanicReset {
            line: 412,
            resets_in_row: n,
        };
        if skip {
            // Defaults, not the stored config; STORE_SKIPPED raised.
            assert_eq!(node.config(), &Config::default());
            assert_ne!(flags_of(&fs) & flags::STORE_SKIPPED, 0);
            assert_eq!(
                events(&fs),
                [EventKind::FaultRaised(flags::STORE_SKIPPED), panic]
            );
            // Nothing is saved: a calibration "saves" into nothing, without
            // a storage fault; the real store stays untouched (below).
            command(&mut node, &w, 2, Command::CalibrateDark);
            let fs = run_until_saved(&mut node, &w);
            assert!(fs.iter().all(|f| !matches!(
                &f.msg,
                DeviceMsg::MeasurementV5(m) if m.measurement.flags & flags::STORAGE_FAILED != 0
            )));
        } else {
            assert_eq!(node.config(), &stored);
            assert_eq!(flags_of(&fs) & flags::STORE_SKIPPED, 0);
            assert_eq!(events(&fs), [panic]);
            storage = node.into_parts().5.0;
            continue;
        }
        // Reported once.
        let mut bytes = Vec::new();
        w.run_frame(&mut node, &mut |b| bytes.extend_from_slice(b));
        assert_eq!(events(&frames(&bytes)), []);
    }
    // The real store was never written while skipped.
    let kept = storage.expect("the store was handed back").writes;
    assert_eq!(kept, 1, "only the original save");
}

#[test]
fn a_brown_out_level_that_is_not_set_is_a_fault() {
    let (mut node, w) = node();
    node.set_boot_faults(true, false);
    let fs = step(&mut node, &w);
    assert_ne!(flags_of(&fs) & flags::BOR_NOT_SET, 0);
    assert_eq!(events(&fs), [EventKind::FaultRaised(flags::BOR_NOT_SET)]);
    assert_eq!(events(&step(&mut node, &w)), []);
}

/// A node iced (and acknowledged) by the scene, and the backup words of
/// its rule after that.
fn iced_node() -> (SimNode, World, [u32; boot::RULE_WORDS]) {
    let (mut node, w) = node();
    w.set(|s| {
        s.signal_na = [5_000.0, 1_500.0];
        s.temp_c = -8.0;
    });
    for _ in 0..node.config().onset_frames {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Ice);
    command(&mut node, &w, 1, Command::AckAlarm);
    let words = node.rule_snapshot().encode();
    (node, w, words)
}

#[test]
fn the_alarm_holds_across_a_watchdog_reset_and_not_across_a_power_on() {
    let (_, _, words) = iced_node();
    // A watchdog reset: the outputs are low (GPIO reset state: floating
    // inputs, the board's pull-down reads low) until the new node resumes.
    let w = World::default();
    w.set(|s| {
        s.signal_na = [5_000.0, 1_500.0];
        s.temp_c = -8.0;
    });
    let mut node = sim_board::sim_node(w.clone(), MemStorage::new(), "sim");
    assert!(!w.alarm.get());
    node.resume_rule(RuleSnapshot::resume(words, false));
    // Alarm and LD2 at once, before any frame; the ack kept; no new onset.
    assert!(w.alarm.get() && w.indicator.get());
    let fs = step(&mut node, &w);
    assert_eq!(node.state(), DetectorState::Ice);
    let f = flags_of(&fs);
    assert_ne!(f & flags::ALARM, 0);
    assert_ne!(f & flags::ALARM_ACKED, 0);
    assert_eq!(events(&fs), []);
    // The ice goes: the resumed alarm clears after M frames as any other.
    w.set(|s| s.signal_na = [0.0, 0.0]);
    let mut cleared = None;
    for i in 1..=node.config().clear_frames {
        if events(&step(&mut node, &w)).contains(&EventKind::IceCleared) {
            cleared = Some(i);
            break;
        }
    }
    assert_eq!(cleared, Some(node.config().clear_frames));
    assert!(!w.alarm.get());

    // A power-on: dry, outputs off, the ice must be seen again.
    let w = World::default();
    let mut node = sim_board::sim_node(w.clone(), MemStorage::new(), "sim");
    node.resume_rule(RuleSnapshot::resume(words, true));
    assert_eq!(node.state(), DetectorState::Dry);
    assert!(!w.alarm.get());
}

#[test]
fn saves_wait_for_a_healthy_supply() {
    let (mut node, w) = node();
    w.set(|s| s.vdda_mv = 2_600.0);
    let c = Config {
        clear_frames: 400,
        ..Config::default()
    };
    command(&mut node, &w, 1, Command::SetConfigV3(c));
    // 20 s of frames at 2.6 V: the save is due after 1 s but waits, and no
    // failure is reported.
    for _ in 0..200 {
        let fs = step(&mut node, &w);
        assert_eq!(flags_of(&fs) & flags::STORAGE_FAILED, 0);
    }
    assert!(node.save_pending());
    // The supply recovers but the PVD still says low: it waits.
    w.set(|s| s.vdda_mv = 3_300.0);
    node.set_supply_low(true);
    step(&mut node, &w);
    assert!(node.save_pending());
    // Both healthy: saved with the next frame.
    node.set_supply_low(false);
    step(&mut node, &w);
    assert!(!node.save_pending());
    let mut storage = node.into_parts().5;
    assert_eq!(storage.writes, 1);
    let mut buf = [0u8; 256];
    assert!(storage.read(&mut buf).unwrap() > 0);
}

#[test]
fn a_clock_that_fails_over_mid_run_is_flagged_and_the_node_keeps_working() {
    // Streaming on the HSE; the clock security system switches to HSI
    // (the board's NMI sets the flag): CLOCK_FALLBACK is raised once, every
    // frame carries it, the frames keep coming and the rule still alarms.
    let (mut node, w) = node();
    for _ in 0..5 {
        assert_eq!(flags_of(&step(&mut node, &w)) & flags::CLOCK_FALLBACK, 0);
    }
    node.set_clock_fallback(true);
    let fs = step(&mut node, &w);
    assert_ne!(flags_of(&fs) & flags::CLOCK_FALLBACK, 0);
    assert_eq!(events(&fs), [EventKind::FaultRaised(flags::CLOCK_FALLBACK)]);
    w.set(|s| {
        s.signal_na = [5_000.0, 1_500.0];
        s.temp_c = -8.0;
    });
    let mut onset = None;
    for i in 1..=node.config().onset_frames {
        let fs = step(&mut node, &w);
        assert_ne!(flags_of(&fs) & flags::CLOCK_FALLBACK, 0);
        if events(&fs).contains(&EventKind::IceOnset) {
            onset = Some(i);
        }
    }
    assert_eq!(onset, Some(node.config().onset_frames));
    assert!(w.alarm.get());
    // Commands are still answered.
    let fs = command(&mut node, &w, 5, Command::GetConfig);
    assert!(matches!(&fs[0].msg, DeviceMsg::Ack(a) if a.id == 5));
}
