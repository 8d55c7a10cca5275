//! Every message survives encode → frame → decode unchanged, and no frame is
//! ever longer than `MAX_FRAME`.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use fois_protocol::*;
use proptest::prelude::*;

fn decode_all<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Vec<Result<T, FrameError>> {
    let mut dec = FrameDecoder::<MAX_FRAME>::new();
    let mut out = Vec::new();
    dec.feed::<T>(bytes, |r| out.push(r));
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn device_frames_round_trip(frame in common::device_frame()) {
        let bytes = encode_to_vec(&frame);
        prop_assert!(bytes.len() <= MAX_FRAME, "{} > {}", bytes.len(), MAX_FRAME);
        prop_assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1);
        prop_assert_eq!(decode_all::<DeviceFrame>(&bytes), vec![Ok(frame)]);
    }

    #[test]
    fn host_frames_round_trip(frame in common::host_frame()) {
        let bytes = encode_to_vec(&frame);
        prop_assert!(bytes.len() <= MAX_FRAME);
        prop_assert_eq!(decode_all::<HostFrame>(&bytes), vec![Ok(frame)]);
    }

    /// A stream of frames cut into arbitrary chunks decodes to the same frames.
    #[test]
    fn chunking_does_not_matter(
        frames in proptest::collection::vec(common::device_frame(), 1..20),
        cut in 1usize..64,
    ) {
        let stream: Vec<u8> = frames.iter().flat_map(encode_to_vec).collect();
        let mut dec = FrameDecoder::<MAX_FRAME>::new();
        let mut got = Vec::new();
        for chunk in stream.chunks(cut) {
            dec.feed::<DeviceFrame>(chunk, |r| got.push(r));
        }
        let want: Vec<_> = frames.into_iter().map(Ok).collect();
        prop_assert_eq!(got, want);
    }

    /// Arbitrary bytes never panic the decoder, and whatever it accepts is a
    /// real message that re-encodes to a frame.
    #[test]
    fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let mut dec = FrameDecoder::<MAX_FRAME>::new();
        dec.feed::<HostFrame>(&bytes, |r| {
            if let Ok(f) = r {
                assert!(!encode_to_vec(&f).is_empty());
            }
        });
        let s = dec.stats();
        let zeros = bytes.iter().filter(|&&b| b == 0).count() as u32;
        prop_assert!(s.frames + s.rejected() <= zeros);
    }
}

