//! The dark-calibration guard on the water-then-freeze scenario
//! (`host/scenarios/water-then-freeze.toml`): a calibration commanded
//! while the water film starts — the rule still reads dry, the film under
//! the onset — is refused with the old and the new baseline; an older
//! host's command is refused as `NotDry`; forced, it is accepted. Before
//! the guard the film became the baseline.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::sync::Arc;

use fois_protocol::{
    AckResult, Command, DetectorState, DeviceFrame, DeviceMsg, ErrorCode, FrameDecoder, HostFrame,
    encode_to_vec,
};
use fois_vnode::{Environment, NodeOptions, VirtualNode};

/// Every frame the node sent through one call.
fn frames(run: impl FnOnce(&mut dyn FnMut(&[u8]))) -> Vec<DeviceFrame> {
    let mut out = Vec::new();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    run(&mut |b: &[u8]| dec.feed::<DeviceFrame>(b, |r| out.extend(r.ok())));
    out
}

fn answer(node: &mut VirtualNode, id: u16, cmd: Command) -> Result<AckResult, ErrorCode> {
    let bytes = encode_to_vec(&HostFrame { id, cmd });
    let fs = frames(|tx| node.handle_rx(&bytes, &mut |b: &[u8]| tx(b)));
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::Ack(a) if a.id == id => Some(Ok(a.result.clone())),
            DeviceMsg::Error(e) if e.id == Some(id) => Some(Err(e.code)),
            _ => None,
        })
        .expect("an answer")
}

#[test]
fn a_calibration_on_the_starting_film_is_refused_unless_forced() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../host/scenarios/water-then-freeze.toml");
    let sc = fois_vnode::scenario::load(&path).unwrap();
    let env = Arc::new(Environment::new(sc.timeline, sc.sensor, sc.seed));
    let mut node = VirtualNode::new(
        env,
        NodeOptions {
            seed: sc.seed,
            ..NodeOptions::default()
        },
    );
    // The boot-time calibration (the button at 1 s, dry face) and streaming.
    let start = encode_to_vec(&HostFrame {
        id: 1,
        cmd: Command::StartStream {
            frame_period_ms: None,
        },
    });
    node.handle_rx(&start, &mut |_: &[u8]| {});
    node.run_until_s(29.0, &mut |_: &[u8]| {});
    let dry = node.node().baseline().expect("calibrated at boot");
    // The film starts at 30 s: run until I1 has risen by 0.4 µA over the
    // baseline, the rule still dry (the onset is 1 µA).
    let mut rise_na = 0;
    while rise_na < 400 {
        assert!(node.clock().now_s() < 200.0, "the film never rose");
        let fs = frames(|tx| node.step_frame(&mut |b: &[u8]| tx(b)));
        if let Some((m, _)) = fs.iter().rev().find_map(|f| f.msg.measurement()) {
            rise_na = m.i1_na - dry.i1_na;
            assert_eq!(m.state, DetectorState::Dry, "rise {rise_na} nA");
        }
    }
    assert!(node.truth().thickness_mm > 0.0);
    let refused = answer(&mut node, 2, Command::CalibrateDarkV4 { force: false });
    let Err(ErrorCode::BaselineShift(s)) = refused else {
        panic!("the film was taken as the baseline: {refused:?}");
    };
    assert_eq!(s.old, dry);
    assert_eq!(s.allowed_na, 250);
    assert!(s.new.i1_na - dry.i1_na > 300, "{s:?}");
    assert_eq!(node.node().baseline(), Some(dry));
    // An older host's command: the code it knows.
    assert_eq!(
        answer(&mut node, 3, Command::CalibrateDark),
        Err(ErrorCode::NotDry)
    );
    assert_eq!(node.node().baseline(), Some(dry));
    // Forced: taken (the user asserts the face is clean and dry).
    let Ok(AckResult::DarkCalibrated(b)) =
        answer(&mut node, 4, Command::CalibrateDarkV4 { force: true })
    else {
        panic!("the forced calibration was refused");
    };
    assert!(b.i1_na - dry.i1_na > 300, "{b:?}");
    assert_eq!(node.node().baseline(), Some(b));
}
