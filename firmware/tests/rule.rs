//! Every path of the ice rule, each with its one-field-wrong twins: the same
//! frames with one value just on the wrong side of its limit must not fire.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_firmware::ice_rule::{Rule, RuleInput, Transition};
use fois_protocol::{Config, DetectorState, EventKind};

fn cfg() -> Config {
    Config::default()
}

fn frame(rise1_na: i32, temperature_centi_c: i16) -> RuleInput {
    RuleInput {
        rise1_na,
        temperature_centi_c,
        air_known: true,
        valid: true,
    }
}

/// Feed `n` copies of `input`; return the transitions.
fn feed(rule: &mut Rule, c: &Config, input: RuleInput, n: u32) -> Vec<Transition> {
    (0..n).filter_map(|_| rule.step(c, input)).collect()
}

fn iced(c: &Config) -> Rule {
    let mut r = Rule::new();
    let cold_film = frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c);
    feed(&mut r, c, cold_film, c.onset_frames.into());
    assert_eq!(r.state(), DetectorState::Ice);
    r
}

fn wet(c: &Config) -> Rule {
    let mut r = Rule::new();
    let warm_film = frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c + 1);
    feed(&mut r, c, warm_film, c.onset_frames.into());
    assert_eq!(r.state(), DetectorState::Wet);
    r
}

#[test]
fn defaults_are_the_documented_ones() {
    let c = cfg();
    assert_eq!(c.load_r1_ohm, 10_000);
    assert_eq!((c.onset_rise_na, c.clear_rise_na), (1_000, 200));
    assert_eq!((c.onset_frames, c.clear_frames), (30, 300));
    assert_eq!((c.freeze_limit_centi_c, c.thaw_limit_centi_c), (50, 250));
}

#[test]
fn dry_to_ice_after_n_cold_frames() {
    let c = cfg();
    let n = u32::from(c.onset_frames);
    let good = frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c);
    let mut r = Rule::new();
    assert!(feed(&mut r, &c, good, n - 1).is_empty());
    assert_eq!(r.state(), DetectorState::Dry);
    let t = r.step(&c, good).expect("N-th frame fires");
    assert_eq!(t.kind, EventKind::IceOnset);
    assert_eq!(t.frames, c.onset_frames);
    assert_eq!((t.from, t.to), (DetectorState::Dry, DetectorState::Ice));
    assert!(r.alarm());

    // One field wrong: rise exactly at the threshold (not above).
    let mut r = Rule::new();
    assert!(
        feed(
            &mut r,
            &c,
            frame(c.onset_rise_na as i32, c.freeze_limit_centi_c),
            10 * n
        )
        .is_empty()
    );
    // One field wrong: 0.01 °C above the freezing limit → wet, not ice.
    let mut r = Rule::new();
    let t = feed(
        &mut r,
        &c,
        frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c + 1),
        n,
    );
    assert_eq!(t.len(), 1);
    assert_eq!(t[0].kind, EventKind::WetOnset);
    assert!(!r.alarm());
    // One field wrong: the run is broken once (one frame under) → starts over.
    let mut r = Rule::new();
    assert!(feed(&mut r, &c, good, n - 1).is_empty());
    assert!(
        r.step(&c, frame(c.onset_rise_na as i32, c.freeze_limit_centi_c))
            .is_none()
    );
    assert!(feed(&mut r, &c, good, n - 1).is_empty());
    assert_eq!(r.state(), DetectorState::Dry);
    assert!(r.step(&c, good).is_some());
    // One field wrong: invalid (saturated) frames never count.
    let mut r = Rule::new();
    let invalid = RuleInput {
        valid: false,
        ..good
    };
    assert!(feed(&mut r, &c, invalid, 10 * n).is_empty());
    assert_eq!(r.state(), DetectorState::Dry);
}

#[test]
fn invalid_frames_neither_advance_nor_reset() {
    let c = cfg();
    let n = u32::from(c.onset_frames);
    let good = frame(c.onset_rise_na as i32 + 1, -500);
    let mut r = Rule::new();
    assert!(feed(&mut r, &c, good, n - 1).is_empty());
    assert!(
        feed(
            &mut r,
            &c,
            RuleInput {
                valid: false,
                ..frame(0, 2_000)
            },
            5
        )
        .is_empty()
    );
    assert_eq!(r.step(&c, good).map(|t| t.kind), Some(EventKind::IceOnset));
}

