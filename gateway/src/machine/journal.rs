//! What an operator reads in the gateway's log (the journal under systemd)
//! about the nodes: one line per ice, wet, alarm and fault event and per
//! lost link, with the node's name and the numbers that matter, and the
//! rate limit that keeps a flapping node from flooding the journal.
//!
//! Each line names the node, the temperature and, when the node sends an
//! ice estimate, its latest one (thickness ± σ, medium and its
//! probability; at an ice onset the estimator may lag the detector's rule,
//! then the line says `(not ice yet)`).
//!
//! | kind | level | when |
//! | --- | --- | --- |
//! | `ice_onset`, `ice_cleared` | INFO | the node's detector enters / leaves ice (its alarm output) |
//! | `wet_onset`, `wet_cleared` | INFO | a water film above freezing appears / dries |
//! | `alarm_acknowledged` | INFO | a measurement first carries the acknowledged flag |
//! | `fault_cleared` | INFO | fault bits cleared |
//! | `fault_raised`, `panic_reset`, `link_lost` | WARN | fault bits set (e.g. `ntc_open`), a panic reset, the serial link lost |
//!
//! **Rate limit.** At most [`LINES_PER_WINDOW`] lines per node and kind
//! within [`WINDOW`]; the lines beyond are not written but counted, and when
//! the window ends one WARN line says how many of which kind were left out.
//! The MQTT event records are not limited: every one is published.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use fois_link::reading::{EstimateReading, EventReading, Reading};
use fois_protocol::Medium;

/// Lines per node and kind within [`WINDOW`].
pub const LINES_PER_WINDOW: u32 = 5;
/// The rate limit's window.
pub const WINDOW: Duration = Duration::from_secs(600);

/// How loud a line is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Ordinary news: ice, wet, an acknowledgement, a fault gone.
    Info,
    /// Needs a look: a fault, a panic reset, a lost link.
    Warn,
}

/// One line for the journal.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// What happened (the rate limit's key with the node).
    pub kind: &'static str,
    /// Its level.
    pub level: Level,
    /// The text, the node's name first.
    pub text: String,
}

/// `estimate thickness ± σ mm medium (p …)`: what the node's estimate
/// says.
fn estimate_words(e: &EstimateReading) -> String {
    format!(
        "estimate {:.1} ± {:.1} mm {} (p {:.2})",
        e.thickness_mm,
        e.thickness_sigma_mm,
        e.medium.name(),
        e.medium_probability
    )
}

/// The line of an event frame of node `name`; `estimate` is the node's
/// latest estimate (None: its firmware sends none, or none came yet).
pub fn event_line(name: &str, e: &EventReading, estimate: Option<&EstimateReading>) -> Line {
    let temp = format!("{:.1} °C", e.temperature_c);
    let rise = format!(
        "channel 1 {:+.1} µA over its dark baseline for {} frame(s)",
        e.rise1_ua, e.frames
    );
    let est = estimate.map(|x| format!("{}, ", estimate_words(x)));
    let est = est.as_deref().unwrap_or("");
    // The detector's rule answers before the estimator, which may still
    // see no ice at the onset: said so, not left to look like a contradiction.
    let ice_est = match estimate {
        Some(x) if matches!(x.medium, Medium::Dry | Medium::Water) => {
            format!("{} (not ice yet), ", estimate_words(x))
        }
        _ => est.to_string(),
    };
    let faults = if e.faults.is_empty() {
        "(none named)".to_string()
    } else {
        e.faults.join(", ")
    };
    let (level, text) = match e.kind {
        "ice_onset" => (
            Level::Info,
            format!("node {name}: ice onset (alarm on): {ice_est}{temp}, {rise}"),
        ),
        "ice_cleared" => (
            Level::Info,
            format!("node {name}: ice cleared (alarm off): {est}{temp}"),
        ),
        "wet_onset" => (
            Level::Info,
            format!(
                "node {name}: wet (a water film above freezing, no alarm): {est}{temp}, {rise}"
            ),
        ),
        "wet_cleared" => (Level::Info, format!("node {name}: dry again: {temp}")),
        "fault_raised" => (
            Level::Warn,
            format!("node {name}: fault raised: {faults} ({temp})"),
        ),
        "fault_cleared" => (
            Level::Info,
            format!("node {name}: fault cleared: {faults} ({temp})"),
        ),
        "panic_reset" => (
            Level::Warn,
            format!("node {name}: restarted after a firmware panic ({temp})"),
        ),
        other => (Level::Info, format!("node {name}: event {other} ({temp})")),
    };
    Line {
        kind: e.kind,
        level,
        text,
    }
}

