//! The JSON payloads the gateway publishes. Units are in the key names
//! (`i1_ua`, `temperature_c`, `thickness_mm`); every node message carries the
//! node's frame `seq` and `uptime_ms`, so a consumer can drop the duplicates
//! a gateway crash may cause (the pair is unique per node until it resets).

use fois_protocol::{DetectorState, Event, EventKind, Hello, IceEstimate, Measurement, flags};
use serde::Serialize;

use crate::text::{centi_c_to_c, na_to_ua};
use crate::timefmt::iso_utc;

/// Names of the fault bits set in `bits` (see `fois_protocol::flags`).
pub fn fault_names(bits: u16) -> Vec<&'static str> {
    [
        (flags::NTC_OPEN, "ntc_open"),
        (flags::NTC_SHORT, "ntc_short"),
        (flags::CONFIG_DEFAULTED, "config_defaulted"),
        (flags::VDDA_OUT_OF_RANGE, "vdda_out_of_range"),
        (flags::STORAGE_FAILED, "storage_failed"),
        (flags::CLOCK_FALLBACK, "clock_fallback"),
    ]
    .into_iter()
    .filter(|(b, _)| bits & b != 0)
    .map(|(_, n)| n)
    .collect()
}

/// The ice estimate's keys (flattened into measurement and state).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EstimateJson {
    /// Posterior mean thickness, mm.
    pub thickness_mm: f64,
    /// Its standard deviation, mm.
    pub thickness_sigma_mm: f64,
    /// Most likely medium.
    pub medium: &'static str,
    /// Probability of that medium, 0–1.
    pub medium_probability: f64,
}

impl From<&IceEstimate> for EstimateJson {
    fn from(e: &IceEstimate) -> Self {
        EstimateJson {
            thickness_mm: f64::from(e.thickness_um) / 1000.0,
            thickness_sigma_mm: f64::from(e.sigma_um) / 1000.0,
            medium: e.medium.name(),
            medium_probability: f64::from(e.probability_permille) / 1000.0,
        }
    }
}

/// `<node>/measurement`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeasurementJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// Frame sequence number.
    pub seq: u32,
    /// Node time since boot, ms.
    pub uptime_ms: u64,
    /// Host time of reception, Unix ms.
    pub host_unix_ms: u64,
    /// The same, ISO 8601 UTC.
    pub host_time_utc: String,
    /// Net photocurrent channel 1, µA.
    pub i1_ua: f64,
    /// Net photocurrent channel 2, µA.
    pub i2_ua: f64,
    /// Ambient level channel 1, µA.
    pub ambient1_ua: f64,
    /// Ambient level channel 2, µA.
    pub ambient2_ua: f64,
    /// Air temperature, °C.
    pub temperature_c: f64,
    /// Analog supply, mV.
    pub vdda_mv: u16,
    /// `dry`, `wet`, `ice`.
    pub state: &'static str,
    /// Alarm output on.
    pub alarm: bool,
    /// Currents usable (no saturation).
    pub valid: bool,
    /// Raw flag bits.
    pub flags: u16,
    /// Active faults.
    pub faults: Vec<&'static str>,
    /// The node's estimate, when it sends one.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<EstimateJson>,
}

impl<'a> MeasurementJson<'a> {
    /// Build from a frame.
    pub fn new(
        node: &'a str,
        seq: u32,
        m: &Measurement,
        estimate: Option<&IceEstimate>,
        host_unix_ms: u64,
    ) -> Self {
        MeasurementJson {
            node,
            seq,
            uptime_ms: m.uptime_ms,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            i1_ua: na_to_ua(m.i1_na.into()),
            i2_ua: na_to_ua(m.i2_na.into()),
            ambient1_ua: na_to_ua(m.ambient1_na.into()),
            ambient2_ua: na_to_ua(m.ambient2_na.into()),
            temperature_c: centi_c_to_c(m.temperature_centi_c),
            vdda_mv: m.vdda_mv,
            state: m.state.name(),
            alarm: m.flags & flags::ALARM != 0,
            valid: m.is_valid(),
            flags: m.flags,
            faults: fault_names(m.flags & flags::FAULT_MASK),
            estimate: estimate.map(EstimateJson::from),
        }
    }
}

