//! What one run produced, from decoded frames only (plus the truth): the
//! [`Outcome`] the runner fills and the checks, the report and the
//! accuracy table read.

use std::time::Duration;

use fois_protocol::{AckResult, DetectorState, ErrorCode, EventKind};
use fois_vnode::{Cover, Truth};

use crate::scenario::Class;

/// Water in air at or below this temperature counts as freezing, not as a
/// false alarm, °C: the NTC's ±0.5 K near 0 °C plus the rule's +0.5 °C
/// freeze limit (firmware/README.md) — inside this band the node cannot
/// tell water from ice, by design.
pub const WATER_FREEZING_BAND_C: f64 = 1.0;

/// An event frame as decoded, with the truth at its time.
#[derive(Debug, Clone)]
pub struct Seen {
    /// Sequence number of the frame.
    pub seq: u32,
    /// Event time (node uptime = virtual time), s.
    pub t_s: f64,
    /// What happened.
    pub kind: EventKind,
    /// I1 rise over the baseline the node reported, nA.
    pub rise1_na: i32,
    /// Temperature the node reported, °C.
    pub temperature_c: f64,
    /// The environment at that instant.
    pub truth: Truth,
}

/// One frame's ice estimate beside the truth (accuracy scenarios).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstSample {
    /// Node uptime, s.
    pub t_s: f64,
    /// What covers the face and how thick it is (truth).
    pub cover: Cover,
    /// True thickness, mm.
    pub true_mm: f64,
    /// Estimated thickness, mm.
    pub est_mm: f64,
    /// Its σ, mm.
    pub sigma_mm: f64,
    /// The most likely medium the node reported.
    pub medium: fois_protocol::Medium,
    /// The true relative optical gain g (LED × temperature factor × face
    /// transmission², `fois_vnode::optics`).
    pub true_gain: f64,
    /// The node's gain estimate and its σ (`MeasurementV3::gain`), if sent.
    pub gain: Option<(f64, f64)>,
    /// The true growth rate, mm/h: the segment's, while ice grows on the
    /// face (0 on a dry face, a paused one, water).
    pub true_rate_mm_per_h: f64,
    /// The node's icing rate (`MeasurementV5::icing`), if sent.
    pub icing: Option<IcingSample>,
}

/// The node's icing rate and period in one frame (`IcingEstimate`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcingSample {
    /// Posterior mean growth rate, mm/h.
    pub rate_mm_per_h: f64,
    /// Its σ, mm/h.
    pub sigma_mm_per_h: f64,
    /// P(accreting), 0–1.
    pub p_accreting: f64,
    /// The icing period's flag.
    pub accreting: bool,
}

impl EstSample {
    /// The estimate is confidently thin: est + 2σ < half the true
    /// thickness (the node would tell a de-icing system there is far less
    /// ice than there is, and be sure of it).
    pub fn confidently_thin(&self) -> bool {
        self.est_mm + 2.0 * self.sigma_mm < 0.5 * self.true_mm
    }
}

/// A reply to a command.
#[derive(Debug, Clone)]
pub struct ReplySeen {
    /// Command id.
    pub id: u16,
    /// Virtual time the reply arrived, s.
    pub t_s: f64,
    /// Ack result or error code.
    pub result: Result<AckResult, ErrorCode>,
}