#[test]
fn wet_freezes_to_ice_and_dries_to_dry() {
    let c = cfg();
    let n = u32::from(c.onset_frames);
    let m = u32::from(c.clear_frames);
    let mut r = wet(&c);
    let cold_film = frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c);
    assert!(feed(&mut r, &c, cold_film, n - 1).is_empty());
    let t = r.step(&c, cold_film).expect("water froze");
    assert_eq!(
        (t.kind, t.from, t.to),
        (EventKind::IceOnset, DetectorState::Wet, DetectorState::Ice)
    );
    // One field wrong: the water stays 0.01 °C above the limit.
    let mut r = wet(&c);
    assert!(
        feed(
            &mut r,
            &c,
            frame(c.onset_rise_na as i32 + 1, c.freeze_limit_centi_c + 1),
            10 * n
        )
        .is_empty()
    );
    assert_eq!(r.state(), DetectorState::Wet);

    // Wet → Dry after M frames below the clear threshold.
    let mut r = wet(&c);
    let dry = frame(c.clear_rise_na as i32 - 1, 1_000);
    assert!(feed(&mut r, &c, dry, m - 1).is_empty());
    let t = r.step(&c, dry).expect("dried");
    assert_eq!(
        (t.kind, t.frames, t.to),
        (EventKind::WetCleared, c.clear_frames, DetectorState::Dry)
    );
    // One field wrong: rise exactly at the clear threshold (hysteresis band).
    let mut r = wet(&c);
    assert!(feed(&mut r, &c, frame(c.clear_rise_na as i32, 1_000), 2 * m).is_empty());
    assert_eq!(r.state(), DetectorState::Wet);
}

#[test]
fn ice_clears_after_m_frames_with_hysteresis() {
    let c = cfg();
    let m = u32::from(c.clear_frames);
    let gone = frame(c.clear_rise_na as i32 - 1, -1_000);
    let mut r = iced(&c);
    assert!(feed(&mut r, &c, gone, m - 1).is_empty());
    let t = r.step(&c, gone).expect("cleared");
    assert_eq!(
        (t.kind, t.frames, t.to),
        (EventKind::IceCleared, c.clear_frames, DetectorState::Dry)
    );
    assert!(!r.alarm());

    // One field wrong: between clear and onset (the hysteresis band) holds the alarm.
    let mut r = iced(&c);
    let band = frame(c.clear_rise_na as i32, -1_000);
    assert!(feed(&mut r, &c, band, 3 * m).is_empty());
    assert!(r.alarm());
    // One field wrong: one frame back above the clear level restarts the count.
    let mut r = iced(&c);
    assert!(feed(&mut r, &c, gone, m - 1).is_empty());
    assert!(r.step(&c, band).is_none());
    assert!(feed(&mut r, &c, gone, m - 1).is_empty());
    assert!(r.alarm());
    assert!(r.step(&c, gone).is_some());
}

#[test]
fn ice_clears_when_it_thaws() {
    let c = cfg();
    let n = u32::from(c.onset_frames);
    let melting = frame(c.onset_rise_na as i32 * 5, c.thaw_limit_centi_c + 1);
    let mut r = iced(&c);
    assert!(feed(&mut r, &c, melting, n - 1).is_empty());
    let t = r.step(&c, melting).expect("thawed");
    // The film is still seen: it is water now.
    assert_eq!(
        (t.kind, t.frames, t.to),
        (EventKind::IceCleared, c.onset_frames, DetectorState::Wet)
    );
    // Thawed and gone at once → dry.
    let mut r = iced(&c);
    let t = feed(&mut r, &c, frame(0, c.thaw_limit_centi_c + 1), n);
    assert_eq!(t.last().map(|t| t.to), Some(DetectorState::Dry));
    // One field wrong: exactly at the thaw limit holds the alarm.
    let mut r = iced(&c);
    assert!(
        feed(
            &mut r,
            &c,
            frame(c.onset_rise_na as i32 * 5, c.thaw_limit_centi_c),
            10 * n
        )
        .is_empty()
    );
    assert!(r.alarm());
    // Between freeze and thaw limits the ice holds too (temperature hysteresis).
    let mut r = iced(&c);
    assert!(
        feed(
            &mut r,
            &c,
            frame(
                c.onset_rise_na as i32 * 5,
                (c.freeze_limit_centi_c + c.thaw_limit_centi_c) / 2
            ),
            10 * n
        )
        .is_empty()
    );
    assert!(r.alarm());
}

