//! What a user of the check's Home Assistant sees: the `fois_probe`
//! integration's snapshots (states, registries, state changes, recorder
//! rows, log), a node's device and entities in them, and the readable
//! table the check prints.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde_json::Value;

/// One probe snapshot: what a user of this Home Assistant sees.
#[derive(Debug, Clone)]
pub struct Snapshot(pub Value);

impl Snapshot {
    /// The running release, e.g. `2024.3.3`.
    pub fn version(&self) -> &str {
        self.0["version"].as_str().unwrap_or("?")
    }

    /// The MQTT config entry is set up (connected to the broker).
    pub fn mqtt_loaded(&self) -> bool {
        self.0["config_entries"].as_array().is_some_and(|a| {
            a.iter()
                .any(|e| e["domain"] == "mqtt" && e["state"] == "loaded")
        })
    }

    /// Every device.
    pub fn devices(&self) -> Vec<&Value> {
        self.0["devices"]
            .as_array()
            .map(|a| a.iter().collect())
            .unwrap_or_default()
    }

    /// The device named `name`.
    pub fn device(&self, name: &str) -> Option<&Value> {
        self.devices().into_iter().find(|d| d["name"] == name)
    }

    /// The registry entries of a device's entities.
    pub fn entities_of(&self, device_id: &str) -> Vec<&Value> {
        self.0["entities"]
            .as_array()
            .map(|a| a.iter().filter(|e| e["device_id"] == device_id).collect())
            .unwrap_or_default()
    }

    /// The registry entry with this unique id.
    pub fn entity(&self, unique_id: &str) -> Option<&Value> {
        self.0["entities"]
            .as_array()?
            .iter()
            .find(|e| e["unique_id"] == unique_id)
    }

    /// The state object of an entity id.
    pub fn state_of(&self, entity_id: &str) -> Option<&Value> {
        self.0["states"]
            .as_array()?
            .iter()
            .find(|s| s["entity_id"] == entity_id)
    }

    /// The state (text) of the entity with this unique id.
    pub fn state(&self, unique_id: &str) -> Option<&str> {
        let e = self.entity(unique_id)?;
        self.state_of(e["entity_id"].as_str()?)?["state"].as_str()
    }

    /// State changes of an entity since Home Assistant started.
    pub fn changes(&self, entity_id: &str) -> u64 {
        self.0["state_changes"][entity_id].as_u64().unwrap_or(0)
    }

    /// Rows of an entity in the recorder's `states` table.
    pub fn rows(&self, entity_id: &str) -> u64 {
        self.0["recorder_rows"][entity_id].as_u64().unwrap_or(0)
    }

    /// Warnings and errors logged, as `LEVEL logger: message` and the
    /// exception's traceback if any (level `PROBE`: the probe's own).
    pub fn log(&self) -> Vec<String> {
        self.0["log"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|l| {
                        let exc = l["exc"].as_str().unwrap_or("");
                        format!(
                            "{} {}: {}{}{}",
                            l["level"].as_str().unwrap_or(""),
                            l["logger"].as_str().unwrap_or(""),
                            l["message"].as_str().unwrap_or(""),
                            if exc.is_empty() { "" } else { "\n" },
                            exc
                        )
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Every state, one a line (for failure messages).
    pub fn states_text(&self) -> String {
        self.0["states"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|s| {
                        format!(
                            "  {} = {}",
                            s["entity_id"].as_str().unwrap_or(""),
                            s["state"]
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            })
            .unwrap_or_default()
    }
}

/// A node as Home Assistant shows it.
pub struct Device {
    /// Its id in the device registry.
    pub id: String,
    /// `fois_node_<hardware id>`.
    pub ident: String,
}

impl Device {
    /// The device `FOIS <name>`.
    pub fn of(s: &Snapshot, name: &str) -> Option<Device> {
        let d = s.device(&format!("FOIS {name}"))?;
        let ident = d["identifiers"][0][1].as_str()?.to_string();
        Some(Device {
            id: d["id"].as_str()?.to_string(),
            ident,
        })
    }

    /// The unique id of its entity `object`.
    pub fn uid(&self, object: &str) -> String {
        format!("{}_{object}", self.ident)
    }
}

/// The entity id of a device's entity `object`.
pub fn entity_id(s: &Snapshot, d: &Device, object: &str) -> String {
    s.entity(&d.uid(object))
        .and_then(|e| e["entity_id"].as_str())
        .unwrap_or_else(|| panic!("no entity {}", d.uid(object)))
        .to_string()
}

/// The state changes of every entity of a device.
pub fn changes(s: &Snapshot, d: &Device) -> BTreeMap<String, (u64, u64)> {
    s.entities_of(&d.id)
        .iter()
        .map(|e| {
            let id = e["entity_id"].as_str().unwrap();
            (id.to_string(), (s.changes(id), s.rows(id)))
        })
        .collect()
}

/// A table of a device's entities as a user sees them.
pub fn table(s: &Snapshot, d: &Device, out: &mut String) {
    let mut rows: Vec<(String, String)> = s
        .entities_of(&d.id)
        .iter()
        .map(|e| {
            let id = e["entity_id"].as_str().unwrap();
            let st = s.state_of(id).cloned().unwrap_or(Value::Null);
            let attrs = &st["attributes"];
            let mut extra = Vec::new();
            for key in ["unit_of_measurement", "device_class", "state_class"] {
                if let Some(v) = attrs[key].as_str() {
                    extra.push(v.to_string());
                }
            }
            if let Some(c) = e["entity_category"].as_str() {
                extra.push(c.to_string());
            }
            for key in ["faults", "probability", "sigma"] {
                if !attrs[key].is_null() {
                    extra.push(format!("{key}={}", attrs[key]));
                }
            }
            (
                id.to_string(),
                format!(
                    "    {:<48} {:<12} {}",
                    id,
                    st["state"].as_str().unwrap_or("-"),
                    extra.join(", ")
                )
                .trim_end()
                .to_string(),
            )
        })
        .collect();
    rows.sort();
    for (_, r) in rows {
        let _ = writeln!(out, "{r}");
    }
}

/// What Home Assistant logged: (what concerns the gateway's messages —
/// anything from MQTT or the templates, anything naming FOIS but the note
/// that the probe is a custom integration, an error whose traceback passes
/// through MQTT or the templates, the probe's own failures —, Home
/// Assistant's other errors).
pub fn log_problems(s: &Snapshot) -> (Vec<String>, Vec<String>) {
    let ours = |l: &str| {
        l.starts_with("PROBE")
            || [
                "components.mqtt",
                "components/mqtt",
                "helpers.template",
                "helpers/template",
            ]
            .iter()
            .any(|k| l.contains(k))
            || l.contains("fois")
                && !l.contains("custom integration fois_probe which has not been tested")
    };
    let mut mine = Vec::new();
    let mut other = Vec::new();
    for l in s.log() {
        if ours(&l) {
            mine.push(l);
        } else if l.starts_with("ERROR") {
            other.push(l);
        }
    }
    (mine, other)
}
