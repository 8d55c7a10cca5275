//! The virtual node's default scene (`foisctl virtual-node` with no flags:
//! 30 s of dry face, then rime at 2 mm/h, −5 °C, Sensor B, seed 1): the
//! node's ice estimate, once a second, against the scene's truth. What a
//! new user sees first must be honest (the truth within 2σ) and name the
//! medium right once there is ice to name (the goal: from 1 mm; met from
//! 2 mm).
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use fois_protocol::{Command, DeviceFrame, DeviceMsg, FrameDecoder, Medium};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

/// One estimate: (true thickness mm, estimate mm, σ mm, medium).
type Row = (f64, f64, f64, Medium);

/// The default scene's estimates until the ice is `until_mm` thick, one
/// per second (every tenth 10 Hz frame).
fn default_scene(until_mm: f64) -> Vec<Row> {
    let seed = 1;
    let env = Arc::new(Environment::new(
        Timeline::new(vec![
            Segment::new(30.0, Cover::Dry),
            Segment::new(f64::INFINITY, Cover::Rime).rate(2.0),
        ]),
        fois_sim::SensorKind::B,
        seed,
    ));
    let mut vn = VirtualNode::new(
        env.clone(),
        NodeOptions {
            seed,
            ..NodeOptions::default()
        },
    );
    vn.command(
        Command::StartStream {
            frame_period_ms: None,
        },
        &mut |_: &[u8]| {},
    )
    .unwrap();
    let rows = Rc::new(RefCell::new(Vec::new()));
    let sink = rows.clone();
    let clock = vn.clock().clone();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let until_s = 30.0 + until_mm / 2.0 * 3_600.0;
    vn.run_until_s(until_s, &mut |bytes: &[u8]| {
        dec.feed::<DeviceFrame>(bytes, |r| {
            if let Ok(DeviceFrame {
                msg: DeviceMsg::MeasurementV5(m),
                ..
            }) = r
                && m.measurement.uptime_ms % 1_000 == 0
                && let Some(e) = m.estimate
            {
                let truth = env.truth(clock.now_ns());
                sink.borrow_mut().push((
                    truth.thickness_mm,
                    f64::from(e.thickness_um) / 1_000.0,
                    f64::from(e.sigma_um) / 1_000.0,
                    e.medium,
                ));
            }
        })
    });
    rows.take()
}

#[test]
fn the_default_scene_is_estimated_honestly_and_named_rime() {
    let rows = default_scene(6.0);
    let from_1mm: Vec<&Row> = rows.iter().filter(|r| r.0 >= 1.0).collect();
    assert!(from_1mm.len() > 8_000, "{} estimates", from_1mm.len());
    let within = from_1mm
        .iter()
        .filter(|r| (r.1 - r.0).abs() <= 2.0 * r.2)
        .count() as f64
        / from_1mm.len() as f64;
    let rime =
        from_1mm.iter().filter(|r| r.3 == Medium::Rime).count() as f64 / from_1mm.len() as f64;
    // The worst stretch: the longest run of estimates outside 2σ, s.
    let mut worst_run = 0;
    let mut run = 0;
    for r in &from_1mm {
        if (r.1 - r.0).abs() > 2.0 * r.2 {
            run += 1;
            worst_run = worst_run.max(run);
        } else {
            run = 0;
        }
    }
    let at = |mm: f64| {
        rows.iter()
            .find(|r| r.0 >= mm)
            .map(|r| format!("{:.2} ± {:.2} {:?}", r.1, r.2, r.3))
            .unwrap_or_default()
    };
    println!(
        "default scene, 1–6 mm of rime at 2 mm/h: {} estimates, {:.1} % within 2σ \
         (longest stretch outside {worst_run} s), medium rime in {:.1} %; at 1 mm {}, 2 mm {}, 5 mm {}",
        from_1mm.len(),
        100.0 * within,
        100.0 * rime,
        at(1.0),
        at(2.0),
        at(5.0)
    );
    for band in 1..6 {
        let b: Vec<&&Row> = from_1mm
            .iter()
            .filter(|r| r.0 >= band as f64 && r.0 < band as f64 + 1.0)
            .collect();
        let named = b.iter().filter(|r| r.3 == Medium::Rime).count();
        println!(
            "  {band}–{} mm: rime named in {named} of {}",
            band + 1,
            b.len()
        );
    }
    assert!(within >= 0.95, "within 2σ {:.1} %", 100.0 * within);
    // The medium: right from 2 mm (goal: from 1 mm; between 1 and 2 mm the
    // node still says glazed in most frames, firmware/README.md).
    let from_2mm: Vec<&&Row> = from_1mm.iter().filter(|r| r.0 >= 2.0).collect();
    let rime_2mm =
        from_2mm.iter().filter(|r| r.3 == Medium::Rime).count() as f64 / from_2mm.len() as f64;
    assert!(
        rime_2mm >= 0.95,
        "rime named from 2 mm {:.1} %",
        100.0 * rime_2mm
    );
    assert!(rime >= 0.80, "rime named from 1 mm {:.1} %", 100.0 * rime);
}