#[test]
fn acknowledge_holds_until_the_ice_clears() {
    let c = cfg();
    let mut r = Rule::new();
    assert!(!r.acknowledge(), "nothing to acknowledge while dry");
    let mut r = iced(&c);
    assert!(r.acknowledge());
    assert!(r.acked() && r.alarm());
    feed(&mut r, &c, frame(0, -1_000), c.clear_frames.into());
    assert!(!r.alarm() && !r.acked());
    // A new alarm is not acknowledged.
    feed(
        &mut r,
        &c,
        frame(c.onset_rise_na as i32 + 1, -1_000),
        c.onset_frames.into(),
    );
    assert!(r.alarm() && !r.acked());
}

#[test]
fn extreme_inputs_do_not_panic() {
    let c = Config {
        onset_frames: 1,
        clear_frames: 1,
        ..cfg()
    };
    let mut r = Rule::new();
    for &(rise, t) in &[
        (i32::MAX, i16::MIN),
        (i32::MIN, i16::MAX),
        (i32::MAX, i16::MAX),
        (0, 0),
    ] {
        let _ = r.step(&c, frame(rise, t));
    }
    // Counters saturate instead of overflowing.
    let mut r = Rule::new();
    feed(&mut r, &c, frame(i32::MAX, i16::MAX), 70_000);
}

/// An NTC fault: the air counts as cold (a film is ice, not water) and
/// never as thawing (ice clears only when the film is gone).
#[test]
fn unknown_air_is_cold_and_never_thaws() {
    let c = cfg();
    let n = u32::from(c.onset_frames);
    let m = u32::from(c.clear_frames);
    let film = c.onset_rise_na as i32 + 1;
    // A warm reading that would make the film water, but the NTC is broken
    // (the node then reads the die, which runs warmer than the air).
    let unknown = |rise1_na: i32| RuleInput {
        air_known: false,
        ..frame(rise1_na, 1_500)
    };
    let mut r = Rule::new();
    let ev = feed(&mut r, &c, unknown(film), n);
    assert_eq!(ev.len(), 1);
    assert_eq!(ev[0].kind, EventKind::IceOnset);
    assert_eq!(ev[0].frames, c.onset_frames);
    // Its twin with a known 15 °C air is water.
    let mut w = Rule::new();
    let ev = feed(&mut w, &c, frame(film, 1_500), n);
    assert_eq!(ev[0].kind, EventKind::WetOnset);
    // Iced, the broken sensor reads "hot": no thaw-clearing, however long.
    let hot = RuleInput {
        air_known: false,
        ..frame(film, 3_000)
    };
    assert!(feed(&mut r, &c, hot, 100 * n).is_empty());
    assert_eq!(r.state(), DetectorState::Ice);
    // The same reading with a working NTC clears by thaw after N frames.
    let mut k = Rule::new();
    feed(&mut k, &c, frame(film, 0), n);
    let ev = feed(&mut k, &c, frame(film, 3_000), n);
    assert_eq!(ev.len(), 1);
    assert_eq!(
        (ev[0].kind, ev[0].frames),
        (EventKind::IceCleared, c.onset_frames)
    );
    // With the NTC broken the ice clears only when the film is gone (M frames).
    let ev = feed(
        &mut r,
        &c,
        RuleInput {
            air_known: false,
            ..frame(c.clear_rise_na as i32 - 1, 3_000)
        },
        m,
    );
    assert_eq!(ev.len(), 1);
    assert_eq!(
        (ev[0].kind, ev[0].to),
        (EventKind::IceCleared, DetectorState::Dry)
    );
    assert_eq!(ev[0].frames, c.clear_frames);
    // Wet (known air), then the NTC fails: the film is now ice.
    let mut w = Rule::new();
    feed(&mut w, &c, frame(film, 1_500), n);
    assert_eq!(w.state(), DetectorState::Wet);
    let ev = feed(&mut w, &c, unknown(film), n);
    assert_eq!(ev.len(), 1);
    assert_eq!(
        (ev[0].kind, ev[0].to),
        (EventKind::IceOnset, DetectorState::Ice)
    );
}

