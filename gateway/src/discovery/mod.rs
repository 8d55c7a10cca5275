//! Home Assistant MQTT discovery: retained config messages under
//! `<ha prefix>/<component>/<node_id>/<object_id>/config` that make every
//! node appear as a device with
//!
//! - `binary_sensor` `ice` (device class `cold`: on = ice on the face, the
//!   detector's state; Home Assistant shows "Cold" / "Normal"),
//! - `sensor` `i1`, `i2` (µA, from the measurement topic), `temperature`
//!   (°C, device class `temperature`),
//! - `sensor` `thickness` (mm, device class `distance`, from the state
//!   topic) once the node sends an ice estimate,
//!
//! and the gateway as a device with a `connectivity` binary sensor. Each
//! node entity is available only while both the gateway and the node are
//! (`availability_mode: all`), so a dead gateway or an unplugged node shows
//! "unavailable", never a stale "Normal".

use fois_protocol::Hello;
use serde_json::{Value, json};

use fois_link::text::{firmware_text, unique_id_hex};

use crate::topics::Topics;

/// The `node_id` of a node's discovery topics (also its device identifier).
pub fn node_id(gateway: &str, node: &str) -> String {
    format!("fois_{gateway}_{node}")
}

/// The gateway's device identifier.
pub fn gateway_id(gateway: &str) -> String {
    format!("fois_{gateway}")
}

fn origin() -> Value {
    json!({
        "name": "fois-gateway",
        "sw_version": env!("CARGO_PKG_VERSION"),
    })
}

/// The gateway's own discovery message: (topic, payload).
pub fn gateway_config(ha_prefix: &str, topics: &Topics, gateway: &str) -> (String, Vec<u8>) {
    let id = gateway_id(gateway);
    let cfg = json!({
        "name": "Connectivity",
        "unique_id": format!("{id}_connectivity"),
        "device_class": "connectivity",
        "state_topic": topics.gateway_availability(),
        "payload_on": "online",
        "payload_off": "offline",
        "entity_category": "diagnostic",
        "device": {
            "identifiers": [id],
            "name": format!("FOIS gateway {gateway}"),
            "manufacturer": "FOIS",
            "model": "fois-gateway",
            "sw_version": env!("CARGO_PKG_VERSION"),
        },
        "origin": origin(),
    });
    (
        format!("{ha_prefix}/binary_sensor/{id}/connectivity/config"),
        cfg.to_string().into_bytes(),
    )
}

