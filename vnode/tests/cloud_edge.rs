//! What a cloud edge does to the net currents in the virtual node's physics
//! (the firmware's dark calibration is built on the answer): the ambient
//! light cancels in the synchronous detection whether bright or dim; an edge
//! that falls inside an acquisition leaves ±Δ/2 in the one cycle it splits,
//! ±Δ/(2K) in that frame, and nothing in any other frame. A slow edge (the
//! penumbra of a real cloud takes seconds) moves no frame by more than its
//! steps do.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use fois_protocol::{DeviceFrame, DeviceMsg, FrameDecoder};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

/// The dry face's LED-induced currents, µA (a small offset).
const DRY_UA: [f64; 2] = [0.6, 0.2];

/// Run a dry face through `segments` (no ADC noise, no calibration) and
/// return each frame's (uptime ms, I1 nA).
fn frames(segments: Vec<Segment>, until_s: f64) -> Vec<(u64, i32)> {
    let env = Arc::new(Environment::with_curves(
        Timeline::new(segments),
        [],
        DRY_UA,
    ));
    let opts = NodeOptions {
        calibrate_at_s: None,
        ..NodeOptions::default()
    };
    let mut node = VirtualNode::new(env, opts);
    let out = Rc::new(RefCell::new(Vec::new()));
    let sink = out.clone();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    node.run_until_s(until_s, &mut |bytes: &[u8]| {
        dec.feed::<DeviceFrame>(bytes, |r| {
            if let DeviceMsg::MeasurementV5(m) = r.unwrap().msg {
                sink.borrow_mut()
                    .push((m.measurement.uptime_ms, m.measurement.i1_na));
            }
        })
    });
    out.take()
}

fn dry(duration_s: f64, ambient_ua: f64) -> Segment {
    Segment::new(duration_s, Cover::Dry)
        .noise(0.0)
        .ambient([ambient_ua, ambient_ua])
}

#[test]
fn a_sharp_edge_inside_an_acquisition_moves_that_one_frame_only() {
    // Sun 80 µA; 1.3 ms into the frame that starts at 1 100 ms a cloud
    // takes it to 8 µA.
    let got = frames(vec![dry(1.1013, 80.0), dry(f64::INFINITY, 8.0)], 2.0);
    // Frames at 0, 100, … 2 000 ms.
    assert_eq!(got.len(), 21);
    let dry_na = 600;
    for &(t, i1) in &got {
        if t == 1_100 {
            // 72 µA / (2 × 8 cycles) = 4.5 µA on the 0.6 µA face; + here:
            // the edge fell between a LED-on sample and the LED-off one
            // after it (between a LED-off and a LED-on sample it is −).
            assert!((i1 - (dry_na + 4_500)).abs() <= 100, "{t} ms: {i1} nA");
        } else {
            // Bright or dim, the ambient cancels: within one ADC step.
            assert!((i1 - dry_na).abs() <= 81, "{t} ms: {i1} nA");
        }
    }
}

#[test]
fn an_edge_between_frames_moves_nothing() {
    // The same cloud between two acquisitions (50 ms after a frame).
    let got = frames(vec![dry(1.15, 80.0), dry(f64::INFINITY, 8.0)], 2.0);
    assert!(got.iter().all(|&(_, i1)| (i1 - 600).abs() <= 81), "{got:?}");
}

#[test]
fn a_slow_edge_leaves_at_most_its_steps() {
    // A penumbra of 2 s: 80 µA → 8 µA in 40 steps of 1.8 µA, 50 ms apart
    // (each lands 1.3 ms into a frame or between two): no frame moves by
    // more than 1.8 µA / 16 = 113 nA plus one ADC step.
    let mut segments = vec![dry(1.0013, 80.0)];
    for k in 1..=40 {
        segments.push(dry(0.05, 80.0 - 1.8 * f64::from(k)));
    }
    segments.push(dry(f64::INFINITY, 8.0));
    let got = frames(segments, 4.0);
    let worst = got.iter().map(|&(_, i1)| (i1 - 600).abs()).max().unwrap();
    println!("slow edge: worst frame off by {worst} nA");
    assert!(worst <= 113 + 81, "{worst} nA");
    assert!(
        worst >= 60,
        "the steps inside acquisitions show: {worst} nA"
    );
}