/// `<node>/state` (retained): what a dashboard shows.
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
    /// Frames missing from the sequence since the gateway started.
    pub frames_lost: u64,
    /// The node's estimate, when it sends one.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<EstimateJson>,
}

impl StateJson {
    /// Build from a frame.
    pub fn new(
        node: &str,
        seq: u32,
        m: &Measurement,
        estimate: Option<&IceEstimate>,
        frames_lost: u64,
        host_unix_ms: u64,
    ) -> Self {
        StateJson {
            node: node.to_string(),
            seq,
            uptime_ms: m.uptime_ms,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            state: m.state.name(),
            ice: m.state == DetectorState::Ice,
            alarm: m.flags & flags::ALARM != 0,
            alarm_acked: m.flags & flags::ALARM_ACKED != 0,
            valid: m.is_valid(),
            faults: fault_names(m.flags & flags::FAULT_MASK),
            dark_baseline: m.flags & flags::NO_BASELINE == 0,
            frames_lost,
            estimate: estimate.map(EstimateJson::from),
        }
    }

    /// True when `other` differs in something that must go out at once
    /// (state, alarm, acknowledgement, validity, faults, baseline, medium,
    /// presence of an estimate).
    pub fn differs_discretely(&self, other: &StateJson) -> bool {
        self.state != other.state
            || self.alarm != other.alarm
            || self.alarm_acked != other.alarm_acked
            || self.valid != other.valid
            || self.faults != other.faults
            || self.dark_baseline != other.dark_baseline
            || self.estimate.map(|e| e.medium) != other.estimate.map(|e| e.medium)
    }

    /// True when the thickness moved by at least `mm`.
    pub fn thickness_moved(&self, other: &StateJson, mm: f64) -> bool {
        match (self.estimate, other.estimate) {
            (Some(a), Some(b)) => (a.thickness_mm - b.thickness_mm).abs() >= mm,
            _ => false,
        }
    }
}

/// `<node>/event` from the node (`source` = `node`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventJson<'a> {
    /// Node name.
    pub node: &'a str,
    /// `node`: the node sent it.
    pub source: &'static str,
    /// `ice_onset`, `ice_cleared`, `wet_onset`, `wet_cleared`,
    /// `fault_raised`, `fault_cleared`.
    pub kind: &'static str,
    /// Frame sequence number.
    pub seq: u32,
    /// Node time, ms.
    pub uptime_ms: u64,
    /// Host time of reception, Unix ms.
    pub host_unix_ms: u64,
    /// Host time, ISO 8601 UTC.
    pub host_time_utc: String,
    /// Net current channel 1 of the frame that caused it, µA.
    pub i1_ua: f64,
    /// Net current channel 2, µA.
    pub i2_ua: f64,
    /// Channel-1 rise over the dark baseline, µA.
    pub rise1_ua: f64,
    /// Air temperature, °C.
    pub temperature_c: f64,
    /// Consecutive frames that met the condition.
    pub frames: u16,
    /// Fault events: the faults raised or cleared.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<&'static str>,
}

