//! `fois-gateway` against a real Mosquitto broker: virtual nodes on
//! pseudo-terminals (served by threads of the test) → gateway (a child
//! process) → broker (started by each test on its own free loopback port)
//! → a subscriber that counts every measurement and event by the node's
//! sequence number.
//!
//! A record is "sent by the node" when its seq lies between the first and
//! the last seq the subscriber saw; the only seqs allowed to be missing in
//! that range are the node's answers to the gateway's handshake (`GetInfo`,
//! `StartStream`: at most 3 per connection), which are not published.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod support;

use std::path::Path;
use std::time::{Duration, Instant};

use fois_vnode::Cover;
use support::*;

/// Handshake answers per connection that are not published.
const ACKS_PER_CONNECTION: usize = 3;

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn report(name: &str, r: &NodeRecords) {
    println!(
        "{name}: {} measurements, {} node events, {} distinct, {} duplicates, holes {:?}",
        r.measurements.len(),
        r.events.len(),
        r.distinct(),
        r.duplicates(),
        r.holes()
    );
}

#[test]
fn three_nodes_every_record_arrives_once_with_discovery_and_state() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(
        broker.port,
        "t-fleet",
        &["fois/#", "homeassistant/#"],
        SubOptions::default(),
    );
    // Rime that trips the alarm after ~1.4 s, a wet face at +5 °C, a dry one.
    let iced = NodeProc::start(Scene::film(Cover::Rime, 20.0, -5.0, 3.0, 10.0, 1));
    let wet = NodeProc::start(Scene::film(Cover::Water, 20.0, 5.0, 3.0, 10.0, 2));
    let dry = NodeProc::start(Scene::dry(10.0, 3));
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(&iced.path, "iced"), (&wet.path, "wet"), (&dry.path, "dry")],
        "",
    );
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    gw.wait_output("node dry on", Duration::from_secs(10));
    std::thread::sleep(Duration::from_secs(5));
    assert_eq!(gw.interrupt(), 0, "{}", gw.output());
    sub.settle(Duration::from_millis(500), Duration::from_secs(10));
    let msgs = sub.messages();
    let out = gw.output();

    let mut total = 0;
    for name in ["iced", "wet", "dry"] {
        let r = NodeRecords::of(&msgs, name);
        report(name, &r);
        // 5 s at 10 Hz x10 = ~500 frames per node.
        assert!(
            r.measurements.len() > 300,
            "{name}: {}",
            r.measurements.len()
        );
        assert_eq!(r.duplicates(), 0, "{name}: duplicates");
        assert!(
            r.holes().len() <= ACKS_PER_CONNECTION,
            "{name}: missing seqs {:?}",
            r.holes()
        );
        let link_ups = r.gateway_events.iter().filter(|e| e.0 == "link_up").count();
        assert_eq!(link_ups, 1, "{name}: {:?}", r.gateway_events);
        total += r.distinct();
    }
    println!(
        "fleet: {total} records received, gateway said: {}",
        out.lines().last().unwrap_or("")
    );
    // The gateway's own count agrees: every record it queued was acknowledged
    // (the link_up events are records too).
    assert!(
        out.contains(&format!(
            "{} record(s) queued, {} acknowledged",
            total + 3,
            total + 3
        )),
        "{out}"
    );

    let kinds = |name: &str| -> Vec<String> {
        NodeRecords::of(&msgs, name)
            .events
            .values()
            .map(|e| e.0.clone())
            .collect()
    };
    assert_eq!(kinds("iced"), vec!["ice_onset"]);
    assert_eq!(kinds("wet"), vec!["wet_onset"]);
    assert!(kinds("dry").is_empty());

    // Measurements: units in the keys, plausible values.
    let m = sub.on("fois/gw/dry/measurement").last().unwrap().json();
    for key in [
        "i1_ua",
        "i2_ua",
        "ambient1_ua",
        "ambient2_ua",
        "temperature_c",
        "vdda_mv",
        "seq",
        "uptime_ms",
        "host_time_utc",
    ] {
        assert!(m.get(key).is_some(), "{key} missing: {m}");
    }
    assert!(
        (m["temperature_c"].as_f64().unwrap() + 5.0).abs() < 0.1,
        "{m}"
    );
    assert!(m["i1_ua"].as_f64().unwrap().abs() < 0.5, "{m}");
    assert_eq!(m["state"], "dry");

    // The last state of each node (retained): ice, wet, dry.
    let last_state = |n: &str| sub.on(&format!("fois/gw/{n}/state")).last().unwrap().json();
    let s = last_state("iced");
    assert_eq!(
        (
            s["state"].as_str(),
            s["ice"].as_bool(),
            s["alarm"].as_bool()
        ),
        (Some("ice"), Some(true), Some(true))
    );
    assert_eq!(last_state("wet")["state"], "wet");
    assert_eq!(last_state("wet")["ice"], false);
    assert_eq!(last_state("dry")["ice"], false);

    // Availability: online while running, offline after the clean stop.
    for n in ["iced", "wet", "dry"] {
        let av: Vec<String> = sub
            .on(&format!("fois/gw/{n}/availability"))
            .iter()
            .map(|m| m.text())
            .collect();
        assert!(av.contains(&"online".to_string()), "{n}: {av:?}");
        assert_eq!(
            av.last().map(String::as_str),
            Some("offline"),
            "{n}: {av:?}"
        );
    }
    let gw_av = sub.on("fois/gw/availability");
    assert_eq!(gw_av.first().unwrap().text(), "online");
    assert_eq!(gw_av.last().unwrap().text(), "offline");
    // The final status, retained after the stop: no node online, what
    // the queue holds then; it comes before the gateway's offline.
    let late = Subscriber::start(
        broker.port,
        "t-late",
        &["fois/gw/status"],
        SubOptions::default(),
    );
    late.wait_for("the retained status", Duration::from_secs(5), |m| {
        !m.is_empty()
    });
    let status = late.on("fois/gw/status");
    let last = status.last().unwrap();
    assert!(last.retain);
    let last = last.json();
    assert_eq!(
        (last["nodes"].as_u64(), last["nodes_online"].as_u64()),
        (Some(3), Some(0)),
        "{last}"
    );
    assert_eq!(last["queue_records"], 0, "{last}");
    let order: Vec<&str> = msgs
        .iter()
        .filter(|m| m.topic == "fois/gw/status" || m.topic == "fois/gw/availability")
        .map(|m| m.topic.as_str())
        .collect();
    let shown: Vec<String> = msgs
        .iter()
        .filter(|m| m.topic == "fois/gw/status" || m.topic == "fois/gw/availability")
        .map(|m| {
            format!(
                "{} {} {:?}",
                m.topic,
                m.text().chars().take(12).collect::<String>(),
                m.at
            )
        })
        .collect();
    assert_eq!(order.last(), Some(&"fois/gw/availability"), "{shown:?}");
    assert_eq!(order[order.len() - 2], "fois/gw/status", "{shown:#?}");
    assert_eq!(order[order.len() - 2], "fois/gw/status", "{order:?}");

    // The log (the journal under systemd) says when a node ices or wets,
    // with its numbers.
    let onset = out
        .lines()
        .find(|l| l.contains("node iced: ice onset (alarm on): "))
        .unwrap_or_else(|| panic!("no ice onset line: {out}"));
    assert!(onset.contains("INFO"), "{onset}");
    // The virtual node runs the firmware's estimator: its estimate is in
    // the line (or said to lag when it does not see ice yet).
    assert!(
        onset.contains(": estimate ") && onset.contains(" mm ") && onset.contains("-5.0 °C"),
        "{onset}"
    );
    assert!(
        out.lines()
            .any(|l| l.contains("INFO") && l.contains("node wet: wet (a water film")),
        "{out}"
    );

    // Home Assistant discovery: what HA needs to build the entities, each
    // node a device named by its hardware id (`cargo xtask ha-check` runs
    // a real Home Assistant on them).
    let mut ids = Vec::new();
    for n in ["iced", "wet", "dry"] {
        let info = sub.on(&format!("fois/gw/{n}/info"));
        let uid = info.last().expect("the node's info").json()["unique_id"]
            .as_str()
            .unwrap()
            .to_string();
        let id = format!("fois_node_{uid}");
        ids.push(id.clone());
        let cfg = |comp: &str, obj: &str| -> serde_json::Value {
            let t = format!("homeassistant/{comp}/{id}/{obj}/config");
            let m = sub.on(&t);
            let m = m.last().unwrap_or_else(|| panic!("no {t}"));
            assert!(m.retain || m.at.elapsed() < Duration::from_secs(60));
            m.json()
        };
        let ice = cfg("binary_sensor", "ice");
        assert_eq!(ice["device_class"], "cold");
        assert_eq!(ice["state_topic"], format!("fois/gw/{n}/state"));
        assert_eq!(ice["payload_on"], "ON");
        assert!(
            ice["value_template"]
                .as_str()
                .unwrap()
                .contains("value_json.ice")
        );
        assert_eq!(ice["unique_id"], format!("{id}_ice"));
        let av: Vec<&str> = ice["availability"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a["topic"].as_str().unwrap())
            .collect();
        assert_eq!(
            av,
            vec![
                "fois/gw/availability".to_string(),
                format!("fois/gw/{n}/availability")
            ]
        );
        assert_eq!(ice["availability_mode"], "all");
        assert_eq!(ice["device"]["identifiers"][0], id);
        assert_eq!(ice["device"]["model"], "virtual-f446");
        assert_eq!(ice["device"]["via_device"], "fois_gw");
        for (obj, key, unit) in [
            ("i1", "i1_ua", "µA"),
            ("i2", "i2_ua", "µA"),
            ("temperature", "temperature_c", "°C"),
        ] {
            let s = cfg("sensor", obj);
            assert_eq!(s["unit_of_measurement"], unit, "{obj}");
            assert_eq!(s["state_topic"], format!("fois/gw/{n}/state"));
            assert!(s["value_template"].as_str().unwrap().contains(key), "{s}");
            assert_eq!(s["device"]["identifiers"][0], id);
            assert_eq!(s["state_class"], "measurement");
        }
        assert_eq!(cfg("sensor", "temperature")["device_class"], "temperature");
        // The virtual nodes run the firmware's ice estimator (protocol 2,
        // MeasurementV2 with an estimate): each gets a thickness entity on
        // its state topic.
        let t = sub.on(&format!("homeassistant/sensor/{id}/thickness/config"));
        let t = t.last().expect("a thickness entity").json();
        assert_eq!(t["unit_of_measurement"], "mm");
        assert_eq!(t["state_topic"], format!("fois/gw/{n}/state"));
    }
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), 3, "every virtual node has its own id: {ids:?}");
    let gwc = sub.on("homeassistant/binary_sensor/fois_gw/connectivity/config");
    assert_eq!(gwc.last().unwrap().json()["device_class"], "connectivity");
}

