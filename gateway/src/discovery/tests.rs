//! The discovery messages: topics, ids, keys per release, and every
//! entity's templates rendered (minijinja) against real state payloads.

use super::*;
use crate::payload::StateJson;
use fois_link::Reading;
use fois_protocol::{
    DetectorState, GainEstimate, IceEstimate, IcingEstimate, Measurement, Medium, flags,
};

fn hello(id: u8) -> Hello {
    Hello {
        protocol_version: 3,
        firmware_version: [0, 3, 1],
        board: Hello::board_from_str("nucleo-f446re"),
        unique_id: [id; 12],
        reset_reason: fois_protocol::ResetReason::PowerOn,
    }
}

fn configs(version: HaVersion, commands: bool, estimate: bool, gain: bool) -> Vec<(String, Value)> {
    let t = Topics::new("fois", "gw", commands.then_some("fois/gw/{node}/command"));
    let d = Discovery {
        prefix: "homeassistant",
        topics: &t,
        gateway: "gw",
        version,
    };
    let h = hello(0xab);
    let node = NodeInfo {
        name: "tower-3",
        key: "abababababababababababab",
        hello: &h,
        estimate,
        gain,
        icing: gain,
    };
    d.node_configs(&node)
        .into_iter()
        .map(|(t, p)| (t, serde_json::from_slice(&p).unwrap()))
        .collect()
}

fn by_object<'a>(c: &'a [(String, Value)], object: &str) -> &'a Value {
    let suffix = format!("/{object}/config");
    &c.iter()
        .find(|(t, _)| t.ends_with(&suffix))
        .unwrap_or_else(|| panic!("no {object}"))
        .1
}

#[test]
fn a_node_is_a_device_under_the_gateway_named_by_its_hardware_id() {
    let c = configs(HaVersion::OLDEST, false, false, false);
    let topics: Vec<&str> = c.iter().map(|(t, _)| t.as_str()).collect();
    let id = "fois_node_abababababababababababab";
    assert_eq!(
        topics,
        [
            "binary_sensor/{id}/ice",
            "sensor/{id}/surface",
            "binary_sensor/{id}/alarm",
            "binary_sensor/{id}/alarm_acked",
            "sensor/{id}/temperature",
            "binary_sensor/{id}/problem",
            "sensor/{id}/i1",
            "sensor/{id}/i2",
            "sensor/{id}/frames_received",
            "sensor/{id}/frames_lost",
        ]
        .map(|t| format!("homeassistant/{}/config", t.replace("{id}", id)))
    );
    for (_, v) in &c {
        let dev = &v["device"];
        assert_eq!(dev["identifiers"][0], id);
        assert_eq!(dev["name"], "FOIS tower-3");
        assert_eq!(dev["via_device"], "fois_gw");
        assert_eq!(dev["model"], "nucleo-f446re");
        assert_eq!(dev["sw_version"], "0.3.1");
        // 2024.1 refuses the whole message with this key.
        assert!(dev.get("serial_number").is_none(), "{v}");
        assert!(v["unique_id"].as_str().unwrap().starts_with(id));
        assert_eq!(v["availability_mode"], "all");
        assert_eq!(v["availability"][0]["topic"], "fois/gw/availability");
        assert_eq!(
            v["availability"][1]["topic"],
            "fois/gw/tower-3/availability"
        );
        assert_eq!(v["state_topic"], "fois/gw/tower-3/state");
        // Home Assistant drops an attribute named `state`: no entity takes
        // the whole payload as attributes.
        assert!(
            v.get("json_attributes_template").is_some() || v.get("json_attributes_topic").is_none()
        );
        assert!(v.get("options").is_none(), "2024.1 has no enum options");
    }
    let ice = by_object(&c, "ice");
    assert_eq!(ice["unique_id"], format!("{id}_ice"));
    assert_eq!(ice["device_class"], "cold");
    let t = by_object(&c, "temperature");
    assert_eq!(
        (
            &t["unit_of_measurement"],
            &t["device_class"],
            &t["state_class"]
        ),
        (&json!("°C"), &json!("temperature"), &json!("measurement"))
    );
    let i1 = by_object(&c, "i1");
    assert_eq!(i1["unit_of_measurement"], "µA");
    assert_eq!(i1["entity_category"], "diagnostic");
    assert!(i1.get("device_class").is_none());
    let p = by_object(&c, "problem");
    assert_eq!(
        (&p["device_class"], &p["entity_category"]),
        (&json!("problem"), &json!("diagnostic"))
    );
    let f = by_object(&c, "frames_lost");
    assert_eq!(f["state_class"], "total_increasing");
    assert_eq!(by_object(&c, "surface")["device_class"], "enum");
}

