//! Modbus RTU on the simulated node: requests (with their CRC) through the
//! node's own server, answers byte for byte, the exceptions, the write
//! enable, broadcasts, malformed frames dropped, writes carried out by the
//! node (alarm acknowledge, setpoints, the switch back to framed), and no
//! panic on any bytes (proptest).
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::modbus::server::{CRC16, crc_ok};
use fois_firmware::modbus::{Answer, RtuServer};
use fois_protocol::registers::{self, CommandResult, status};
use fois_protocol::*;
use proptest::prelude::*;

fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend(CRC16.checksum(body).to_le_bytes());
    v
}

fn read(addr: u8, fc: u8, start: u16, count: u16) -> Vec<u8> {
    let [s0, s1] = start.to_be_bytes();
    let [c0, c1] = count.to_be_bytes();
    with_crc(&[addr, fc, s0, s1, c0, c1])
}

fn write1(addr: u8, reg: u16, v: u16) -> Vec<u8> {
    let [r0, r1] = reg.to_be_bytes();
    let [v0, v1] = v.to_be_bytes();
    with_crc(&[addr, 6, r0, r1, v0, v1])
}

fn write_n(addr: u8, reg: u16, vs: &[u16]) -> Vec<u8> {
    let [r0, r1] = reg.to_be_bytes();
    let mut b = vec![addr, 16, r0, r1, 0, vs.len() as u8, 2 * vs.len() as u8];
    for v in vs {
        b.extend(v.to_be_bytes());
    }
    with_crc(&b)
}

/// The words of a read's answer (checked: address, function, count, CRC).
fn words(a: &Answer, addr: u8, fc: u8) -> Vec<u16> {
    let r = a.reply.as_ref().expect("no answer");
    assert!(crc_ok(r), "{r:02x?}");
    assert_eq!((r[0], r[1]), (addr, fc), "{r:02x?}");
    let n = usize::from(r[2]);
    assert_eq!(r.len(), 3 + n + 2);
    r[3..3 + n]
        .chunks(2)
        .map(|w| u16::from_be_bytes([w[0], w[1]]))
        .collect()
}

/// The exception code of an answer.
fn exception(a: &Answer, addr: u8, fc: u8) -> u8 {
    let r = a.reply.as_ref().expect("no answer");
    assert!(crc_ok(r));
    assert_eq!(r.len(), 5, "{r:02x?}");
    assert_eq!((r[0], r[1]), (addr, fc | 0x80));
    r[2]
}

/// An iced node (alarm on) with its view.
fn iced() -> (SimNode, World) {
    let (mut node, w) = node();
    w.set(|s| s.temp_c = -4.0);
    step(&mut node, &w);
    w.set(|s| s.signal_na = [2_500.0, 800.0]);
    for _ in 0..node.config().onset_frames {
        step(&mut node, &w);
    }
    assert_eq!(node.state(), DetectorState::Ice);
    (node, w)
}

#[test]
fn every_register_is_the_nodes_last_measurement_in_the_maps_scales() {
    let (mut node, w) = iced();
    let fs = step(&mut node, &w);
    let (m, est, gain, icing, seq) = fs
        .iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::MeasurementV5(v) => {
                Some((v.measurement.clone(), v.estimate, v.gain, v.icing, f.seq))
            }
            _ => None,
        })
        .expect("a measurement");
    let mut server = RtuServer::new(7);
    let view = node.modbus_view();
    let a = server.answer(&read(7, 4, 0, 27), &view, w.now_ms());
    let r = words(&a, 7, 4);
    assert_eq!(r.len(), 27);
    // The same mapping the gateway uses, from this frame's integers.
    let mut want = registers::not_available();
    registers::set32(&mut want, registers::FRAMES_LOST, registers::NA_U32);
    registers::set(&mut want, registers::STATUS, status::LINK_UP);
    registers::measurement_registers(
        &mut want,
        &registers::Sample {
            measurement: &m,
            seq,
            estimate: est.as_ref(),
            gain: gain.as_ref(),
            icing: icing.as_ref().map(registers::IcingRate::from),
        },
    );
    assert_eq!(r, want.to_vec());
    // And in plain numbers: the state, the alarm, I1 in nA, °C × 100.
    assert_eq!(r[1], 2);
    assert_ne!(r[0] & status::ALARM, 0);
    assert_eq!(r[0] & status::STALE, 0);
    let i1 = ((u32::from(r[3]) << 16) | u32::from(r[4])) as i32;
    assert_eq!(i1, m.i1_na);
    assert!((i1 - 2_500).abs() <= 100, "{i1}");
    assert_eq!(r[7] as i16, m.temperature_centi_c);
    assert_eq!((u32::from(r[18]) << 16) | u32::from(r[19]), seq);
    // The gateway-only registers: not available.
    assert_eq!((r[16], r[17]), (0xFFFF, 0xFFFF));
    assert_eq!((r[21], r[22]), (0xFFFF, 0xFFFF));
    // The icing rate, in 0.01 mm/h and ‰, once the frame carries it.
    let i = icing.expect("a version-5 node reports its icing rate");
    assert_eq!(r[24], (i.rate_um_per_h + 5) / 10);
    assert_eq!(r[26], i.accreting_permille);
    assert_ne!(r[0] & status::ICING_RATE, 0);
    // FC 03 reads the same.
    let h = server.answer(&read(7, 3, 0, 27), &view, w.now_ms());
    assert_eq!(words(&h, 7, 3), r);
}

