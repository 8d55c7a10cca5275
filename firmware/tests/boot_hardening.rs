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

/// The reset a panic ends in (`SCB::sys_reset`: SFTRSTF and PINRST).
fn software_reset() -> boot::ResetCause {
    boot::ResetCause::from_flags(boot::ResetFlags {
        software: true,
        pin: true,
        ..Default::default()
    })
}

#[test]
fn a_panic_reset_is_reported_once_and_the_third_in_a_row_skips_the_store() {
    let (storage, stored) = stored_config();
    // The panic handler recorded three panics at line 412, resetting each time.
    let mut words = [0u32; boot::PANIC_WORDS];
    let mut storage = Some(storage);
    for n in 1..=3u8 {
        words = boot::record_panic(words, 412);
        let plan = boot::plan_boot(words, software_reset());
        words = plan.words;
        let w = World::default();
        let skip = plan.skip_store;
        let mode = if skip {
            boot::StoreRead::Skip
        } else {
            boot::StoreRead::Read
        };
        let store = SkippableStorage::new(storage.take().expect("the store"), mode);
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
        if !skip {
            assert_eq!(node.config(), &stored);
            assert_eq!(flags_of(&fs) & flags::STORE_SKIPPED, 0);
            assert_eq!(events(&fs), [panic]);
            storage = Some(node.into_parts().5.into_inner());
            continue;
        }
        // Defaults, not the stored config; STORE_SKIPPED raised.
        assert_eq!(node.config(), &Config::default());
        assert_ne!(flags_of(&fs) & flags::STORE_SKIPPED, 0);
        assert_eq!(
            events(&fs),
            [EventKind::FaultRaised(flags::STORE_SKIPPED), panic]
        );
        // Reported once.
        let mut bytes = Vec::new();
        w.run_frame(&mut node, &mut |b| bytes.extend_from_slice(b));
        assert_eq!(events(&frames(&bytes)), []);
        // A calibration in the skip mode is saved: the store is started
        // afresh with the record the node runs (the bad record replaced
        // remotely), without a storage fault.
        command(&mut node, &w, 2, Command::CalibrateDark);
        let fs = run_until_saved(&mut node, &w);
        assert!(fs.iter().all(|f| !matches!(
            &f.msg,
            DeviceMsg::MeasurementV5(m) if m.measurement.flags & flags::STORAGE_FAILED != 0
        )));
        let baseline = node.baseline();
        assert!(baseline.is_some());
        let kept = node.into_parts().5.into_inner();
        assert_eq!(kept.writes, 2, "the original save and the skip mode's");
        // The next boot reads it: the defaults and the new baseline.
        let node = sim_board::sim_node(World::default(), kept, "sim");
        assert_eq!(node.config(), &Config::default());
        assert_eq!(node.baseline(), baseline);
    }
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
fn the_alarm_holds_across_a_watchdog_reset_and_a_brown_out_and_not_across_a_power_on() {
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
    assert!(RuleSnapshot::resume(words, false).alarm_on());
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

    // A brown-out alone (BORRSTF without PORRSTF): the backup registers
    // held, the alarm and its acknowledgement resume as after a watchdog.
    let brown_out = boot::ResetCause::from_flags(boot::ResetFlags {
        brown_out: true,
        pin: true,
        ..Default::default()
    });
    assert_eq!(brown_out.reason, ResetReason::PowerOn);
    let w = World::default();
    let mut node = sim_board::sim_node(w.clone(), MemStorage::new(), "sim");
    node.resume_rule(RuleSnapshot::resume(words, brown_out.power_lost));
    assert!(w.alarm.get());
    assert_eq!(
        node.rule_snapshot(),
        RuleSnapshot {
            state: DetectorState::Ice,
            acked: true
        }
    );

    // A power-on: dry, outputs off, the ice must be seen again.
    let power_on = boot::ResetCause::from_flags(boot::ResetFlags {
        power_on: true,
        brown_out: true,
        pin: true,
        ..Default::default()
    });
    let w = World::default();
    let mut node = sim_board::sim_node(w.clone(), MemStorage::new(), "sim");
    node.resume_rule(RuleSnapshot::resume(words, power_on.power_lost));
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

#[test]
fn failed_saves_back_off_to_an_hour() {
    let mut storage = MemStorage::new();
    storage.fail_writes = true;
    let (mut node, w) = node_with(storage);
    command(
        &mut node,
        &w,
        1,
        Command::SetConfigV3(Config {
            onset_frames: 9,
            ..Config::default()
        }),
    );
    // Three hours of a store that never takes a write, polled every second:
    // the attempts (each an erase on the board) come 60, 60, 120, 240, ... s
    // apart, then hourly — 8 of them, not 1 080.
    let t0 = w.now_ms();
    let mut attempts = Vec::new();
    let mut due = node.save_due_ms();
    for s in 0..3 * 3_600u64 {
        let now = t0 + s * 1_000;
        node.poll_storage(now);
        if node.save_due_ms() != due {
            attempts.push(s);
            due = node.save_due_ms();
        }
    }
    assert!(node.save_pending(), "still retried");
    let gaps: Vec<u64> = attempts.windows(2).map(|p| p[1] - p[0]).collect();
    assert_eq!(gaps, [60, 120, 240, 480, 960, 1_920, 3_600]);
    assert_eq!(node.into_parts().5.writes, 0);
}
