//! The results table and the goals summary.

use std::fmt::Write as _;

use crate::outcome::Outcome;

/// Verdict of one run against the project's goals.
#[derive(Debug, Clone, PartialEq)]
pub enum Goal {
    /// No goal for this class.
    None,
    /// Goal met (text says which).
    Met(String),
    /// Goal missed (text says by how much).
    Missed(String),
}

/// The goal verdict of `o`.
pub fn goal(o: &Outcome) -> Goal {
    if let Some(limit) = o.class.alarm_goal_mm() {
        return match o.first_alarm() {
            Some(a) if a.truth.thickness_mm <= limit => Goal::Met(format!("≤ {limit} mm")),
            Some(a) => Goal::Missed(format!(
                "≤ {limit} mm: missed by {:.2} mm",
                a.truth.thickness_mm - limit
            )),
            None => Goal::Missed(format!("≤ {limit} mm: no alarm")),
        };
    }
    if o.class.no_ice() {
        let n = o.false_alarms();
        return if n == 0 {
            Goal::Met("0 false".into())
        } else {
            Goal::Missed(format!("0 false: {n} false alarms"))
        };
    }
    Goal::None
}

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or_else(|| "—".to_string(), |v| format!("{v:.digits$}"))
}

/// A Markdown table of the runs.
pub fn table(outcomes: &[Outcome]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| scenario | class | sensor | ice at 1st alarm (mm) | latency (s) | false alarms | frames lost | goal | expectations | virtual | wall |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | --- | ---: | ---: | ---: | ---: | --- | --- | ---: | ---: |"
    );
    for o in outcomes {
        let g = match goal(o) {
            Goal::None => "—".to_string(),
            Goal::Met(t) => format!("met ({t})"),
            Goal::Missed(t) => format!("**MISSED** ({t})"),
        };
        let exp = if !o.checked {
            "reported only".to_string()
        } else if o.failures.is_empty() {
            "pass".to_string()
        } else {
            format!("**FAIL** ({})", o.failures.len())
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} s |",
            o.name,
            o.class.name(),
            o.sensor,
            opt(o.first_alarm().map(|a| a.truth.thickness_mm), 3),
            opt(o.latency_s(), 1),
            o.false_alarms(),
            o.frames_lost(),
            g,
            exp,
            human_time(o.virtual_s),
            o.wall.as_secs_f64()
        );
    }
    s
}

fn human_time(s: f64) -> String {
    if s >= 3600.0 {
        format!("{:.1} h", s / 3600.0)
    } else if s >= 60.0 {
        format!("{:.0} min", s / 60.0)
    } else {
        format!("{s:.0} s")
    }
}

/// Notes: what each run's events were, failures, and anything notable
/// (alarms dropped on iced faces, saturated frames, lossy links).
pub fn notes(outcomes: &[Outcome]) -> String {
    let mut s = String::new();
    for o in outcomes {
        let mut line = Vec::new();
        let evs: Vec<String> = o
            .events
            .iter()
            .map(|e| {
                format!(
                    "{} {:.1} s ({:.3} mm {}, {:.1} °C)",
                    e.kind.name(),
                    e.t_s,
                    e.truth.thickness_mm,
                    e.truth.cover.name(),
                    e.truth.air_temp_c
                )
            })
            .collect();
        line.push(if evs.is_empty() {
            "no events".to_string()
        } else {
            evs.join(", ")
        });
        if o.dropped_alarms() > 0 {
            line.push(format!(
                "{} alarm(s) cleared with ice still on the face",
                o.dropped_alarms()
            ));
        }
        if o.saturated > 0 {
            line.push(format!("{} saturated frames", o.saturated));
        }
        if o.link_dropped + o.link_corrupted > 0 {
            line.push(format!(
                "link dropped {} and corrupted {} frames; decoder rejected {}",
                o.link_dropped, o.link_corrupted, o.rejected
            ));
        }
        if let Some((a, b)) = o.i1_range_na {
            line.push(format!("I1 {a}…{b} nA"));
        }
        let _ = writeln!(s, "- {}: {}", o.name, line.join("; "));
        for f in &o.failures {
            let _ = writeln!(s, "  - FAIL: {f}");
        }
    }
    s
}

/// The goals in one paragraph: met or missed, with the margins.
pub fn goals_summary(outcomes: &[Outcome]) -> String {
    let mut s = String::new();
    let worst = |cls: crate::scenario::Class, sensor: &str| {
        let runs: Vec<&Outcome> = outcomes
            .iter()
            .filter(|o| o.class == cls && o.sensor == sensor && o.checked)
            .collect();
        let missed: Vec<String> = runs
            .iter()
            .filter_map(|o| match goal(o) {
                Goal::Missed(t) => Some(format!("{} ({t})", o.name)),
                _ => None,
            })
            .collect();
        let max = runs
            .iter()
            .filter_map(|o| o.first_alarm().map(|a| a.truth.thickness_mm))
            .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))));
        (runs.len(), missed, max)
    };
    for (cls, label) in [
        (crate::scenario::Class::Rime, "rime, first alarm ≤ 0.2 mm"),
        (
            crate::scenario::Class::Glazed,
            "glazed, first alarm ≤ 0.5 mm",
        ),
    ] {
        for sensor in ["B", "A"] {
            let (n, missed, max) = worst(cls, sensor);
            if n == 0 {
                continue;
            }
            let _ = writeln!(
                s,
                "- {label}, Sensor {sensor}: {} of {n} runs met; largest thickness at first alarm {} mm{}",
                n - missed.len(),
                opt(max, 3),
                if missed.is_empty() {
                    String::new()
                } else {
                    format!("; missed: {}", missed.join(", "))
                }
            );
        }
    }
    let no_ice: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.class.no_ice() && o.checked)
        .collect();
    let fa: u32 = no_ice.iter().map(|o| o.false_alarms()).sum();
    let hours: f64 = no_ice.iter().map(|o| o.virtual_s).sum::<f64>() / 3600.0;
    let _ = writeln!(
        s,
        "- zero false alarms over dry/wet/ambient: {} ({fa} false alarms in {} scenarios, {hours:.1} h simulated)",
        if fa == 0 { "met" } else { "MISSED" },
        no_ice.len()
    );
    let all_fa: u32 = outcomes
        .iter()
        .filter(|o| o.checked)
        .map(|o| o.false_alarms())
        .sum();
    let _ = writeln!(
        s,
        "- false alarms over every asserted scenario: {all_fa}; frames lost: {}",
        outcomes.iter().map(|o| o.frames_lost()).sum::<u64>()
    );
    s
}
