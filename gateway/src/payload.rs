//! The JSON payloads the gateway publishes. The values are a
//! [`fois_link::Reading`] (or [`EventReading`]): units are converted there,
//! once, for this and for `foisctl`'s CSV log; units are in the key names
//! (`i1_ua`, `temperature_c`, `thickness_mm`). Every node message carries the
//! node's frame `seq` and `uptime_ms`, so a consumer can drop the duplicates
//! a gateway crash may cause (the pair is unique per node until it resets).

use fois_link::reading::{EstimateReading, EventReading, GainReading, IcingReading, Reading};
use fois_link::text::{firmware_text, unique_id_hex};
use fois_link::timefmt::iso_utc;
use fois_protocol::{Hello, Medium};
use serde::Serialize;

/// `<node>/measurement`: the reading's keys, flattened, after the node's
/// name, the frame's `seq` and the host time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeasurementJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// Frame sequence number.
    pub seq: u32,
    /// Host time of reception, Unix ms.
    pub host_unix_ms: u64,
    /// The same, ISO 8601 UTC.
    pub host_time_utc: String,
    /// Every value of the frame (`uptime_ms`, `i1_ua`, …, `faults`, the
    /// estimate's and the gain's keys when the node sent them).
    #[serde(flatten)]
    pub reading: &'a Reading,
}

impl<'a> MeasurementJson<'a> {
    /// The message of one frame.
    pub fn new(node: &'a str, seq: u32, reading: &'a Reading, host_unix_ms: u64) -> Self {
        MeasurementJson {
            node,
            seq,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            reading,
        }
    }
}

/// `<node>/state` (retained): what a dashboard shows. Published when
/// something discrete changes, the continuous values deadbanded
/// ([`crate::state_filter`]): Home Assistant's entities read it, and every
/// change of an entity is a row in its database.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StateJson {
    /// Node name.
    pub node: String,
    /// Sequence number of the frame it comes from.
    pub seq: u32,
    /// Node time of that frame, ms.
    pub uptime_ms: u64,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
    /// Host time, ISO 8601 UTC.
    pub host_time_utc: String,
    /// `dry`, `wet`, `ice`.
    pub state: &'static str,
    /// True when the detector says ice (the Home Assistant binary sensor).
    pub ice: bool,
    /// Alarm output on.
    pub alarm: bool,
    /// The alarm was acknowledged (output stays on while ice remains).
    pub alarm_acked: bool,
    /// Currents usable.
    pub valid: bool,
    /// Active faults.
    pub faults: Vec<&'static str>,
    /// A dark baseline is stored.
    pub dark_baseline: bool,
    /// Frames received from the node since the gateway started (refreshed
    /// at most every [`crate::state_filter::COUNTERS_EVERY`]).
    pub frames_received: u64,
    /// Frames missing from the sequence since the gateway started.
    pub frames_lost: u64,
    /// Net photocurrent of channel 1, µA (deadbanded).
    pub i1_ua: f64,
    /// Net photocurrent of channel 2, µA (deadbanded).
    pub i2_ua: f64,
    /// Air temperature, °C (deadbanded).
    pub temperature_c: f64,
    /// The node's ice estimate, when it sends one.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<EstimateReading>,
    /// The estimate's thickness when its medium is ice (glazed, rime), else
    /// 0: a water film is not ice.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ice_thickness_mm: Option<f64>,
    /// The estimate's thickness when its medium is water, else 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub water_film_mm: Option<f64>,
    /// The node's optical gain estimate, when it sends one.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub gain: Option<GainReading>,
    /// The node's icing rate and meteorological icing, when it sends them.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub icing: Option<IcingReading>,
}

impl StateJson {
    /// The state after one frame: its values exact (the filter holds them).
    pub fn new(node: &str, seq: u32, r: &Reading, frames: (u64, u64), host_unix_ms: u64) -> Self {
        let (frames_received, frames_lost) = frames;
        let film = |of: &[Medium]| {
            r.estimate.map(|e| {
                if of.contains(&e.medium) {
                    e.thickness_mm
                } else {
                    0.0
                }
            })
        };
        StateJson {
            node: node.to_string(),
            seq,
            uptime_ms: r.uptime_ms,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            state: r.state.name(),
            ice: r.ice(),
            alarm: r.alarm,
            alarm_acked: r.alarm_acked,
            valid: r.valid,
            faults: r.faults.clone(),
            dark_baseline: r.dark_baseline,
            frames_received,
            frames_lost,
            i1_ua: r.i1_ua,
            i2_ua: r.i2_ua,
            temperature_c: r.temperature_c,
            estimate: r.estimate,
            ice_thickness_mm: film(&[Medium::Glazed, Medium::Rime]),
            water_film_mm: film(&[Medium::Water]),
            gain: r.gain,
            icing: r.icing,
        }
    }

