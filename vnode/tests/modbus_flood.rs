//! A Modbus master flooding the node with requests (a read of the whole
//! block every 3 ms of node time, garbage and broken frames among them)
//! changes nothing the node does: the same measurement frames, byte for
//! byte, the same events and the same alarm edges as the same node left
//! alone. The requests go through the firmware's own framer and server
//! (`fois_vnode::modbus_link`) on the node's virtual clock.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use fois_firmware::modbus::server::CRC16;
use fois_protocol::{Command, LinkProtocol, LinkSettings, Parity};
use fois_vnode::modbus_link::ModbusLink;
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

fn iced_node() -> VirtualNode {
    // 20 s dry, then a cover reading 3 µA over the dark face at -5 °C:
    // ice, the alarm on 3 s later.
    let tl = Timeline::new(vec![
        Segment::new(20.0, Cover::Dry).temp(-5.0),
        Segment::new(f64::INFINITY, Cover::Dry)
            .target([3.0, 1.0])
            .temp(-5.0),
    ]);
    let env = Arc::new(Environment::with_curves(tl, [], [0.6, 0.2]));
    let mut node = VirtualNode::new(env, NodeOptions::default());
    let modbus = LinkSettings {
        protocol: LinkProtocol::ModbusRtu,
        modbus_address: 5,
        parity: Parity::Even8E1,
    };
    node.command(Command::SetLinkSettings(modbus), &mut |_| {})
        .unwrap();
    node
}

fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend(CRC16.checksum(body).to_le_bytes());
    v
}

#[test]
fn a_request_flood_changes_no_frame_and_no_alarm_edge() {
    let end_s = 60.0;
    // Alone.
    let mut quiet = iced_node();
    let mut quiet_frames = Vec::new();
    quiet.run_until_s(end_s, &mut |b| quiet_frames.extend_from_slice(b));

    // Flooded: every 3 ms a request, every tenth of them broken.
    let mut busy = iced_node();
    let mut busy_frames = Vec::new();
    let mut link = ModbusLink::new(19_200, busy.node().link_settings());
    let read = with_crc(&[5, 4, 0, 0, 0, 27]);
    let mut answers = Vec::new();
    let mut sent = 0u64;
    let mut t_us = busy.clock().now_ns() / 1_000;
    while (t_us as f64) < end_s * 1e6 {
        busy.advance_to(t_us * 1_000, &mut |b| busy_frames.extend_from_slice(b));
        let req: Vec<u8> = if sent % 10 == 9 {
            vec![5, 4, 0xFF, 0x13]
        } else {
            read.clone()
        };
        sent += 1;
        link.receive(
            &mut busy,
            &req,
            t_us,
            &mut |r| answers.push(r.to_vec()),
            &mut |b| busy_frames.extend_from_slice(b),
        );
        // The silence after it ends the frame; the answer follows.
        let t_end = t_us + u64::from(link.silences().t35_us);
        busy.advance_to(t_end * 1_000, &mut |b| busy_frames.extend_from_slice(b));
        link.poll(
            &mut busy,
            t_end,
            &mut |r| answers.push(r.to_vec()),
            &mut |b| busy_frames.extend_from_slice(b),
        );
        t_us += 3_000;
    }
    busy.advance_to((end_s * 1e9) as u64, &mut |b| {
        busy_frames.extend_from_slice(b)
    });

    let good = sent - sent / 10;
    println!(
        "{sent} requests in {end_s} s of node time, {} answered; {} frame bytes",
        answers.len(),
        busy_frames.len()
    );
    assert_eq!(
        answers.len() as u64,
        good,
        "every good request, and only those"
    );
    assert!(
        answers
            .iter()
            .all(|a| a.len() == 3 + 54 + 2 && a[..3] == [5, 4, 54])
    );
    assert!(quiet.node().state() == fois_protocol::DetectorState::Ice);
    assert_eq!(busy_frames, quiet_frames, "the node's frames changed");
    assert_eq!(busy.alarm_pin().edges(), quiet.alarm_pin().edges());
    assert!(!busy.alarm_pin().edges().is_empty(), "the alarm tripped");
}
