//! The state machine without a broker: node reports and broker events in,
//! the actions it answers with checked one by one.

use std::time::{Duration, Instant};

use fois_protocol::{
    DetectorState, DeviceFrame, DeviceMsg, GainEstimate, Hello, Measurement, MeasurementV3,
    PROTOCOL_VERSION, ResetReason, SeqEvent, flags,
};
use rumqttc::QoS;

use super::{Action, Gateway};
use crate::command::NodeCommand;
use crate::config::file::{FileConfig, Overrides};
use crate::queue::{Queue, QueueLimits};
use crate::reader::{NodeMsg, NodeUpdate};

fn gateway(dir: &std::path::Path, extra: &str) -> Gateway {
    let text = format!(
        "name = \"gw\"\n[queue]\ndir = \"{}\"\n{extra}\n[[node]]\nport = \"/dev/a\"\nname = \"a\"\n",
        dir.display()
    );
    let cfg = FileConfig::parse(&text)
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let (queue, _) = Queue::open(dir, QueueLimits::for_max_bytes(1 << 20)).unwrap();
    let fleet = crate::snapshot::Fleet::of(&cfg);
    Gateway::new(cfg, queue, fleet, Instant::now())
}

fn hello() -> Hello {
    Hello {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: [1, 2, 3],
        board: Hello::board_from_str("nucleo-f446re"),
        unique_id: [0xab; 12],
        reset_reason: ResetReason::PowerOn,
    }
}

fn up() -> NodeMsg {
    NodeMsg {
        node: 0,
        host_unix_ms: 1_000,
        update: NodeUpdate::Up(hello()),
    }
}

/// An iced frame's measurement: 30 and 9 µA at −5 °C.
fn iced_measurement(uptime_ms: u64, flags: u16) -> Measurement {
    Measurement {
        uptime_ms,
        i1_na: 30_000,
        i2_na: 9_000,
        ambient1_na: 0,
        ambient2_na: 0,
        temperature_centi_c: -500,
        vdda_mv: 3300,
        flags,
        state: DetectorState::Ice,
    }
}

fn frame(seq: u32, uptime_ms: u64, gain: Option<GainEstimate>, flags: u16) -> NodeMsg {
    NodeMsg {
        node: 0,
        host_unix_ms: 2_000,
        update: NodeUpdate::Frame(
            DeviceFrame {
                seq,
                msg: DeviceMsg::MeasurementV3(MeasurementV3 {
                    measurement: iced_measurement(uptime_ms, flags),
                    estimate: None,
                    gain,
                }),
            },
            if seq == 0 {
                SeqEvent::First
            } else {
                SeqEvent::InOrder
            },
        ),
    }
}

fn topics(actions: &[Action]) -> Vec<String> {
    actions
        .iter()
        .map(|a| match a {
            Action::Publish { topic, .. } => topic.clone(),
            Action::Subscribe { topic, .. } => format!("SUBSCRIBE {topic}"),
            Action::Command { command, .. } => format!("COMMAND {}", command.name()),
            Action::RollOut { order, .. } => format!("ROLLOUT {order:?}"),
        })
        .collect()
}

fn payload_of(actions: &[Action], topic: &str) -> Option<serde_json::Value> {
    actions.iter().rev().find_map(|a| match a {
        Action::Publish {
            topic: t, payload, ..
        } if t == topic => serde_json::from_slice(payload).ok(),
        _ => None,
    })
}