#[test]
fn estimate_gain_and_command_entities_come_with_what_the_node_sends() {
    let all = configs(HaVersion::OLDEST, true, true, true);
    assert_eq!(all.len(), 19);
    for (object, key) in [
        ("thickness", "ice_thickness_mm"),
        ("water_film", "water_film_mm"),
        ("thickness_sigma", "thickness_sigma_mm"),
    ] {
        let v = by_object(&all, object);
        assert_eq!(v["unit_of_measurement"], "mm", "{object}");
        assert_eq!(v["device_class"], "distance", "{object}");
        assert_eq!(v["state_class"], "measurement", "{object}");
        assert!(
            v["value_template"].as_str().unwrap().contains(key),
            "{object}"
        );
    }
    assert_eq!(by_object(&all, "thickness")["name"], "Ice thickness");
    assert_eq!(by_object(&all, "medium")["device_class"], "enum");
    let gain = by_object(&all, "gain");
    assert_eq!(gain["entity_category"], "diagnostic");
    let ack = by_object(&all, "ack");
    assert_eq!(ack["command_topic"], "fois/gw/tower-3/command");
    assert_eq!(ack["payload_press"], "ack");
    assert_eq!(
        ack["retain"], false,
        "the gateway refuses retained commands"
    );
    let cal = by_object(&all, "calibrate_dark");
    assert_eq!(cal["payload_press"], "calibrate-dark");
    assert_eq!(cal["entity_category"], "config");
    assert!(all.iter().all(|(t, _)| !t.contains("/link/")));
    let plain = configs(HaVersion::OLDEST, false, true, false);
    assert_eq!(plain.len(), 14);
    assert!(
        plain
            .iter()
            .all(|(t, _)| !t.contains("/gain/") && !t.contains("/ack/"))
    );
}

#[test]
fn newer_keys_only_for_releases_that_take_them() {
    let c = configs(HaVersion::new(2024, 3), false, true, false);
    assert_eq!(
        by_object(&c, "ice")["device"]["serial_number"],
        "abababababababababababab"
    );
    assert!(by_object(&c, "medium").get("options").is_none());
    let c = configs(HaVersion::new(2024, 9), false, true, false);
    assert_eq!(
        by_object(&c, "medium")["options"],
        json!(["dry", "water", "glazed", "rime"])
    );
    assert_eq!(
        by_object(&c, "surface")["options"],
        json!(["dry", "wet", "ice"])
    );
}

#[test]
fn stale_configs_are_the_buttons_without_commands_and_the_name_based_ones() {
    let t = Topics::new("fois", "gw", None);
    let d = Discovery {
        prefix: "ha",
        topics: &t,
        gateway: "gw",
        version: HaVersion::OLDEST,
    };
    let h = hello(1);
    let node = NodeInfo {
        name: "tower-3",
        key: "k",
        hello: &h,
        estimate: false,
        gain: false,
        icing: false,
    };
    assert_eq!(
        d.stale_topics(&node),
        [
            "ha/button/fois_node_k/ack/config",
            "ha/button/fois_node_k/calibrate_dark/config",
            "ha/binary_sensor/fois_gw_tower-3/ice/config",
            "ha/sensor/fois_gw_tower-3/i1/config",
            "ha/sensor/fois_gw_tower-3/i2/config",
            "ha/sensor/fois_gw_tower-3/temperature/config",
            "ha/sensor/fois_gw_tower-3/thickness/config",
        ]
    );
    let t = Topics::new("fois", "gw", Some("c/{node}"));
    let d = Discovery { topics: &t, ..d };
    assert_eq!(d.stale_topics(&node).len(), 5, "commands on: buttons kept");
}

#[test]
fn the_gateway_is_a_connectivity_sensor() {
    let g = Discovery {
        prefix: "homeassistant",
        topics: &Topics::new("fois", "gw", None),
        gateway: "gw",
        version: HaVersion::OLDEST,
    }
    .gateway_config();
    assert_eq!(
        g.0,
        "homeassistant/binary_sensor/fois_gw/connectivity/config"
    );
}

/// The state payload of a frame, as the gateway publishes it.
fn payload(
    state: DetectorState,
    medium: Option<Medium>,
    flag_bits: u16,
    gain: bool,
) -> serde_json::Value {
    let m = Measurement {
        uptime_ms: 1_000,
        i1_na: 28_467,
        i2_na: 10_174,
        ambient1_na: 0,
        ambient2_na: 0,
        temperature_centi_c: 500,
        vdda_mv: 3300,
        flags: flag_bits,
        state,
    };
    let est = medium.map(|medium| IceEstimate {
        thickness_um: 400,
        sigma_um: 60,
        medium,
        probability_permille: 930,
    });
    let g = GainEstimate {
        gain_ppm: 1_020_000,
        sigma_ppm: 40_000,
    };
    let r = Reading::new(&m, est.as_ref(), gain.then_some(&g));
    serde_json::to_value(StateJson::new("tower-3", 5, &r, (120, 2), 0)).unwrap()
}

