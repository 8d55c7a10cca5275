//! One register map, two servers: the same measurement read from the
//! gateway's Modbus TCP table (`fois_gateway::modbus::register_map`, from
//! the node's snapshot as the reader fills it) and from the node's own
//! Modbus RTU link (the virtual node's firmware framer and server, a real
//! RTU request with its CRC) gives the same value in every register both
//! serve; the gateway-only ones (data age, frames lost) read "not
//! available" on the node.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;
use std::time::{Duration, Instant};

use fois_gateway::modbus::{REGISTERS, register_map};
use fois_gateway::snapshot::NodeSnapshot;
use fois_link::Reading;
use fois_protocol::registers::{DATA_AGE, FRAMES_LOST, NA_U16};
use fois_protocol::{
    Command, DeviceFrame, DeviceMsg, FrameDecoder, LinkProtocol, LinkSettings, Parity,
};
use fois_vnode::modbus_link::ModbusLink;
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

#[test]
fn a_register_read_over_tcp_and_over_rtu_gives_the_same_value_for_the_same_measurement() {
    // Dry 10 s, then a cover reading 3 µA over the dark face at -5 °C: ice.
    let tl = Timeline::new(vec![
        Segment::new(10.0, Cover::Dry).temp(-5.0),
        Segment::new(f64::INFINITY, Cover::Dry)
            .target([3.0, 1.0])
            .temp(-5.0),
    ]);
    let env = Arc::new(Environment::with_curves(tl, [], [0.6, 0.2]));
    let mut node = VirtualNode::new(env, NodeOptions::default());
    let settings = LinkSettings {
        protocol: LinkProtocol::ModbusRtu,
        modbus_address: 9,
        parity: Parity::Even8E1,
    };
    node.command(Command::SetLinkSettings(settings), &mut |_| {})
        .unwrap();
    let mut link = ModbusLink::new(19_200, settings);
    let mut frames = Vec::new();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    for t_s in [5.0, 20.0, 30.5] {
        let mut bytes = Vec::new();
        node.run_until_s(t_s, &mut |b| bytes.extend_from_slice(b));
        dec.feed::<DeviceFrame>(&bytes, |r| {
            if let Ok(f) = r {
                frames.push(f);
            }
        });
        // The node's last measurement frame, as the gateway's reader takes it.
        let last = frames
            .iter()
            .rev()
            .find(|f| matches!(f.msg, DeviceMsg::MeasurementV5(_)))
            .unwrap();
        let mut snap = NodeSnapshot::new(0, Some("tower-9".into()), "/dev/x".into());
        snap.link_up = true;
        snap.reading = Reading::of(&last.msg);
        snap.seq = Some(last.seq);
        let now = Instant::now();
        snap.received = Some(now);
        let tcp = register_map(&snap, now, Duration::from_secs(3));

        // The same registers over RTU: FC 04 of the whole block.
        let mut req = vec![9, 4, 0, 0, 0, REGISTERS as u8];
        req.extend(CRC16.checksum(&req).to_le_bytes());
        let t_us = node.clock().now_ns() / 1_000;
        let mut answer = Vec::new();
        link.receive(
            &mut node,
            &req,
            t_us,
            &mut |r| answer.extend_from_slice(r),
            &mut |_| {},
        );
        let end = t_us + u64::from(link.silences().t35_us);
        link.poll(
            &mut node,
            end,
            &mut |r| answer.extend_from_slice(r),
            &mut |_| {},
        );
        assert_eq!(answer.len(), 3 + 2 * REGISTERS + 2, "{answer:02x?}");
        let rtu: Vec<u16> = answer[3..3 + 2 * REGISTERS]
            .chunks(2)
            .map(|w| u16::from_be_bytes([w[0], w[1]]))
            .collect();

        let gateway_only =
            |a: usize| [DATA_AGE, DATA_AGE + 1, FRAMES_LOST, FRAMES_LOST + 1].contains(&(a as u16));
        for a in 0..REGISTERS {
            if gateway_only(a) {
                assert_eq!(rtu[a], NA_U16, "register {a} on the node at {t_s} s");
            } else {
                assert_eq!(tcp[a], rtu[a], "register {a} at {t_s} s: {tcp:?} {rtu:?}");
            }
        }
        println!(
            "{t_s} s: status {:#06x}, state {}, I1 word {:#06x}",
            tcp[0], tcp[1], tcp[4]
        );
    }
    assert_eq!(
        node.node().state(),
        fois_protocol::DetectorState::Ice,
        "the last comparison was of an iced node"
    );
}