/// The discovery messages of one node: (topic, payload) each.
/// `with_thickness`: the node sends an estimate, add the thickness sensor.
pub fn node_configs(
    ha_prefix: &str,
    topics: &Topics,
    gateway: &str,
    node: &str,
    hello: &Hello,
    with_thickness: bool,
) -> Vec<(String, Vec<u8>)> {
    let id = node_id(gateway, node);
    let device = json!({
        "identifiers": [id],
        "name": format!("FOIS {node}"),
        "manufacturer": "FOIS",
        "model": hello.board_name(),
        "sw_version": firmware_text(hello),
        "serial_number": unique_id_hex(hello),
        "via_device": gateway_id(gateway),
    });
    let availability = json!([
        { "topic": topics.gateway_availability() },
        { "topic": topics.availability(node) },
    ]);
    let common = |name: &str, obj: &str| -> serde_json::Map<String, Value> {
        let mut m = serde_json::Map::new();
        m.insert("name".into(), json!(name));
        m.insert("unique_id".into(), json!(format!("{id}_{obj}")));
        m.insert("availability".into(), availability.clone());
        m.insert("availability_mode".into(), json!("all"));
        m.insert("payload_available".into(), json!("online"));
        m.insert("payload_not_available".into(), json!("offline"));
        m.insert("device".into(), device.clone());
        m.insert("origin".into(), origin());
        m
    };
    let mut out = Vec::new();
    let mut push = |component: &str, obj: &str, m: serde_json::Map<String, Value>| {
        out.push((
            format!("{ha_prefix}/{component}/{id}/{obj}/config"),
            Value::Object(m).to_string().into_bytes(),
        ));
    };

    let mut ice = common("Ice", "ice");
    ice.insert("device_class".into(), json!("cold"));
    ice.insert("state_topic".into(), json!(topics.state(node)));
    ice.insert(
        "value_template".into(),
        json!("{{ 'ON' if value_json.ice else 'OFF' }}"),
    );
    ice.insert("payload_on".into(), json!("ON"));
    ice.insert("payload_off".into(), json!("OFF"));
    ice.insert("json_attributes_topic".into(), json!(topics.state(node)));
    push("binary_sensor", "ice", ice);

    for (obj, name, key) in [("i1", "I1", "i1_ua"), ("i2", "I2", "i2_ua")] {
        let mut s = common(name, obj);
        s.insert("state_topic".into(), json!(topics.measurement(node)));
        s.insert(
            "value_template".into(),
            json!(format!("{{{{ value_json.{key} }}}}")),
        );
        // Home Assistant's `current` device class takes A and mA only.
        s.insert("unit_of_measurement".into(), json!("µA"));
        s.insert("state_class".into(), json!("measurement"));
        s.insert("suggested_display_precision".into(), json!(3));
        push("sensor", obj, s);
    }

    let mut t = common("Temperature", "temperature");
    t.insert("device_class".into(), json!("temperature"));
    t.insert("state_topic".into(), json!(topics.measurement(node)));
    t.insert(
        "value_template".into(),
        json!("{{ value_json.temperature_c }}"),
    );
    t.insert("unit_of_measurement".into(), json!("°C"));
    t.insert("state_class".into(), json!("measurement"));
    t.insert("suggested_display_precision".into(), json!(1));
    push("sensor", "temperature", t);

    if with_thickness {
        let mut d = common("Ice thickness", "thickness");
        d.insert("device_class".into(), json!("distance"));
        d.insert("state_topic".into(), json!(topics.state(node)));
        d.insert(
            "value_template".into(),
            json!("{{ value_json.thickness_mm if value_json.thickness_mm is defined else none }}"),
        );
        d.insert("unit_of_measurement".into(), json!("mm"));
        d.insert("state_class".into(), json!("measurement"));
        d.insert("suggested_display_precision".into(), json!(2));
        push("sensor", "thickness", d);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hello() -> Hello {
        Hello {
            protocol_version: 2,
            firmware_version: [0, 3, 1],
            board: Hello::board_from_str("nucleo-f446re"),
            unique_id: [1; 12],
            reset_reason: fois_protocol::ResetReason::PowerOn,
        }
    }

    #[test]
    fn node_configs_carry_what_home_assistant_needs() {
        let t = Topics::new("fois", "gw", None);
        let msgs = node_configs("homeassistant", &t, "gw", "n1", &hello(), false);
        let topics: Vec<&str> = msgs.iter().map(|m| m.0.as_str()).collect();
        assert_eq!(
            topics,
            vec![
                "homeassistant/binary_sensor/fois_gw_n1/ice/config",
                "homeassistant/sensor/fois_gw_n1/i1/config",
                "homeassistant/sensor/fois_gw_n1/i2/config",
                "homeassistant/sensor/fois_gw_n1/temperature/config",
            ]
        );
        let ice: Value = serde_json::from_slice(&msgs[0].1).unwrap();
        assert_eq!(ice["device_class"], "cold");
        assert_eq!(ice["state_topic"], "fois/gw/n1/state");
        assert_eq!(ice["unique_id"], "fois_gw_n1_ice");
        assert_eq!(ice["availability_mode"], "all");
        assert_eq!(ice["availability"][1]["topic"], "fois/gw/n1/availability");
        assert_eq!(ice["device"]["identifiers"][0], "fois_gw_n1");
        assert_eq!(ice["device"]["model"], "nucleo-f446re");
        assert_eq!(ice["device"]["sw_version"], "0.3.1");
        let temp: Value = serde_json::from_slice(&msgs[3].1).unwrap();
        assert_eq!(temp["unit_of_measurement"], "°C");
        assert_eq!(temp["device_class"], "temperature");
        let with = node_configs("ha", &t, "gw", "n1", &hello(), true);
        let thick: Value = serde_json::from_slice(&with[4].1).unwrap();
        assert_eq!(with[4].0, "ha/sensor/fois_gw_n1/thickness/config");
        assert_eq!(thick["unit_of_measurement"], "mm");
        assert_eq!(thick["device_class"], "distance");
    }
}
