//! The ice rule: dry / wet / ice, with debounce and hysteresis.
//!
//! Input per valid frame: the rise of I1 over its dark baseline and the air
//! temperature. A *film* is a rise above `onset_rise_na`; the film is *gone*
//! below `clear_rise_na` (< onset: hysteresis); *cold* is at or below
//! `freeze_limit_centi_c`; *thawing* is above `thaw_limit_centi_c`.
//!
//! - Dry → Ice: a film on N (`onset_frames`) consecutive cold frames.
//! - Dry → Wet: a film on N consecutive frames, the last one not cold.
//! - Wet → Ice: a film on N consecutive cold frames (the water froze).
//! - Wet → Dry: the film gone for M (`clear_frames`) consecutive frames.
//! - Ice → Dry: the film gone for M consecutive frames.
//! - Ice → Wet/Dry: thawing on N consecutive frames (Wet if a film remains).
//!
//! Frames flagged invalid (saturated) are skipped: they neither advance nor
//! reset a counter, and never change the state.
//!
//! Without an air temperature (NTC open or shorted) the air counts as cold
//! and never as thawing: a film then means ice (an alarm rather than a
//! wrong all-clear), and ice clears only when the film is optically gone.

use fois_protocol::{Config, DetectorState, EventKind};

/// What the rule sees of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RuleInput {
    /// I1 minus its dark baseline, nA.
    pub rise1_na: i32,
    /// Air temperature, 0.01 °C.
    pub temperature_centi_c: i16,
    /// False when the air temperature is unknown (NTC fault): the rule then
    /// takes the air as cold and never as thawing.
    pub air_known: bool,
    /// False for a saturated frame: the rule ignores it.
    pub valid: bool,
}

/// A state change and how many consecutive frames met its condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transition {
    /// The event to send.
    pub kind: EventKind,
    /// Consecutive frames that met the condition.
    pub frames: u16,
    /// The state before.
    pub from: DetectorState,
    /// The state after.
    pub to: DetectorState,
}

/// The rule's state and counters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rule {
    state: DetectorState,
    /// Consecutive frames with a film.
    film: u16,
    /// Consecutive frames with a film at or below the freezing limit.
    cold_film: u16,
    /// Consecutive frames with the film gone.
    gone: u16,
    /// Consecutive frames above the thaw limit.
    thaw: u16,
    acked: bool,
}

impl Default for Rule {
    fn default() -> Self {
        Self::new()
    }
}

impl Rule {
    /// Dry, counters at zero.
    pub const fn new() -> Self {
        Rule {
            state: DetectorState::Dry,
            film: 0,
            cold_film: 0,
            gone: 0,
            thaw: 0,
            acked: false,
        }
    }

    /// The rule resumed in `state` after a reset (counters at zero; the
    /// acknowledgement kept only while iced): see `platform::boot::RuleSnapshot`.
    pub const fn resumed(state: DetectorState, acked: bool) -> Self {
        let mut rule = Rule::new();
        rule.state = state;
        rule.acked = acked && matches!(state, DetectorState::Ice);
        rule
    }

    /// The current state.
    pub fn state(&self) -> DetectorState {
        self.state
    }

    /// True while iced: the alarm output and LD2 are on.
    pub fn alarm(&self) -> bool {
        self.state == DetectorState::Ice
    }

    /// True when the user acknowledged the present alarm.
    pub fn acked(&self) -> bool {
        self.acked && self.alarm()
    }

    /// Acknowledge the alarm (only meaningful while iced; the output stays on
    /// while the ice holds). Returns true if an alarm was acknowledged.
    pub fn acknowledge(&mut self) -> bool {
        self.acked = self.alarm();
        self.acked
    }

    /// Feed one frame; returns the transition it caused, if any.
    pub fn step(&mut self, cfg: &Config, input: RuleInput) -> Option<Transition> {
        if !input.valid {
            return None;
        }
        let rise = i64::from(input.rise1_na);
        let film = rise > i64::from(cfg.onset_rise_na);
        let gone = rise < i64::from(cfg.clear_rise_na);
        let cold = !input.air_known || input.temperature_centi_c <= cfg.freeze_limit_centi_c;
        let thawing = input.air_known && input.temperature_centi_c > cfg.thaw_limit_centi_c;
        let n = cfg.onset_frames.max(1);
        let m = cfg.clear_frames.max(1);

        bump(&mut self.film, film);
        bump(&mut self.cold_film, film && cold);
        bump(&mut self.gone, gone);
        bump(&mut self.thaw, thawing);

        let from = self.state;
        let (to, kind, frames) = match self.state {
            DetectorState::Dry if self.cold_film >= n => {
                (DetectorState::Ice, EventKind::IceOnset, self.cold_film)
            }
            DetectorState::Dry if self.film >= n && !cold => {
                (DetectorState::Wet, EventKind::WetOnset, self.film)
            }
            DetectorState::Wet if self.cold_film >= n => {
                (DetectorState::Ice, EventKind::IceOnset, self.cold_film)
            }
            DetectorState::Wet if self.gone >= m => {
                (DetectorState::Dry, EventKind::WetCleared, self.gone)
            }
            DetectorState::Ice if self.gone >= m => {
                (DetectorState::Dry, EventKind::IceCleared, self.gone)
            }
            DetectorState::Ice if self.thaw >= n => {
                let to = if gone {
                    DetectorState::Dry
                } else {
                    DetectorState::Wet
                };
                (to, EventKind::IceCleared, self.thaw)
            }
            _ => return None,
        };
        self.state = to;
        self.acked = false;
        // A new state starts its own counts: the evidence is used once.
        self.film = 0;
        self.cold_film = 0;
        self.gone = 0;
        self.thaw = 0;
        Some(Transition {
            kind,
            frames,
            from,
            to,
        })
    }
}

fn bump(counter: &mut u16, condition: bool) {
    *counter = if condition {
        counter.saturating_add(1)
    } else {
        0
    };
}