/// The number of records a gateway status line counts as queued
/// ("…, 1 queued, …"), or `None` for any other line.
fn queued_in_status(line: &str) -> Option<u64> {
    let before = line
        .split(" queued,")
        .next()
        .filter(|b| b.len() < line.len())?;
    before.rsplit(' ').next()?.parse().ok()
}

/// The drain check reads the queued count of a status line, and nothing from other lines
/// (the reconnection's "sending N queued record(s)" included).
#[test]
fn queued_in_status_reads_only_status_lines() {
    let status = " INFO status: 2/2 node(s) online, 3294 frame(s) received, 3286 record(s) \
                  acknowledged, 2 queued, 0 lost by the queue; broker connected";
    assert_eq!(queued_in_status(status), Some(2));
    let backlog = status.replace(" 2 queued,", " 2980 queued,");
    assert_eq!(queued_in_status(&backlog), Some(2980));
    assert_eq!(
        queued_in_status(
            " INFO connected to the broker 127.0.0.1:1; sending 3008 queued record(s)"
        ),
        None
    );
    assert_eq!(queued_in_status(" WARN broker lost"), None);
}

#[test]
fn broker_stopped_for_30_s_and_restarted_nothing_is_lost() {
    let dir = tempfile::tempdir().unwrap();
    // The broker keeps the subscriber's session across its restart (the
    // gateway's own records survive in the gateway's disk queue).
    let mut broker = Broker::start(
        dir.path(),
        "persistence true\npersistence_location {dir}/\nautosave_interval 1\n",
    );
    let sub = Subscriber::start(
        broker.port,
        "t-outage",
        &["fois/#"],
        SubOptions {
            persistent: true,
            ..SubOptions::default()
        },
    );
    let a = NodeProc::start(Scene::dry(5.0, 4));
    let b = NodeProc::start(Scene::dry(5.0, 5));
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(&a.path, "a"), (&b.path, "b")],
        "",
    );
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    gw.wait_output("node b on", Duration::from_secs(10));
    std::thread::sleep(Duration::from_secs(2));
    broker.stop();
    let down_at = Instant::now();
    gw.wait_output("broker 127.0.0.1", Duration::from_secs(5));
    std::thread::sleep(Duration::from_secs(30).saturating_sub(down_at.elapsed()));
    broker.restart();
    // The second connection (the first may say "sending" too, when a node
    // was quicker than the broker at the start).
    let t0 = Instant::now();
    while gw.output().matches("connected to the broker").count() < 2 {
        assert!(t0.elapsed() < Duration::from_secs(10), "{}", gw.output());
        std::thread::sleep(Duration::from_millis(50));
    }
    // The backlog drains, then a clean stop. The nodes keep sending
    // (100 records/s in all), so a status line may always count the one or
    // two records in flight: drained means a status line after the
    // reconnection counts fewer than one second of records.
    let t0 = Instant::now();
    while !gw
        .output()
        .rsplit("sending")
        .next()
        .unwrap_or("")
        .lines()
        .filter_map(queued_in_status)
        .any(|queued| queued < 100)
    {
        assert!(t0.elapsed() < Duration::from_secs(30), "{}", gw.output());
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_eq!(gw.interrupt(), 0);
    sub.settle(Duration::from_millis(800), Duration::from_secs(20));
    let msgs = sub.messages();
    let out = gw.output();
    // The reconnection after the outage (the first "sending" is the start).
    let queued_line = out
        .lines()
        .rfind(|l| l.contains("sending"))
        .unwrap()
        .to_string();
    println!("{queued_line}");
    let queued: u64 = queued_line
        .split("sending ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    // 30 s x 2 nodes x 50 frames/s went to the disk queue.
    assert!(queued > 2500, "{queued}\n{out}");
    for name in ["a", "b"] {
        let r = NodeRecords::of(&msgs, name);
        report(name, &r);
        assert!(
            r.measurements.len() > 1500,
            "{name}: {}",
            r.measurements.len()
        );
        assert!(
            r.holes().len() <= ACKS_PER_CONNECTION,
            "{name}: lost {:?}",
            r.holes()
        );
        // QoS 1 is "at least once": what was in flight when the broker died
        // (to it from the gateway, or from it to the subscriber) may arrive
        // twice, with the same seq; never more than one window of it.
        assert!(
            r.duplicates() <= fois_gateway::inflight::WINDOW,
            "{name}: {} duplicates",
            r.duplicates()
        );
        // In order: host times never go back within a node's stream.
        assert!(r.host_ms.windows(2).all(|w| w[0] <= w[1]));
    }
}

#[test]
fn gateway_killed_with_sigkill_and_restarted_loses_at_most_1_s() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-kill", &["fois/#"], SubOptions::default());
    // 50 frames/s per node.
    let speed = 5.0;
    let a = NodeProc::start(Scene::dry(5.0, 6));
    let b = NodeProc::start(Scene::dry(5.0, 7));
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(&a.path, "a"), (&b.path, "b")],
        "",
    );
    let out = dir.path().join("gw.out");
    let mut kills = vec![];
    for round in 0..3 {
        let mut gw = GatewayProc::start(&cfg, &[], &out);
        let t0 = Instant::now();
        while gw.output().matches("node b on").count() <= round {
            assert!(t0.elapsed() < Duration::from_secs(10), "{}", gw.output());
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(1500 + 170 * round as u64));
        kills.push(fois_link::timefmt::unix_ms_now());
        gw.kill9();
        std::thread::sleep(Duration::from_millis(300));
    }
    let mut gw = GatewayProc::start(&cfg, &[], &out);
    gw.wait_output("sending", Duration::from_secs(10));
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(gw.interrupt(), 0);
    sub.settle(Duration::from_millis(500), Duration::from_secs(10));
    let msgs = sub.messages();
    for name in ["a", "b"] {
        let r = NodeRecords::of(&msgs, name);
        report(name, &r);
        // Each kill may lose what arrived after the last queue flush
        // (< 0.2 s), plus the handshake answers of each of the 4 connections.
        let allowed = (3.0 * 10.0 * speed) as usize + 4 * ACKS_PER_CONNECTION;
        assert!(
            r.holes().len() <= allowed,
            "{name}: {} missing (allowed {allowed}): {:?}",
            r.holes().len(),
            r.holes()
        );
        // In host time: for every kill, a record received within 1 s before it.
        for k in &kills {
            let last_before = r.host_ms.iter().filter(|t| *t < k).max().unwrap();
            println!("{name}: last record {} ms before a kill", k - last_before);
            assert!(
                k - last_before <= 1000,
                "{name}: {} ms lost",
                k - last_before
            );
        }
        // Duplicates (re-sent after a crash) carry the same seq: a consumer drops them.
        println!("{name}: {} duplicates across 3 kills", r.duplicates());
    }
}