    /// True when `other` differs in something that must go out at once
    /// (state, alarm, acknowledgement, validity, faults, baseline, medium,
    /// presence of an estimate or a gain, the icing period on or off).
    pub fn differs_discretely(&self, other: &StateJson) -> bool {
        self.state != other.state
            || self.alarm != other.alarm
            || self.alarm_acked != other.alarm_acked
            || self.valid != other.valid
            || self.faults != other.faults
            || self.dark_baseline != other.dark_baseline
            || self.estimate.map(|e| e.medium) != other.estimate.map(|e| e.medium)
            || self.gain.is_some() != other.gain.is_some()
            || self.icing.map(|i| i.accreting) != other.icing.map(|i| i.accreting)
    }
}

/// `<node>/event` from the node (`source` = `node`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// `node`: the node sent it.
    pub source: &'static str,
    /// Frame sequence number.
    pub seq: u32,
    /// Host time of reception, Unix ms.
    pub host_unix_ms: u64,
    /// Host time, ISO 8601 UTC.
    pub host_time_utc: String,
    /// `kind`, `uptime_ms`, the currents, `temperature_c`, `frames`, the
    /// faults of a fault event.
    #[serde(flatten)]
    pub event: &'a EventReading,
}

impl<'a> EventJson<'a> {
    /// The message of one event frame.
    pub fn new(node: &'a str, seq: u32, event: &'a EventReading, host_unix_ms: u64) -> Self {
        EventJson {
            node,
            source: "node",
            seq,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            event,
        }
    }
}

/// `<node>/event` made by the gateway (`source` = `gateway`): the link came
/// or went, frames were lost, the node restarted.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinkEventJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// `gateway`.
    pub source: &'static str,
    /// `link_up`, `link_lost`, `frames_lost`, `node_restart`.
    pub kind: &'static str,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
    /// Host time, ISO 8601 UTC.
    pub host_time_utc: String,
    /// The frame it refers to (gaps, restarts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seq: Option<u32>,
    /// `frames_lost`: how many.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_lost: Option<u64>,
    /// Free text (reason, port, identity).
    pub detail: String,
}

impl<'a> LinkEventJson<'a> {
    /// A gateway event.
    pub fn new(node: &'a str, kind: &'static str, detail: String, host_unix_ms: u64) -> Self {
        LinkEventJson {
            node,
            source: "gateway",
            kind,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            seq: None,
            frames_lost: None,
            detail,
        }
    }
}

/// `<node>/info` (retained).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InfoJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// Serial port.
    pub port: &'a str,
    /// Board name.
    pub board: String,
    /// Firmware version, `major.minor.patch`.
    pub firmware: String,
    /// Protocol version.
    pub protocol: u16,
    /// MCU unique id, hex.
    pub unique_id: String,
    /// Why the node last reset.
    pub reset_reason: String,
}

impl<'a> InfoJson<'a> {
    /// Build from a hello.
    pub fn new(node: &'a str, port: &'a str, h: &Hello) -> Self {
        InfoJson {
            node,
            port,
            board: h.board_name().to_string(),
            firmware: firmware_text(h),
            protocol: h.protocol_version,
            unique_id: unique_id_hex(h),
            reset_reason: format!("{:?}", h.reset_reason),
        }
    }
}

/// `<node>/command/result`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CommandResultJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// `ack` or `calibrate-dark` (or what was asked).
    pub command: &'a str,
    /// Carried out.
    pub ok: bool,
    /// The node's answer or why it was not sent.
    pub detail: String,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

/// `<node>/update/progress` (QoS 0): one event of a node's update.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UpdateProgressJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// The image's file name.
    pub image: &'a str,
    /// `step`, `progress`, `retry` or `resumed`.
    pub event: &'static str,
    /// The step (connect, begin, transfer, verify, commit, reboot, confirm).
    pub step: Option<&'static str>,
    /// Bytes the node has.
    pub done: Option<u32>,
    /// Bytes of the image.
    pub total: Option<u32>,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

/// `<node>/update/result` (retained): how a node's update ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UpdateResultJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// The image's file name.
    pub image: &'a str,
    /// The node runs the image, confirmed.
    pub ok: bool,
    /// The versions, or why it failed.
    pub detail: String,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

/// `<gw>/firmware/result` (retained): a roll-out's end, or why a roll-out
/// command was refused.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RolloutResultJson {
    /// The image's file name (as the command gave it).
    pub image: String,
    /// Every node updated.
    pub ok: bool,
    /// In words.
    pub detail: String,
    /// The nodes updated, in order.
    pub updated: Vec<String>,
    /// The node that failed (the roll-out stopped there).
    pub failed: Option<String>,
    /// The nodes not reached.
    pub not_reached: Vec<String>,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

