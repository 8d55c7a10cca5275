//! A node's frames in the units people read: the one mapping from the
//! wire's integers (nA, 0.01 °C, µm, ‰, ppm, flag bits) to µA, °C, mm,
//! probabilities, gain factors and fault names. The CSV log of `foisctl
//! monitor`, the monitor's status lines and the gateway's JSON payloads are
//! all made from a [`Reading`] (or an [`EventReading`]), so a unit is
//! converted in one place only.
//!
//! Serialised (serde), a reading's keys are its field names, units in the
//! name: `i1_ua`, `temperature_c`, `thickness_mm`; `state` and `medium` as
//! lower-case words; `faults` as the names of
//! [`fois_protocol::flags::NAMES`]; the estimate's and the gain's keys only
//! when the node sent them.

use fois_protocol::{
    DetectorState, DeviceMsg, Event, EventKind, GainEstimate, IceEstimate, IcingEstimate,
    Measurement, Medium, flags,
};
use serde::{Serialize, Serializer};

/// nA → µA.
pub fn ua(na: i64) -> f64 {
    na as f64 / 1000.0
}

/// 0.01 °C (the wire's temperature unit) → °C.
pub fn celsius(centi_c: i16) -> f64 {
    f64::from(centi_c) / 100.0
}

/// µm → mm.
pub fn mm(um: u16) -> f64 {
    f64::from(um) / 1000.0
}

/// ‰ → a fraction 0–1.
pub fn fraction(permille: u16) -> f64 {
    f64::from(permille) / 1000.0
}

/// ppm → a plain factor (1 000 000 ppm = 1).
pub fn ppm(ppm: u32) -> f64 {
    f64::from(ppm) / 1e6
}

/// The names of the fault bits set in `bits` (`fois_protocol::flags::NAMES`,
/// only the bits of `FAULT_MASK`), in bit order.
pub fn fault_names(bits: u16) -> Vec<&'static str> {
    flags::names(bits & flags::FAULT_MASK).collect()
}

fn state_name<S: Serializer>(s: &DetectorState, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(s.name())
}

fn medium_name<S: Serializer>(m: &Medium, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(m.name())
}

/// The node's ice estimate in mm and as a probability.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EstimateReading {
    /// Posterior mean thickness, mm.
    pub thickness_mm: f64,
    /// Its standard deviation, mm.
    pub thickness_sigma_mm: f64,
    /// The most likely medium (`dry`, `water`, `glazed`, `rime`).
    #[serde(serialize_with = "medium_name")]
    pub medium: Medium,
    /// Its posterior probability, 0–1.
    pub medium_probability: f64,
}

impl From<&IceEstimate> for EstimateReading {
    fn from(e: &IceEstimate) -> Self {
        EstimateReading {
            thickness_mm: mm(e.thickness_um),
            thickness_sigma_mm: mm(e.sigma_um),
            medium: e.medium,
            medium_probability: fraction(e.probability_permille),
        }
    }
}

/// The node's optical gain estimate as plain factors (1 = the response
/// table's gain).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GainReading {
    /// Estimated gain.
    pub gain: f64,
    /// Its standard deviation.
    pub gain_sigma: f64,
}

impl From<&GainEstimate> for GainReading {
    fn from(g: &GainEstimate) -> Self {
        GainReading {
            gain: ppm(g.gain_ppm),
            gain_sigma: ppm(g.sigma_ppm),
        }
    }
}

/// The node's icing rate (protocol 5) in mm/h and as a probability:
/// meteorological icing (ice accreting now) beside the estimate's
/// instrumental icing (ice present).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IcingReading {
    /// Posterior mean growth rate, mm/h (0 while nothing grows).
    pub rate_mm_per_h: f64,
    /// Its standard deviation, mm/h.
    pub rate_sigma_mm_per_h: f64,
    /// Probability that ice accretes now, 0–1.
    pub accreting_probability: f64,
    /// An icing period is on (the probability with the node's hysteresis).
    pub accreting: bool,
}

impl From<&IcingEstimate> for IcingReading {
    fn from(i: &IcingEstimate) -> Self {
        IcingReading {
            rate_mm_per_h: f64::from(i.rate_um_per_h) / 1000.0,
            rate_sigma_mm_per_h: f64::from(i.sigma_um_per_h) / 1000.0,
            accreting_probability: fraction(i.accreting_permille),
            accreting: i.accreting,
        }
    }
}