#[test]
fn unplugged_node_is_offline_within_5_s_and_back_online_when_it_returns() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-unplug", &["fois/#"], SubOptions::default());
    let link = dir.path().join("node-a");
    let ls = link.to_str().unwrap();
    let mut a = NodeProc::start_linked(Scene::dry(5.0, 1), &link);
    let b = NodeProc::start(Scene::dry(5.0, 1));
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(ls, "a"), (&b.path, "b")],
        "",
    );
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    for name in ["a", "b"] {
        let topic = format!("fois/gw/{name}/availability");
        sub.wait_for(&format!("{name} online"), Duration::from_secs(10), |m| {
            m.iter().any(|m| m.topic == topic && m.payload == b"online")
        });
    }
    std::thread::sleep(Duration::from_secs(1));
    let before = sub.on("fois/gw/a/availability").len();
    let unplugged = Instant::now();
    a.kill9();
    sub.wait_for("a offline", Duration::from_secs(5), |m| {
        m.iter()
            .filter(|m| m.topic == "fois/gw/a/availability")
            .skip(before)
            .any(|m| m.payload == b"offline")
    });
    let took = unplugged.elapsed();
    println!("offline {} ms after the pty closed", took.as_millis());
    assert!(took < Duration::from_secs(5));
    // The other node stays online and keeps publishing.
    let nb = sub.on("fois/gw/b/measurement").len();
    std::thread::sleep(Duration::from_millis(500));
    assert!(sub.on("fois/gw/b/measurement").len() > nb + 10);
    // Once online, b is never announced offline (before its handshake the gateway may
    // announce it offline, when the broker connection comes first).
    let b_availability = sub.on("fois/gw/b/availability");
    let b_up = b_availability
        .iter()
        .position(|m| m.payload == b"online")
        .unwrap();
    assert!(
        b_availability[b_up..]
            .iter()
            .all(|m| m.payload == b"online"),
        "b went offline while a was unplugged"
    );
    // Plugged back: online again, with a link_lost and a second link_up.
    let _a2 = NodeProc::start_linked(Scene::dry(5.0, 1), &link);
    sub.wait_for("a back online", Duration::from_secs(10), |m| {
        m.iter()
            .rfind(|m| m.topic == "fois/gw/a/availability")
            .is_some_and(|m| m.payload == b"online")
    });
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(gw.interrupt(), 0);
    sub.settle(Duration::from_millis(300), Duration::from_secs(5));
    let r = NodeRecords::of(&sub.messages(), "a");
    let kinds: Vec<&str> = r.gateway_events.iter().map(|e| e.0.as_str()).collect();
    assert!(kinds.starts_with(&["link_up", "link_lost"]), "{kinds:?}");
    assert!(kinds.contains(&"node_restart"), "{kinds:?}");
    assert_eq!(
        kinds.iter().filter(|k| **k == "link_up").count(),
        2,
        "{kinds:?}"
    );
}

