//! proptest strategies for every message of the protocol, shared by the
//! round-trip, size and corruption tests.
#![allow(dead_code)]

use fois_protocol::*;
use proptest::prelude::*;

pub fn reset_reason() -> impl Strategy<Value = ResetReason> {
    prop_oneof![
        Just(ResetReason::PowerOn),
        Just(ResetReason::Pin),
        Just(ResetReason::Software),
        Just(ResetReason::IndependentWatchdog),
        Just(ResetReason::WindowWatchdog),
        Just(ResetReason::LowPower),
        Just(ResetReason::Unknown),
    ]
}

pub fn hello() -> impl Strategy<Value = Hello> {
    (
        any::<u16>(),
        any::<[u8; 3]>(),
        any::<[u8; 16]>(),
        any::<[u8; 12]>(),
        reset_reason(),
    )
        .prop_map(
            |(protocol_version, firmware_version, board, unique_id, reset_reason)| Hello {
                protocol_version,
                firmware_version,
                board,
                unique_id,
                reset_reason,
            },
        )
}

pub fn state() -> impl Strategy<Value = DetectorState> {
    prop_oneof![
        Just(DetectorState::Dry),
        Just(DetectorState::Wet),
        Just(DetectorState::Ice),
    ]
}

pub fn measurement() -> impl Strategy<Value = Measurement> {
    (
        any::<u64>(),
        any::<i32>(),
        any::<i32>(),
        any::<u32>(),
        any::<u32>(),
        any::<i16>(),
        any::<u16>(),
        any::<u16>(),
        state(),
    )
        .prop_map(
            |(uptime_ms, i1_na, i2_na, ambient1_na, ambient2_na, t, vdda_mv, flags, state)| {
                Measurement {
                    uptime_ms,
                    i1_na,
                    i2_na,
                    ambient1_na,
                    ambient2_na,
                    temperature_centi_c: t,
                    vdda_mv,
                    flags,
                    state,
                }
            },
        )
}

pub fn medium() -> impl Strategy<Value = Medium> {
    prop_oneof![
        Just(Medium::Dry),
        Just(Medium::Water),
        Just(Medium::Glazed),
        Just(Medium::Rime),
    ]
}

pub fn ice_estimate() -> impl Strategy<Value = IceEstimate> {
    (any::<u16>(), any::<u16>(), medium(), any::<u16>()).prop_map(
        |(thickness_um, sigma_um, medium, probability_permille)| IceEstimate {
            thickness_um,
            sigma_um,
            medium,
            probability_permille,
        },
    )
}

pub fn measurement_v2() -> impl Strategy<Value = MeasurementV2> {
    (measurement(), proptest::option::of(ice_estimate())).prop_map(|(measurement, estimate)| {
        MeasurementV2 {
            measurement,
            estimate,
        }
    })
}

pub fn event_kind() -> impl Strategy<Value = EventKind> {
    prop_oneof![
        Just(EventKind::IceOnset),
        Just(EventKind::IceCleared),
        Just(EventKind::WetOnset),
        Just(EventKind::WetCleared),
        any::<u16>().prop_map(EventKind::FaultRaised),
        any::<u16>().prop_map(EventKind::FaultCleared),
    ]
}

pub fn event() -> impl Strategy<Value = Event> {
    (
        any::<u64>(),
        event_kind(),
        any::<i32>(),
        any::<i32>(),
        any::<i32>(),
        any::<i16>(),
        any::<u16>(),
    )
        .prop_map(
            |(uptime_ms, kind, i1_na, i2_na, rise1_na, t, frames)| Event {
                uptime_ms,
                kind,
                i1_na,
                i2_na,
                rise1_na,
                temperature_centi_c: t,
                frames,
            },
        )
}

