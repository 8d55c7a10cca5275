//! The field-safety scenarios with their numbers: strong sun that clips the
//! phototransistors (the alarm neither clears nor is its onset silently
//! missed) and an NTC unplugged in the middle of an accretion (fault raised,
//! no thaw-clearing). The files are in `hil/scenarios/`; this asserts more
//! than their `[expect]` tables can say.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use fois_hil::Outcome;
use fois_protocol::{DetectorState, EventKind, flags};

/// Run one shipped scenario file; its own expectations must hold too.
fn run(file: &str) -> Outcome {
    common::run_file(file).0
}

fn kinds(o: &Outcome) -> Vec<EventKind> {
    o.events.iter().map(|e| e.kind).collect()
}

#[test]
fn strong_sun_on_ice_is_flagged_and_the_alarm_holds() {
    let o = run("sun-saturation-iced.toml");
    // 10 Hz: 600 s of sun = 6 000 frames, every one flagged (a frame that
    // straddles the sun's edge may or may not be); none outside the sun.
    assert!(
        (5_999..=6_001).contains(&o.saturated),
        "{} saturated frames",
        o.saturated
    );
    assert_eq!(kinds(&o), [EventKind::IceOnset], "{:?}", o.events);
    let onset = &o.events[0];
    // Rime from 300 s at 3 mm/h; the alarm at under 0.1 mm (0.05 mm =
    // 60 s), long before the sun (600 s).
    assert!(
        (300.0..360.0).contains(&onset.t_s),
        "onset at {}",
        onset.t_s
    );
    assert!(onset.truth.thickness_mm < 0.05, "{:?}", onset.truth);
    assert_eq!(o.states, [DetectorState::Dry, DetectorState::Ice]);
    assert_eq!(o.final_state, Some(DetectorState::Ice));
    assert_eq!(o.dropped_alarms(), 0);
}

#[test]
fn rime_under_strong_sun_alarms_when_the_sun_goes() {
    let o = run("sun-saturation-onset.toml");
    // 900 s of sun (300 dry, 600 rime) = 9 000 frames, all flagged: the
    // host sees a blind node, not a dry one.
    assert!(
        (8_999..=9_001).contains(&o.saturated),
        "{} saturated frames",
        o.saturated
    );
    assert_eq!(kinds(&o), [EventKind::IceOnset], "{:?}", o.events);
    let onset = &o.events[0];
    // The sun goes at 1 200 s; onset after N = 30 valid frames (3 s).
    assert!(
        (1_202.9..1_203.2).contains(&onset.t_s),
        "onset at {}",
        onset.t_s
    );
    // 600 s of rime at 3 mm/h = 0.5 mm on the face by then.
    assert!(
        (0.49..0.51).contains(&onset.truth.thickness_mm),
        "{} mm",
        onset.truth.thickness_mm
    );
    assert!(onset.rise1_na >= 1_000, "rise {} nA", onset.rise1_na);
    assert_eq!(o.final_state, Some(DetectorState::Ice));
}

#[test]
fn unplugged_ntc_raises_the_fault_and_never_thaw_clears() {
    let o = run("ntc-unplugged-icing.toml");
    let k = kinds(&o);
    assert_eq!(k.len(), 2, "{:?}", o.events);
    assert_eq!(k[0], EventKind::IceOnset);
    let EventKind::FaultRaised(bits) = k[1] else {
        panic!("second event: {:?}", k[1]);
    };
    assert_eq!(bits, flags::NTC_OPEN, "fault bits {bits:#06x}");
    // Onset in the rime before the NTC goes (300–600 s); the fault with
    // the first frame after 600 s.
    assert!(
        (300.0..360.0).contains(&o.events[0].t_s),
        "{:?}",
        o.events[0]
    );
    assert!(
        (600.0..600.2).contains(&o.events[1].t_s),
        "fault at {}",
        o.events[1].t_s
    );
    // The air ended at +4 °C (a thaw, had the node known it), the ice is
    // still there: the alarm holds to the end (1 800 s).
    assert!(o.virtual_s >= 1_800.0);
    assert_eq!(o.states, [DetectorState::Dry, DetectorState::Ice]);
    assert_eq!(o.final_state, Some(DetectorState::Ice));
    assert_eq!(o.dropped_alarms(), 0);
}