/// A node with its alarm on (rime at 30 mm/h from 2 s, speed 10).
fn iced_node() -> NodeProc {
    NodeProc::start(Scene::film(Cover::Rime, 30.0, -5.0, 2.0, 10.0, 1))
}

fn wait_alarm(sub: &Subscriber) {
    sub.wait_for("the alarm", Duration::from_secs(20), |m| {
        m.iter()
            .any(|m| m.topic == "fois/gw/n1/state" && m.json()["alarm"] == true)
    });
}

/// The last state of n1 says the alarm was acknowledged.
fn acked_in(msgs: &[Msg]) -> bool {
    msgs.iter()
        .rfind(|m| m.topic == "fois/gw/n1/state")
        .is_some_and(|m| m.json()["alarm_acked"] == true)
}

fn acked(sub: &Subscriber) -> bool {
    acked_in(&sub.messages())
}

#[test]
fn mqtt_commands_are_refused_when_disabled_and_carried_out_only_on_their_topic() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-cmd", &["fois/#"], SubOptions::default());
    let node = iced_node();
    let nodes = [(node.path.as_str(), "n1")];

    // Disabled (the default): the gateway does not even subscribe.
    let off = gateway_config(dir.path(), "off", broker.port, &nodes, "");
    let mut gw = GatewayProc::start(&off, &[], &dir.path().join("off.out"));
    wait_alarm(&sub);
    sub.publish("fois/gw/n1/command", "ack", false);
    std::thread::sleep(Duration::from_secs(3));
    assert!(!acked(&sub), "acknowledged with commands disabled");
    assert!(sub.on("fois/gw/n1/command/result").is_empty());
    assert_eq!(gw.interrupt(), 0);

    // A retained command waits on the broker: delivered as retained when the
    // gateway subscribes, it is refused (it would repeat on every reconnect).
    sub.publish("ops/gw/n1/do", "ack", true);
    // Enabled on a chosen topic.
    let on = gateway_config(
        dir.path(),
        "on",
        broker.port,
        &nodes,
        "[commands]\nenabled = true\ntopic = \"ops/gw/{node}/do\"\nmin_interval_ms = 1000\n",
    );
    let mut gw = GatewayProc::start(&on, &[], &dir.path().join("on.out"));
    gw.wait_output("node n1 on", Duration::from_secs(10));
    std::thread::sleep(Duration::from_millis(500));
    assert!(!acked(&sub));
    // The default topic is not the configured one: nothing happens.
    sub.publish("fois/gw/n1/command", "ack", false);
    sub.wait_for("the refusal", Duration::from_secs(5), |m| {
        m.iter().any(|m| m.topic == "fois/gw/n1/command/result")
    });
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        !acked(&sub),
        "a retained or misplaced command was carried out"
    );
    let r = sub.on("fois/gw/n1/command/result");
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].json()["ok"], false);
    assert!(r[0].json()["detail"].as_str().unwrap().contains("retained"));
    // The gateway deleted the retained command: a new subscriber gets none.
    let late = Subscriber::start(broker.port, "t-late", &["ops/#"], SubOptions::default());
    std::thread::sleep(Duration::from_millis(500));
    assert!(late.on("ops/gw/n1/do").is_empty(), "still retained");
    drop(late);
    // A retained `ack` published while the gateway is connected reaches it
    // with the retain flag clear; its check (a second subscription) brings
    // the retained copy: refused and deleted, never carried out.
    sub.publish("ops/gw/n1/do", "ack", true);
    sub.wait_for("the second retained refusal", Duration::from_secs(5), |m| {
        m.iter()
            .filter(|m| m.topic == "fois/gw/n1/command/result" && m.text().contains("retained"))
            .count()
            >= 2
    });
    std::thread::sleep(Duration::from_millis(1500));
    assert!(!acked(&sub), "a retained ack was carried out");

    sub.publish("ops/gw/n1/do", "ack", false);
    sub.wait_for("acknowledged", Duration::from_secs(5), acked_in);
    // At most one command per second per node (min_interval_ms): a
    // calibration right after the ack is refused by the gateway ...
    sub.publish("ops/gw/n1/do", "{\"command\": \"calibrate-dark\"}", false);
    sub.wait_for("the rate limit", Duration::from_secs(5), |m| {
        m.iter()
            .any(|m| m.topic == "fois/gw/n1/command/result" && m.text().contains("rate limit"))
    });
    // ... and a second later by the node itself (an iced face is no dark
    // reference); unknown words by the gateway.
    std::thread::sleep(Duration::from_millis(1100));
    sub.publish("ops/gw/n1/do", "{\"command\": \"calibrate-dark\"}", false);
    sub.publish("ops/gw/n1/do", "reboot", false);
    sub.wait_for("4 more results", Duration::from_secs(8), |m| {
        m.iter()
            .filter(|m| m.topic == "fois/gw/n1/command/result")
            .count()
            >= 6
    });
    let results: Vec<serde_json::Value> = sub
        .on("fois/gw/n1/command/result")
        .iter()
        .map(|m| m.json())
        .collect();
    println!("{results:#?}");
    let by = |c: &str| {
        results
            .iter()
            .rev()
            .find(|r| r["command"] == c)
            .unwrap()
            .clone()
    };
    assert_eq!(by("ack")["ok"], true);
    assert!(
        by("ack")["detail"]
            .as_str()
            .unwrap()
            .contains("AlarmAcknowledged")
    );
    assert_eq!(by("calibrate-dark")["ok"], false);
    let why = by("calibrate-dark")["detail"].as_str().unwrap().to_string();
    assert!(
        why.contains("NotDry") || why.contains("CalibrationRefused"),
        "{why}"
    );
    assert_eq!(by("reboot")["ok"], false);
    assert!(
        by("reboot")["detail"]
            .as_str()
            .unwrap()
            .contains("unknown command")
    );
    assert_eq!(gw.interrupt(), 0);
}

