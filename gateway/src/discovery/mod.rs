//! Home Assistant MQTT discovery: retained config messages under
//! `<ha prefix>/<component>/<node_id>/<object_id>/config` that make every
//! node a device under the gateway's device (`via_device`), with the
//! entities of [`entities`] reading the node's retained state topic, and
//! the gateway a device with a `connectivity` binary sensor.
//!
//! - Ids come from the node's hardware id (`Hello::unique_id`), not its
//!   configured name: the device `fois_node_<id hex>`, each entity
//!   `fois_node_<id hex>_<object>`, so renaming a node in the config keeps
//!   its entities and their history (the device's name follows the config).
//! - Each node entity is available only while both the gateway and the
//!   node are (`availability_mode: all`): a dead gateway or an unplugged
//!   node shows "unavailable", never a stale "Normal".
//! - The messages fit the oldest Home Assistant release configured
//!   ([`HaVersion`]): newer keys only when it takes them.
//! - Stale configs are deleted (an empty retained message) once per node
//!   and run: the buttons when commands are off, and the configs of
//!   gateway versions that named entities after the node's name.
//!
//! Checked by a real Home Assistant: `cargo xtask ha-check` (gateway
//! README, "Home Assistant").

pub mod entities;
pub mod version;

use fois_protocol::Hello;
use serde_json::{Map, Value, json};

use fois_link::text::{firmware_text, unique_id_hex};

use crate::topics::Topics;
use entities::{Entity, Source};
pub use version::HaVersion;

/// A node's device identifier and the `node_id` level of its discovery
/// topics: from its key ([`crate::snapshot::key_of`]).
pub fn node_id(key: &str) -> String {
    format!("fois_node_{key}")
}

/// The gateway's device identifier.
pub fn gateway_id(gateway: &str) -> String {
    format!("fois_{gateway}")
}

/// What one gateway announces, and for which Home Assistant.
#[derive(Debug, Clone, Copy)]
pub struct Discovery<'a> {
    /// The discovery prefix (`homeassistant`).
    pub prefix: &'a str,
    /// The gateway's topics.
    pub topics: &'a Topics,
    /// The gateway's name.
    pub gateway: &'a str,
    /// The oldest Home Assistant release to satisfy.
    pub version: HaVersion,
}

/// One node as discovery sees it.
#[derive(Debug, Clone, Copy)]
pub struct NodeInfo<'a> {
    /// Its name in topics (the config's, or its unique id).
    pub name: &'a str,
    /// Its key ([`crate::snapshot::key_of`]).
    pub key: &'a str,
    /// Its `Hello`.
    pub hello: &'a Hello,
    /// It has sent an ice estimate: the thickness, water film, σ and medium
    /// entities.
    pub estimate: bool,
    /// It has sent an optical gain estimate: the gain entity.
    pub gain: bool,
    /// It has sent an icing rate (protocol 5): the icing-rate and
    /// icing-now entities.
    pub icing: bool,
}

fn origin() -> Value {
    json!({
        "name": "fois-gateway",
        "sw_version": env!("CARGO_PKG_VERSION"),
    })
}

