//! The gateway's Home Assistant discovery, checked by a real Home Assistant
//! core: a Mosquitto broker, four virtual nodes on ptys (the firmware's own
//! `Node`), `fois-gateway` with discovery and commands on, and Home
//! Assistant (from the virtualenv `FOIS_HA_PYTHON` names) on the same
//! broker. What a user of that Home Assistant sees is read through the
//! `fois_probe` integration (tests/home_assistant/) and asserted:
//!
//! - one device per node under the gateway's device (`via_device`), ids
//!   from the hardware id, `serial_number` only where the release takes it;
//! - every entity with its unit, device class, state class and category;
//! - the ice sensor ON and the surface "ice" while rime grows, the alarm
//!   acknowledged by pressing the button, everything OFF and "dry" when the
//!   ice is gone; a water film at +5 °C "wet", with 0 mm of ice and the
//!   film apart;
//! - no discovery message refused, no template warning;
//! - the state changes per node per minute (one database row each);
//! - an unplugged node's entities unavailable, the others not;
//! - a node renamed in the config keeps its device and entities.
//!
//! Ignored in `cargo test`: `cargo xtask ha-check` installs Home Assistant
//! (each supported release in its own virtualenv) and runs it.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod support;

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use fois_vnode::{Cover, NtcWiring, Segment};
use serde_json::{Value, json};
use support::ha_snapshot::{Device, changes, entity_id, log_problems, table};
use support::home_assistant::HomeAssistant;
use support::*;

/// What a user must see of an entity: (object, entity domain, device
/// class, unit, state class, category).
type Expected = (
    &'static str,
    &'static str,
    Option<&'static str>,
    Option<&'static str>,
    Option<&'static str>,
    Option<&'static str>,
);

/// Every entity of a node (with an estimate, commands on).
const EXPECTED: [Expected; 16] = [
    ("ice", "binary_sensor", Some("cold"), None, None, None),
    ("surface", "sensor", Some("enum"), None, None, None),
    ("alarm", "binary_sensor", Some("safety"), None, None, None),
    ("alarm_acked", "binary_sensor", None, None, None, None),
    (
        "temperature",
        "sensor",
        Some("temperature"),
        Some("°C"),
        Some("measurement"),
        None,
    ),
    (
        "thickness",
        "sensor",
        Some("distance"),
        Some("mm"),
        Some("measurement"),
        None,
    ),
    (
        "water_film",
        "sensor",
        Some("distance"),
        Some("mm"),
        Some("measurement"),
        None,
    ),
    (
        "thickness_sigma",
        "sensor",
        Some("distance"),
        Some("mm"),
        Some("measurement"),
        Some("diagnostic"),
    ),
    ("medium", "sensor", Some("enum"), None, None, None),
    (
        "problem",
        "binary_sensor",
        Some("problem"),
        None,
        None,
        Some("diagnostic"),
    ),
    (
        "i1",
        "sensor",
        None,
        Some("µA"),
        Some("measurement"),
        Some("diagnostic"),
    ),
    (
        "i2",
        "sensor",
        None,
        Some("µA"),
        Some("measurement"),
        Some("diagnostic"),
    ),
    (
        "frames_received",
        "sensor",
        None,
        None,
        Some("total_increasing"),
        Some("diagnostic"),
    ),
    (
        "frames_lost",
        "sensor",
        None,
        None,
        Some("total_increasing"),
        Some("diagnostic"),
    ),
    ("ack", "button", None, None, None, None),
    ("calibrate_dark", "button", None, None, None, Some("config")),
];

/// The nodes, by name in the config.
const NODES: [&str; 4] = ["iced", "wet", "dry", "rime"];