#[test]
fn password_auth_works_and_the_password_is_never_printed() {
    let dir = tempfile::tempdir().unwrap();
    let secret = "S3cr3t-pa55word-7fq";
    let pwfile = dir.path().join("passwd");
    let st = std::process::Command::new(mosquitto_tool("mosquitto_passwd"))
        .arg("-c")
        .arg("-b")
        .arg(&pwfile)
        .args(["gw", secret])
        .status()
        .unwrap();
    assert!(st.success());
    let broker = Broker::start(
        dir.path(),
        &format!(
            "listener {{port}} 127.0.0.1\nallow_anonymous false\npassword_file {}\n",
            pwfile.display()
        ),
    );
    let sub = Subscriber::start(
        broker.port,
        "t-auth",
        &["fois/#"],
        SubOptions {
            credentials: Some(("gw".into(), secret.into())),
            ..SubOptions::default()
        },
    );
    let node = NodeProc::start(Scene::dry(5.0, 1));
    let nodes = [(node.path.as_str(), "n1")];
    // A wrong password: refused, said clearly, the password not shown.
    let bad = write(
        dir.path(),
        "bad.toml",
        &gateway_toml(broker.port, &dir.path().join("q"), &nodes, "").replace(
            "keep_alive_s = 2\n",
            "keep_alive_s = 2\nusername = \"gw\"\npassword = \"wrong-Pa55-xyz\"\n",
        ),
    );
    let mut gw = GatewayProc::start(&bad, &[], &dir.path().join("bad.out"));
    gw.wait_output("refused", Duration::from_secs(10));
    assert_eq!(gw.interrupt(), 0);
    let out = gw.output();
    assert!(
        out.contains("NotAuthorized") || out.contains("BadUserNamePassword"),
        "{out}"
    );
    assert!(!out.contains("wrong-Pa55-xyz"), "{out}");

    // The right one, from a password file.
    let pw = write(dir.path(), "gw.pw", &format!("{secret}\n"));
    let good = write(
        dir.path(),
        "good.toml",
        &gateway_toml(broker.port, &dir.path().join("q"), &nodes, "").replace(
            "keep_alive_s = 2\n",
            &format!(
                "keep_alive_s = 2\nusername = \"gw\"\npassword_file = \"{}\"\n",
                pw.display()
            ),
        ),
    );
    let mut gw = GatewayProc::start(&good, &[], &dir.path().join("good.out"));
    sub.wait_for("measurements", Duration::from_secs(10), |m| {
        m.iter()
            .filter(|m| m.topic == "fois/gw/n1/measurement")
            .count()
            > 20
    });
    assert_eq!(gw.interrupt(), 0);
    let out = gw.output();
    assert!(out.contains("connected to the broker"), "{out}");
    // Nowhere: run log, --print-config, --help.
    let printed = std::process::Command::new(BIN)
        .args(["--config"])
        .arg(&good)
        .arg("--print-config")
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&printed.stdout).to_string()
        + &String::from_utf8_lossy(&printed.stderr);
    assert!(printed.contains("Secret(***)"), "{printed}");
    let help = std::process::Command::new(BIN)
        .args(["--help"])
        .output()
        .unwrap();
    for text in [
        out,
        printed,
        String::from_utf8_lossy(&help.stdout).to_string(),
    ] {
        assert!(!text.contains(secret), "the password was printed:\n{text}");
    }
}