#[test]
fn nothing_goes_out_before_the_broker_and_everything_after_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    let t0 = Instant::now();
    gw.on_node(up(), t0);
    gw.on_node(frame(1, 100, None, flags::ALARM), t0);
    gw.pump();
    assert!(gw.actions().is_empty(), "not connected: nothing to send");
    assert_eq!(
        gw.pending(),
        2,
        "link_up and the measurement wait in the queue"
    );
    // The snapshot has the node's latest measurement already.
    let snap = gw.fleet().node(0).unwrap();
    assert!(snap.link_up);
    assert_eq!(snap.seq, Some(1));
    assert_eq!(snap.reading.as_ref().map(|r| r.i1_ua), Some(30.0));

    gw.on_connected(t0);
    gw.pump();
    let a = gw.actions();
    let t = topics(&a);
    // The name claim first (subscribe, then claim), then the announcements.
    assert_eq!(
        t[..3],
        [
            "SUBSCRIBE fois/gw/owner",
            "fois/gw/owner",
            "fois/gw/availability"
        ]
    );
    // Its own availability watched after `online` went out.
    let at = |x: &str| t.iter().position(|y| y == x).unwrap();
    assert!(at("SUBSCRIBE fois/gw/availability") > at("fois/gw/availability"));
    assert!(t.contains(&"homeassistant/binary_sensor/fois_gw/connectivity/config".into()));
    assert!(t.contains(&"fois/gw/a/availability".into()));
    assert!(t.contains(&"fois/gw/a/state".into()));
    assert!(t.contains(&"fois/gw/status".into()));
    // The two records last, in order, at least once.
    let records: Vec<&Action> = a
        .iter()
        .filter(|a| {
            matches!(
                a,
                Action::Publish {
                    qos: QoS::AtLeastOnce,
                    retain: false,
                    ..
                }
            )
        })
        .collect();
    assert_eq!(records.len(), 2);
    assert_eq!(
        topics(&a[a.len() - 2..]),
        vec!["fois/gw/a/event", "fois/gw/a/measurement"]
    );
    // The event loop numbers every publish in order; QoS 0 ones get 0.
    let mut next = 1;
    for x in &a {
        if let Action::Publish { qos, .. } = x {
            let pkid = match qos {
                QoS::AtMostOnce => 0,
                _ => {
                    next += 1;
                    next - 1
                }
            };
            gw.on_outgoing_publish(pkid);
        }
    }
    assert_eq!(gw.unacked(), 2);
    // The name claim and the gateway's availability are QoS 1 too (1, 2),
    // not records.
    gw.on_puback(1);
    gw.on_puback(2);
    assert_eq!(gw.pending(), 2);
    gw.on_puback(3);
    gw.on_puback(4);
    assert_eq!(gw.pending(), 0, "both records acknowledged");
    assert_eq!(gw.summary().records_acked, 2);
}

#[test]
fn the_gain_and_its_fault_reach_state_and_measurement() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.on_node(up(), t0);
    let gain = GainEstimate {
        gain_ppm: 640_000,
        sigma_ppm: 30_000,
    };
    gw.on_node(frame(1, 100, Some(gain), flags::GAIN_OUT_OF_BAND), t0);
    gw.pump();
    let a = gw.actions();
    let state = payload_of(&a, "fois/gw/a/state").unwrap();
    assert_eq!(state["gain"], 0.64);
    assert_eq!(state["gain_sigma"], 0.03);
    assert_eq!(state["faults"], serde_json::json!(["gain_out_of_band"]));
    let m = payload_of(&a, "fois/gw/a/measurement").unwrap();
    assert_eq!(m["gain"], 0.64);
    assert_eq!(m["faults"], serde_json::json!(["gain_out_of_band"]));
    let snap = gw.fleet().node(0).unwrap();
    assert!(snap.reading.unwrap().gain_out_of_band());
}

fn command_results(actions: &[Action]) -> Vec<(bool, String)> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Publish { topic, payload, .. } if topic == "fois/gw/a/command/result" => {
                let v: serde_json::Value = serde_json::from_slice(payload).ok()?;
                Some((
                    v["ok"].as_bool().unwrap_or(true),
                    v["detail"].as_str().unwrap_or("").to_string(),
                ))
            }
            _ => None,
        })
        .collect()
}

/// The event loop sends the actions' subscriptions (packet ids from 1000).
fn sent(gw: &mut Gateway, actions: Vec<Action>) -> Vec<Action> {
    let mut pkid = 1000;
    for a in &actions {
        if matches!(a, Action::Subscribe { .. }) {
            gw.on_outgoing_subscribe(pkid);
            pkid += 1;
        }
    }
    actions
}

/// A command message on node a's topic, as the broker hands it to a
/// subscribed client (retain flag clear), then the check: the checking
/// subscription goes out (packet id `pkid`), its SUBACK comes at `t`, no
/// retained copy follows; the actions up to `t` + 250 ms.
fn live_command(gw: &mut Gateway, payload: &[u8], t: Instant, pkid: u16) -> Vec<Action> {
    gw.on_incoming("fois/gw/a/command", payload, false, t);
    let mut a = gw.actions();
    if a.iter().any(|x| matches!(x, Action::Subscribe { .. })) {
        gw.on_outgoing_subscribe(pkid);
        gw.on_suback(pkid, t);
    }
    gw.tick(t + Duration::from_millis(100), Duration::from_secs(3600));
    assert!(
        !gw.actions()
            .iter()
            .any(|x| matches!(x, Action::Command { .. })),
        "not before the grace has passed"
    );
    gw.tick(t + Duration::from_millis(250), Duration::from_secs(3600));
    a.extend(gw.actions());
    a
}

