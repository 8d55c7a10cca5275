//! The version-4 commands that cannot mislead, on the simulated board: a
//! dark calibration that would move the stored baseline by more than the
//! noise allows is refused with both baselines unless forced; a face that
//! is not dry is refused with what the rule sees; `AckAlarmV4` without an
//! alarm answers `NoAlarm`. Older hosts' commands keep the answers they can
//! decode.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_protocol::*;

/// The one answer to `cmd`: an `Ack`'s result or an `Error`'s code.
fn answer(node: &mut SimNode, w: &World, id: u16, cmd: Command) -> Result<AckResult, ErrorCode> {
    let fs = command(node, w, id, cmd);
    assert_eq!(fs.len(), 1, "{fs:?}");
    match &fs[0].msg {
        DeviceMsg::Ack(a) if a.id == id => Ok(a.result.clone()),
        DeviceMsg::Error(e) if e.id == Some(id) => Err(e.code),
        other => panic!("unexpected answer {other:?}"),
    }
}

/// A dry face (600 nA / 200 nA of crosstalk) at +5 °C, a few frames run.
fn dry_node() -> (SimNode, World) {
    let (mut node, w) = node();
    w.seed_noise(3);
    w.set(|s| {
        s.signal_na = [600.0, 200.0];
        s.temp_c = 5.0;
        s.noise_lsb = 1.0;
    });
    for _ in 0..3 {
        step(&mut node, &w);
    }
    (node, w)
}

fn baseline(r: Result<AckResult, ErrorCode>) -> Baseline {
    match r {
        Ok(AckResult::DarkCalibrated(b)) => b,
        other => panic!("not calibrated: {other:?}"),
    }
}

#[test]
fn a_starting_film_is_refused_with_both_baselines_unless_forced() {
    let (mut node, w) = dry_node();
    // The first calibration: nothing stored, the dry face's 600 nA of
    // crosstalk is not compared with the zero placeholder.
    let first = baseline(answer(
        &mut node,
        &w,
        1,
        Command::CalibrateDarkV4 { force: false },
    ));
    assert!((first.i1_na - 600).abs() <= 50, "{first:?}");
    // A water film starts: +354 nA on I1, +120 nA on I2, the rule still dry
    // (354 nA is under the 1 µA onset).
    w.set(|s| s.signal_na = [954.0, 320.0]);
    for _ in 0..3 {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Dry);
    let refused = answer(&mut node, &w, 2, Command::CalibrateDarkV4 { force: false });
    let Err(ErrorCode::BaselineShift(s)) = refused else {
        panic!("not refused: {refused:?}");
    };
    assert_eq!(s.old, first);
    assert!((s.new.i1_na - 954).abs() <= 50, "{s:?}");
    assert_eq!(s.allowed_na, 250);
    assert!(s.shift_na() > 300, "{s:?}");
    assert_eq!(
        node.baseline(),
        Some(first),
        "the refused baseline was applied"
    );
    // An older host's command is refused the same, with the code it knows.
    assert_eq!(
        answer(&mut node, &w, 3, Command::CalibrateDark),
        Err(ErrorCode::NotDry)
    );
    assert_eq!(node.baseline(), Some(first));
    // Forced (the user says the face is clean and the change is real).
    let forced = baseline(answer(
        &mut node,
        &w,
        4,
        Command::CalibrateDarkV4 { force: true },
    ));
    assert!((forced.i1_na - 954).abs() <= 50, "{forced:?}");
    assert_eq!(node.baseline(), Some(forced));
}

#[test]
fn the_same_dry_face_recalibrates_without_force() {
    let (mut node, w) = dry_node();
    let first = baseline(answer(&mut node, &w, 1, Command::CalibrateDark));
    // Dust: +150 nA, inside the 250 nA allowance.
    w.set(|s| s.signal_na = [750.0, 200.0]);
    let second = baseline(answer(
        &mut node,
        &w,
        2,
        Command::CalibrateDarkV4 { force: false },
    ));
    assert!(
        (second.i1_na - first.i1_na - 150).abs() <= 50,
        "{first:?} → {second:?}"
    );
    // The old command on the same face: the old answer.
    baseline(answer(&mut node, &w, 3, Command::CalibrateDark));
}

#[test]
fn a_wet_face_is_refused_with_what_the_rule_sees_and_force_overrides() {
    let (mut node, w) = dry_node();
    w.set(|s| s.signal_na = [5_000.0, 1_500.0]);
    for _ in 0..node.config().onset_frames + 1 {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Wet);
    let r = answer(&mut node, &w, 1, Command::CalibrateDarkV4 { force: false });
    let Err(ErrorCode::FaceNotDry(f)) = r else {
        panic!("{r:?}");
    };
    assert_eq!(f.state, DetectorState::Wet);
    // No baseline stored: the rise is over zero.
    assert!((f.rise1_na - 5_000).abs() <= 80, "{f:?}");
    assert_eq!(
        answer(&mut node, &w, 2, Command::CalibrateDark),
        Err(ErrorCode::NotDry)
    );
    assert_eq!(node.baseline(), None);
    // Forced: a node whose dry face reads above the onset over zero (a new
    // LED, much crosstalk) can still be calibrated.
    let b = baseline(answer(
        &mut node,
        &w,
        3,
        Command::CalibrateDarkV4 { force: true },
    ));
    assert!((b.i1_na - 5_000).abs() <= 80, "{b:?}");
}

#[test]
fn ack_without_alarm_says_so_and_the_old_ack_keeps_its_answer() {
    let (mut node, w) = dry_node();
    assert_eq!(
        answer(&mut node, &w, 1, Command::AckAlarmV4),
        Ok(AckResult::NoAlarm)
    );
    // An older host: the answer it knows.
    assert_eq!(
        answer(&mut node, &w, 2, Command::AckAlarm),
        Ok(AckResult::AlarmAcknowledged)
    );
    let m = step(&mut node, &w);
    let flags_now = m
        .iter()
        .find_map(|f| f.msg.measurement().map(|(m, _)| m.flags))
        .unwrap_or(0);
    assert_eq!(flags_now & (flags::ALARM | flags::ALARM_ACKED), 0);
    // Ice: 2.5 µA at −4 °C until the alarm is on, then acknowledged.
    w.set(|s| {
        s.signal_na = [3_100.0, 900.0];
        s.temp_c = -4.0;
    });
    for _ in 0..node.config().onset_frames + 1 {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Ice);
    assert_eq!(
        answer(&mut node, &w, 3, Command::AckAlarmV4),
        Ok(AckResult::AlarmAcknowledged)
    );
    let m = step(&mut node, &w);
    let flags_now = m
        .iter()
        .find_map(|f| f.msg.measurement().map(|(m, _)| m.flags))
        .unwrap_or(0);
    assert_ne!(flags_now & flags::ALARM_ACKED, 0);
}