/// One measurement frame (any protocol version) in µA, °C, mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reading {
    /// Node time since boot, ms.
    pub uptime_ms: u64,
    /// Net photocurrent of channel 1 (LED on − LED off), µA.
    pub i1_ua: f64,
    /// Net photocurrent of channel 2, µA.
    pub i2_ua: f64,
    /// Ambient level of channel 1 (LED off), µA.
    pub ambient1_ua: f64,
    /// Ambient level of channel 2, µA.
    pub ambient2_ua: f64,
    /// Air temperature, °C.
    pub temperature_c: f64,
    /// Analog supply, mV.
    pub vdda_mv: u16,
    /// The detector's state after the frame.
    #[serde(serialize_with = "state_name")]
    pub state: DetectorState,
    /// The alarm output is on.
    pub alarm: bool,
    /// The alarm was acknowledged (the output stays on while ice remains).
    pub alarm_acked: bool,
    /// The currents may be used (no channel saturated).
    pub valid: bool,
    /// A dark baseline is stored.
    pub dark_baseline: bool,
    /// The raw flag bits.
    pub flags: u16,
    /// The active faults, by name.
    pub faults: Vec<&'static str>,
    /// The node's ice estimate (protocol 2 and later, once it has one).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<EstimateReading>,
    /// The node's optical gain estimate (protocol 3, once it has one).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub gain: Option<GainReading>,
    /// The node's icing rate (protocol 5, once it has one).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub icing: Option<IcingReading>,
}

impl Reading {
    /// A measurement with the estimates the node sent with it.
    pub fn new(
        m: &Measurement,
        estimate: Option<&IceEstimate>,
        gain: Option<&GainEstimate>,
    ) -> Reading {
        Reading {
            uptime_ms: m.uptime_ms,
            i1_ua: ua(m.i1_na.into()),
            i2_ua: ua(m.i2_na.into()),
            ambient1_ua: ua(m.ambient1_na.into()),
            ambient2_ua: ua(m.ambient2_na.into()),
            temperature_c: celsius(m.temperature_centi_c),
            vdda_mv: m.vdda_mv,
            state: m.state,
            alarm: m.flags & flags::ALARM != 0,
            alarm_acked: m.flags & flags::ALARM_ACKED != 0,
            valid: m.is_valid(),
            dark_baseline: m.flags & flags::NO_BASELINE == 0,
            flags: m.flags,
            faults: fault_names(m.flags),
            estimate: estimate.map(EstimateReading::from),
            gain: gain.map(GainReading::from),
            icing: None,
        }
    }

    /// The reading with the icing rate the node sent with it (protocol 5).
    pub fn with_icing(mut self, icing: Option<&IcingEstimate>) -> Reading {
        self.icing = icing.map(IcingReading::from);
        self
    }

    /// The reading of a measurement message (`Measurement`,
    /// `MeasurementV2`, `MeasurementV3`, `MeasurementV5`); `None` for any
    /// other message.
    pub fn of(msg: &DeviceMsg) -> Option<Reading> {
        let (m, estimate) = msg.measurement()?;
        Some(Reading::new(m, estimate, msg.gain()).with_icing(msg.icing()))
    }

    /// The detector says ice.
    pub fn ice(&self) -> bool {
        self.state == DetectorState::Ice
    }

    /// The estimated optical gain left its plausible band (`gain_out_of_band`).
    pub fn gain_out_of_band(&self) -> bool {
        self.flags & flags::GAIN_OUT_OF_BAND != 0
    }
}

/// One event frame in µA and °C.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventReading {
    /// `ice_onset`, `ice_cleared`, `wet_onset`, `wet_cleared`,
    /// `fault_raised`, `fault_cleared`, `panic_reset`, `icing_started`,
    /// `icing_ended`.
    pub kind: &'static str,
    /// Node time, ms.
    pub uptime_ms: u64,
    /// Net current of channel 1 in the frame that caused it, µA.
    pub i1_ua: f64,
    /// Net current of channel 2, µA.
    pub i2_ua: f64,
    /// Channel 1's rise over the dark baseline, µA.
    pub rise1_ua: f64,
    /// Air temperature, °C.
    pub temperature_c: f64,
    /// Consecutive frames that met the condition.
    pub frames: u16,
    /// Fault events: the faults raised or cleared.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<&'static str>,
}