#[test]
fn commands_are_rate_limited_per_node() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(
        dir.path(),
        "[commands]\nenabled = true\nmin_interval_ms = 5000",
    );
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.on_node(up(), t0);
    let a = gw.actions();
    let subscribed = sent(&mut gw, a);
    assert!(topics(&subscribed).contains(&"SUBSCRIBE fois/gw/a/command".into()));
    // 20 dark calibrations in a row (each a flash save on a board).
    let mut all = Vec::new();
    for k in 0..20u16 {
        let t = t0 + Duration::from_millis(200 * u64::from(k));
        all.extend(live_command(&mut gw, b"calibrate-dark", t, 100 + k));
    }
    let sent: Vec<&Action> = all
        .iter()
        .filter(|a| matches!(a, Action::Command { .. }))
        .collect();
    assert_eq!(
        sent,
        vec![&Action::Command {
            node: 0,
            command: NodeCommand::CalibrateDark
        }]
    );
    let refused = command_results(&all);
    assert_eq!(refused.len(), 19);
    assert!(
        refused
            .iter()
            .all(|(ok, d)| !ok && d.contains("rate limit")),
        "{refused:?}"
    );
    // After the interval, the next one goes through.
    let a = live_command(&mut gw, b"ack", t0 + Duration::from_secs(12), 200);
    assert!(
        topics(&a).contains(&"COMMAND ack".to_string()),
        "{:?}",
        topics(&a)
    );
}

#[test]
fn a_command_published_retained_while_connected_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "[commands]\nenabled = true");
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.on_node(up(), t0);
    let a = gw.actions();
    sent(&mut gw, a);
    // Delivered live (flag clear) although published retained: the check
    // subscribes again ...
    gw.on_incoming("fois/gw/a/command", b"ack", false, t0);
    assert_eq!(topics(&gw.actions()), vec!["SUBSCRIBE fois/gw/a/command"]);
    gw.on_outgoing_subscribe(9);
    gw.on_suback(9, t0);
    // ... and the broker sends the retained copy, flagged, after the SUBACK.
    gw.on_incoming("fois/gw/a/command", b"ack", true, t0);
    gw.tick(t0 + Duration::from_secs(1), Duration::from_secs(3600));
    let a = gw.actions();
    assert!(
        !a.iter().any(|x| matches!(x, Action::Command { .. })),
        "not carried out"
    );
    let r = command_results(&a);
    assert!(r.len() == 1 && r[0].1.contains("retained"), "{r:?}");
    // A check whose SUBACK never comes is refused, not carried out.
    gw.on_incoming(
        "fois/gw/a/command",
        b"ack",
        false,
        t0 + Duration::from_secs(2),
    );
    gw.tick(t0 + Duration::from_secs(13), Duration::from_secs(3600));
    let a = gw.actions();
    assert!(!a.iter().any(|x| matches!(x, Action::Command { .. })));
    assert!(
        command_results(&a)[0].1.contains("did not confirm"),
        "{:?}",
        command_results(&a)
    );
}

#[test]
fn requests_the_client_refused_are_sent_again() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "[homeassistant]\nenabled = false");
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.on_node(up(), t0);
    for k in 1..=3 {
        gw.on_node(frame(k, u64::from(k) * 1000, None, 0), t0);
    }
    gw.pump();
    let a = gw.actions();
    let n = a.len();
    // The client's request channel took all but the last two records.
    gw.unsent(&a[n - 2..]);
    assert_eq!(
        gw.unacked(),
        2,
        "link_up and the first measurement in flight"
    );
    gw.pump();
    let again = gw.actions();
    assert_eq!(
        topics(&again),
        topics(&a[n - 2..]),
        "the same two, in order"
    );
}

fn claim(instance: &str, started_unix_ms: u64, claimed_unix_ms: u64) -> Vec<u8> {
    use super::claim::{Claim, Instance};
    serde_json::to_vec(&Claim {
        gateway: "gw".into(),
        by: Instance {
            instance: instance.into(),
            host: "site-pc".into(),
            pid: 77,
            started_unix_ms,
        },
        claimed_unix_ms,
    })
    .unwrap()
}

fn me(started_unix_ms: u64) -> super::claim::Instance {
    super::claim::Instance {
        instance: "me".into(),
        host: "here".into(),
        pid: 1,
        started_unix_ms,
    }
}

#[test]
fn the_younger_of_two_gateways_with_one_name_stops() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    gw.set_instance(me(1_000));
    let t0 = Instant::now();
    gw.on_connected(t0);
    let claimed = payload_of(&gw.actions(), "fois/gw/owner").unwrap();
    assert_eq!(claimed["instance"], "me");
    assert_eq!(claimed["started_unix_ms"], 1_000);
    // A gateway that died before this one started left its claim: no
    // conflict (a restart after a crash).
    gw.on_incoming("fois/gw/owner", &claim("dead", 10, 500), true, t0);
    // Our own claim coming back: nothing.
    gw.on_incoming(
        "fois/gw/owner",
        &claimed.to_string().into_bytes(),
        false,
        t0,
    );
    assert_eq!(gw.conflict(), None);
    assert!(gw.actions().is_empty());
    // An older gateway claims the name after this one started: this one,
    // the younger, must stop.
    gw.on_incoming("fois/gw/owner", &claim("old", 900, 1_500), true, t0);
    let why = gw.conflict().unwrap();
    assert!(why.contains("another gateway named gw"), "{why}");
    assert!(why.contains("host site-pc, pid 77"), "{why}");
}