#[test]
fn tls_with_a_client_certificate() {
    let dir = tempfile::tempdir().unwrap();
    pki::make_pki(dir.path());
    let tls_port = free_port();
    let d = dir.path().display();
    // A plain listener for the test's subscriber, a mutual-TLS one for the gateway.
    let broker = Broker::start(
        dir.path(),
        &format!(
            "listener {{port}} 127.0.0.1\nallow_anonymous true\n\
             listener {tls_port} 127.0.0.1\ncafile {d}/ca.pem\ncertfile {d}/server.pem\n\
             keyfile {d}/server.key\nrequire_certificate true\n"
        ),
    );
    let sub = Subscriber::start(broker.port, "t-tls", &["fois/#"], SubOptions::default());
    let node = NodeProc::start(Scene::dry(5.0, 1));
    let nodes = [(node.path.as_str(), "n1")];
    let base = gateway_toml(tls_port, &dir.path().join("q"), &nodes, "");
    let with_tls = |tls: &str| {
        base.replace(
            "keep_alive_s = 2\n",
            &format!("keep_alive_s = 2\n[broker.tls]\n{tls}\n"),
        )
    };
    // Without a client certificate the broker refuses the handshake.
    let nocert = write(
        dir.path(),
        "nocert.toml",
        &with_tls(&format!("ca_file = \"{d}/ca.pem\"")),
    );
    let mut gw = GatewayProc::start(&nocert, &[], &dir.path().join("nocert.out"));
    gw.wait_output("unreachable", Duration::from_secs(10));
    assert_eq!(gw.interrupt(), 0);
    assert!(
        !gw.output().contains("connected to the broker"),
        "{}",
        gw.output()
    );
    // With it: connected over TLS, measurements flow.
    let good = write(
        dir.path(),
        "tls.toml",
        &with_tls(&format!(
            "ca_file = \"{d}/ca.pem\"\nclient_cert_file = \"{d}/client.pem\"\nclient_key_file = \"{d}/client.key\""
        )),
    );
    let mut gw = GatewayProc::start(&good, &[], &dir.path().join("tls.out"));
    sub.wait_for("measurements over TLS", Duration::from_secs(10), |m| {
        m.iter()
            .filter(|m| m.topic == "fois/gw/n1/measurement")
            .count()
            > 20
    });
    assert_eq!(gw.interrupt(), 0);
    assert!(gw.output().contains("(TLS)"), "{}", gw.output());
}

#[test]
fn a_node_with_an_ice_estimate_gets_a_thickness_entity() {
    use fois_protocol::{
        Ack, AckResult, Command, DetectorState, DeviceFrame, DeviceMsg, FrameDecoder, Hello,
        HostFrame, IceEstimate, Measurement, MeasurementV2, Medium, PROTOCOL_VERSION, ResetReason,
        encode_to_vec,
    };
    use serialport::SerialPort;
    use std::io::{Read, Write};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(
        broker.port,
        "t-est",
        &["fois/#", "homeassistant/#"],
        SubOptions::default(),
    );
    // A protocol-2 node that sends MeasurementV2 with an estimate: 1.25 mm rime.
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(5)).unwrap();
    let path = slave.name().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let feeder = std::thread::spawn(move || {
        let _slave = slave;
        let hello = Hello {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: [0, 2, 0],
            board: Hello::board_from_str("nucleo-f446re"),
            unique_id: [0x42; 12],
            reset_reason: ResetReason::PowerOn,
        };
        let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
        let mut seq = 0u32;
        let mut buf = [0u8; 256];
        let mut next = Instant::now();
        let start = Instant::now();
        while !s2.load(Ordering::Relaxed) {
            let mut send = |msg: DeviceMsg, master: &mut serialport::TTYPort| {
                let _ = master.write_all(&encode_to_vec(&DeviceFrame { seq, msg }));
                seq += 1;
            };
            if let Ok(n) = master.read(&mut buf) {
                let mut cmds = vec![];
                dec.feed::<HostFrame>(&buf[..n], |r| cmds.extend(r.ok()));
                for c in cmds {
                    let result = match c.cmd {
                        Command::GetInfo => AckResult::Info(hello.clone()),
                        Command::StartStream { .. } => AckResult::Streaming {
                            frame_period_ms: 50,
                        },
                        _ => continue,
                    };
                    send(DeviceMsg::Ack(Ack { id: c.id, result }), &mut master);
                }
            }
            if Instant::now() >= next {
                next += Duration::from_millis(50);
                let m = Measurement {
                    uptime_ms: start.elapsed().as_millis() as u64,
                    i1_na: 2500,
                    i2_na: 900,
                    ambient1_na: 0,
                    ambient2_na: 0,
                    temperature_centi_c: -800,
                    vdda_mv: 3300,
                    flags: fois_protocol::flags::ALARM,
                    state: DetectorState::Ice,
                };
                let estimate = Some(IceEstimate {
                    thickness_um: 1250,
                    sigma_um: 100,
                    medium: Medium::Rime,
                    probability_permille: 900,
                });
                send(
                    DeviceMsg::MeasurementV2(MeasurementV2 {
                        measurement: m,
                        estimate,
                    }),
                    &mut master,
                );
            }
        }
    });
    let cfg = gateway_config(dir.path(), "gw", broker.port, &[(&path, "est")], "");
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    sub.wait_for("the thickness entity", Duration::from_secs(10), |m| {
        m.iter().any(|m| {
            m.topic == "homeassistant/sensor/fois_node_424242424242424242424242/thickness/config"
        })
    });
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(gw.interrupt(), 0);
    stop.store(true, Ordering::Relaxed);
    feeder.join().unwrap();
    let t = sub.on("homeassistant/sensor/fois_node_424242424242424242424242/thickness/config");
    let t = t.last().unwrap().json();
    assert_eq!(t["unit_of_measurement"], "mm");
    assert_eq!(t["device_class"], "distance");
    assert_eq!(t["state_topic"], "fois/gw/est/state");
    let s = sub.on("fois/gw/est/state");
    let s = s.first().unwrap().json();
    assert_eq!(s["thickness_mm"], 1.25);
    assert_eq!(s["thickness_sigma_mm"], 0.1);
    assert_eq!(s["medium"], "rime");
    assert_eq!(s["medium_probability"], 0.9);
    assert_eq!(s["ice"], true);
    let m = sub.on("fois/gw/est/measurement");
    assert!(m.len() > 5);
    assert_eq!(m[0].json()["thickness_mm"], 1.25);
    assert_eq!(m[0].json()["i1_ua"], 2.5);
    // Every measurement arrived: the feeder's seqs minus its two answers.
    let r = NodeRecords::of(&sub.messages(), "est");
    assert!(r.holes().len() <= ACKS_PER_CONNECTION, "{:?}", r.holes());
    assert_eq!(r.duplicates(), 0);
}