/// Everything one run produced, from decoded frames only (plus the truth).
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Scenario name.
    pub name: String,
    /// Goal class.
    pub class: Class,
    /// Sensor kind name.
    pub sensor: &'static str,
    /// Expectations asserted (false: a sweep level reported only).
    pub checked: bool,
    /// Sweep level, rms LSB.
    pub sweep_lsb: Option<f64>,
    /// Virtual time run, s.
    pub virtual_s: f64,
    /// Frames the node ran (from the runner, for the frame rate).
    pub node_frames: u64,
    /// Frames decoded.
    pub decoded: u64,
    /// Measurements decoded.
    pub measurements: u64,
    /// Measurements flagged saturated (invalid).
    pub saturated: u64,
    /// Hello frames.
    pub hellos: u64,
    /// Rule and fault events, in order.
    pub events: Vec<Seen>,
    /// The icing period's events (`IcingStarted`, `IcingEnded`: the
    /// growth history's), with their node time, s.
    pub icing_events: Vec<(f64, EventKind)>,
    /// Replies to commands (and to the button), in order.
    pub replies: Vec<ReplySeen>,
    /// The commands sent: (id, virtual time s); the button's id is
    /// `BUTTON_ID`. The config's `SetConfig` (if any) comes first.
    pub sent: Vec<(u16, f64)>,
    /// `Error` frames with no command of ours behind them.
    pub stray_errors: u32,
    /// States of the measurements, repeats merged.
    pub states: Vec<DetectorState>,
    /// State of the last measurement.
    pub final_state: Option<DetectorState>,
    /// Frames missing from the sequence numbers.
    pub seq_missing: u64,
    /// Frames the decoder rejected (CRC, COBS, oversized, malformed).
    pub rejected: u64,
    /// Frames dropped or corrupted by the scenario's lossy link.
    pub link_dropped: u64,
    /// Frames corrupted by the lossy link.
    pub link_corrupted: u64,
    /// When ice first covers the face (truth), s.
    pub ice_start_s: Option<f64>,
    /// Inconsistencies between frames, or frames and the alarm pin.
    pub inconsistencies: Vec<String>,
    /// Smallest and largest I1 the measurements reported, nA.
    pub i1_range_na: Option<(i32, i32)>,
    /// The estimates of every measurement beside the truth (scenarios with
    /// `accuracy = true` only; empty otherwise).
    pub estimates: Vec<EstSample>,
    /// Measurements with water on the face above the freezing band.
    pub warm_water_frames: u64,
    /// … of which the node's estimate called ice (glazed or rime).
    pub warm_water_called_ice: u64,
    /// Wall time of the run.
    pub wall: Duration,
    /// Expectations that failed (filled by [`crate::check`]).
    pub failures: Vec<String>,
}

impl Outcome {
    /// The first `IceOnset`.
    pub fn first_alarm(&self) -> Option<&Seen> {
        self.events.iter().find(|e| e.kind == EventKind::IceOnset)
    }

    /// Alarms with no ice on the face: dry, or water above the freezing band.
    pub fn false_alarms(&self) -> u32 {
        self.events
            .iter()
            .filter(|e| e.kind == EventKind::IceOnset && is_false_alarm(&e.truth))
            .count() as u32
    }

    /// `IceCleared` while ice is still on the face in freezing air.
    pub fn dropped_alarms(&self) -> u32 {
        self.events
            .iter()
            .filter(|e| {
                e.kind == EventKind::IceCleared
                    && matches!(e.truth.cover, Cover::Flat | Cover::Glazed | Cover::Rime)
                    && e.truth.thickness_mm > 0.0
                    && e.truth.air_temp_c <= 0.0
            })
            .count() as u32
    }

    /// First alarm time minus the time ice first covered the face, s.
    pub fn latency_s(&self) -> Option<f64> {
        Some(self.first_alarm()?.t_s - self.ice_start_s?)
    }

    /// Frames lost between node and decoder (sequence gaps + rejected frames
    /// that left no gap are both counted once: the sequence gap counts them).
    pub fn frames_lost(&self) -> u64 {
        self.seq_missing
    }
}

/// True when an alarm at this truth is a false one.
pub fn is_false_alarm(t: &Truth) -> bool {
    match t.cover {
        Cover::Dry => true,
        Cover::Water => t.air_temp_c > WATER_FREEZING_BAND_C,
        _ => t.thickness_mm <= 0.0,
    }
}

impl Outcome {
    /// Nothing observed yet: a Sensor B run, checked, no sweep, no ice.
    pub(crate) fn empty(name: &str, class: Class) -> Self {
        Outcome {
            name: name.to_string(),
            class,
            sensor: "B",
            checked: true,
            sweep_lsb: None,
            virtual_s: 0.0,
            node_frames: 0,
            decoded: 0,
            measurements: 0,
            saturated: 0,
            hellos: 0,
            events: Vec::new(),
            icing_events: Vec::new(),
            replies: Vec::new(),
            sent: Vec::new(),
            stray_errors: 0,
            states: Vec::new(),
            final_state: None,
            seq_missing: 0,
            rejected: 0,
            link_dropped: 0,
            link_corrupted: 0,
            ice_start_s: None,
            inconsistencies: Vec::new(),
            i1_range_na: None,
            estimates: Vec::new(),
            warm_water_frames: 0,
            warm_water_called_ice: 0,
            wall: Duration::ZERO,
            failures: Vec::new(),
        }
    }
}

/// An empty outcome for the unit tests of the modules that read outcomes.
#[cfg(test)]
pub(crate) mod tests_support {
    use super::*;

    pub(crate) fn outcome(name: &str) -> Outcome {
        Outcome::empty(name, crate::scenario::Class::Rime)
    }
}
