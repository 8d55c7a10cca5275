//! Roll-out commands in the state machine: refused when retained, naming
//! a path, an unknown node, a file that is not a signed image, or while a
//! roll-out runs; otherwise a `RollOut` action; each node's result and the
//! roll-out's published retained.

use std::time::{Duration, Instant};

use fois_link::signed_image::SignedImage;
use fois_link::update::UpdateReport;
use fois_protocol::{Hello, ImageTrailer};

use super::super::Action;
use super::{gateway, payload_of, topics, up};
use crate::reader::{NodeMsg, NodeUpdate};
use crate::rollout::{NodeOutcome, RolloutOutcome};

const FW_TOPIC: &str = "fois/gw/firmware/command";
const RESULT: &str = "fois/gw/firmware/result";

fn write_image(dir: &std::path::Path, name: &str) {
    let body = vec![0x42u8; 1000];
    let trailer = ImageTrailer {
        body_len: 1000,
        version: [0, 7, 0],
        flags: 0,
        board: Hello::board_from_str("NUCLEO-F446RE"),
    };
    let img = SignedImage::assemble(&body, &trailer, &[1; 64]).unwrap();
    std::fs::write(dir.join(name), img.as_bytes()).unwrap();
}

#[test]
fn a_roll_out_command_is_checked_then_handed_to_the_service() {
    let dir = tempfile::tempdir().unwrap();
    let fw = tempfile::tempdir().unwrap();
    write_image(fw.path(), "fois-0.7.0.fois");
    std::fs::write(fw.path().join("notes.txt"), "not an image").unwrap();
    let mut gw = gateway(
        dir.path(),
        &format!(
            "[commands]\nenabled = true\n[firmware]\ndir = \"{}\"",
            fw.path().display()
        ),
    );
    let now = Instant::now();
    gw.on_connected(now);
    gw.on_node(up(), now);
    let a = gw.actions();
    assert!(
        topics(&a).contains(&format!("SUBSCRIBE {FW_TOPIC}")),
        "{:?}",
        topics(&a)
    );

    let refused = |gw: &mut super::super::Gateway, payload: &str, retained: bool, why: &str| {
        gw.on_incoming(FW_TOPIC, payload.as_bytes(), retained, now);
        let a = gw.actions();
        assert!(
            !topics(&a).iter().any(|t| t.starts_with("ROLLOUT")),
            "{payload}"
        );
        let r = payload_of(&a, RESULT).unwrap();
        assert_eq!(r["ok"], false);
        let detail = r["detail"].as_str().unwrap();
        assert!(detail.contains(why), "{payload}: {detail}");
    };
    let cmd = |image: &str| format!(r#"{{"command": "update", "image": "{image}"}}"#);
    refused(&mut gw, &cmd("fois-0.7.0.fois"), true, "retained");
    refused(
        &mut gw,
        &cmd("../fois-0.7.0.fois"),
        false,
        "not an image name",
    );
    refused(&mut gw, &cmd("missing.fois"), false, "missing.fois");
    refused(&mut gw, &cmd("notes.txt"), false, "too short");
    refused(
        &mut gw,
        r#"{"command": "update", "image": "fois-0.7.0.fois", "nodes": ["b"]}"#,
        false,
        "no node named `b`",
    );
    refused(&mut gw, "reset", false, "not a roll-out command");

    gw.on_incoming(FW_TOPIC, cmd("fois-0.7.0.fois").as_bytes(), false, now);
    let a = gw.actions();
    match a.iter().find(|a| matches!(a, Action::RollOut { .. })) {
        Some(Action::RollOut { image, order, opts }) => {
            assert_eq!(order, &vec![0]);
            assert_eq!(image.version(), [0, 7, 0]);
            assert_eq!(opts.confirm_timeout, Duration::from_secs(120));
        }
        other => panic!("{other:?}"),
    }
    refused(&mut gw, &cmd("fois-0.7.0.fois"), false, "still running");

    // The node's result and the roll-out's, retained.
    let report = UpdateReport {
        from_version: [1, 2, 3],
        running: [0, 7, 0],
        already_running: false,
        started_at: 0,
        retries: 0,
        resumes: 0,
        transfer_time: Duration::from_secs(12),
    };
    gw.on_node(
        NodeMsg {
            node: 0,
            host_unix_ms: 5,
            update: NodeUpdate::UpdateDone {
                ok: true,
                detail: "updated".into(),
            },
        },
        now,
    );
    gw.on_node(
        NodeMsg {
            node: 0,
            host_unix_ms: 6,
            update: NodeUpdate::RolloutEnd(RolloutOutcome {
                results: vec![(0, NodeOutcome::Updated(report))],
                not_reached: vec![],
            }),
        },
        now,
    );
    let a = gw.actions();
    let retained = |topic: &str| {
        a.iter()
            .any(|x| matches!(x, Action::Publish { topic: t, retain: true, .. } if t == topic))
    };
    let node_topic = "fois/gw/a/update/result";
    assert!(retained(node_topic) && retained(RESULT), "{:?}", topics(&a));
    let r = payload_of(&a, node_topic).unwrap();
    assert_eq!(
        (r["ok"].as_bool(), r["image"].as_str()),
        (Some(true), Some("fois-0.7.0.fois"))
    );
    let r = payload_of(&a, RESULT).unwrap();
    assert_eq!(r["ok"], true);
    assert_eq!(r["updated"], serde_json::json!(["a"]));
    // Done: a new roll-out is taken again.
    gw.on_incoming(FW_TOPIC, cmd("fois-0.7.0.fois").as_bytes(), false, now);
    assert!(
        gw.actions()
            .iter()
            .any(|a| matches!(a, Action::RollOut { .. }))
    );
}

#[test]
fn without_a_firmware_section_the_topic_is_not_watched() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "[commands]\nenabled = true");
    let now = Instant::now();
    gw.on_connected(now);
    let a = gw.actions();
    assert!(
        !topics(&a).iter().any(|t| t.contains("firmware")),
        "{:?}",
        topics(&a)
    );
    gw.on_incoming(
        FW_TOPIC,
        br#"{"command": "update", "image": "a.fois"}"#,
        false,
        now,
    );
    assert!(
        !gw.actions()
            .iter()
            .any(|a| matches!(a, Action::RollOut { .. }))
    );
}
