//! The node as the host sees it: frames out, commands in, outputs, storage.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::MemStorage;
use fois_firmware::node::dispatch::BUTTON_ID;
use fois_protocol::*;

fn measurement(fs: &[DeviceFrame]) -> Measurement {
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::MeasurementV5(m) => Some(m.measurement.clone()),
            _ => None,
        })
        .expect("a measurement")
}

fn events(fs: &[DeviceFrame]) -> Vec<Event> {
    fs.iter()
        .filter_map(|f| match &f.msg {
            DeviceMsg::Event(e) => Some(e.clone()),
            _ => None,
        })
        .collect()
}

fn only(fs: Vec<DeviceFrame>) -> DeviceMsg {
    assert_eq!(fs.len(), 1, "{fs:?}");
    fs.into_iter().next().map(|f| f.msg).unwrap()
}

fn ack(fs: Vec<DeviceFrame>, id: u16) -> AckResult {
    match only(fs) {
        DeviceMsg::Ack(a) => {
            assert_eq!(a.id, id);
            a.result
        }
        other => panic!("expected an ack, got {other:?}"),
    }
}

fn error(fs: Vec<DeviceFrame>) -> ErrorReply {
    match only(fs) {
        DeviceMsg::Error(e) => e,
        other => panic!("expected an error, got {other:?}"),
    }
}

#[test]
fn boots_with_defaults_and_says_hello() {
    let (mut node, w) = node();
    assert_eq!(node.config(), &Config::default());
    assert!(node.is_streaming(), "stream_on_boot");
    assert_eq!(node.frame_period_ms(), 100);
    let h = node.hello();
    assert_eq!(h.protocol_version, PROTOCOL_VERSION);
    assert_eq!(h.board_name(), "sim");
    assert_eq!(h.firmware_version, [0, 1, 0]);
    let mut bytes = Vec::new();
    node.send_hello(&mut |b| bytes.extend_from_slice(b));
    let fs = frames(&bytes);
    assert_eq!(fs[0].seq, 0);
    assert_eq!(fs[0].msg, DeviceMsg::Hello(h));
    // First frame: no baseline yet, no fault.
    let fs = step(&mut node, &w);
    assert_eq!(fs[0].seq, 1, "sequence numbers count every frame");
    let m = measurement(&fs);
    assert_eq!(m.flags, flags::NO_BASELINE);
    assert_eq!(m.state, DetectorState::Dry);
    assert_eq!(m.vdda_mv, 3_300);
    assert!(events(&fs).is_empty());
    assert!(!w.led.get(), "the LED is left off between frames");
}

#[test]
fn currents_temperature_and_ambient() {
    let (mut node, w) = node();
    w.set(|s| {
        s.signal_na = [12_000.0, 4_000.0];
        s.ambient_na = [30_000.0, 5_000.0];
        s.temp_c = -5.0;
    });
    let m = measurement(&step(&mut node, &w));
    // One ADC step is 80.6 nA at 3.3 V / 10 kΩ; the 8-cycle mean is within one.
    assert!((m.i1_na - 12_000).abs() <= 81, "{m:?}");
    assert!((m.i2_na - 4_000).abs() <= 81, "{m:?}");
    assert!((m.ambient1_na as i64 - 30_000).abs() <= 81, "{m:?}");
    assert!((m.ambient2_na as i64 - 5_000).abs() <= 81, "{m:?}");
    assert!((m.temperature_centi_c + 500).abs() <= 10, "{m:?}");
    // 8 LED pulses per frame, K = cycles_per_frame.
    assert_eq!(w.led_toggles.get(), 8);
    // A 3.0 V supply is measured through VREFINT and the currents stay right.
    w.set(|s| s.vdda_mv = 3_000.0);
    let m = measurement(&step(&mut node, &w));
    assert!((2_995..=3_005).contains(&m.vdda_mv), "{m:?}");
    assert!((m.i1_na - 12_000).abs() <= 90, "{m:?}");
    assert_eq!(m.flags & flags::VDDA_OUT_OF_RANGE, 0);
}

