//! One-line texts of protocol messages (a node's identity, answers, errors,
//! event kinds), as the monitor prints them and the log stores them.

use fois_protocol::{Ack, AckResult, ErrorReply, EventKind, Hello};

/// nA → µA.
pub fn na_to_ua(na: i64) -> f64 {
    na as f64 / 1000.0
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
    };
    format!("id={} {what}", a.id)
}

/// One line describing an error reply.
pub fn error_text(e: &ErrorReply) -> String {
    let id = e.id.map_or("none".to_string(), |i| i.to_string());
    let why = match &e.code {
        fois_protocol::ErrorCode::InvalidConfig(c) => format!("InvalidConfig: {c}"),
        other => format!("{other:?}"),
    };
    format!("id={id} {why}")
}