mod property {
    use super::*;
    use proptest::prelude::*;

    fn input() -> impl Strategy<Value = RuleInput> {
        let c = cfg();
        let on = c.onset_rise_na as i32;
        let cl = c.clear_rise_na as i32;
        let fr = c.freeze_limit_centi_c;
        let th = c.thaw_limit_centi_c;
        (
            prop_oneof![
                Just(cl - 1),
                Just(cl),
                Just(on),
                Just(on + 1),
                -5_000..50_000i32
            ],
            prop_oneof![
                Just(fr),
                Just(fr + 1),
                Just(th),
                Just(th + 1),
                -3_000..3_000i16
            ],
            prop::bool::weighted(0.95),
            prop::bool::weighted(0.9),
        )
            .prop_map(
                |(rise1_na, temperature_centi_c, valid, air_known)| RuleInput {
                    rise1_na,
                    temperature_centi_c,
                    air_known,
                    valid,
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Whatever the frames, every transition is backed by exactly the
        /// evidence the rule documents (on the valid frames before it).
        #[test]
        fn every_transition_has_its_evidence(
            frames in proptest::collection::vec(input(), 0..400),
            n in 1u16..6,
            m in 1u16..12,
        ) {
            let c = Config { onset_frames: n, clear_frames: m, ..cfg() };
            let film = |f: &RuleInput| i64::from(f.rise1_na) > i64::from(c.onset_rise_na);
            let gone = |f: &RuleInput| i64::from(f.rise1_na) < i64::from(c.clear_rise_na);
            // Unknown air (NTC fault) is cold and never thawing.
            let cold = |f: &RuleInput| !f.air_known || f.temperature_centi_c <= c.freeze_limit_centi_c;
            let thaw = |f: &RuleInput| f.air_known && f.temperature_centi_c > c.thaw_limit_centi_c;
            let mut r = Rule::new();
            let mut valid: Vec<RuleInput> = Vec::new();
            for f in frames {
                let before = r.state();
                let t = r.step(&c, f);
                if !f.valid {
                    prop_assert!(t.is_none());
                    continue;
                }
                valid.push(f);
                let last = |k: u16| valid.iter().rev().take(usize::from(k)).copied().collect::<Vec<_>>();
                if let Some(t) = t {
                    prop_assert_eq!(t.from, before);
                    let back = last(t.frames);
                    prop_assert_eq!(back.len(), usize::from(t.frames));
                    match (t.kind, t.to) {
                        (EventKind::IceOnset, DetectorState::Ice) => {
                            prop_assert!(t.frames >= n);
                            prop_assert!(back.iter().all(|f| film(f) && cold(f)));
                        }
                        (EventKind::WetOnset, DetectorState::Wet) => {
                            prop_assert!(t.frames >= n && !cold(&f));
                            prop_assert!(back.iter().all(&film));
                        }
                        (EventKind::WetCleared, DetectorState::Dry) => {
                            prop_assert!(t.frames >= m && back.iter().all(&gone));
                        }
                        (EventKind::IceCleared, _) => {
                            let by_gone = t.frames >= m && back.iter().all(&gone);
                            let by_thaw = t.frames >= n && back.iter().all(&thaw);
                            prop_assert!(by_gone || by_thaw);
                        }
                        other => prop_assert!(false, "unexpected {:?}", other),
                    }
                } else {
                    prop_assert_eq!(r.state(), before);
                }
                prop_assert_eq!(r.alarm(), r.state() == DetectorState::Ice);
            }
        }
    }
}