/// The line when a measurement first carries the alarm-acknowledged flag.
pub fn acknowledged_line(name: &str, r: &Reading) -> Line {
    let est = r
        .estimate
        .as_ref()
        .map(|e| format!("{}, ", estimate_words(e)))
        .unwrap_or_default();
    Line {
        kind: "alarm_acknowledged",
        level: Level::Info,
        text: format!(
            "node {name}: alarm acknowledged (the output stays on while ice remains): {est}{:.1} °C",
            r.temperature_c
        ),
    }
}

/// One node and kind's window.
#[derive(Debug, Clone, Copy)]
struct Window {
    start: Instant,
    written: u32,
    suppressed: u64,
}

/// The per node and kind rate limit.
#[derive(Debug, Default)]
pub struct Limiter {
    windows: HashMap<(usize, &'static str), Window>,
}

/// Lines a window left out: node, kind, how many.
pub type Suppressed = (usize, &'static str, u64);

impl Limiter {
    /// May a line of `kind` for node `node` be written at `now`? (Counted
    /// either way.) Call [`Limiter::lifted`] first, so a window that ended
    /// reports what it left out before a new one starts.
    pub fn admit(&mut self, node: usize, kind: &'static str, now: Instant) -> bool {
        let w = self.windows.entry((node, kind)).or_insert(Window {
            start: now,
            written: 0,
            suppressed: 0,
        });
        if now.saturating_duration_since(w.start) >= WINDOW {
            *w = Window {
                start: now,
                written: 0,
                suppressed: 0,
            };
        }
        if w.written < LINES_PER_WINDOW {
            w.written += 1;
            true
        } else {
            w.suppressed += 1;
            false
        }
    }

    /// The windows that ended by `now` having left lines out (each
    /// reported once, in node and kind order).
    pub fn lifted(&mut self, now: Instant) -> Vec<Suppressed> {
        let mut out: Vec<Suppressed> = Vec::new();
        self.windows.retain(|&(node, kind), w| {
            if now.saturating_duration_since(w.start) < WINDOW {
                return true;
            }
            if w.suppressed > 0 {
                out.push((node, kind, w.suppressed));
            }
            false
        });
        out.sort();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_lines_per_node_and_kind_per_window_then_the_count() {
        let t0 = Instant::now();
        let mut l = Limiter::default();
        let admitted: Vec<bool> = (0..8)
            .map(|i| l.admit(0, "ice_onset", t0 + Duration::from_secs(i)))
            .collect();
        assert_eq!(
            admitted,
            [true, true, true, true, true, false, false, false]
        );
        // Another kind and another node have windows of their own.
        assert!(l.admit(0, "ice_cleared", t0));
        assert!(l.admit(1, "ice_onset", t0));
        assert!(l.lifted(t0 + WINDOW - Duration::from_millis(1)).is_empty());
        // The window ends: the three left out are reported once.
        assert_eq!(l.lifted(t0 + WINDOW), vec![(0, "ice_onset", 3)]);
        assert!(l.lifted(t0 + WINDOW * 2).is_empty());
        assert!(l.admit(0, "ice_onset", t0 + WINDOW));
    }
}
