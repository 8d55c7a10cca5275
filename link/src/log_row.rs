//! One row of the monitor's CSV log: the column list ([`HEADER`]), a row
//! ([`Row`]) and its fields as text ([`row_fields`]). `foisctl monitor`
//! (fois-host's `csvlog`) and the fleet gateway's daily logs both write rows
//! through this, so both files have one layout.
//!
//! Columns ([`HEADER`]), empty where they do not apply:
//!
//! | column | unit | meaning |
//! | --- | --- | --- |
//! | `host_time_utc` | ISO-8601 | host clock when the row was made |
//! | `host_unix_ms` | ms | the same, Unix milliseconds |
//! | `kind` | | `measurement`, `event`, `hello`, `ack`, `error`, `gap`, `link_lost`, `link_up`, `node_restart`, `rejected`, `note` |
//! | `seq` | | the node's frame sequence number |
//! | `uptime_ms` | ms | node time since boot |
//! | `i1_ua`, `i2_ua` | µA | net photocurrents (LED on − off) |
//! | `ambient1_ua`, `ambient2_ua` | µA | ambient level (LED off) |
//! | `temperature_c` | °C | air temperature |
//! | `vdda_mv` | mV | analog supply |
//! | `state` | | `Dry`, `Wet`, `Ice` |
//! | `alarm` | 0/1 | alarm output on |
//! | `valid` | 0/1 | currents usable (no saturation) |
//! | `flags` | | the node's status bits as one number (`fois_protocol::flags`: 1 ch1 saturated, 2 ch2 saturated, 4 NTC open, 8 NTC short, 16 config defaulted, 32 no dark baseline, 64 alarm on, 128 alarm acknowledged, 256 V_DDA out of range, 512 flash write failed, 1024 clock fallback, 2048 brown-out level not set, 4096 store skipped, 8192 gain out of band) |
//! | `faults` | | the fault bits among them by name, space-separated (`ntc_open gain_out_of_band`); on `fault_raised`/`fault_cleared` event rows the faults raised or cleared. Logs written before this column existed read the same (columns are found by name) |
//! | `frames_lost` | frames | `gap` rows: frames missing from the sequence |
//! | `detail` | | event kind, error, answer, reason |
//! | `est_thickness_mm` | mm | the node's ice estimate: posterior mean thickness (protocol v2 nodes; empty for v1) |
//! | `est_sigma_mm` | mm | its standard deviation |
//! | `est_kind` | | most likely medium: `dry`, `water`, `glazed`, `rime` |
//! | `est_p` | 0–1 | posterior probability of that medium |
//! | `est_gain` | 1 = table | the node's estimate of its optical gain (protocol v3 nodes; empty for older) |
//! | `est_gain_sigma` | | its standard deviation |
//! | `est_rate_mm_per_h` | mm/h | the node's icing rate: posterior mean growth rate now, 0 while nothing grows (protocol v5 nodes; empty for older) |
//! | `est_rate_sigma_mm_per_h` | mm/h | its standard deviation |
//! | `est_accreting` | 0/1 | meteorological icing: an icing period is on (the node's P(accreting) with hysteresis) |

use fois_protocol::{DeviceMsg, Event};

use crate::reading::{EventReading, Reading};
use crate::text::{ack_text, error_text, event_name, hello_text};
use crate::timefmt::iso_utc;

/// The header line (without newline).
pub const HEADER: &str = "host_time_utc,host_unix_ms,kind,seq,uptime_ms,i1_ua,i2_ua,ambient1_ua,ambient2_ua,temperature_c,vdda_mv,state,alarm,valid,flags,faults,frames_lost,detail,est_thickness_mm,est_sigma_mm,est_kind,est_p,est_gain,est_gain_sigma,est_rate_mm_per_h,est_rate_sigma_mm_per_h,est_accreting";

/// One row of the log. Build it with the constructors, then the log writer (fois-host `CsvLog::write`, the gateway's daily log).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Row {
    /// Host time, Unix ms (0 = now, filled in by the writer).
    pub host_unix_ms: u64,
    /// Row kind (see the module doc).
    pub kind: &'static str,
    /// Node sequence number.
    pub seq: Option<u32>,
    /// Node uptime, ms (rows that are not a measurement or an event, e.g.
    /// `node_restart`; a reading carries its own).
    pub uptime_ms: Option<u64>,
    /// A measurement row's values (`fois_link::Reading`: µA, °C, mm, the
    /// estimates).
    pub reading: Option<Reading>,
    /// An event row's values.
    pub event: Option<EventReading>,
    /// Frames lost (gap rows).
    pub frames_lost: Option<u64>,
    /// Free text.
    pub detail: String,
}