impl Discovery<'_> {
    fn topic(&self, component: &str, node_id: &str, object: &str) -> String {
        format!("{}/{component}/{node_id}/{object}/config", self.prefix)
    }

    /// The gateway's own discovery message: (topic, payload).
    pub fn gateway_config(&self) -> (String, Vec<u8>) {
        let id = gateway_id(self.gateway);
        let cfg = json!({
            "name": "Connectivity",
            "unique_id": format!("{id}_connectivity"),
            "device_class": "connectivity",
            "state_topic": self.topics.gateway_availability(),
            "payload_on": "online",
            "payload_off": "offline",
            "entity_category": "diagnostic",
            "device": {
                "identifiers": [id],
                "name": format!("FOIS gateway {}", self.gateway),
                "manufacturer": "FOIS",
                "model": "fois-gateway",
                "sw_version": env!("CARGO_PKG_VERSION"),
            },
            "origin": origin(),
        });
        (
            self.topic("binary_sensor", &id, "connectivity"),
            cfg.to_string().into_bytes(),
        )
    }

    fn device(&self, node: &NodeInfo) -> Value {
        let mut d = json!({
            "identifiers": [node_id(node.key)],
            "name": format!("FOIS {}", node.name),
            "manufacturer": "FOIS",
            "model": node.hello.board_name(),
            "sw_version": firmware_text(node.hello),
            "via_device": gateway_id(self.gateway),
        });
        if self.version.serial_number() {
            d["serial_number"] = json!(unique_id_hex(node.hello));
        }
        d
    }

    /// The entities a node has now (its estimate and gain as sent so far,
    /// the buttons when commands are on).
    fn wanted(&self, node: &NodeInfo) -> impl Iterator<Item = &'static Entity> {
        let commands = self.topics.command(node.name).is_some();
        let (estimate, gain, icing) = (node.estimate, node.gain, node.icing);
        entities::NODE.iter().filter(move |e| match e.needs {
            entities::Needs::Always => true,
            entities::Needs::Estimate => estimate,
            entities::Needs::Gain => gain,
            entities::Needs::Icing => icing,
            entities::Needs::Commands => commands,
        })
    }

    /// The discovery messages of one node: (topic, payload) each.
    pub fn node_configs(&self, node: &NodeInfo) -> Vec<(String, Vec<u8>)> {
        let id = node_id(node.key);
        let device = self.device(node);
        let availability = json!([
            { "topic": self.topics.gateway_availability() },
            { "topic": self.topics.availability(node.name) },
        ]);
        let state = self.topics.state(node.name);
        self.wanted(node)
            .map(|e| {
                let mut m = Map::new();
                m.insert("name".into(), json!(e.name));
                m.insert("unique_id".into(), json!(format!("{id}_{}", e.object)));
                m.insert("availability".into(), availability.clone());
                m.insert("availability_mode".into(), json!("all"));
                m.insert("payload_available".into(), json!("online"));
                m.insert("payload_not_available".into(), json!("offline"));
                m.insert("device".into(), device.clone());
                m.insert("origin".into(), origin());
                if let Some(c) = e.category {
                    m.insert("entity_category".into(), json!(c));
                }
                if let Some(c) = e.device_class {
                    m.insert("device_class".into(), json!(c));
                }
                match e.source {
                    Source::Flag(key) => {
                        m.insert("state_topic".into(), json!(state));
                        m.insert(
                            "value_template".into(),
                            json!(format!("{{{{ 'ON' if value_json.{key} else 'OFF' }}}}")),
                        );
                        m.insert("payload_on".into(), json!("ON"));
                        m.insert("payload_off".into(), json!("OFF"));
                    }
                    Source::Any(key) => {
                        m.insert("state_topic".into(), json!(state));
                        m.insert(
                            "value_template".into(),
                            json!(format!(
                                "{{{{ 'ON' if value_json.{key} | length > 0 else 'OFF' }}}}"
                            )),
                        );
                        m.insert("payload_on".into(), json!("ON"));
                        m.insert("payload_off".into(), json!("OFF"));
                    }
                    Source::Value(key) => {
                        m.insert("state_topic".into(), json!(state));
                        m.insert("value_template".into(), json!(defined(key)));
                    }
                    Source::Press(payload) => {
                        if let Some(t) = self.topics.command(node.name) {
                            m.insert("command_topic".into(), json!(t));
                        }
                        m.insert("payload_press".into(), json!(payload));
                        m.insert("retain".into(), json!(false));
                    }
                }
                if let Some(u) = e.unit {
                    m.insert("unit_of_measurement".into(), json!(u));
                }
                if let Some(c) = e.state_class {
                    m.insert("state_class".into(), json!(c));
                }
                if let Some(p) = e.precision {
                    m.insert("suggested_display_precision".into(), json!(p));
                }
                if !e.options.is_empty() && self.version.enum_options() {
                    m.insert("options".into(), json!(e.options));
                }
                if !e.attributes.is_empty() {
                    m.insert("json_attributes_topic".into(), json!(state));
                    m.insert(
                        "json_attributes_template".into(),
                        json!(attributes_template(e.attributes)),
                    );
                }
                (
                    self.topic(e.component, &id, e.object),
                    Value::Object(m).to_string().into_bytes(),
                )
            })
            .collect()
    }

    /// Discovery topics to empty (retained) once per node and run: the
    /// node's entities it does not have now that never come back by
    /// themselves (the buttons with commands off), and the configs of
    /// gateway versions that named everything after the node's name.
    pub fn stale_topics(&self, node: &NodeInfo) -> Vec<String> {
        let id = node_id(node.key);
        let wanted: Vec<&str> = self.wanted(node).map(|e| e.object).collect();
        let mut out: Vec<String> = entities::NODE
            .iter()
            .filter(|e| e.needs == entities::Needs::Commands && !wanted.contains(&e.object))
            .map(|e| self.topic(e.component, &id, e.object))
            .collect();
        let old = format!("fois_{}_{}", self.gateway, node.name);
        for (component, object) in entities::BY_NAME_BEFORE {
            out.push(self.topic(component, &old, object));
        }
        out
    }
}

/// `{{ value_json.KEY if value_json.KEY is defined else none }}`: a key the
/// node has not sent yet shows "unknown", not a template error.
fn defined(key: &str) -> String {
    format!("{{{{ value_json.{key} if value_json.{key} is defined else none }}}}")
}

/// The attributes `(name, state key)` of an entity, as a template that
/// renders a JSON object (`{}` until the first key is sent).
fn attributes_template(attributes: &[(&str, &str)]) -> String {
    let pairs: Vec<String> = attributes
        .iter()
        .map(|(name, key)| format!("'{name}': value_json.{key}"))
        .collect();
    format!(
        "{{{{ {{{}}} | tojson if value_json.{} is defined else '{{}}' }}}}",
        pairs.join(", "),
        attributes[0].1
    )
}

#[cfg(test)]
mod tests;