#[test]
fn a_second_gateway_of_the_same_name_stops_and_the_first_keeps_its_fleet() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-twice", &["fois/#"], SubOptions::default());
    let n1 = NodeProc::start(Scene::dry(5.0, 1));
    let n2 = NodeProc::start(Scene::dry(5.0, 2));
    // One name (so one client id, the default), each its own queue: two
    // sites configured alike by mistake.
    let a_cfg = write(
        dir.path(),
        "a.toml",
        &gateway_toml(broker.port, &dir.path().join("qa"), &[(&n1.path, "n1")], ""),
    );
    let b_cfg = write(
        dir.path(),
        "b.toml",
        &gateway_toml(broker.port, &dir.path().join("qb"), &[(&n2.path, "n1")], ""),
    );
    let mut a = GatewayProc::start(&a_cfg, &[], &dir.path().join("a.out"));
    a.wait_output("node n1 on", Duration::from_secs(10));
    std::thread::sleep(Duration::from_secs(1));
    let mut b = GatewayProc::start(&b_cfg, &[], &dir.path().join("b.out"));
    let t0 = Instant::now();
    assert_eq!(b.wait_exit(Duration::from_secs(30)), 3, "{}", b.output());
    println!(
        "the second gateway stopped {:.1} s after its start",
        t0.elapsed().as_secs_f64()
    );
    assert!(
        b.output()
            .contains("another gateway named gw runs since before this one"),
        "{}",
        b.output()
    );
    assert!(
        a.output().contains("a second gateway named gw started"),
        "{}",
        a.output()
    );
    // The first one goes on: after its republication its node and itself
    // are online and its measurements flow.
    let stopped = Instant::now();
    std::thread::sleep(Duration::from_secs(5));
    let msgs = sub.messages();
    let last = |topic: &str| {
        msgs.iter()
            .rfind(|m| m.topic == topic)
            .map(|m| m.text())
            .unwrap_or_default()
    };
    assert_eq!(last("fois/gw/availability"), "online");
    assert_eq!(last("fois/gw/n1/availability"), "online");
    let fresh = msgs
        .iter()
        .filter(|m| m.topic == "fois/gw/n1/measurement" && m.at > stopped)
        .count();
    assert!(fresh > 10, "{fresh} measurements after the second stopped");
    assert_eq!(a.interrupt(), 0, "{}", a.output());
}

#[test]
fn an_oversized_retained_command_is_skipped_and_the_connection_stays() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-big", &["fois/#"], SubOptions::default());
    // 70 KiB, retained, on the command topic before the gateway starts: it
    // arrives at every subscription (every reconnection).
    let big = "x".repeat(70 * 1024);
    sub.publish("fois/gw/n1/command", &big, true);
    let node = NodeProc::start(Scene::dry(5.0, 1));
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(&node.path, "n1")],
        "[commands]\nenabled = true\n",
    );
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    sub.wait_for("the skip", Duration::from_secs(10), |m| {
        m.iter().any(|m| {
            m.topic == "fois/gw/n1/command/result" && m.text().contains("71680-byte message")
        })
    });
    std::thread::sleep(Duration::from_secs(3));
    let measured = sub.on("fois/gw/n1/measurement").len();
    assert_eq!(gw.interrupt(), 0);
    let out = gw.output();
    assert!(
        out.contains("1 broker connection(s)"),
        "it never reconnected:\n{out}"
    );
    assert!(measured > 20, "{measured} measurements");
    // The gateway deleted it: a new subscriber finds nothing retained.
    let late = Subscriber::start(
        broker.port,
        "t-late",
        &["fois/gw/n1/command"],
        SubOptions::default(),
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(late.messages().is_empty(), "still retained");
}