impl EventReading {
    /// An event frame.
    pub fn new(e: &Event) -> EventReading {
        let faults = match e.kind {
            EventKind::FaultRaised(b) | EventKind::FaultCleared(b) => fault_names(b),
            _ => Vec::new(),
        };
        EventReading {
            kind: e.kind.name(),
            uptime_ms: e.uptime_ms,
            i1_ua: ua(e.i1_na.into()),
            i2_ua: ua(e.i2_na.into()),
            rise1_ua: ua(e.rise1_na.into()),
            temperature_c: celsius(e.temperature_centi_c),
            frames: e.frames,
            faults,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::fixtures::{gain_estimate, iced_measurement, rime_estimate};

    /// The iced node, its gain out of band.
    fn meas() -> Measurement {
        let mut m = iced_measurement();
        m.flags |= flags::GAIN_OUT_OF_BAND;
        m
    }

    #[test]
    fn a_measurement_in_the_units_people_read() {
        let (est, gain) = (rime_estimate(), gain_estimate());
        let r = Reading::new(&meas(), Some(&est), Some(&gain));
        assert_eq!((r.i1_ua, r.i2_ua, r.ambient1_ua), (1.5, -0.25, 20.0));
        assert_eq!(r.temperature_c, -5.12);
        assert!(r.ice() && r.alarm && r.alarm_acked && r.valid && r.dark_baseline);
        assert!(r.gain_out_of_band());
        // Fault names come from the protocol's one list; non-fault bits
        // (alarm, acknowledged) are not faults.
        assert_eq!(r.faults, vec!["ntc_open", "gain_out_of_band"]);
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["state"], "ice");
        assert_eq!(v["thickness_mm"], 1.25);
        assert_eq!(v["thickness_sigma_mm"], 0.08);
        assert_eq!(v["medium"], "rime");
        assert_eq!(v["medium_probability"], 0.93);
        assert_eq!(v["gain"], 1.15026);
        assert_eq!(v["gain_sigma"], 0.061);
        assert_eq!(
            v["faults"],
            serde_json::json!(["ntc_open", "gain_out_of_band"])
        );
        // Without estimates: no keys at all (not null).
        let v = serde_json::to_value(Reading::new(&meas(), None, None)).unwrap();
        assert!(
            v.get("thickness_mm").is_none() && v.get("gain").is_none(),
            "{v}"
        );
    }

    #[test]
    fn every_measurement_version_gives_the_same_reading() {
        let v1 = DeviceMsg::Measurement(meas());
        let v3 = DeviceMsg::MeasurementV3(fois_protocol::MeasurementV3 {
            measurement: meas(),
            estimate: None,
            gain: None,
        });
        assert_eq!(Reading::of(&v1), Reading::of(&v3));
        assert!(Reading::of(&DeviceMsg::Event(event())).is_none());
        let v5 = DeviceMsg::MeasurementV5(fois_protocol::MeasurementV5 {
            measurement: meas(),
            estimate: None,
            gain: None,
            icing: None,
        });
        assert_eq!(Reading::of(&v1), Reading::of(&v5));
    }

    #[test]
    fn the_icing_rate_in_mm_per_h_and_its_keys_only_when_sent() {
        let v5 = DeviceMsg::MeasurementV5(fois_protocol::MeasurementV5 {
            measurement: meas(),
            estimate: Some(rime_estimate()),
            gain: Some(gain_estimate()),
            icing: Some(IcingEstimate {
                rate_um_per_h: 2_150,
                sigma_um_per_h: 600,
                accreting_permille: 940,
                accreting: true,
            }),
        });
        let r = Reading::of(&v5).unwrap();
        let i = r.icing.unwrap();
        assert_eq!((i.rate_mm_per_h, i.rate_sigma_mm_per_h), (2.15, 0.6));
        assert_eq!((i.accreting_probability, i.accreting), (0.94, true));
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["rate_mm_per_h"], 2.15);
        assert_eq!(v["rate_sigma_mm_per_h"], 0.6);
        assert_eq!(v["accreting_probability"], 0.94);
        assert_eq!(v["accreting"], true);
        let v = serde_json::to_value(Reading::new(&meas(), None, None)).unwrap();
        assert!(v.get("rate_mm_per_h").is_none() && v.get("accreting").is_none());
    }

    fn event() -> Event {
        Event {
            uptime_ms: 5,
            kind: EventKind::FaultRaised(flags::NTC_SHORT | flags::CLOCK_FALLBACK),
            i1_na: 2_000,
            i2_na: 0,
            rise1_na: 1_900,
            temperature_centi_c: 150,
            frames: 1,
        }
    }

    #[test]
    fn a_fault_event_names_its_faults() {
        let e = EventReading::new(&event());
        assert_eq!(e.kind, "fault_raised");
        assert_eq!(e.faults, vec!["ntc_short", "clock_fallback"]);
        assert_eq!((e.i1_ua, e.rise1_ua, e.temperature_c), (2.0, 1.9, 1.5));
    }
}