#[test]
fn saturation_flags_the_frame_and_the_rule_ignores_it() {
    let (mut node, w) = node();
    // Full sun on channel 1: 340 µA × 10 kΩ = 3.4 V, past the clip.
    w.set(|s| {
        s.ambient_na = [340_000.0, 0.0];
        s.signal_na = [20_000.0, 0.0];
        s.temp_c = -10.0;
    });
    for _ in 0..3 * node.config().onset_frames {
        let fs = step(&mut node, &w);
        let m = measurement(&fs);
        assert!(!m.is_valid());
        assert_eq!(m.flags & flags::INVALID_MASK, flags::SATURATED_CH1);
        assert_eq!(m.state, DetectorState::Dry);
        assert!(events(&fs).is_empty());
    }
}

/// The phototransistor clips at V_DDA − V_CE(sat) (3.05 V here), well below
/// the ADC's full scale: a frame whose LED-on samples reach the clip must be
/// flagged, or the squeezed difference reads as "no film".
#[test]
fn saturation_is_flagged_at_the_phototransistor_clip_from_the_measured_supply() {
    let (mut node, w) = node();
    // 295 µA of sun (2.95 V) + 20 µA of ice signal: LED on would be 3.15 V
    // but clips at 3.05 V, so the net reads 10 µA instead of 20. Every
    // sample is below the old 4 000-code limit (3.22 V), which let it through.
    w.set(|s| {
        s.ambient_na = [295_000.0, 0.0];
        s.signal_na = [20_000.0, 0.0];
    });
    let m = measurement(&step(&mut node, &w));
    assert!(
        (m.i1_na - 10_000).abs() <= 81,
        "the clip squeezes the signal: {m:?}"
    );
    assert_eq!(m.flags & flags::INVALID_MASK, flags::SATURATED_CH1, "{m:?}");
    // Just under the flag level (2.8 V at 3.3 V): 265 µA + 10 µA = 2.75 V, valid and right.
    w.set(|s| {
        s.ambient_na = [265_000.0, 0.0];
        s.signal_na = [10_000.0, 0.0];
    });
    let m = measurement(&step(&mut node, &w));
    assert!(m.is_valid(), "{m:?}");
    assert!((m.i1_na - 10_000).abs() <= 81, "{m:?}");
    // The level follows the supply measured in the frame: at 3.0 V the
    // clip is at 2.75 V and the flag from 2.5 V.
    w.set(|s| {
        s.vdda_mv = 3_000.0;
        s.ambient_na = [250_000.0, 0.0];
        s.signal_na = [10_000.0, 0.0];
    });
    let m = measurement(&step(&mut node, &w));
    assert_eq!(m.flags & flags::INVALID_MASK, flags::SATURATED_CH1, "{m:?}");
    w.set(|s| s.ambient_na = [230_000.0, 0.0]);
    let m = measurement(&step(&mut node, &w));
    assert!(m.is_valid(), "{m:?}");
    assert!((m.i1_na - 10_000).abs() <= 90, "{m:?}");
}

#[test]
fn ntc_faults_fall_back_to_the_internal_sensor() {
    let (mut node, w) = node();
    w.set(|s| s.temp_c = -3.0);
    let fs = step(&mut node, &w);
    assert!(events(&fs).is_empty());
    w.set(|s| s.ntc_code = Some(4095));
    let fs = step(&mut node, &w);
    let m = measurement(&fs);
    assert_eq!(
        m.flags & (flags::NTC_OPEN | flags::NTC_SHORT),
        flags::NTC_OPEN
    );
    // Internal sensor: 2.5 mV/°C ≈ 0.3 codes/°C... within 2 °C here.
    assert!((m.temperature_centi_c + 300).abs() <= 200, "{m:?}");
    let ev = events(&fs);
    assert_eq!(ev.len(), 1);
    assert_eq!(ev[0].kind, EventKind::FaultRaised(flags::NTC_OPEN));
    // Still open: no new event.
    assert!(events(&step(&mut node, &w)).is_empty());
    w.set(|s| s.ntc_code = Some(0));
    let ev = events(&step(&mut node, &w));
    assert_eq!(
        ev.iter().map(|e| e.kind).collect::<Vec<_>>(),
        vec![
            EventKind::FaultRaised(flags::NTC_SHORT),
            EventKind::FaultCleared(flags::NTC_OPEN)
        ]
    );
    w.set(|s| s.ntc_code = None);
    let ev = events(&step(&mut node, &w));
    assert_eq!(ev[0].kind, EventKind::FaultCleared(flags::NTC_SHORT));
}