#[test]
fn another_front_end_reads_every_node_and_sends_commands_through_the_service() {
    use fois_gateway::command::{FrontEndCommand, NodeCommand};
    use fois_gateway::config::file::{FileConfig, Overrides};
    use fois_gateway::service::{RunLimits, Service};
    use std::sync::atomic::{AtomicBool, Ordering};

    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(broker.port, "t-front", &["fois/#"], SubOptions::default());
    let node = iced_node();
    let cfg = FileConfig::parse(&gateway_toml(
        broker.port,
        &dir.path().join("q"),
        &[(&node.path, "n1"), ("/dev/does-not-exist", "n2")],
        "",
    ))
    .unwrap()
    .resolve(&Overrides::default())
    .unwrap();
    let service = Service::new(cfg);
    let fleet = service.fleet();
    let commands = service.commands();
    static STOP: AtomicBool = AtomicBool::new(false);
    let run = std::thread::spawn(move || {
        service.run(RunLimits {
            stop: &STOP,
            duration: None,
            status_every: Duration::from_secs(3600),
        })
    });
    // The alarm trips (rime at 30 mm/h after 2 s of dry face at ×10).
    let t0 = Instant::now();
    let iced = loop {
        let n = fleet.node(0).unwrap();
        if n.reading.as_ref().is_some_and(|r| r.alarm) {
            break n;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "{n:?}");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(iced.link_up && iced.hello.is_some());
    assert!(iced.age(Instant::now()).unwrap() < Duration::from_secs(2));
    let missing = fleet.node(1).unwrap();
    assert!(!missing.link_up && missing.reading.is_none() && missing.age(Instant::now()).is_none());
    // A command from the front end: the same path as MQTT's, its answer
    // published as a command result.
    commands
        .send(FrontEndCommand {
            node: 0,
            command: NodeCommand::AckAlarm,
            reply: None,
        })
        .unwrap();
    let t0 = Instant::now();
    while !fleet
        .node(0)
        .unwrap()
        .reading
        .is_some_and(|r| r.alarm_acked)
    {
        assert!(t0.elapsed() < Duration::from_secs(10), "not acknowledged");
        std::thread::sleep(Duration::from_millis(50));
    }
    sub.wait_for("the command result", Duration::from_secs(5), |m| {
        m.iter().any(|m| {
            m.topic == "fois/gw/n1/command/result" && m.text().contains("AlarmAcknowledged")
        })
    });
    STOP.store(true, Ordering::Relaxed);
    let sum = run.join().unwrap().unwrap();
    assert_eq!(sum.broker_connects, 1);
    assert!(sum.frames > 20, "{sum:?}");
}

#[test]
fn a_modbus_acknowledge_flood_gets_busy_answers_and_one_command_result() {
    use std::io::{Read, Write};

    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(
        broker.port,
        "t-flood",
        &["fois/gw/n1/state", "fois/gw/n1/command/result"],
        SubOptions::default(),
    );
    let node = iced_node();
    let modbus_port = free_port();
    let cfg = gateway_config(
        dir.path(),
        "gw",
        broker.port,
        &[(&node.path, "n1")],
        &format!(
            "[modbus]\nenabled = true\ncommands = true\nlisten = \"127.0.0.1:{modbus_port}\"\n"
        ),
    );
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.log"));
    wait_alarm(&sub);
    let mut s = std::net::TcpStream::connect(("127.0.0.1", modbus_port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    // Batches of 20 pipelined writes of 1 to alarm_ack (unit 1), for 3 s.
    let (mut ok, mut busy, mut writes) = (0, 0, 0u32);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(3) {
        let mut batch = Vec::new();
        for k in 0..20u16 {
            let tid = (writes as u16).wrapping_add(k);
            batch.extend(tid.to_be_bytes());
            batch.extend([0, 0, 0, 6, 1, 0x06, 0, 23, 0, 1]);
        }
        s.write_all(&batch).unwrap();
        for _ in 0..20 {
            let mut h = [0u8; 7];
            s.read_exact(&mut h).unwrap();
            let mut pdu = vec![0u8; usize::from(h[5]) - 1];
            s.read_exact(&mut pdu).unwrap();
            match pdu.as_slice() {
                [0x06, 0, 23, 0, 1] => ok += 1,
                [0x86, 0x06] => busy += 1,
                other => panic!("answer {other:02x?}"),
            }
        }
        writes += 20;
    }
    let rate = f64::from(writes) / t0.elapsed().as_secs_f64();
    println!("{writes} acknowledge writes at {rate:.0}/s: {ok} success, {busy} busy (06)");
    assert!(writes >= 1_000, "{writes}");
    // [commands] min_interval_ms 5 s: one write handed to the node.
    assert_eq!((ok, busy), (1, writes - 1));
    std::thread::sleep(Duration::from_secs(1));
    let results = sub.on("fois/gw/n1/command/result");
    assert_eq!(results.len(), 1, "{results:?}");
    assert!(
        results[0].text().contains("AlarmAcknowledged"),
        "{}",
        results[0].text()
    );
    assert_eq!(gw.interrupt(), 0);
    let out = gw.output();
    let refusal_lines = out.lines().filter(|l| l.contains("refused")).count();
    println!("{refusal_lines} refusal log line(s)");
    assert_eq!(refusal_lines, 1, "{out}");
}

#[test]
fn another_instances_last_will_leaves_no_phantom_offline_on_a_running_gateway() {
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let sub = Subscriber::start(
        broker.port,
        "t-phantom",
        &["fois/gw/availability"],
        SubOptions::default(),
    );
    let node = NodeProc::start(Scene::dry(5.0, 1));
    let cfg = gateway_config(dir.path(), "gw", broker.port, &[(&node.path, "n1")], "");
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    gw.wait_output("node n1 on", Duration::from_secs(10));
    // A second instance's connection with the gateway's last will (retained
    // `offline` on its availability), killed: the broker publishes the will.
    let mut intruder = std::process::Command::new(mosquitto_tool("mosquitto_sub"))
        .args([
            "-h",
            "127.0.0.1",
            "-p",
            &broker.port.to_string(),
            "-i",
            "gw-second",
        ])
        .args(["-t", "fois/nothing", "--will-topic", "fois/gw/availability"])
        .args([
            "--will-payload",
            "offline",
            "--will-retain",
            "--will-qos",
            "1",
        ])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(700));
    intruder.kill().unwrap();
    intruder.wait().unwrap();
    sub.wait_for("the will", Duration::from_secs(5), |m| {
        m.iter().any(|m| m.text() == "offline")
    });
    std::thread::sleep(Duration::from_secs(2));
    // What a newcomer (Home Assistant after a restart) finds retained.
    let late = Subscriber::start(
        broker.port,
        "t-phantom-late",
        &["fois/gw/availability"],
        SubOptions::default(),
    );
    late.wait_for("the retained availability", Duration::from_secs(5), |m| {
        !m.is_empty()
    });
    let m = late.messages();
    assert!(m[0].retain);
    assert_eq!(m[0].text(), "online", "a phantom offline stayed");
    assert!(
        gw.output()
            .contains("`offline` appeared on fois/gw/availability"),
        "{}",
        gw.output()
    );
    assert_eq!(gw.interrupt(), 0);
    // Its own goodbye stays: a clean stop leaves `offline`.
    std::thread::sleep(Duration::from_millis(500));
    let after = sub.messages();
    assert_eq!(after.last().unwrap().text(), "offline", "{after:?}");
}