#[test]
fn exceptions_for_function_address_quantity_and_a_write_without_enable() {
    let (node, w) = node();
    let view = node.modbus_view();
    let mut s = RtuServer::new(1);
    let t = w.now_ms();
    // 01: coils, diagnostics, a code ≥ 0x80.
    for fc in [1u8, 2, 5, 8, 0x2B, 0x81, 0xFF] {
        let a = s.answer(&with_crc(&[1, fc, 0, 0, 0, 1]), &view, t);
        assert_eq!(exception(&a, 1, fc & 0x7F), 1, "fc {fc:#x}");
    }
    // 02: beyond either block, crossing a block's end, writing a read-only register.
    for (start, count) in [(27, 1), (26, 2), (50, 1), (99, 2), (109, 2), (110, 1)] {
        let a = s.answer(&read(1, 3, start, count), &view, t);
        assert_eq!(exception(&a, 1, 3), 2, "{start}+{count}");
    }
    assert_eq!(exception(&s.answer(&write1(1, 0, 1), &view, t), 1, 6), 2);
    assert_eq!(exception(&s.answer(&write1(1, 102, 1), &view, t), 1, 6), 2);
    // 03: quantity 0, 126; FC 16 of 124; byte count not twice the quantity.
    assert_eq!(exception(&s.answer(&read(1, 4, 0, 0), &view, t), 1, 4), 3);
    assert_eq!(exception(&s.answer(&read(1, 4, 0, 126), &view, t), 1, 4), 3);
    let mut big = vec![1, 16, 0, 100, 0, 124, 248];
    big.extend([0u8; 248]);
    assert_eq!(exception(&s.answer(&with_crc(&big), &view, t), 1, 16), 3);
    let odd = with_crc(&[1, 16, 0, 100, 0, 2, 2, 0x57, 0x45]);
    assert_eq!(exception(&s.answer(&odd, &view, t), 1, 16), 3);
    // 04: a write while writes are disabled; nothing queued.
    let a = s.answer(&write1(1, registers::ACK, 1), &view, t);
    assert_eq!(exception(&a, 1, 6), 4);
    assert!(a.actions.is_empty());
    // Enabled: a wrong value is 03, a right one echoed and queued.
    let a = s.answer(&write1(1, registers::WRITE_ENABLE, 0x5745), &view, t);
    assert_eq!(a.reply.as_deref(), Some(&write1(1, 100, 0x5745)[..]));
    assert_eq!(
        exception(&s.answer(&write1(1, registers::ACK, 2), &view, t), 1, 6),
        3
    );
    assert_eq!(
        exception(&s.answer(&write1(1, 104, 248), &view, t), 1, 6),
        3
    );
    assert_eq!(exception(&s.answer(&write1(1, 105, 3), &view, t), 1, 6), 3);
    // The config rule: a thaw limit below the freeze limit is refused.
    assert_eq!(
        exception(&s.answer(&write1(1, 107, (-500i16) as u16), &view, t), 1, 6),
        3
    );
    let a = s.answer(&write1(1, registers::ACK, 1), &view, t);
    assert_eq!(a.reply.as_deref(), Some(&write1(1, 23, 1)[..]));
    assert_eq!(a.actions.len(), 1);
    // The enable lapses 60 s after the last accepted write.
    assert!(s.writes_enabled(t + 59_999));
    let a = s.answer(&write1(1, registers::ACK, 1), &view, t + 60_000);
    assert_eq!(exception(&a, 1, 6), 4);
}