#[test]
fn the_older_of_two_gateways_claims_again_and_publishes_everything_again() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    gw.set_instance(me(1_000));
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.on_node(up(), t0);
    let _ = gw.actions();
    gw.on_incoming("fois/gw/owner", &claim("young", 2_000, 2_001), false, t0);
    assert_eq!(gw.conflict(), None, "the older one keeps running");
    let a = gw.actions();
    assert_eq!(topics(&a), vec!["fois/gw/owner"], "it claims again");
    assert_eq!(payload_of(&a, "fois/gw/owner").unwrap()["instance"], "me");
    gw.tick(t0 + Duration::from_secs(1), Duration::from_secs(3600));
    assert!(gw.actions().is_empty());
    // When the younger one has stopped: every retained message again.
    gw.tick(t0 + Duration::from_secs(3), Duration::from_secs(3600));
    let t = topics(&gw.actions());
    for topic in [
        "fois/gw/availability",
        "fois/gw/a/availability",
        "fois/gw/a/info",
    ] {
        assert!(t.contains(&topic.to_string()), "{topic} not in {t:?}");
    }
}

#[test]
fn a_phantom_offline_of_a_running_gateway_is_answered_online_but_not_its_own_goodbye() {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    let t0 = Instant::now();
    gw.on_connected(t0);
    let _ = gw.actions();
    // Its own `online` (the subscription's retained copy): nothing.
    gw.on_incoming("fois/gw/availability", b"online", true, t0);
    assert!(gw.actions().is_empty());
    // Another instance's last will, retained or live: `online` again.
    for retained in [false, true] {
        gw.on_incoming("fois/gw/availability", b"offline", retained, t0);
        let a = gw.actions();
        assert_eq!(topics(&a), ["fois/gw/availability"]);
        assert!(matches!(
            &a[0],
            Action::Publish { payload, retain: true, qos: QoS::AtLeastOnce, .. }
                if payload.as_slice() == b"online"
        ));
    }
    // After its goodbye the `offline` is its own.
    gw.goodbye(t0);
    let _ = gw.actions();
    gw.on_incoming("fois/gw/availability", b"offline", false, t0);
    assert!(gw.actions().is_empty());
}

/// The node ids (`fois_node_<key>`) in the discovery topics of `actions`.
fn discovered_keys(actions: &[Action]) -> std::collections::BTreeSet<String> {
    topics(actions)
        .iter()
        .filter_map(|t| {
            t.split('/')
                .nth(2)?
                .strip_prefix("fois_node_")
                .map(str::to_string)
        })
        .collect()
}

#[test]
fn a_node_has_one_key_for_its_topics_and_its_home_assistant_ids() {
    // Two unnamed nodes (0 and 1, before the named `a`) with one unique id
    // (virtual nodes share theirs):
    // the first keeps the id, the second gets `-<its index>`, in its topics
    // and its Home Assistant ids alike; the first's do not change when the
    // second comes.
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(
        dir.path(),
        "[[node]]\nport = \"/dev/b\"\n[[node]]\nport = \"/dev/c\"\n",
    );
    let t0 = Instant::now();
    gw.on_connected(t0);
    gw.actions();
    let id = "abababababababababababab";
    let with = |node| NodeMsg { node, ..up() };
    gw.on_node(with(0), t0);
    let first = gw.actions();
    assert_eq!(discovered_keys(&first), [id.to_string()].into());
    assert!(topics(&first).contains(&format!("fois/gw/{id}/availability")));
    gw.on_node(with(1), t0);
    let second = gw.actions();
    let key2 = format!("{id}-1");
    assert_eq!(discovered_keys(&second), [key2.clone()].into());
    assert!(topics(&second).contains(&format!("fois/gw/{key2}/availability")));
    gw.on_connected(t0);
    let again = gw.actions();
    assert_eq!(
        discovered_keys(&again),
        [id.to_string(), key2.clone()].into()
    );
    let snaps = gw.fleet().nodes();
    assert_eq!(snaps[0].name.as_deref(), Some(id));
    assert_eq!(snaps[0].key.as_deref(), Some(id));
    assert_eq!(snaps[1].name.as_deref(), Some(key2.as_str()));
    assert_eq!(snaps[1].key.as_deref(), Some(key2.as_str()));
}

mod journal;
mod rollout;