/// What Home Assistant computes from a message: each entity's value (and
/// attributes), rendered with minijinja (`None`, as Jinja prints it, is "unknown" to Home Assistant).
fn render(config: &Value, message: &serde_json::Value) -> (String, Option<serde_json::Value>) {
    let env = minijinja::Environment::new();
    let ctx = minijinja::context! { value_json => minijinja::Value::from(minijinja::value::Serde(message)) };
    let value = env
        .render_str(config["value_template"].as_str().unwrap(), &ctx)
        .unwrap();
    let attributes = config.get("json_attributes_template").map(|t| {
        serde_json::from_str(&env.render_str(t.as_str().unwrap(), &ctx).unwrap()).unwrap()
    });
    (value, attributes)
}

#[test]
fn every_template_shows_what_the_state_says() {
    let c = configs(HaVersion::OLDEST, false, true, true);
    let show = |object: &str, msg: &serde_json::Value| render(by_object(&c, object), msg);

    // A water film at +5 °C: wet, no ice, a 0.40 mm film, not 0.40 mm of ice.
    let wet = payload(DetectorState::Wet, Some(Medium::Water), 0, false);
    assert_eq!(show("ice", &wet).0, "OFF");
    assert_eq!(show("surface", &wet).0, "wet");
    assert_eq!(show("thickness", &wet).0, "0.0");
    assert_eq!(show("water_film", &wet).0, "0.4");
    assert_eq!(show("thickness_sigma", &wet).0, "0.06");
    assert_eq!(
        show("medium", &wet),
        ("water".into(), Some(json!({"probability": 0.93})))
    );
    assert_eq!(show("temperature", &wet).0, "5.0");
    assert_eq!(show("i1", &wet).0, "28.467");
    assert_eq!(show("frames_received", &wet).0, "120");
    assert_eq!(show("frames_lost", &wet).0, "2");
    assert_eq!(
        show("problem", &wet),
        ("OFF".into(), Some(json!({"faults": []})))
    );
    // No gain sent: unknown, not a template error.
    assert_eq!(show("gain", &wet), ("None".into(), Some(json!({}))));

    // Rime with the alarm acknowledged, an open NTC and a gain estimate.
    let iced = payload(
        DetectorState::Ice,
        Some(Medium::Rime),
        flags::ALARM | flags::ALARM_ACKED | flags::NTC_OPEN,
        true,
    );
    assert_eq!(show("ice", &iced).0, "ON");
    assert_eq!(show("surface", &iced).0, "ice");
    assert_eq!(show("alarm", &iced).0, "ON");
    assert_eq!(show("alarm_acked", &iced).0, "ON");
    assert_eq!(show("thickness", &iced).0, "0.4");
    assert_eq!(show("water_film", &iced).0, "0.0");
    assert_eq!(
        show("problem", &iced),
        ("ON".into(), Some(json!({"faults": ["ntc_open"]})))
    );
    assert_eq!(
        show("gain", &iced),
        ("1.02".into(), Some(json!({"sigma": 0.04})))
    );

    // A protocol-1 node (no estimate): the estimate's entities show unknown.
    let dry = payload(DetectorState::Dry, None, 0, false);
    assert_eq!(show("ice", &dry).0, "OFF");
    assert_eq!(show("alarm", &dry).0, "OFF");
    assert_eq!(show("thickness", &dry).0, "None");
    assert_eq!(show("medium", &dry), ("None".into(), Some(json!({}))));
    // A node without an icing rate: unknown, not a template error.
    assert_eq!(show("icing_rate", &dry), ("None".into(), Some(json!({}))));

    // Rime growing at 2.15 ± 0.6 mm/h, an icing period on.
    let mut r = Reading::new(
        &Measurement {
            uptime_ms: 1_000,
            i1_na: 28_467,
            i2_na: 10_174,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: -500,
            vdda_mv: 3300,
            flags: 0,
            state: DetectorState::Ice,
        },
        None,
        None,
    );
    r.icing = Some(fois_link::reading::IcingReading::from(&IcingEstimate {
        rate_um_per_h: 2_150,
        sigma_um_per_h: 600,
        accreting_permille: 940,
        accreting: true,
    }));
    let growing = serde_json::to_value(StateJson::new("tower-3", 6, &r, (121, 2), 0)).unwrap();
    assert_eq!(
        show("icing_rate", &growing),
        ("2.15".into(), Some(json!({"sigma": 0.6})))
    );
    assert_eq!(
        show("icing_now", &growing),
        ("ON".into(), Some(json!({"probability": 0.94})))
    );
    assert_eq!(show("icing_now", &dry).0, "OFF");
}
