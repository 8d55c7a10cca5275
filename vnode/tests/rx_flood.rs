//! A host that floods the node with commands: the link hands the node one
//! host frame at a time and the main loop runs what came due in between
//! (as the board's link task yields per frame), so the measurement goes on.
//! Forty dark calibrations at 8 LSB of noise take ~6 s of node time.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use fois_protocol::{Command, DeviceFrame, DeviceMsg, FrameDecoder, HostFrame, encode_to_vec};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

#[test]
fn a_flood_of_calibrations_does_not_starve_the_measurement() {
    let tl = Timeline::constant(
        Segment::new(f64::INFINITY, Cover::Dry)
            .noise(8.0)
            .ambient([5.0, 5.0]),
    );
    let env = Arc::new(Environment::with_curves(tl, [], [0.6, 0.2]));
    let opts = NodeOptions {
        calibrate_at_s: None,
        ..NodeOptions::default()
    };
    let mut node = VirtualNode::new(env, opts);
    let frames_ms = Rc::new(RefCell::new(Vec::new()));
    let answers = Rc::new(RefCell::new(0u32));
    let (f, a) = (frames_ms.clone(), answers.clone());
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut tx = move |bytes: &[u8]| {
        dec.feed::<DeviceFrame>(bytes, |r| match r.unwrap().msg {
            DeviceMsg::MeasurementV5(m) => f.borrow_mut().push(m.measurement.uptime_ms),
            DeviceMsg::Ack(_) | DeviceMsg::Error(_) => *a.borrow_mut() += 1,
            _ => {}
        })
    };
    node.run_until_s(1.0, &mut tx);
    // Forty calibrations in one burst of bytes.
    let mut flood = Vec::new();
    for id in 1..=40u16 {
        flood.extend(encode_to_vec(&HostFrame {
            id,
            cmd: Command::CalibrateDark,
        }));
    }
    let t0 = node.clock().now_ms();
    node.handle_rx(&flood, &mut tx);
    let took = node.clock().now_ms() - t0;
    node.run_until_s(node.clock().now_s() + 1.0, &mut tx);
    assert_eq!(*answers.borrow(), 40, "every command answered");
    let frames = frames_ms.borrow();
    let during: Vec<u64> = frames.iter().copied().filter(|t| *t >= t0).collect();
    let worst_gap = during.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    println!(
        "40 calibrations took {took} ms; {} frames meanwhile, worst gap {worst_gap} ms",
        during.len()
    );
    assert!(took > 3_000, "the flood is long: {took} ms");
    // Frames keep coming: no gap longer than one calibration (at most
    // ~300 ms at this noise) plus the frame period.
    assert!(worst_gap <= 400, "worst gap {worst_gap} ms");
    assert!(during.len() as u64 >= took / 400, "{} frames", during.len());
}