#[test]
fn icing_drives_alarm_and_ld2_and_sends_events() {
    let (mut node, w) = node();
    let n = node.config().onset_frames;
    w.set(|s| s.temp_c = -4.0);
    step(&mut node, &w);
    // Rime at ~0.2 mm: I1 ≈ 2.5 µA (thesis: > 25 µA below 2 mm).
    w.set(|s| s.signal_na = [2_500.0, 800.0]);
    for i in 1..n {
        let fs = step(&mut node, &w);
        assert!(events(&fs).is_empty(), "frame {i}");
        assert!(!w.alarm.get() && !w.indicator.get());
    }
    let fs = step(&mut node, &w);
    let ev = events(&fs);
    assert_eq!(ev.len(), 1);
    let e = &ev[0];
    assert_eq!(e.kind, EventKind::IceOnset);
    assert_eq!(e.frames, n);
    assert!((e.rise1_na - 2_500).abs() <= 81, "{e:?}");
    assert!((e.temperature_centi_c + 400).abs() <= 10, "{e:?}");
    let m = measurement(&fs);
    assert_eq!(m.state, DetectorState::Ice);
    assert_ne!(m.flags & flags::ALARM, 0);
    assert!(w.alarm.get() && w.indicator.get());
    assert_eq!(node.state(), DetectorState::Ice);

    // The host acknowledges: flag set, output stays on while iced.
    assert_eq!(
        ack(command(&mut node, &w, 7, Command::AckAlarm), 7),
        AckResult::AlarmAcknowledged
    );
    let m = measurement(&step(&mut node, &w));
    assert_ne!(m.flags & flags::ALARM_ACKED, 0);
    assert!(w.alarm.get());
    // Dark calibration is refused on an iced face.
    assert_eq!(
        error(command(&mut node, &w, 8, Command::CalibrateDark)).code,
        ErrorCode::NotDry
    );

    // The ice sheds: M frames later the alarm clears.
    w.set(|s| s.signal_na = [0.0, 0.0]);
    let m_frames = node.config().clear_frames;
    let mut cleared_at = None;
    for i in 1..=m_frames {
        let ev = events(&step(&mut node, &w));
        if !ev.is_empty() {
            assert_eq!(ev[0].kind, EventKind::IceCleared);
            assert_eq!(ev[0].frames, m_frames);
            cleared_at = Some(i);
        }
    }
    assert_eq!(cleared_at, Some(m_frames));
    assert!(!w.alarm.get() && !w.indicator.get());
}

#[test]
fn water_above_the_freezing_limit_is_wet_not_ice() {
    let (mut node, w) = node();
    w.set(|s| {
        s.temp_c = 4.0;
        s.signal_na = [12_000.0, 3_000.0]; // reads like glazed ice (thesis §5.2.3)
    });
    let n = node.config().onset_frames;
    let mut kinds = Vec::new();
    for _ in 0..3 * n {
        kinds.extend(events(&step(&mut node, &w)).into_iter().map(|e| e.kind));
    }
    assert_eq!(kinds, vec![EventKind::WetOnset]);
    assert!(!w.alarm.get());
    // The water is no dark reference: calibration refused, baseline kept.
    assert_eq!(
        error(command(&mut node, &w, 4, Command::CalibrateDark)),
        ErrorReply {
            id: Some(4),
            code: ErrorCode::NotDry
        }
    );
    assert_eq!(node.baseline(), None);
    // The water freezes.
    w.set(|s| s.temp_c = -1.0);
    for _ in 0..n {
        kinds.extend(events(&step(&mut node, &w)).into_iter().map(|e| e.kind));
    }
    assert_eq!(kinds, vec![EventKind::WetOnset, EventKind::IceOnset]);
    assert!(w.alarm.get());
}

