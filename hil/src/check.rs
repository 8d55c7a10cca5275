//! A scenario's expectations against what was decoded.

use fois_protocol::{DetectorState, EventKind};

use crate::outcome::Outcome;
use crate::scenario::{Reply, Scenario, state_named};

/// Every expectation of `sc` that `o` does not meet (empty: all hold). The
/// structural checks (sequence, alarm pin, flags vs state, stray errors,
/// command replies) apply to every scenario.
pub fn check(sc: &Scenario, o: &Outcome) -> Vec<String> {
    let mut fail = Vec::new();
    let e = &sc.file.expect;
    fail.extend(o.inconsistencies.iter().cloned());
    if o.measurements == 0 {
        fail.push("no measurement decoded".into());
    }
    if o.frames_lost() > e.max_frames_lost {
        fail.push(format!(
            "{} frames lost (sequence gaps), at most {} allowed",
            o.frames_lost(),
            e.max_frames_lost
        ));
    }
    if let Some(n) = e.min_frames_lost
        && o.frames_lost() < n
    {
        fail.push(format!(
            "{} frames lost, expected at least {n}",
            o.frames_lost()
        ));
    }
    if o.stray_errors > e.max_errors {
        fail.push(format!(
            "{} Error frames not asked for, at most {} allowed",
            o.stray_errors, e.max_errors
        ));
    }
    check_replies(sc, o, &mut fail);
    if !o.checked {
        return fail;
    }
    let first = o.first_alarm();
    match (e.alarm, first) {
        (Some(true), None) => fail.push("expected an ice alarm, none came".into()),
        (Some(false), Some(a)) => fail.push(format!(
            "expected no ice alarm, one came at {:.1} s ({:.3} mm {}, {:.2} °C)",
            a.t_s,
            a.truth.thickness_mm,
            a.truth.cover.name(),
            a.truth.air_temp_c
        )),
        _ => {}
    }
    if let Some(mm) = e.alarm_by_mm {
        match first {
            Some(a) if a.truth.thickness_mm <= mm => {}
            Some(a) => fail.push(format!(
                "first alarm at {:.3} mm, expected by {mm} mm",
                a.truth.thickness_mm
            )),
            None => fail.push(format!("no alarm, expected one by {mm} mm")),
        }
    }
    if let Some(t) = e.alarm_by_s {
        match first {
            Some(a) if a.t_s <= t => {}
            Some(a) => fail.push(format!("first alarm at {:.1} s, expected by {t} s", a.t_s)),
            None => fail.push(format!("no alarm, expected one by {t} s")),
        }
    }
    if let (Some(t), Some(a)) = (e.no_alarm_before_s, first)
        && a.t_s < t
    {
        fail.push(format!(
            "alarm at {:.1} s, none allowed before {t} s",
            a.t_s
        ));
    }
    if let Some(t) = e.wet_by_s {
        match o.events.iter().find(|x| x.kind == EventKind::WetOnset) {
            Some(w) if w.t_s <= t => {}
            Some(w) => fail.push(format!("wet at {:.1} s, expected by {t} s", w.t_s)),
            None => fail.push(format!("never wet, expected by {t} s")),
        }
    }
    if let Some(want) = &e.events {
        let got: Vec<&str> = o.events.iter().map(|x| x.kind.name()).collect();
        if got != want.iter().map(String::as_str).collect::<Vec<_>>() {
            fail.push(format!(
                "events {got:?}, expected {want:?} (at {:?} s)",
                o.events
                    .iter()
                    .map(|x| (x.t_s * 10.0).round() / 10.0)
                    .collect::<Vec<_>>()
            ));
        }
    }
    if let Some(want) = &e.states {
        let got: Vec<&str> = o.states.iter().map(|&s| s.name()).collect();
        if got != want.iter().map(String::as_str).collect::<Vec<_>>() {
            fail.push(format!("states {got:?}, expected {want:?}"));
        }
    }
    if let Some(want) = e.final_state.as_deref().and_then(state_named)
        && o.final_state != Some(want)
    {
        fail.push(format!(
            "final state {:?}, expected {}",
            o.final_state.map(DetectorState::name),
            want.name()
        ));
    }
    let fa = o.false_alarms();
    if fa > e.max_false_alarms {
        fail.push(format!(
            "{fa} false alarms, at most {} allowed",
            e.max_false_alarms
        ));
    }
    if let Some(n) = e.min_saturated_frames
        && o.saturated < n
    {
        fail.push(format!(
            "{} saturated measurements, expected at least {n}",
            o.saturated
        ));
    }
    if let Some(n) = e.min_measurements
        && o.measurements < n
    {
        fail.push(format!(
            "{} measurements, expected at least {n}",
            o.measurements
        ));
    }
    if let Some(d) = e.not_confidently_thin_from_mm {
        let thin: Vec<_> = o
            .estimates
            .iter()
            .filter(|s| {
                use fois_vnode::Cover::{Flat, Glazed, Rime};
                matches!(s.cover, Flat | Glazed | Rime) && s.true_mm >= d
            })
            .filter(|s| s.confidently_thin())
            .collect();
        if let Some(first) = thin.first() {
            fail.push(format!(
                "{} frames from {d} mm confidently thin (est + 2σ < half the truth); first at {:.0} s: {:.2} ± {:.2} mm at {:.2} mm",
                thin.len(),
                first.t_s,
                first.est_mm,
                first.sigma_mm,
                first.true_mm
            ));
        }
    }
    fail
}

fn check_replies(sc: &Scenario, o: &Outcome, fail: &mut Vec<String>) {
    let mut used = vec![false; o.replies.len()];
    let wants = sc
        .config
        .iter()
        .map(|_| ("set_config".to_string(), Reply::Ack, None))
        .chain(
            sc.file
                .commands
                .iter()
                .map(|c| (format!("{:?} at {} s", c.send, c.at_s), c.expect, c.refusal)),
        );
    for ((what, want, refusal), &(id, _)) in wants.zip(o.sent.iter()) {
        let found = o
            .replies
            .iter()
            .enumerate()
            .find(|(i, r)| !used[*i] && r.id == id);
        match found {
            None => fail.push(format!("{what}: no reply")),
            Some((i, r)) => {
                used[i] = true;
                let got = if r.result.is_ok() {
                    Reply::Ack
                } else {
                    Reply::Error
                };
                if got != want {
                    fail.push(format!("{what}: got {:?}, expected {want:?}", r.result));
                } else if let (Some(refusal), Err(code)) = (refusal, &r.result)
                    && !refusal.matches(code)
                {
                    fail.push(format!(
                        "{what}: refused with {code:?}, expected {refusal:?}"
                    ));
                }
            }
        }
    }
}
