//! One-line texts of protocol messages (a node's identity, answers, errors,
//! event kinds), as the monitor prints them, the log stores them and the
//! gateway logs them; the wire's units converted by [`crate::reading`].

use fois_protocol::{
    Ack, AckResult, ErrorReply, EventKind, GainEstimate, Hello, IceEstimate, IcingEstimate, Medium,
};

use crate::reading::{fraction, mm, ua};

/// Short name of an event kind (`IceOnset`, `FaultRaised(0x0004)`).
pub fn event_name(kind: &EventKind) -> String {
    match kind {
        EventKind::FaultRaised(b) => format!("FaultRaised(0x{b:04x})"),
        EventKind::FaultCleared(b) => format!("FaultCleared(0x{b:04x})"),
        other => format!("{other:?}"),
    }
}

/// The node's 96-bit unique id as lower-case hex (24 characters).
pub fn unique_id_hex(h: &Hello) -> String {
    h.unique_id.iter().map(|b| format!("{b:02x}")).collect()
}

/// The firmware version as `major.minor.patch`.
pub fn firmware_text(h: &Hello) -> String {
    version_text(h.firmware_version)
}

/// One line describing a node.
pub fn hello_text(h: &Hello) -> String {
    let id = unique_id_hex(h);
    format!(
        "board={} firmware={} protocol={} id={id} reset={:?}",
        h.board_name(),
        firmware_text(h),
        h.protocol_version,
        h.reset_reason
    )
}

/// A firmware version as `major.minor.patch`.
pub fn version_text(v: fois_protocol::FirmwareVersion) -> String {
    format!("{}.{}.{}", v[0], v[1], v[2])
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
            ua(b.i1_na.into()),
            ua(b.i2_na.into())
        ),
        AckResult::AlarmAcknowledged => "AlarmAcknowledged".into(),
        AckResult::Resetting => "Resetting".into(),
        AckResult::ConfigV3(c) => format!("ConfigV3 {c:?}"),
        AckResult::GainCalibrated(g) => format!("GainCalibrated {}", gain_text(g)),
        AckResult::GainReset => "GainReset".into(),
        AckResult::NoAlarm => "NoAlarm (no alarm to acknowledge)".into(),
        AckResult::LinkSettings(l) => format!(
            "LinkSettings protocol={:?} modbus_address={} parity={}",
            l.protocol,
            l.modbus_address,
            l.parity.name()
        ),
        AckResult::UpdateStatus(u) => format!(
            "UpdateStatus phase={:?} next_offset={} image_len={}",
            u.phase, u.next_offset, u.image_len
        ),
        AckResult::ImageInfo(i) => format!(
            "ImageInfo version={} state={:?} slot_bytes={}",
            version_text(i.version),
            i.state,
            i.slot_bytes
        ),
        AckResult::UpdateCommitted { version } => {
            format!(
                "UpdateCommitted: resetting into {} on trial",
                version_text(*version)
            )
        }
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
        fois_protocol::ErrorCode::BaselineShift(s) => format!(
            "BaselineShift: the baseline would move from I1 {:.3} µA, I2 {:.3} µA \
             to I1 {:.3} µA, I2 {:.3} µA ({:.3} µA, more than the {:.3} µA allowed)",
            ua(s.old.i1_na.into()),
            ua(s.old.i2_na.into()),
            ua(s.new.i1_na.into()),
            ua(s.new.i2_na.into()),
            ua(s.shift_na().into()),
            ua(s.allowed_na.into())
        ),
        fois_protocol::ErrorCode::FaceNotDry(f) => format!(
            "FaceNotDry: the node reads {}, I1 rise {:.3} µA",
            f.state.name(),
            ua(f.rise1_na.into())
        ),
        fois_protocol::ErrorCode::UpdateRefused(r) => {
            format!("UpdateRefused({r:?}): {}", r.describe())
        }
        other => format!("{other:?}"),
    };
    format!("id={id} {why}")
}

/// The optical gain as the monitor shows it: `gain 1.150 ± 0.060`.
pub fn gain_text(g: &GainEstimate) -> String {
    let g = crate::reading::GainReading::from(g);
    format!("gain {:.3} ± {:.3}", g.gain, g.gain_sigma)
}

/// The icing rate as the monitor shows it: `rate 2.15 ± 0.60 mm/h
/// ACCRETING (p 0.94)`, or `... not accreting (p 0.12)` outside an icing
/// period (the node's flag, with its hysteresis).
pub fn icing_text(i: &IcingEstimate) -> String {
    let r = crate::reading::IcingReading::from(i);
    format!(
        "rate {:.2} ± {:.2} mm/h {} (p {:.2})",
        r.rate_mm_per_h,
        r.rate_sigma_mm_per_h,
        if r.accreting {
            "ACCRETING"
        } else {
            "not accreting"
        },
        r.accreting_probability
    )
}

/// The estimate as the monitor shows it: `ICE rime 2.3 ± 0.3 mm (p 0.97)`,
/// `WATER 0.4 ± 0.2 mm (p 0.99)`, `DRY (p 0.99)`.
pub fn estimate_text(e: &IceEstimate) -> String {
    let p = fraction(e.probability_permille);
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
    fn icing_texts() {
        let mut i = IcingEstimate {
            rate_um_per_h: 2_150,
            sigma_um_per_h: 600,
            accreting_permille: 940,
            accreting: true,
        };
        assert_eq!(icing_text(&i), "rate 2.15 ± 0.60 mm/h ACCRETING (p 0.94)");
        i.accreting = false;
        i.accreting_permille = 120;
        assert_eq!(
            icing_text(&i),
            "rate 2.15 ± 0.60 mm/h not accreting (p 0.12)"
        );
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