#[test]
fn dark_calibration_by_command_and_button_persists() {
    let storage;
    {
        let (mut node, w) = node_with(MemStorage::new());
        // A face with a small steady offset (e.g. cross-talk): 600 nA.
        w.set(|s| s.signal_na = [600.0, 200.0]);
        let AckResult::DarkCalibrated(b) =
            ack(command(&mut node, &w, 3, Command::CalibrateDark), 3)
        else {
            panic!()
        };
        assert!(
            (b.i1_na - 600).abs() <= 81 && (b.i2_na - 200).abs() <= 81,
            "{b:?}"
        );
        assert_eq!(node.baseline(), Some(b));
        let m = measurement(&step(&mut node, &w));
        assert_eq!(m.flags & flags::NO_BASELINE, 0);
        // Button while dry = dark calibration, reported with BUTTON_ID.
        w.set(|s| s.signal_na = [700.0, 200.0]);
        let mut bytes = Vec::new();
        node.button_pressed(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
        let AckResult::DarkCalibrated(b2) = ack(frames(&bytes), BUTTON_ID) else {
            panic!()
        };
        assert!((b2.i1_na - 700).abs() <= 81);
        run_until_saved(&mut node, &w);
        let (_, _, _, _, _, s) = node.into_parts();
        storage = s;
    }
    // Two calibrations 100 ms apart: one write.
    assert_eq!(storage.writes, 1);
    // A new boot reads it back.
    let (node, _w) = node_with(storage);
    assert!(node.baseline().is_some_and(|b| (b.i1_na - 700).abs() <= 81));
}

#[test]
fn dark_calibration_refuses_saturated_or_unsteady_light() {
    let (mut node, w) = node();
    w.set(|s| s.ambient_na = [400_000.0, 0.0]);
    assert_eq!(
        error(command(&mut node, &w, 1, Command::CalibrateDark)).code,
        ErrorCode::CalibrationRefused(CalibrationRefusal::Saturated)
    );
    // A film coming and going: I1 changes by 200 µA/s, so the four
    // calibration frames (~15 ms) disagree by more than onset/2 = 500 nA.
    w.set(|s| {
        s.ambient_na = [20_000.0, 0.0];
        s.signal_ramp_na_per_s = [200_000.0, 0.0];
    });
    assert!(matches!(
        error(command(&mut node, &w, 2, Command::CalibrateDark)).code,
        ErrorCode::CalibrationRefused(_)
    ));
    assert_eq!(node.baseline(), None);
}

#[test]
fn button_while_iced_acknowledges() {
    let (mut node, w) = node();
    w.set(|s| {
        s.temp_c = -8.0;
        s.signal_na = [25_000.0, 8_000.0];
    });
    for _ in 0..node.config().onset_frames {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Ice);
    let mut bytes = Vec::new();
    node.button_pressed(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
    assert_eq!(ack(frames(&bytes), BUTTON_ID), AckResult::AlarmAcknowledged);
    assert_eq!(node.baseline(), None, "no calibration while iced");
    let m = measurement(&step(&mut node, &w));
    assert_ne!(m.flags & flags::ALARM_ACKED, 0);
}

#[test]
fn every_command_is_answered() {
    let (mut node, w) = node();
    assert_eq!(
        ack(command(&mut node, &w, 1, Command::GetInfo), 1),
        AckResult::Info(node.hello())
    );
    assert_eq!(
        ack(command(&mut node, &w, 2, Command::GetConfig), 2),
        AckResult::ConfigV3(Config::default())
    );
    assert_eq!(
        ack(command(&mut node, &w, 3, Command::StopStream), 3),
        AckResult::Stopped
    );
    assert!(!node.is_streaming());
    // Not streaming: frames still run the rule but send nothing.
    assert!(step(&mut node, &w).is_empty());
    assert_eq!(
        ack(
            command(
                &mut node,
                &w,
                4,
                Command::StartStream {
                    frame_period_ms: Some(1_000)
                }
            ),
            4
        ),
        AckResult::Streaming {
            frame_period_ms: 1_000
        }
    );
    assert_eq!(node.frame_period_ms(), 1_000);
    assert_eq!(
        error(command(
            &mut node,
            &w,
            5,
            Command::StartStream {
                frame_period_ms: Some(5)
            }
        )),
        ErrorReply {
            id: Some(5),
            code: ErrorCode::InvalidRate
        }
    );
    assert_eq!(
        node.frame_period_ms(),
        1_000,
        "a refused rate changes nothing"
    );
    assert_eq!(
        ack(
            command(
                &mut node,
                &w,
                6,
                Command::StartStream {
                    frame_period_ms: None
                }
            ),
            6
        ),
        AckResult::Streaming {
            frame_period_ms: 100
        }
    );
    assert_eq!(
        ack(command(&mut node, &w, 9, Command::Reset), 9),
        AckResult::Resetting
    );
    assert!(node.take_reset_request());
    assert!(!node.take_reset_request(), "once");
}

#[test]
fn set_config_validates_applies_and_persists() {
    let (mut node, w) = node();
    let c = Config {
        onset_rise_na: 2_000,
        frame_period_ms: 200,
        ..Config::default()
    };
    assert_eq!(
        ack(
            command(&mut node, &w, 1, Command::SetConfigV3(c.clone())),
            1
        ),
        AckResult::ConfigV3(c.clone())
    );
    assert_eq!(node.config(), &c);
    assert_eq!(node.frame_period_ms(), 200);
    // One field wrong → refused with the protocol's reason, nothing changes.
    let mut bad = c.clone();
    bad.clear_rise_na = bad.onset_rise_na;
    assert_eq!(
        error(command(&mut node, &w, 2, Command::SetConfigV3(bad))),
        ErrorReply {
            id: Some(2),
            code: ErrorCode::InvalidConfig(ConfigError::ClearNotBelowOnset)
        }
    );
    let mut bad = c.clone();
    bad.settle_us = 19;
    assert_eq!(
        error(command(&mut node, &w, 3, Command::SetConfigV3(bad))).code,
        ErrorCode::InvalidConfig(ConfigError::BelowMin(ConfigField::SettleUs))
    );
    assert_eq!(node.config(), &c);
    run_until_saved(&mut node, &w);
    // The same config again: nothing to write.
    command(&mut node, &w, 4, Command::SetConfigV3(c.clone()));
    assert!(!node.save_pending());
    let (_, _, _, _, _, storage) = node.into_parts();
    assert_eq!(
        storage.writes, 1,
        "refused or unchanged configs are not written"
    );
    let (node, _) = node_with(storage);
    assert_eq!(node.config(), &c);
}

/// A host of protocol version 1/2 sends the old config shape: its twelve
/// fields are applied, the node's version-3 fields are kept, and the answer
/// comes back in the old shape; `GetConfig` answers with every field.
#[test]
fn an_older_hosts_config_keeps_the_newer_fields() {
    let (mut node, w) = node();
    let v3 = Config {
        gain_tempco_ppm_per_k: -2_500,
        gain_low_permille: 750,
        ..Config::default()
    };
    command(&mut node, &w, 1, Command::SetConfigV3(v3.clone()));
    let old = ConfigV1 {
        onset_frames: 12,
        ..ConfigV1::from(&Config::default())
    };
    assert_eq!(
        ack(
            command(&mut node, &w, 2, Command::SetConfig(old.clone())),
            2
        ),
        AckResult::Config(old)
    );
    let want = Config {
        onset_frames: 12,
        ..v3
    };
    assert_eq!(node.config(), &want);
    assert_eq!(
        ack(command(&mut node, &w, 3, Command::GetConfig), 3),
        AckResult::ConfigV3(want)
    );
    // The gain band rule is the protocol's: an empty band is refused.
    let bad = Config {
        gain_low_permille: 1_000,
        gain_high_permille: 1_000,
        ..Config::default()
    };
    assert_eq!(
        error(command(&mut node, &w, 4, Command::SetConfigV3(bad))).code,
        ErrorCode::InvalidConfig(ConfigError::GainBandEmpty)
    );
}

#[test]
fn storage_failure_is_reported_and_the_change_holds() {
    let mut storage = MemStorage::new();
    storage.fail_writes = true;
    let (mut node, w) = node_with(storage);
    let c = Config {
        onset_frames: 10,
        ..Config::default()
    };
    // Applied at once; the save comes after the quiet time.
    assert_eq!(
        ack(
            command(&mut node, &w, 1, Command::SetConfigV3(c.clone())),
            1
        ),
        AckResult::ConfigV3(c.clone())
    );
    assert_eq!(node.config(), &c, "holds until the next reset");
    let t0 = w.now_ms();
    let mut raised_at = None;
    for _ in 0..30 {
        let fs = step(&mut node, &w);
        if events(&fs)
            .iter()
            .any(|e| e.kind == EventKind::FaultRaised(flags::STORAGE_FAILED))
        {
            raised_at = Some(w.now_ms() - t0);
            break;
        }
    }
    // The save ran after the 1 s quiet time; the fault goes out with the next frame.
    let raised_at = raised_at.expect("STORAGE_FAILED raised");
    assert!((1_000..=1_300).contains(&raised_at), "{raised_at} ms");
    assert_ne!(
        measurement(&step(&mut node, &w)).flags & flags::STORAGE_FAILED,
        0
    );
    assert!(node.save_pending(), "retried later");
    assert_eq!(
        node.save_due_ms().map(|t| t - t0),
        Some(fois_firmware::node::saving::SAVE_MIN_INTERVAL_MS + 1_000)
    );
}

#[test]
fn corrupt_or_old_storage_means_defaults_and_a_fault() {
    for bytes in [
        &b"FOIS\x01\x00\x05\x00garbage-crc"[..],
        &b"\x00\x00\x00"[..],
        &[0x46, 0x4F, 0x49, 0x53, 0, 0, 0, 0, 1, 2, 3, 4][..],
    ] {
        let (mut node, w) = node_with(MemStorage::with_bytes(bytes));
        assert_eq!(node.config(), &Config::default());
        let fs = step(&mut node, &w);
        let m = measurement(&fs);
        assert_ne!(m.flags & flags::CONFIG_DEFAULTED, 0);
        assert_eq!(
            events(&fs)[0].kind,
            EventKind::FaultRaised(flags::CONFIG_DEFAULTED)
        );
        // A good SetConfig repairs it and clears the fault.
        command(&mut node, &w, 1, Command::SetConfigV3(Config::default()));
        let fs = step(&mut node, &w);
        assert_eq!(measurement(&fs).flags & flags::CONFIG_DEFAULTED, 0);
        assert_eq!(
            events(&fs)[0].kind,
            EventKind::FaultCleared(flags::CONFIG_DEFAULTED)
        );
    }
}

#[test]
fn garbled_unknown_and_oversized_frames_get_errors_and_measurement_goes_on() {
    let (mut node, w) = node();
    let mut bytes = Vec::new();
    let mut tx = |b: &[u8]| bytes.extend_from_slice(b);
    // Garbage, a good command split byte by byte, a CRC-failing copy, an oversized run.
    node.handle_rx(&[0x13, 0x37, 0x00], 0, &mut tx);
    let good = encode_to_vec(&HostFrame {
        id: 42,
        cmd: Command::GetConfig,
    });
    for b in &good {
        node.handle_rx(std::slice::from_ref(b), 0, &mut tx);
    }
    let mut flipped = good.clone();
    flipped[3] ^= 0x10;
    node.handle_rx(&flipped, 0, &mut tx);
    node.handle_rx(&[0x55; 2 * MAX_FRAME], 0, &mut tx);
    node.handle_rx(&[0x00], 0, &mut tx);
    // A frame with a valid CRC but command number 8 (none such in this version).
    node.handle_rx(&encode_to_vec(&(1u16, 8u8)), 0, &mut tx);
    let got: Vec<DeviceMsg> = frames(&bytes).into_iter().map(|f| f.msg).collect();
    assert_eq!(got.len(), 5, "{got:?}");
    assert_eq!(
        got[0],
        DeviceMsg::Error(ErrorReply {
            id: None,
            code: ErrorCode::Garbled
        })
    );
    assert!(matches!(&got[1], DeviceMsg::Ack(Ack { id: 42, .. })));
    assert_eq!(
        got[2],
        DeviceMsg::Error(ErrorReply {
            id: None,
            code: ErrorCode::Garbled
        })
    );
    assert_eq!(
        got[3],
        DeviceMsg::Error(ErrorReply {
            id: None,
            code: ErrorCode::Oversized
        })
    );
    assert_eq!(
        got[4],
        DeviceMsg::Error(ErrorReply {
            id: None,
            code: ErrorCode::UnknownCommand
        })
    );
    assert!(measurement(&step(&mut node, &w)).is_valid());
}

#[test]
fn sequence_numbers_are_contiguous_across_kinds() {
    let (mut node, w) = node();
    let mut bytes = Vec::new();
    node.send_hello(&mut |b| bytes.extend_from_slice(b));
    for _ in 0..3 {
        node.run_frame(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
        let wire = encode_to_vec(&HostFrame {
            id: 1,
            cmd: Command::GetInfo,
        });
        node.handle_rx(&wire, 0, &mut |b| bytes.extend_from_slice(b));
    }
    let seqs: Vec<u32> = frames(&bytes).iter().map(|f| f.seq).collect();
    assert_eq!(seqs, (0..7).collect::<Vec<_>>());
    assert_eq!(node.next_seq(), 7);
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Random bytes in random chunks never panic, every reply is a valid
        /// frame, and the node keeps measuring.
        #[test]
        fn random_input_never_breaks_the_node(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8)) {
            let (mut node, w) = node();
            let mut bytes = Vec::new();
            for c in &chunks {
                node.handle_rx(c, 0, &mut |b| bytes.extend_from_slice(b));
                node.run_frame(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
            }
            let fs = frames(&bytes);
            let ms = fs.iter().filter(|f| matches!(f.msg, DeviceMsg::MeasurementV5(_))).count();
            prop_assert!(ms == chunks.len() || !node.is_streaming());
        }
    }
}

mod saving {
    use super::*;
    use fois_firmware::node::saving::{SAVE_MAX_DELAY_MS, SAVE_MIN_INTERVAL_MS, SAVE_QUIET_MS};

    fn writes(node: SimNode) -> u32 {
        node.into_parts().5.writes
    }

    /// A burst of config changes and calibrations is one write, after the
    /// quiet time; the next change waits out the minimum interval.
    #[test]
    fn a_burst_is_one_write_and_writes_are_rate_limited() {
        let (mut node, w) = node();
        for i in 0..10u16 {
            let c = Config {
                onset_rise_na: 1_000 + u32::from(i) * 100,
                ..Config::default()
            };
            command(&mut node, &w, i, Command::SetConfigV3(c));
            w.advance_ms(50);
        }
        let last_change = w.now_ms();
        command(&mut node, &w, 20, Command::CalibrateDark);
        assert_eq!(node.save_due_ms(), Some(last_change + SAVE_QUIET_MS));
        // Frames before the due time do not write.
        let mut saved_at = None;
        for _ in 0..40 {
            let now = w.now_ms();
            step(&mut node, &w);
            if !node.save_pending() {
                saved_at = Some(now);
                break;
            }
        }
        let saved_at = saved_at.expect("saved");
        // Saved by the first frame at or after the due time (frames are 100 ms).
        let due = last_change + SAVE_QUIET_MS;
        assert!((due..due + 100).contains(&saved_at), "{saved_at}");
        // A change 2 s later waits for the minute's minimum interval.
        w.advance_ms(2_000);
        let c = Config {
            onset_frames: 40,
            ..node.config().clone()
        };
        command(&mut node, &w, 30, Command::SetConfigV3(c.clone()));
        let due = node.save_due_ms().expect("pending");
        assert_eq!(due, saved_at + SAVE_MIN_INTERVAL_MS);
        run_until_saved(&mut node, &w);
        assert_eq!(writes(node), 2);
    }

    /// Changes that never stop are still saved, every max delay.
    #[test]
    fn endless_changes_are_saved_at_the_max_delay() {
        let (mut node, w) = node();
        let t0 = w.now_ms();
        let mut saves_at = Vec::new();
        for i in 0..900u32 {
            // A new value every 100 ms for 90 s: never quiet for 1 s.
            let c = Config {
                onset_rise_na: 1_000 + i,
                ..Config::default()
            };
            command(&mut node, &w, 1, Command::SetConfigV3(c));
            let now = w.now_ms() - t0;
            step(&mut node, &w);
            if !node.save_pending() {
                saves_at.push(now);
            }
        }
        // The first at SAVE_MAX_DELAY_MS after the first unsaved change, the
        // next SAVE_MIN_INTERVAL_MS after it (the max delay, from 10 100 ms,
        // came sooner; the interval wins).
        assert_eq!(SAVE_MAX_DELAY_MS, 10_000);
        assert_eq!(SAVE_MIN_INTERVAL_MS, 60_000);
        assert_eq!(saves_at, vec![10_000, 70_000], "{saves_at:?}");
    }

    /// The button's acknowledgement never writes flash.
    #[test]
    fn the_button_ack_never_writes() {
        let (mut node, w) = node();
        w.set(|s| {
            s.temp_c = -8.0;
            s.signal_na = [25_000.0, 8_000.0];
        });
        for _ in 0..node.config().onset_frames {
            step(&mut node, &w);
        }
        assert_eq!(node.state(), DetectorState::Ice);
        for _ in 0..20 {
            let mut bytes = Vec::new();
            node.button_pressed(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
            assert_eq!(ack(frames(&bytes), BUTTON_ID), AckResult::AlarmAcknowledged);
            assert!(!node.save_pending());
            step(&mut node, &w);
        }
        assert_eq!(writes(node), 0);
    }

    /// A reset saves what is pending first (else a config sent just before
    /// a reset would be lost).
    #[test]
    fn reset_saves_what_is_pending() {
        let (mut node, w) = node();
        let c = Config {
            clear_frames: 500,
            ..Config::default()
        };
        command(&mut node, &w, 1, Command::SetConfigV3(c.clone()));
        assert!(node.save_pending());
        assert_eq!(
            ack(command(&mut node, &w, 2, Command::Reset), 2),
            AckResult::Resetting
        );
        assert!(!node.save_pending());
        assert!(node.take_reset_request());
        let storage = node.into_parts().5;
        assert_eq!(storage.writes, 1);
        let (node, _) = node_with(storage);
        assert_eq!(node.config(), &c);
    }
}

/// The NTC breaks during icing in warm-looking conditions: the node reads
/// the die (warmer than the air); the film must still mean ice, and the
/// alarm must not clear on the die's "thaw".
#[test]
fn ntc_fault_makes_a_film_ice_and_blocks_thaw_clearing() {
    let (mut node, w) = node();
    let n = u32::from(node.config().onset_frames);
    // The die reads 12 °C; the real air is at -1 °C.
    w.set(|s| {
        s.temp_c = 12.0;
        s.ntc_code = Some(4095);
        s.signal_na = [3_000.0, 900.0];
    });
    let mut kinds = Vec::new();
    for _ in 0..n {
        kinds.extend(events(&step(&mut node, &w)).into_iter().map(|e| e.kind));
    }
    assert_eq!(
        kinds,
        vec![EventKind::FaultRaised(flags::NTC_OPEN), EventKind::IceOnset]
    );
    assert!(w.alarm.get());
    // With a working NTC at the same 12 °C it is water.
    let (mut twin, tw) = common::node();
    tw.set(|s| {
        s.temp_c = 12.0;
        s.signal_na = [3_000.0, 900.0];
    });
    for _ in 0..n {
        step(&mut twin, &tw);
    }
    assert_eq!(twin.state(), DetectorState::Wet);
    // The die "warms" to 30 °C: the alarm holds for 10 N frames.
    w.set(|s| s.temp_c = 30.0);
    for _ in 0..10 * n {
        assert!(events(&step(&mut node, &w)).is_empty());
    }
    assert!(w.alarm.get());
    // The film goes: cleared after M frames, on optics.
    w.set(|s| s.signal_na = [0.0, 0.0]);
    let m = u32::from(node.config().clear_frames);
    let mut cleared = 0;
    for i in 1..=m {
        if events(&step(&mut node, &w))
            .iter()
            .any(|e| e.kind == EventKind::IceCleared)
        {
            cleared = i;
        }
    }
    assert_eq!(cleared, m);
    assert!(!w.alarm.get());
}

#[test]
fn clock_fallback_is_a_fault_flag() {
    let (mut node, w) = node();
    node.set_clock_fallback(true);
    let fs = step(&mut node, &w);
    assert_ne!(measurement(&fs).flags & flags::CLOCK_FALLBACK, 0);
    assert_eq!(
        events(&fs)[0].kind,
        EventKind::FaultRaised(flags::CLOCK_FALLBACK)
    );
    assert!(events(&step(&mut node, &w)).is_empty(), "raised once");
}