/// Any config, valid or not: the wire carries what it is given.
pub fn config() -> impl Strategy<Value = Config> {
    (
        (any::<u32>(), any::<u16>(), any::<u16>(), any::<u32>()),
        (any::<u32>(), any::<u32>(), any::<u16>(), any::<u32>()),
        (any::<u16>(), any::<i16>(), any::<i16>(), any::<bool>()),
    )
        .prop_map(|((a, b, c, d), (e, f, g, h), (i, j, k, l))| Config {
            frame_period_ms: a,
            cycles_per_frame: b,
            settle_us: c,
            load_r1_ohm: d,
            load_r2_ohm: e,
            onset_rise_na: f,
            onset_frames: g,
            clear_rise_na: h,
            clear_frames: i,
            freeze_limit_centi_c: j,
            thaw_limit_centi_c: k,
            stream_on_boot: l,
        })
}

pub fn config_field() -> impl Strategy<Value = ConfigField> {
    (0..FIELDS.len()).prop_map(|i| FIELDS[i].field)
}

pub fn config_error() -> impl Strategy<Value = ConfigError> {
    prop_oneof![
        config_field().prop_map(ConfigError::BelowMin),
        config_field().prop_map(ConfigError::AboveMax),
        Just(ConfigError::ClearNotBelowOnset),
        Just(ConfigError::ThawNotAboveFreeze),
        Just(ConfigError::CyclesDoNotFitPeriod),
        Just(ConfigError::UnknownField),
        Just(ConfigError::NotANumber),
    ]
}

pub fn ack_result() -> impl Strategy<Value = AckResult> {
    prop_oneof![
        hello().prop_map(AckResult::Info),
        config().prop_map(AckResult::Config),
        any::<u32>().prop_map(|frame_period_ms| AckResult::Streaming { frame_period_ms }),
        Just(AckResult::Stopped),
        (any::<i32>(), any::<i32>())
            .prop_map(|(i1_na, i2_na)| AckResult::DarkCalibrated(Baseline { i1_na, i2_na })),
        Just(AckResult::AlarmAcknowledged),
        Just(AckResult::Resetting),
    ]
}

pub fn error_code() -> impl Strategy<Value = ErrorCode> {
    prop_oneof![
        Just(ErrorCode::Garbled),
        Just(ErrorCode::UnknownCommand),
        Just(ErrorCode::Oversized),
        config_error().prop_map(ErrorCode::InvalidConfig),
        Just(ErrorCode::InvalidRate),
        Just(ErrorCode::CalibrationFailed),
        Just(ErrorCode::StorageFailed),
        Just(ErrorCode::NotDry),
    ]
}

pub fn device_msg() -> impl Strategy<Value = DeviceMsg> {
    prop_oneof![
        hello().prop_map(DeviceMsg::Hello),
        measurement().prop_map(DeviceMsg::Measurement),
        event().prop_map(DeviceMsg::Event),
        (any::<u16>(), ack_result()).prop_map(|(id, result)| DeviceMsg::Ack(Ack { id, result })),
        (any::<Option<u16>>(), error_code())
            .prop_map(|(id, code)| DeviceMsg::Error(ErrorReply { id, code })),
        measurement_v2().prop_map(DeviceMsg::MeasurementV2),
    ]
}

pub fn device_frame() -> impl Strategy<Value = DeviceFrame> {
    (any::<u32>(), device_msg()).prop_map(|(seq, msg)| DeviceFrame { seq, msg })
}

pub fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        Just(Command::GetInfo),
        Just(Command::GetConfig),
        config().prop_map(Command::SetConfig),
        any::<Option<u32>>().prop_map(|frame_period_ms| Command::StartStream { frame_period_ms }),
        Just(Command::StopStream),
        Just(Command::CalibrateDark),
        Just(Command::AckAlarm),
        Just(Command::Reset),
    ]
}

pub fn host_frame() -> impl Strategy<Value = HostFrame> {
    (any::<u16>(), command()).prop_map(|(id, cmd)| HostFrame { id, cmd })
}