#[test]
fn malformed_frames_are_dropped_and_the_next_good_one_answered() {
    let (node, w) = node();
    let view = node.modbus_view();
    let mut s = RtuServer::new(1);
    let t = w.now_ms();
    let good = read(1, 4, 0, 2);
    let mut bad_crc = good.clone();
    bad_crc[7] ^= 1;
    let mut two = good.clone();
    two.extend(&good);
    let mut long = good.clone();
    long.push(0);
    let mut trailing_crc_ok = good[..6].to_vec();
    trailing_crc_ok.push(0x55);
    let trailing_crc_ok = with_crc(&trailing_crc_ok);
    for (what, bytes) in [
        ("bad CRC", bad_crc),
        ("truncated", good[..5].to_vec()),
        ("empty", vec![]),
        ("two frames back to back", two),
        ("a byte too long", long),
        ("trailing byte under a good CRC", trailing_crc_ok),
        ("another address", read(2, 4, 0, 2)),
        ("garbage", vec![0xFF; 40]),
        ("broadcast read", read(0, 4, 0, 2)),
    ] {
        let a = s.answer(&bytes, &view, t);
        assert!(a.reply.is_none() && a.actions.is_empty(), "{what}");
    }
    assert_eq!(words(&s.answer(&good, &view, t), 1, 4).len(), 2);
}

#[test]
fn writes_acknowledge_the_alarm_change_setpoints_and_a_broadcast_is_not_answered() {
    let (mut node, w) = iced();
    let mut s = RtuServer::new(9);
    let t = w.now_ms();
    let view = node.modbus_view();
    assert_eq!(view.registers[0] & status::ALARM_ACKED, 0);
    // A broadcast enables writes and writes the setpoints: no answer.
    let a = s.answer(&write1(0, 100, 0x5745), &view, t);
    assert!(a.reply.is_none());
    let a = s.answer(&write_n(0, 106, &[(-150i16) as u16, 250]), &view, t);
    assert!(a.reply.is_none());
    assert_eq!(a.actions.len(), 1);
    for act in a.actions {
        assert_eq!(node.modbus_action(act, t), CommandResult::Done);
    }
    assert_eq!(node.config().freeze_limit_centi_c, -150);
    assert_eq!(node.config().thaw_limit_centi_c, 250);
    // The acknowledge, answered by its echo, then carried out.
    let a = s.answer(&write_n(9, registers::ACK, &[1]), &node.modbus_view(), t);
    assert_eq!(
        a.reply.as_deref(),
        Some(&with_crc(&[9, 16, 0, 23, 0, 1])[..])
    );
    for act in a.actions {
        let r = node.modbus_action(act, t);
        s.set_last_result(r);
        assert_eq!(r, CommandResult::Done);
    }
    step(&mut node, &w);
    let r = words(&s.answer(&read(9, 3, 0, 1), &node.modbus_view(), t), 9, 3);
    assert_ne!(r[0] & status::ALARM_ACKED, 0);
    assert_ne!(r[0] & status::ALARM, 0, "the output stays on while iced");
    // The node block: writes enabled, result done, the link (framed: the
    // node's own settings, this server is the test's) at address 1 with
    // 8E1, the setpoints.
    let nb = words(
        &s.answer(&read(9, 3, 100, 10), &node.modbus_view(), t),
        9,
        3,
    );
    let c = node.config();
    assert_eq!(
        nb,
        [
            1,
            0,
            1,
            0,
            1,
            0,
            (-150i16) as u16,
            250,
            c.onset_frames,
            c.clear_frames
        ]
    );
    assert_eq!((c.onset_frames, c.clear_frames), (30, 300));
    // A dark calibration on an iced face is refused: result 3.
    let a = s.answer(&write1(9, 101, 1), &node.modbus_view(), t);
    let r = node.modbus_action(a.actions[0].clone(), t);
    assert_eq!(r, CommandResult::Refused);
}

