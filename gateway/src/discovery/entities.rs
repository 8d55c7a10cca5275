//! The entities of a node in Home Assistant: one table, read by the
//! discovery messages ([`super::Discovery::node_configs`]), their tests,
//! and documented in the gateway README ("Home Assistant").
//!
//! Every entity reads the node's retained state topic (`<node>/state`),
//! whose continuous values are deadbanded ([`crate::state_filter`]), so a
//! quiet node writes nothing into Home Assistant's database. Entity names
//! follow the device's ("FOIS tower-3 Ice").

/// When a node has an entity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    /// Always.
    Always,
    /// Once the node has sent an ice estimate (protocol 2 and later).
    Estimate,
    /// Once the node has sent an optical gain estimate (protocol 3).
    Gain,
    /// Once the node has sent an icing rate (protocol 5).
    Icing,
    /// While MQTT commands are enabled in the config.
    Commands,
}

/// Where an entity's value comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// A boolean key of the state: `ON` when true.
    Flag(&'static str),
    /// A list key of the state: `ON` when it is not empty.
    Any(&'static str),
    /// A key of the state, as it is.
    Value(&'static str),
    /// A button: publishes this word on the node's command topic.
    Press(&'static str),
}

/// One entity of a node.
#[derive(Debug, Clone, Copy)]
pub struct Entity {
    /// Home Assistant component: `binary_sensor`, `sensor`, `button`.
    pub component: &'static str,
    /// Object id: the last part of the unique id and of the topic.
    pub object: &'static str,
    /// Its name, after the device's.
    pub name: &'static str,
    /// What it shows.
    pub source: Source,
    /// Home Assistant device class.
    pub device_class: Option<&'static str>,
    /// Unit.
    pub unit: Option<&'static str>,
    /// `measurement`, `total_increasing`.
    pub state_class: Option<&'static str>,
    /// `diagnostic` or `config` (None: a primary entity).
    pub category: Option<&'static str>,
    /// Decimals shown.
    pub precision: Option<u8>,
    /// An enum sensor's states (sent to releases that take them).
    pub options: &'static [&'static str],
    /// Attributes: (name, key of the state).
    pub attributes: &'static [(&'static str, &'static str)],
    /// When the node has it.
    pub needs: Needs,
}

const fn entity(
    component: &'static str,
    object: &'static str,
    name: &'static str,
    source: Source,
) -> Entity {
    Entity {
        component,
        object,
        name,
        source,
        device_class: None,
        unit: None,
        state_class: None,
        category: None,
        precision: None,
        options: &[],
        attributes: &[],
        needs: Needs::Always,
    }
}

const fn measured(
    object: &'static str,
    name: &'static str,
    key: &'static str,
    unit: &'static str,
    precision: u8,
) -> Entity {
    Entity {
        unit: Some(unit),
        state_class: Some("measurement"),
        precision: Some(precision),
        ..entity("sensor", object, name, Source::Value(key))
    }
}

const fn distance(object: &'static str, name: &'static str, key: &'static str) -> Entity {
    Entity {
        device_class: Some("distance"),
        needs: Needs::Estimate,
        ..measured(object, name, key, "mm", 2)
    }
}

const fn diagnostic(e: Entity) -> Entity {
    Entity {
        category: Some("diagnostic"),
        ..e
    }
}

const fn counter(object: &'static str, name: &'static str, key: &'static str) -> Entity {
    Entity {
        state_class: Some("total_increasing"),
        category: Some("diagnostic"),
        ..entity("sensor", object, name, Source::Value(key))
    }
}

/// Every entity a node can have, in the order they are announced.
pub const NODE: [Entity; 19] = [
    // What a user watches.
    Entity {
        device_class: Some("cold"),
        ..entity("binary_sensor", "ice", "Ice", Source::Flag("ice"))
    },
    Entity {
        device_class: Some("enum"),
        options: &["dry", "wet", "ice"],
        ..entity("sensor", "surface", "Surface", Source::Value("state"))
    },
    Entity {
        device_class: Some("safety"),
        ..entity("binary_sensor", "alarm", "Ice alarm", Source::Flag("alarm"))
    },
    entity(
        "binary_sensor",
        "alarm_acked",
        "Alarm acknowledged",
        Source::Flag("alarm_acked"),
    ),
    Entity {
        device_class: Some("temperature"),
        ..measured("temperature", "Temperature", "temperature_c", "°C", 1)
    },
    distance("thickness", "Ice thickness", "ice_thickness_mm"),
    distance("water_film", "Water film", "water_film_mm"),
    diagnostic(distance(
        "thickness_sigma",
        "Thickness σ",
        "thickness_sigma_mm",
    )),
    Entity {
        device_class: Some("enum"),
        options: &["dry", "water", "glazed", "rime"],
        attributes: &[("probability", "medium_probability")],
        needs: Needs::Estimate,
        ..entity("sensor", "medium", "Medium", Source::Value("medium"))
    },
    // Meteorological icing (ice accreting now) beside the ice above
    // (instrumental icing: ice present).
    Entity {
        attributes: &[("sigma", "rate_sigma_mm_per_h")],
        needs: Needs::Icing,
        ..measured("icing_rate", "Icing rate", "rate_mm_per_h", "mm/h", 2)
    },
    Entity {
        device_class: Some("cold"),
        attributes: &[("probability", "accreting_probability")],
        needs: Needs::Icing,
        ..entity(
            "binary_sensor",
            "icing_now",
            "Icing now",
            Source::Flag("accreting"),
        )
    },
    // The node's health and its raw values.
    Entity {
        device_class: Some("problem"),
        category: Some("diagnostic"),
        attributes: &[("faults", "faults")],
        ..entity("binary_sensor", "problem", "Problem", Source::Any("faults"))
    },
    // Home Assistant's `current` device class takes A and mA only.
    diagnostic(measured("i1", "I1", "i1_ua", "µA", 2)),
    diagnostic(measured("i2", "I2", "i2_ua", "µA", 2)),
    Entity {
        state_class: Some("measurement"),
        category: Some("diagnostic"),
        precision: Some(3),
        attributes: &[("sigma", "gain_sigma")],
        needs: Needs::Gain,
        ..entity("sensor", "gain", "Optical gain", Source::Value("gain"))
    },
    counter("frames_received", "Frames received", "frames_received"),
    counter("frames_lost", "Frames lost", "frames_lost"),
    // Commands, when the config enables them.
    Entity {
        needs: Needs::Commands,
        ..entity("button", "ack", "Acknowledge alarm", Source::Press("ack"))
    },
    Entity {
        category: Some("config"),
        needs: Needs::Commands,
        ..entity(
            "button",
            "calibrate_dark",
            "Dark calibration",
            Source::Press("calibrate-dark"),
        )
    },
];

/// The (component, object) of every node entity of gateway versions that
/// named node entities after the node's name (`fois_<gw>_<node>`): their
/// configs are emptied so the old entities do not stay beside the new ones.
pub const BY_NAME_BEFORE: [(&str, &str); 5] = [
    ("binary_sensor", "ice"),
    ("sensor", "i1"),
    ("sensor", "i2"),
    ("sensor", "temperature"),
    ("sensor", "thickness"),
];