/// The largest message of each direction, built by hand with every varint at
/// its widest, fits in MAX_FRAME; and MAX_PAYLOAD is tight for it.
#[test]
fn max_frame_bounds_the_widest_messages() {
    let widest_measurement = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::Measurement(Measurement {
            uptime_ms: u64::MAX,
            i1_na: i32::MIN,
            i2_na: i32::MIN,
            ambient1_na: u32::MAX,
            ambient2_na: u32::MAX,
            temperature_centi_c: i16::MIN,
            vdda_mv: u16::MAX,
            flags: u16::MAX,
            state: DetectorState::Ice,
        }),
    };
    let widest_measurement_v2 = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::MeasurementV2(MeasurementV2 {
            measurement: match widest_measurement.msg.clone() {
                DeviceMsg::Measurement(m) => m,
                _ => unreachable!(),
            },
            estimate: Some(IceEstimate {
                thickness_um: u16::MAX,
                sigma_um: u16::MAX,
                medium: Medium::Rime,
                probability_permille: u16::MAX,
            }),
        }),
    };
    let widest_measurement_v3 = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::MeasurementV3(MeasurementV3 {
            measurement: match widest_measurement.msg.clone() {
                DeviceMsg::Measurement(m) => m,
                _ => unreachable!(),
            },
            estimate: Some(IceEstimate {
                thickness_um: u16::MAX,
                sigma_um: u16::MAX,
                medium: Medium::Rime,
                probability_permille: u16::MAX,
            }),
            gain: Some(GainEstimate {
                gain_ppm: u32::MAX,
                sigma_ppm: u32::MAX,
            }),
        }),
    };
    let widest_config_v1 = ConfigV1 {
        frame_period_ms: u32::MAX,
        cycles_per_frame: u16::MAX,
        settle_us: u16::MAX,
        load_r1_ohm: u32::MAX,
        load_r2_ohm: u32::MAX,
        onset_rise_na: u32::MAX,
        onset_frames: u16::MAX,
        clear_rise_na: u32::MAX,
        clear_frames: u16::MAX,
        freeze_limit_centi_c: i16::MIN,
        thaw_limit_centi_c: i16::MIN,
        stream_on_boot: true,
    };
    let widest_config = Config {
        gain_tempco_ppm_per_k: i32::MIN,
        gain_tempco_sd_ppm_per_k: u32::MAX,
        gain_low_permille: u16::MAX,
        gain_high_permille: u16::MAX,
        ..Config::from(widest_config_v1.clone())
    };
    // The version-3 content, and the widest icing rate.
    let widest_measurement_v5 = match widest_measurement_v3.msg.clone() {
        DeviceMsg::MeasurementV3(v3) => DeviceFrame {
            seq: u32::MAX,
            msg: DeviceMsg::MeasurementV5(MeasurementV5 {
                measurement: v3.measurement,
                estimate: v3.estimate,
                gain: v3.gain,
                icing: Some(IcingEstimate {
                    rate_um_per_h: u16::MAX,
                    sigma_um_per_h: u16::MAX,
                    accreting_permille: u16::MAX,
                    accreting: true,
                }),
            }),
        },
        _ => unreachable!(),
    };
    let widest_ack = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::Ack(Ack {
            id: u16::MAX,
            result: AckResult::Config(widest_config_v1.clone()),
        }),
    };
    let widest_ack_v3 = DeviceFrame {
        seq: u32::MAX,
        msg: DeviceMsg::Ack(Ack {
            id: u16::MAX,
            result: AckResult::ConfigV3(widest_config.clone()),
        }),
    };
    let widest_cmd = HostFrame {
        id: u16::MAX,
        cmd: Command::SetConfig(widest_config_v1),
    };
    let widest_cmd_v3 = HostFrame {
        id: u16::MAX,
        cmd: Command::SetConfigV3(widest_config),
    };
    let widest_chunk = HostFrame {
        id: u16::MAX,
        cmd: Command::UpdateChunk(UpdateChunk {
            offset: u32::MAX,
            crc32: u32::MAX,
            data: ChunkData::new(&[0xFF; UPDATE_CHUNK_MAX]).unwrap(),
        }),
    };
    let sizes = [
        postcard::to_stdvec(&widest_measurement).unwrap().len(),
        postcard::to_stdvec(&widest_measurement_v2).unwrap().len(),
        postcard::to_stdvec(&widest_measurement_v3).unwrap().len(),
        postcard::to_stdvec(&widest_ack).unwrap().len(),
        postcard::to_stdvec(&widest_ack_v3).unwrap().len(),
        postcard::to_stdvec(&widest_cmd).unwrap().len(),
        postcard::to_stdvec(&widest_cmd_v3).unwrap().len(),
        postcard::to_stdvec(&widest_measurement_v5).unwrap().len(),
        postcard::to_stdvec(&widest_chunk).unwrap().len(),
    ];
    for s in sizes {
        assert!(s <= MAX_PAYLOAD, "payload {s} > MAX_PAYLOAD {MAX_PAYLOAD}");
    }
    // The widest `UpdateChunk` (version 6: 256 image bytes) is the largest
    // message (the widest `MeasurementV5` 79 B): MAX_PAYLOAD is exact.
    assert_eq!(sizes[8], MAX_PAYLOAD);
    assert_eq!(sizes.iter().max().copied(), Some(MAX_PAYLOAD));
    for f in [
        &widest_measurement,
        &widest_measurement_v2,
        &widest_measurement_v3,
        &widest_measurement_v5,
        &widest_ack,
        &widest_ack_v3,
    ] {
        assert!(encode_to_vec(f).len() <= MAX_FRAME);
    }
    for f in [&widest_cmd, &widest_cmd_v3, &widest_chunk] {
        assert!(encode_to_vec(f).len() <= MAX_FRAME);
    }
    println!("MAX_PAYLOAD = {MAX_PAYLOAD} B, MAX_FRAME = {MAX_FRAME} B, sizes {sizes:?}");
}

/// A typical 10 Hz measurement frame is small: what the UART carries.
#[test]
fn typical_measurement_frame_size() {
    let m = DeviceFrame {
        seq: 123_456,
        msg: DeviceMsg::Measurement(Measurement {
            uptime_ms: 12_345_678,
            i1_na: 25_000,
            i2_na: 8_000,
            ambient1_na: 40_000,
            ambient2_na: 30_000,
            temperature_centi_c: -512,
            vdda_mv: 3_300,
            flags: flags::ALARM,
            state: DetectorState::Ice,
        }),
    };
    let n = encode_to_vec(&m).len();
    // 115200 baud 8N1 = 11520 B/s; at 10 Hz a frame must stay far below 1152 B.
    assert!(n <= 40, "typical measurement frame is {n} B");
    let DeviceMsg::Measurement(measurement) = m.msg else {
        unreachable!()
    };
    let v2 = DeviceFrame {
        seq: 123_456,
        msg: DeviceMsg::MeasurementV2(MeasurementV2 {
            measurement,
            estimate: Some(IceEstimate {
                thickness_um: 2_300,
                sigma_um: 300,
                medium: Medium::Rime,
                probability_permille: 970,
            }),
        }),
    };
    let n2 = encode_to_vec(&v2).len();
    assert!(n2 <= 48, "typical version-2 measurement frame is {n2} B");
    let DeviceMsg::MeasurementV2(MeasurementV2 {
        measurement,
        estimate,
    }) = v2.msg
    else {
        unreachable!()
    };
    let v3 = DeviceFrame {
        seq: 123_456,
        msg: DeviceMsg::MeasurementV3(MeasurementV3 {
            measurement,
            estimate,
            gain: Some(GainEstimate {
                gain_ppm: 1_032_000,
                sigma_ppm: 41_000,
            }),
        }),
    };
    let n3 = encode_to_vec(&v3).len();
    // 19 200 Bd (long field cables) carries 1 920 B/s: at 10 Hz a frame must stay under 192 B.
    assert!(n3 <= 56, "typical version-3 measurement frame is {n3} B");
    println!("typical measurement frame: v1 {n} B, v2 {n2} B, v3 {n3} B");
}