#[test]
fn a_modbus_write_and_the_button_at_power_up_switch_back_to_framed_and_it_survives_a_reset() {
    let (mut node, w) = node();
    let t = w.now_ms();
    let modbus = LinkSettings {
        protocol: LinkProtocol::ModbusRtu,
        modbus_address: 12,
        parity: Parity::None8N2,
    };
    assert_eq!(
        node.command(Command::SetLinkSettings(modbus), t),
        Ok(AckResult::LinkSettings(modbus))
    );
    // Saved at once, and a reset asked for: the board sets its UART up
    // from the record.
    assert!(!node.save_pending());
    assert!(node.take_reset_request());
    assert_eq!(
        node.command(Command::SetLinkSettings(modbus), t),
        Ok(AckResult::LinkSettings(modbus))
    );
    assert!(!node.take_reset_request(), "no change, no reset");
    // A reset: the record brings the Modbus link back.
    let storage = node.into_parts().5;
    let mut node = fois_firmware::sim_board::sim_node(w.clone(), storage, "sim");
    assert_eq!(node.link_settings(), modbus);
    // Modbus: writes enabled, link_protocol = 0.
    let mut s = RtuServer::new(12);
    let view = node.modbus_view();
    s.answer(&write1(12, 100, 0x5745), &view, t);
    let a = s.answer(&write1(12, 103, 0), &view, t);
    assert_eq!(a.reply.as_deref(), Some(&write1(12, 103, 0)[..]));
    for act in a.actions {
        assert_eq!(node.modbus_action(act, t), CommandResult::Done);
    }
    assert_eq!(node.link_settings(), modbus.framed());
    // Back to Modbus; the button held at power-up returns to framed.
    node.command(Command::SetLinkSettings(modbus), t).unwrap();
    assert!(node.take_reset_request());
    assert!(node.button_held_at_boot(t));
    assert!(!node.button_held_at_boot(t), "already framed");
    assert_eq!(node.link_settings().protocol, LinkProtocol::Framed);
    assert!(!node.save_pending(), "saved at once");
    let storage = node.into_parts().5;
    let mut node = fois_firmware::sim_board::sim_node(w.clone(), storage, "sim");
    assert_eq!(node.link_settings(), modbus.framed());
    // An address of 0 is refused by the framed command too.
    let bad = LinkSettings {
        modbus_address: 0,
        ..modbus
    };
    assert_eq!(
        node.command(Command::SetLinkSettings(bad), t),
        Err(ErrorCode::InvalidLinkSettings(
            LinkSettingsError::AddressOutOfRange
        ))
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4_000, rng_seed: proptest::test_runner::RngSeed::Fixed(33), ..ProptestConfig::default() })]

    /// Any bytes: no panic; an answer only to a frame with a good CRC for
    /// this address, itself with a good CRC, echoing the address.
    #[test]
    fn any_request_never_panics_and_answers_are_well_formed(
        body in proptest::collection::vec(any::<u8>(), 0..300),
        fix_crc in any::<bool>(),
        enable in any::<bool>(),
    ) {
        let (node, w) = node();
        let view = node.modbus_view();
        let mut s = RtuServer::new(1);
        if enable {
            s.answer(&write1(1, 100, 0x5745), &view, 0);
        }
        let req = if fix_crc { with_crc(&body) } else { body.clone() };
        let a = s.answer(&req, &view, w.now_ms());
        if let Some(r) = &a.reply {
            prop_assert!(crc_ok(&req));
            prop_assert_eq!(req[0], 1);
            prop_assert!(crc_ok(r));
            prop_assert_eq!(r[0], 1);
            prop_assert!(r.len() <= 256);
        }
    }
}

/// firmware/README.md shows both blocks of the map as
/// `fois_protocol::registers` defines them (and prints them when not).
#[test]
fn the_readme_shows_the_register_map() {
    let readme = include_str!("../README.md");
    for (name, table) in [
        (
            "measurement block",
            registers::markdown_table(&registers::TABLE),
        ),
        (
            "node block",
            registers::markdown_table(&registers::NODE_TABLE),
        ),
    ] {
        assert!(
            readme.contains(&table),
            "firmware/README.md's {name} differs from fois_protocol::registers; it is:\n\n{table}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2_000, rng_seed: proptest::test_runner::RngSeed::Fixed(35), ..ProptestConfig::default() })]

    /// Any bytes at any gaps: the framer never panics, never gives a frame
    /// over 256 bytes, and every frame it gives is exactly a run of bytes
    /// without a gap over t1.5, ended by t3.5 of silence.
    #[test]
    fn the_silence_framer_gives_exactly_the_unbroken_runs(
        input in proptest::collection::vec((0u16..5_000, any::<u8>()), 0..600),
    ) {
        use fois_firmware::modbus::{SilenceFramer, Silences};
        let s = Silences::at(19_200, Parity::Even8E1);
        let mut f = SilenceFramer::new(s);
        let mut t = 0u64;
        let mut got = Vec::new();
        // The model: runs split at gaps ≥ t3.5; a run with a gap > t1.5
        // or over 256 bytes is dropped.
        let mut want = Vec::new();
        let (mut run, mut broken) = (Vec::new(), false);
        for (i, &(gap, b)) in input.iter().enumerate() {
            t += u64::from(gap);
            if i > 0 && u32::from(gap) >= s.t35_us {
                if !broken && run.len() <= 256 { want.push(run.clone()); }
                run.clear();
                broken = false;
            } else if i > 0 && u32::from(gap) > s.t15_us {
                broken = true;
            }
            run.push(b);
            if let Some(fr) = f.push(b, t) { got.push(fr.to_vec()); }
        }
        if !input.is_empty() && !broken && run.len() <= 256 { want.push(run); }
        if let Some(fr) = f.poll(t + u64::from(s.t35_us)) { got.push(fr.to_vec()); }
        prop_assert_eq!(got, want);
    }
}