/// The gateway's config: defaults for publishing (what a site runs),
/// discovery for `version`, commands on.
fn config(dir: &Path, broker: u16, version: &str, nodes: &[(&str, &str)]) -> std::path::PathBuf {
    let mut s = format!(
        "name = \"gw\"\n[broker]\nhost = \"127.0.0.1\"\nport = {broker}\nkeep_alive_s = 2\n\
         [queue]\ndir = \"{}\"\n[homeassistant]\nversion = \"{version}\"\n\
         [commands]\nenabled = true\nmin_interval_ms = 1000\n",
        dir.join("q").display()
    );
    for (port, name) in nodes {
        let _ = write!(s, "[[node]]\nport = \"{port}\"\nname = \"{name}\"\n");
    }
    let p = dir.join("gw.toml");
    std::fs::write(&p, s).unwrap();
    p
}

#[test]
#[ignore = "runs a real Home Assistant: cargo xtask ha-check"]
fn home_assistant_shows_each_node_under_the_gateway_as_a_user_expects() {
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let broker = Broker::start(dir.path(), "");
    let ha_dir = dir.path().join("ha");
    let mut ha = HomeAssistant::start(&ha_dir, broker.port);
    let up = ha.wait(
        "the MQTT integration loaded",
        Duration::from_secs(180),
        |s| s.mqtt_loaded(),
    );
    let release = up.version().to_string();
    let ha_started_s = started.elapsed().as_secs_f64();
    let configured: String = release.split('.').take(2).collect::<Vec<_>>().join(".");
    let mut report = format!(
        "Home Assistant {release} (gateway [homeassistant] version = \"{configured}\"): up in {ha_started_s:.0} s\n"
    );

    // Rime grows for 60 s of real time, then the face is dry again; a water
    // film at +5 °C grows to 0.4 mm and stays; a dry node in real time.
    let iced = NodeProc::timeline(
        10.0,
        vec![
            Segment::new(3.0, Cover::Dry),
            Segment::new(600.0, Cover::Rime).rate(30.0),
            Segment::new(f64::INFINITY, Cover::Dry),
        ],
        11,
    );
    let wet = NodeProc::timeline(
        10.0,
        vec![
            Segment::new(3.0, Cover::Dry).temp(5.0),
            Segment::new(72.0, Cover::Water).rate(20.0).temp(5.0),
            Segment::new(f64::INFINITY, Cover::Water).temp(5.0),
        ],
        12,
    );
    // A dry face in real time, its NTC unplugged: a fault.
    let mut dry = NodeProc::timeline(
        1.0,
        vec![Segment::new(f64::INFINITY, Cover::Dry).ntc(NtcWiring::Open)],
        13,
    );
    // Rime growing at 6 mm/h in real time: the rate of state changes while
    // ice grows, as a site would see it.
    let rime = NodeProc::timeline(
        1.0,
        vec![
            Segment::new(3.0, Cover::Dry),
            Segment::new(f64::INFINITY, Cover::Rime).rate(6.0),
        ],
        14,
    );
    let names = [
        ("iced", &iced),
        ("wet", &wet),
        ("dry", &dry),
        ("rime", &rime),
    ];
    let ports: Vec<(&str, &str)> = names.iter().map(|(n, p)| (p.path.as_str(), *n)).collect();
    let cfg = config(dir.path(), broker.port, &configured, &ports);
    let out = dir.path().join("gw.out");
    let mut gw = GatewayProc::start(&cfg, &[], &out);

    // Devices: one per node, under the gateway's.
    let s = ha.wait(
        "the gateway and four node devices",
        Duration::from_secs(60),
        |s| {
            s.device("FOIS gateway gw").is_some()
                && NODES.iter().all(|n| {
                    Device::of(s, n).is_some_and(|d| s.entities_of(&d.id).len() >= EXPECTED.len())
                })
        },
    );
    let gateway = s.device("FOIS gateway gw").unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let devs: Vec<Device> = NODES.iter().map(|n| Device::of(&s, n).unwrap()).collect();
    let serial = fois_gateway::discovery::HaVersion::parse(&configured)
        .unwrap()
        .serial_number();
    for (d, n) in devs.iter().zip(NODES) {
        let reg = s.device(&format!("FOIS {n}")).unwrap();
        assert_eq!(
            reg["via_device_id"],
            gateway.as_str(),
            "{n} is under the gateway"
        );
        assert_eq!(reg["model"], "virtual-f446");
        let hw = d
            .ident
            .strip_prefix("fois_node_")
            .expect("an id from the hardware id");
        assert_eq!(hw.len(), 24, "{hw}");
        assert_eq!(
            reg["serial_number"],
            if serial { json!(hw) } else { Value::Null },
            "{n}: serial_number where the release takes it"
        );
    }
    let mut idents: Vec<&str> = devs.iter().map(|d| d.ident.as_str()).collect();
    idents.sort_unstable();
    idents.dedup();
    assert_eq!(idents.len(), NODES.len(), "one device per node");
    let _ = writeln!(
        report,
        "devices: FOIS gateway gw; FOIS iced, FOIS wet, FOIS dry, FOIS rime, each via the gateway (serial_number {})",
        if serial { "shown" } else { "left out" }
    );

    // Every entity with its unit and classes (the registry: what the UI shows).
    for (d, n) in devs.iter().zip(NODES) {
        for (object, domain, class, unit, state_class, category) in EXPECTED {
            let e = s
                .entity(&d.uid(object))
                .unwrap_or_else(|| panic!("{n}: no entity {object}:\n{}", s.states_text()));
            let id = e["entity_id"].as_str().unwrap();
            assert!(id.starts_with(&format!("{domain}.fois_{n}_")), "{id}");
            assert_eq!(e["original_device_class"].as_str(), class, "{id}");
            assert_eq!(e["unit_of_measurement"].as_str(), unit, "{id}");
            assert_eq!(
                e["capabilities"]["state_class"].as_str(),
                state_class,
                "{id}"
            );
            assert_eq!(e["entity_category"].as_str(), category, "{id}");
        }
    }

    // The iced node: ice on, alarm on; the button acknowledges it.
    let (di, dw, dd, dr) = (&devs[0], &devs[1], &devs[2], &devs[3]);
    let icing = (s.clone(), Instant::now());
    let s = ha.wait("ice on the iced node", Duration::from_secs(40), |s| {
        s.state(&di.uid("ice")) == Some("on") && s.state(&di.uid("alarm")) == Some("on")
    });
    assert_eq!(s.state(&di.uid("surface")), Some("ice"));
    assert_eq!(s.state(&di.uid("alarm_acked")), Some("off"));
    let t0 = Instant::now();
    ha.call(
        "button",
        "press",
        json!({"entity_id": entity_id(&s, di, "ack")}),
    );
    let s = ha.wait("the alarm acknowledged", Duration::from_secs(20), |s| {
        s.state(&di.uid("alarm_acked")) == Some("on")
    });
    let ack_s = t0.elapsed().as_secs_f64();
    let thick: f64 = s.state(&di.uid("thickness")).unwrap().parse().unwrap();
    assert!(thick > 0.1, "rime thickness {thick} mm");
    assert!(matches!(
        s.state(&di.uid("medium")),
        Some("rime" | "glazed")
    ));
    assert_eq!(s.state(&di.uid("water_film")), Some("0.0"));
    let _ = writeln!(
        report,
        "iced: ice on, surface ice, alarm on; \"Acknowledge alarm\" pressed -> acknowledged in {ack_s:.1} s; ice thickness {thick} mm, medium {}",
        s.state(&di.uid("medium")).unwrap()
    );

    // The water film: wet, no ice, 0 mm of ice, the film apart.
    let s = ha.wait("the wet node wet", Duration::from_secs(40), |s| {
        s.state(&dw.uid("surface")) == Some("wet") && s.state(&dw.uid("medium")) == Some("water")
    });
    assert_eq!(s.state(&dw.uid("ice")), Some("off"));
    assert_eq!(
        s.state(&dw.uid("thickness")),
        Some("0.0"),
        "a water film is not ice"
    );
    let film: f64 = s.state(&dw.uid("water_film")).unwrap().parse().unwrap();
    assert!((0.1..1.5).contains(&film), "water film {film} mm");
    let temp = s.state(&dw.uid("temperature")).unwrap().to_string();
    let _ = writeln!(
        report,
        "wet: surface wet, ice off, ice thickness 0.0 mm, water film {film} mm, medium water, {temp} °C"
    );
    let problem = s.state_of(&entity_id(&s, dw, "problem")).unwrap();
    assert_eq!(problem["state"], "off");
    assert_eq!(problem["attributes"]["faults"], json!([]));

    // The ice goes: everything back to normal.
    let s = ha.wait("the ice gone", Duration::from_secs(120), |s| {
        s.state(&di.uid("ice")) == Some("off") && s.state(&di.uid("surface")) == Some("dry")
    });
    assert_eq!(s.state(&di.uid("alarm")), Some("off"));
    assert_eq!(s.state(&di.uid("alarm_acked")), Some("off"));
    let _ = writeln!(
        report,
        "iced: ice off, surface dry, alarm off once the face is dry again"
    );
    let (c0, c1) = (changes(&icing.0, di), changes(&s, di));
    let delta: u64 = c1
        .iter()
        .map(|(k, v)| v.0 - c0.get(k).map_or(0, |x| x.0))
        .sum();
    let _ = writeln!(
        report,
        "iced (x10 real time) while the rime grew and went: {:.1} state changes/min over {:.1} min",
        delta as f64 / (icing.1.elapsed().as_secs_f64() / 60.0),
        icing.1.elapsed().as_secs_f64() / 60.0
    );

    // State changes (database rows) per node over a quiet minute.
    let a = ha.snapshot().unwrap();
    let ta = Instant::now();
    std::thread::sleep(Duration::from_secs(60));
    let b = ha.snapshot().unwrap();
    let minutes = ta.elapsed().as_secs_f64() / 60.0;
    for (d, n, speed) in [
        (di, "iced", 10),
        (dw, "wet", 10),
        (dd, "dry", 1),
        (dr, "rime", 1),
    ] {
        let (ca, cb) = (changes(&a, d), changes(&b, d));
        let delta: u64 = cb
            .iter()
            .map(|(k, v)| v.0 - ca.get(k).map_or(0, |x| x.0))
            .sum();
        let rows: u64 = cb
            .iter()
            .map(|(k, v)| v.1.saturating_sub(ca.get(k).map_or(0, |x| x.1)))
            .sum();
        let per_min = delta as f64 / minutes;
        let mut which: Vec<String> = cb
            .iter()
            .filter_map(|(k, v)| {
                let d = v.0 - ca.get(k).map_or(0, |x| x.0);
                let short = k
                    .split_once(&format!(".fois_{n}_"))
                    .map_or(k.as_str(), |x| x.1);
                (d > 0).then(|| format!("{short} {d}"))
            })
            .collect();
        which.sort();
        let _ = writeln!(
            report,
            "{n} (x{speed} real time): {per_min:.1} state changes/min over {minutes:.1} min ({rows} recorder rows){}",
            if which.is_empty() {
                String::new()
            } else {
                format!(": {}", which.join(", "))
            }
        );
        assert!(
            per_min <= 30.0,
            "{n}: {per_min:.1} state changes per minute"
        );
        if n == "dry" {
            assert!(
                per_min <= 1.0,
                "a quiet node writes (almost) nothing: {per_min:.1}/min"
            );
        }
    }

    // The fault, by name; dark calibration from its button.
    let s = ha.snapshot().unwrap();
    let problem = s.state_of(&entity_id(&s, dd, "problem")).unwrap().clone();
    assert_eq!(problem["state"], "on", "{problem}");
    let faults = problem["attributes"]["faults"].clone();
    assert!(
        faults.as_array().unwrap().iter().any(|f| f == "ntc_open"),
        "{problem}"
    );
    ha.call(
        "button",
        "press",
        json!({"entity_id": entity_id(&s, dd, "calibrate_dark")}),
    );
    gw.wait_output(
        "command calibrate-dark for dry: done",
        Duration::from_secs(20),
    );
    let _ = writeln!(
        report,
        "dry (NTC unplugged): Problem on, faults {faults}; \"Dark calibration\" pressed -> the node calibrated"
    );

    // Unplugged: the node's entities unavailable, the others not.
    dry.kill9();
    let t0 = Instant::now();
    let s = ha.wait(
        "the unplugged node unavailable",
        Duration::from_secs(30),
        |s| {
            s.entities_of(&dd.id).iter().all(|e| {
                s.state_of(e["entity_id"].as_str().unwrap())
                    .is_some_and(|st| st["state"] == "unavailable")
            })
        },
    );
    let unplug_s = t0.elapsed().as_secs_f64();
    for d in [di, dw, dr] {
        for e in s.entities_of(&d.id) {
            let st = s.state_of(e["entity_id"].as_str().unwrap()).unwrap();
            assert_ne!(st["state"], "unavailable", "{st}");
        }
    }
    let _ = writeln!(
        report,
        "dry unplugged: its {} entities unavailable after {unplug_s:.1} s, the other nodes' available",
        s.entities_of(&dd.id).len()
    );

    // A rename in the config: same device, same entities.
    let before: Vec<String> = s
        .entities_of(&dw.id)
        .iter()
        .map(|e| e["entity_id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(gw.interrupt(), 0);
    let ports = [
        (iced.path.as_str(), "iced"),
        (wet.path.as_str(), "pond"),
        (dry.path.as_str(), "dry"),
        (rime.path.as_str(), "rime"),
    ];
    let cfg = config(dir.path(), broker.port, &configured, &ports);
    let mut gw = GatewayProc::start(&cfg, &[], &out);
    let s = ha.wait("the renamed node", Duration::from_secs(40), |s| {
        s.device("FOIS pond")
            .is_some_and(|d| d["id"] == dw.id.as_str())
            && s.state(&dw.uid("surface")) == Some("wet")
    });
    let mut after: Vec<String> = s
        .entities_of(&dw.id)
        .iter()
        .map(|e| e["entity_id"].as_str().unwrap().to_string())
        .collect();
    after.sort();
    let mut b4 = before.clone();
    b4.sort();
    assert_eq!(after, b4, "the same entities (and their history)");
    assert!(s.device("FOIS wet").is_none());
    assert_eq!(s.devices().len(), 1 + NODES.len(), "no device left behind");
    let _ = writeln!(
        report,
        "wet renamed pond in the config: the same device and its {} entities (ids unchanged), now \"FOIS pond\"",
        after.len()
    );

    // Nothing refused, no template warning. Home Assistant's own errors
    // that do not concern MQTT (its tracebacks say where) are shown, not
    // failed on.
    let (problems, other) = log_problems(&s);
    assert!(
        problems.is_empty(),
        "Home Assistant logged:\n{}",
        problems.join("\n")
    );
    let _ = writeln!(
        report,
        "log: no discovery message refused, no template warning{}",
        if other.is_empty() {
            String::new()
        } else {
            format!(
                "; Home Assistant's own errors, not about MQTT:\n{}",
                other.join("\n")
            )
        }
    );

    let _ = writeln!(
        report,
        "what a user sees (after the rename; dry unplugged):"
    );
    for (d, n) in [(di, "iced"), (dw, "pond"), (dd, "dry"), (dr, "rime")] {
        let _ = writeln!(report, "  FOIS {n}");
        table(&s, d, &mut report);
    }
    assert_eq!(gw.interrupt(), 0);
    let st = ha.stop();
    let _ = writeln!(
        report,
        "run: {:.0} s in all (Home Assistant stopped: {})",
        started.elapsed().as_secs_f64(),
        st.map_or("killed".into(), |s| s.to_string())
    );
    println!("{report}");
    if let Some(p) = std::env::var_os("FOIS_HA_REPORT") {
        std::fs::write(p, &report).unwrap();
    }
}
