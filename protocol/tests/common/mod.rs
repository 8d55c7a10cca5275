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

pub fn gain_estimate() -> impl Strategy<Value = GainEstimate> {
    (any::<u32>(), any::<u32>()).prop_map(|(gain_ppm, sigma_ppm)| GainEstimate {
        gain_ppm,
        sigma_ppm,
    })
}

pub fn measurement_v3() -> impl Strategy<Value = MeasurementV3> {
    (
        measurement(),
        proptest::option::of(ice_estimate()),
        proptest::option::of(gain_estimate()),
    )
        .prop_map(|(measurement, estimate, gain)| MeasurementV3 {
            measurement,
            estimate,
            gain,
        })
}

pub fn icing_estimate() -> impl Strategy<Value = IcingEstimate> {
    (any::<u16>(), any::<u16>(), any::<u16>(), any::<bool>()).prop_map(
        |(rate_um_per_h, sigma_um_per_h, accreting_permille, accreting)| IcingEstimate {
            rate_um_per_h,
            sigma_um_per_h,
            accreting_permille,
            accreting,
        },
    )
}

pub fn measurement_v5() -> impl Strategy<Value = MeasurementV5> {
    (
        measurement(),
        proptest::option::of(ice_estimate()),
        proptest::option::of(gain_estimate()),
        proptest::option::of(icing_estimate()),
    )
        .prop_map(|(measurement, estimate, gain, icing)| MeasurementV5 {
            measurement,
            estimate,
            gain,
            icing,
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
        (any::<u32>(), any::<u8>()).prop_map(|(line, resets_in_row)| EventKind::PanicReset {
            line,
            resets_in_row
        }),
        Just(EventKind::IcingStarted),
        Just(EventKind::IcingEnded),
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

/// Any config of the version-1 shape, valid or not: the wire carries what
/// it is given.
pub fn config_v1() -> impl Strategy<Value = ConfigV1> {
    (
        (any::<u32>(), any::<u16>(), any::<u16>(), any::<u32>()),
        (any::<u32>(), any::<u32>(), any::<u16>(), any::<u32>()),
        (any::<u16>(), any::<i16>(), any::<i16>(), any::<bool>()),
    )
        .prop_map(|((a, b, c, d), (e, f, g, h), (i, j, k, l))| ConfigV1 {
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

/// Any whole config (version 3), valid or not.
pub fn config() -> impl Strategy<Value = Config> {
    (
        config_v1(),
        any::<i32>(),
        any::<u32>(),
        any::<u16>(),
        any::<u16>(),
    )
        .prop_map(|(v1, tempco, tempco_sd, low, high)| Config {
            gain_tempco_ppm_per_k: tempco,
            gain_tempco_sd_ppm_per_k: tempco_sd,
            gain_low_permille: low,
            gain_high_permille: high,
            ..Config::from(v1)
        })
}

pub fn calibration_refusal() -> impl Strategy<Value = CalibrationRefusal> {
    prop_oneof![
        Just(CalibrationRefusal::Saturated),
        Just(CalibrationRefusal::Trend),
        Just(CalibrationRefusal::Step),
        Just(CalibrationRefusal::Noisy),
        Just(CalibrationRefusal::ImplausibleGain),
        Just(CalibrationRefusal::InvalidTarget),
    ]
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
        Just(ConfigError::GainBandEmpty),
    ]
}

pub fn ack_result() -> impl Strategy<Value = AckResult> {
    prop_oneof![
        hello().prop_map(AckResult::Info),
        config_v1().prop_map(AckResult::Config),
        any::<u32>().prop_map(|frame_period_ms| AckResult::Streaming { frame_period_ms }),
        Just(AckResult::Stopped),
        (any::<i32>(), any::<i32>())
            .prop_map(|(i1_na, i2_na)| AckResult::DarkCalibrated(Baseline { i1_na, i2_na })),
        Just(AckResult::AlarmAcknowledged),
        Just(AckResult::Resetting),
        config().prop_map(AckResult::ConfigV3),
        gain_estimate().prop_map(AckResult::GainCalibrated),
        Just(AckResult::GainReset),
        Just(AckResult::NoAlarm),
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
        calibration_refusal().prop_map(ErrorCode::CalibrationRefused),
        (any::<[i32; 4]>(), any::<u32>()).prop_map(|(b, allowed_na)| {
            ErrorCode::BaselineShift(BaselineShift {
                old: Baseline {
                    i1_na: b[0],
                    i2_na: b[1],
                },
                new: Baseline {
                    i1_na: b[2],
                    i2_na: b[3],
                },
                allowed_na,
            })
        }),
        (state(), any::<i32>())
            .prop_map(|(state, rise1_na)| ErrorCode::FaceNotDry(FaceReading { state, rise1_na })),
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
        measurement_v3().prop_map(DeviceMsg::MeasurementV3),
        measurement_v5().prop_map(DeviceMsg::MeasurementV5),
    ]
}

pub fn device_frame() -> impl Strategy<Value = DeviceFrame> {
    (any::<u32>(), device_msg()).prop_map(|(seq, msg)| DeviceFrame { seq, msg })
}

pub fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        Just(Command::GetInfo),
        Just(Command::GetConfig),
        config_v1().prop_map(Command::SetConfig),
        any::<Option<u32>>().prop_map(|frame_period_ms| Command::StartStream { frame_period_ms }),
        Just(Command::StopStream),
        Just(Command::CalibrateDark),
        Just(Command::AckAlarm),
        Just(Command::Reset),
        config().prop_map(Command::SetConfigV3),
        (any::<u32>(), any::<u32>())
            .prop_map(|(i1_na, i2_na)| Command::CalibrateGain(GainTarget { i1_na, i2_na })),
        Just(Command::ResetGain),
        any::<bool>().prop_map(|force| Command::CalibrateDarkV4 { force }),
        Just(Command::AckAlarmV4),
    ]
}

pub fn host_frame() -> impl Strategy<Value = HostFrame> {
    (any::<u16>(), command()).prop_map(|(id, cmd)| HostFrame { id, cmd })
}