/// `<gw>/status` (retained).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusJson {
    /// Gateway name.
    pub gateway: String,
    /// Nodes configured.
    pub nodes: usize,
    /// Nodes connected now.
    pub nodes_online: usize,
    /// Records (events, measurements) published and acknowledged by the broker.
    pub records_acked: u64,
    /// Records waiting in the disk queue.
    pub queue_records: u64,
    /// Bytes of the queue on disk.
    pub queue_bytes: u64,
    /// Records the queue lost, ever (its bound, a full or vanished disk;
    /// oldest measurements first, events never while memory lasts).
    pub queue_dropped: u64,
    /// Gateway uptime, s.
    pub uptime_s: u64,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::{Event, EventKind, GainEstimate, flags};

    use fois_link::fixtures::{iced_measurement as meas, rime_estimate};

    #[test]
    fn measurement_keys_carry_units_values_and_the_gain() {
        let est = rime_estimate();
        let mut m = meas();
        m.flags |= flags::GAIN_OUT_OF_BAND;
        let gain = GainEstimate {
            gain_ppm: 820_000,
            sigma_ppm: 40_000,
        };
        let r = Reading::new(&m, Some(&est), Some(&gain));
        let v: serde_json::Value =
            serde_json::to_value(MeasurementJson::new("n1", 7, &r, 1_000)).unwrap();
        assert_eq!(v["node"], "n1");
        assert_eq!(v["seq"], 7);
        assert_eq!(v["uptime_ms"], 12_345);
        assert_eq!(v["i1_ua"], 1.5);
        assert_eq!(v["i2_ua"], -0.25);
        assert_eq!(v["ambient1_ua"], 20.0);
        assert_eq!(v["temperature_c"], -5.12);
        assert_eq!(v["state"], "ice");
        assert_eq!(v["alarm"], true);
        assert_eq!(
            v["faults"],
            serde_json::json!(["ntc_open", "gain_out_of_band"])
        );
        assert_eq!(v["thickness_mm"], 1.25);
        assert_eq!(v["thickness_sigma_mm"], 0.08);
        assert_eq!(v["medium"], "rime");
        assert_eq!(v["medium_probability"], 0.93);
        assert_eq!(v["gain"], 0.82);
        assert_eq!(v["gain_sigma"], 0.04);
        assert_eq!(v["host_time_utc"], "1970-01-01T00:00:01.000Z");
        // No estimate, no gain: no such keys at all (not null).
        let r = Reading::new(&meas(), None, None);
        let v = serde_json::to_value(MeasurementJson::new("n1", 7, &r, 0)).unwrap();
        assert!(
            v.get("thickness_mm").is_none() && v.get("gain").is_none(),
            "{v}"
        );
    }

    #[test]
    fn state_says_ice_acked_gain_and_detects_changes() {
        let gain = GainEstimate {
            gain_ppm: 1_000_000,
            sigma_ppm: 50_000,
        };
        let s = StateJson::new(
            "n1",
            1,
            &Reading::new(&meas(), None, Some(&gain)),
            (40, 3),
            0,
        );
        let v = serde_json::to_value(&s).unwrap();
        assert_eq!(v["ice"], true);
        assert_eq!(v["alarm_acked"], true);
        assert_eq!(v["frames_lost"], 3);
        assert_eq!(v["frames_received"], 40);
        assert_eq!(v["i1_ua"], 1.5);
        assert_eq!(v["temperature_c"], -5.12);
        assert_eq!(v["gain"], 1.0);
        assert_eq!(v["gain_sigma"], 0.05);
        let mut m = meas();
        m.uptime_ms += 100;
        let same = StateJson::new("n1", 2, &Reading::new(&m, None, Some(&gain)), (41, 3), 5);
        assert!(!s.differs_discretely(&same));
        m.flags &= !flags::ALARM_ACKED;
        let unacked = StateJson::new("n1", 3, &Reading::new(&m, None, Some(&gain)), (41, 3), 5);
        assert!(s.differs_discretely(&unacked));
        m.flags |= flags::ALARM_ACKED | flags::GAIN_OUT_OF_BAND;
        let out_of_band = StateJson::new("n1", 4, &Reading::new(&m, None, Some(&gain)), (41, 3), 5);
        assert!(s.differs_discretely(&out_of_band), "a new fault");
    }

    #[test]
    fn fault_event_names_its_faults() {
        let e = Event {
            uptime_ms: 5,
            kind: EventKind::FaultRaised(flags::NTC_SHORT | flags::CLOCK_FALLBACK),
            i1_na: 0,
            i2_na: 0,
            rise1_na: 0,
            temperature_centi_c: 0,
            frames: 1,
        };
        let r = EventReading::new(&e);
        let v = serde_json::to_value(EventJson::new("n", 9, &r, 0)).unwrap();
        assert_eq!(v["kind"], "fault_raised");
        assert_eq!(v["source"], "node");
        assert_eq!(v["seq"], 9);
        assert_eq!(v["uptime_ms"], 5);
        assert_eq!(
            v["faults"],
            serde_json::json!(["ntc_short", "clock_fallback"])
        );
    }
}