impl Row {
    /// A row of `kind` with only a detail text.
    pub fn note(kind: &'static str, detail: impl Into<String>) -> Row {
        Row {
            kind,
            detail: detail.into(),
            ..Row::default()
        }
    }

    /// A measurement row.
    pub fn measurement(seq: u32, reading: Reading) -> Row {
        Row {
            kind: "measurement",
            seq: Some(seq),
            reading: Some(reading),
            ..Row::default()
        }
    }

    /// An event row.
    pub fn event(seq: u32, e: &Event) -> Row {
        let r = EventReading::new(e);
        Row {
            kind: "event",
            seq: Some(seq),
            detail: format!(
                "{} rise1_ua={:.3} frames={}",
                event_name(&e.kind),
                r.rise1_ua,
                r.frames
            ),
            event: Some(r),
            ..Row::default()
        }
    }

    /// A row for any device message.
    pub fn device(seq: u32, msg: &DeviceMsg) -> Row {
        match msg {
            DeviceMsg::Measurement(_)
            | DeviceMsg::MeasurementV2(_)
            | DeviceMsg::MeasurementV3(_)
            | DeviceMsg::MeasurementV5(_) => Row {
                kind: "measurement",
                seq: Some(seq),
                reading: Reading::of(msg),
                ..Row::default()
            },
            DeviceMsg::Event(e) => Row::event(seq, e),
            DeviceMsg::Hello(h) => Row {
                seq: Some(seq),
                ..Row::note("hello", hello_text(h))
            },
            DeviceMsg::Ack(a) => Row {
                seq: Some(seq),
                ..Row::note("ack", ack_text(a))
            },
            DeviceMsg::Error(e) => Row {
                seq: Some(seq),
                ..Row::note("error", error_text(e))
            },
        }
    }

    /// A gap of `lost` frames before `seq`.
    pub fn gap(seq: u32, lost: u64) -> Row {
        Row {
            seq: Some(seq),
            frames_lost: Some(lost),
            ..Row::note("gap", format!("{lost} frame(s) missing before seq {seq}"))
        }
    }
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

fn fixed(v: Option<f64>, decimals: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.decimals$}"))
}

/// The fields of a row, in the order of [`HEADER`]. The values come from
/// the row's [`Reading`] or [`EventReading`] (units converted there); this
/// only chooses the decimals.
pub fn row_fields(host_unix_ms: u64, r: &Row) -> [String; 27] {
    let m = r.reading.as_ref();
    let e = r.event.as_ref();
    let est = m.and_then(|m| m.estimate.as_ref());
    let gain = m.and_then(|m| m.gain.as_ref());
    let icing = m.and_then(|m| m.icing.as_ref());
    let uptime = m.map(|m| m.uptime_ms).or(e.map(|e| e.uptime_ms));
    [
        iso_utc(host_unix_ms),
        host_unix_ms.to_string(),
        r.kind.to_string(),
        opt(r.seq),
        opt(uptime.or(r.uptime_ms)),
        fixed(m.map(|m| m.i1_ua).or(e.map(|e| e.i1_ua)), 3),
        fixed(m.map(|m| m.i2_ua).or(e.map(|e| e.i2_ua)), 3),
        fixed(m.map(|m| m.ambient1_ua), 3),
        fixed(m.map(|m| m.ambient2_ua), 3),
        fixed(m.map(|m| m.temperature_c).or(e.map(|e| e.temperature_c)), 2),
        opt(m.map(|m| m.vdda_mv)),
        m.map_or(String::new(), |m| format!("{:?}", m.state)),
        opt(m.map(|m| u8::from(m.alarm))),
        opt(m.map(|m| u8::from(m.valid))),
        opt(m.map(|m| m.flags)),
        m.map(|m| &m.faults)
            .or(e.map(|e| &e.faults))
            .map_or(String::new(), |f| f.join(" ")),
        opt(r.frames_lost),
        r.detail.clone(),
        fixed(est.map(|e| e.thickness_mm), 3),
        fixed(est.map(|e| e.thickness_sigma_mm), 3),
        est.map_or(String::new(), |e| e.medium.name().to_string()),
        fixed(est.map(|e| e.medium_probability), 3),
        fixed(gain.map(|g| g.gain), 4),
        fixed(gain.map(|g| g.gain_sigma), 4),
        fixed(icing.map(|i| i.rate_mm_per_h), 3),
        fixed(icing.map(|i| i.rate_sigma_mm_per_h), 3),
        opt(icing.map(|i| u8::from(i.accreting))),
    ]
}
