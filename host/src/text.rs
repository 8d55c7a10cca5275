//! One-line texts of protocol messages (a node's identity, answers, errors,
//! event kinds), as the monitor prints them, the log stores them and the
//! gateway publishes them; the wire's units in the text's (µA, °C).

use fois_protocol::{
    Ack, AckResult, ErrorReply, EventKind, GainEstimate, Hello, IceEstimate, Medium,
};

/// nA → µA.
pub fn na_to_ua(na: i64) -> f64 {
    na as f64 / 1000.0
}

/// 0.01 °C (the wire's temperature unit) → °C.
pub fn centi_c_to_c(centi_c: i16) -> f64 {
    f64::from(centi_c) / 100.0
}

/// Short name of an event kind (`IceOnset`, `FaultRaised(0x0004)`).
pub fn event_name(kind: &EventKind) -> String {
    match kind {
        EventKind::FaultRaised(b) => format!("FaultRaised(0x{b:04x})"),
        EventKind::FaultCleared(b) => format!("FaultCleared(0x{b:04x})"),
        other => format!("{other:?}"),
    }
}

/// One line describing a node.
pub fn hello_text(h: &Hello) -> String {
    let [a, b, c] = h.firmware_version;
    let id: String = h.unique_id.iter().map(|b| format!("{b:02x}")).collect();
    format!(
        "board={} firmware={a}.{b}.{c} protocol={} id={id} reset={:?}",
        h.board_name(),
        h.protocol_version,
        h.reset_reason
    )
}

/// One line describing an answer.
pub fn ack_text(a: &Ack) -> String {
    let what = match &a.result {
        AckResult::Info(h) => format!("Info {}", hello_text(h)),
        AckResult::Config(c) => format!("Config {c:?}"),
        AckResult::Streaming { frame_period_ms } => {
            format!("Streaming frame_period_ms={frame_period_ms}")
        }
        AckResult::Stopped => "Stopped".into(),
        AckResult::DarkCalibrated(b) => format!(
            "DarkCalibrated i1_ua={:.3} i2_ua={:.3}",
            na_to_ua(b.i1_na.into()),
            na_to_ua(b.i2_na.into())
        ),
        AckResult::AlarmAcknowledged => "AlarmAcknowledged".into(),
        AckResult::Resetting => "Resetting".into(),
        AckResult::ConfigV3(c) => format!("ConfigV3 {c:?}"),
        AckResult::GainCalibrated(g) => format!("GainCalibrated {}", gain_text(g)),
        AckResult::GainReset => "GainReset".into(),
    };
    format!("id={} {what}", a.id)
}

/// One line describing an error reply.
pub fn error_text(e: &ErrorReply) -> String {
    let id = e.id.map_or("none".to_string(), |i| i.to_string());
    let why = match &e.code {
        fois_protocol::ErrorCode::InvalidConfig(c) => format!("InvalidConfig: {c}"),
        fois_protocol::ErrorCode::CalibrationRefused(r) => {
            format!("CalibrationRefused({r:?}): {}", r.describe())
        }
        other => format!("{other:?}"),
    };
    format!("id={id} {why}")
}

/// The optical gain as the monitor shows it: `gain 1.150 ± 0.060`.
pub fn gain_text(g: &GainEstimate) -> String {
    format!("gain {:.3} ± {:.3}", g.gain(), g.sigma())
}

/// The estimate as the monitor shows it: `ICE rime 2.3 ± 0.3 mm (p 0.97)`,
/// `WATER 0.4 ± 0.2 mm (p 0.99)`, `DRY (p 0.99)`.
pub fn estimate_text(e: &IceEstimate) -> String {
    let p = f64::from(e.probability_permille) / 1000.0;
    let mm = |um: u16| f64::from(um) / 1000.0;
    let what = match e.medium {
        Medium::Dry => return format!("DRY (p {p:.2})"),
        Medium::Water => "WATER".to_string(),
        ice => format!("ICE {}", ice.name()),
    };
    format!(
        "{what} {:.1} ± {:.1} mm (p {p:.2})",
        mm(e.thickness_um),
        mm(e.sigma_um)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(um: u16, sd: u16, medium: Medium, pm: u16) -> IceEstimate {
        IceEstimate {
            thickness_um: um,
            sigma_um: sd,
            medium,
            probability_permille: pm,
        }
    }

    #[test]
    fn estimate_texts() {
        assert_eq!(
            estimate_text(&est(2300, 300, Medium::Rime, 970)),
            "ICE rime 2.3 ± 0.3 mm (p 0.97)"
        );
        assert_eq!(
            estimate_text(&est(12_040, 4_400, Medium::Glazed, 512)),
            "ICE glazed 12.0 ± 4.4 mm (p 0.51)"
        );
        assert_eq!(
            estimate_text(&est(400, 200, Medium::Water, 1000)),
            "WATER 0.4 ± 0.2 mm (p 1.00)"
        );
        assert_eq!(
            estimate_text(&est(30, 90, Medium::Dry, 990)),
            "DRY (p 0.99)"
        );
    }
}