impl<'a> EventJson<'a> {
    /// Build from a frame.
    pub fn new(node: &'a str, seq: u32, e: &Event, host_unix_ms: u64) -> Self {
        let faults = match e.kind {
            EventKind::FaultRaised(b) | EventKind::FaultCleared(b) => fault_names(b),
            _ => Vec::new(),
        };
        EventJson {
            node,
            source: "node",
            kind: e.kind.name(),
            seq,
            uptime_ms: e.uptime_ms,
            host_unix_ms,
            host_time_utc: iso_utc(host_unix_ms),
            i1_ua: na_to_ua(e.i1_na.into()),
            i2_ua: na_to_ua(e.i2_na.into()),
            rise1_ua: na_to_ua(e.rise1_na.into()),
            temperature_c: centi_c_to_c(e.temperature_centi_c),
            frames: e.frames,
            faults,
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

/// The unique id as lower-case hex.
pub fn unique_id_hex(h: &Hello) -> String {
    h.unique_id.iter().map(|b| format!("{b:02x}")).collect()
}

impl<'a> InfoJson<'a> {
    /// Build from a hello.
    pub fn new(node: &'a str, port: &'a str, h: &Hello) -> Self {
        let [a, b, c] = h.firmware_version;
        InfoJson {
            node,
            port,
            board: h.board_name().to_string(),
            firmware: format!("{a}.{b}.{c}"),
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
    /// Records dropped because the queue hit its bound (oldest first), since
    /// the queue was created.
    pub queue_dropped: u64,
    /// Gateway uptime, s.
    pub uptime_s: u64,
    /// Host time, Unix ms.
    pub host_unix_ms: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::Medium;

    fn meas() -> Measurement {
        Measurement {
            uptime_ms: 12_345,
            i1_na: 1_500,
            i2_na: -250,
            ambient1_na: 20_000,
            ambient2_na: 0,
            temperature_centi_c: -512,
            vdda_mv: 3300,
            flags: flags::ALARM | flags::NTC_OPEN | flags::ALARM_ACKED,
            state: DetectorState::Ice,
        }
    }

    #[test]
    fn measurement_keys_carry_units_and_values() {
        let est = IceEstimate {
            thickness_um: 1_250,
            sigma_um: 80,
            medium: Medium::Rime,
            probability_permille: 930,
        };
        let v: serde_json::Value =
            serde_json::to_value(MeasurementJson::new("n1", 7, &meas(), Some(&est), 1_000))
                .unwrap();
        assert_eq!(v["node"], "n1");
        assert_eq!(v["seq"], 7);
        assert_eq!(v["uptime_ms"], 12_345);
        assert_eq!(v["i1_ua"], 1.5);
        assert_eq!(v["i2_ua"], -0.25);
        assert_eq!(v["ambient1_ua"], 20.0);
        assert_eq!(v["temperature_c"], -5.12);
        assert_eq!(v["state"], "ice");
        assert_eq!(v["alarm"], true);
        assert_eq!(v["faults"], serde_json::json!(["ntc_open"]));
        assert_eq!(v["thickness_mm"], 1.25);
        assert_eq!(v["thickness_sigma_mm"], 0.08);
        assert_eq!(v["medium"], "rime");
        assert_eq!(v["medium_probability"], 0.93);
        assert_eq!(v["host_time_utc"], "1970-01-01T00:00:01.000Z");
        // No estimate: no thickness keys at all (not null).
        let v = serde_json::to_value(MeasurementJson::new("n1", 7, &meas(), None, 0)).unwrap();
        assert!(v.get("thickness_mm").is_none(), "{v}");
    }

    #[test]
    fn state_says_ice_acked_and_detects_changes() {
        let s = StateJson::new("n1", 1, &meas(), None, 3, 0);
        let v = serde_json::to_value(&s).unwrap();
        assert_eq!(v["ice"], true);
        assert_eq!(v["alarm_acked"], true);
        assert_eq!(v["frames_lost"], 3);
        let mut m = meas();
        m.uptime_ms += 100;
        assert!(!s.differs_discretely(&StateJson::new("n1", 2, &m, None, 3, 5)));
        m.flags &= !flags::ALARM_ACKED;
        assert!(s.differs_discretely(&StateJson::new("n1", 3, &m, None, 3, 5)));
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
        let v = serde_json::to_value(EventJson::new("n", 9, &e, 0)).unwrap();
        assert_eq!(v["kind"], "fault_raised");
        assert_eq!(v["source"], "node");
        assert_eq!(
            v["faults"],
            serde_json::json!(["ntc_short", "clock_fallback"])
        );
    }
}
