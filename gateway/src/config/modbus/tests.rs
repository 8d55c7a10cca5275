//! `[modbus]` read from whole config files, as the resolver sees it (a
//! file of its own: it reads [`crate::config::file`], which reads
//! [`super`]).

use super::*;
use crate::config::file::{FileConfig, Overrides};

fn resolve(text: &str) -> anyhow::Result<Option<ModbusConfig>> {
    FileConfig::parse(text)?
        .resolve(&Overrides::default())
        .map(|c| c.modbus)
}

const NODES: &str = "[[node]]\nport = \"/a\"\n[[node]]\nport = \"/b\"\nmodbus_unit = 7\n\
                     [[node]]\nport = \"/c\"\n";

#[test]
fn off_by_default_then_loopback_5020_read_only_units_by_position() {
    assert_eq!(resolve(NODES).unwrap(), None);
    let m = resolve(&format!("[modbus]\nenabled = true\n{NODES}"))
        .unwrap()
        .unwrap();
    assert_eq!(m.listen, "127.0.0.1:5020".parse().unwrap());
    assert!(!m.commands);
    assert_eq!(m.stale_after, Duration::from_secs(10));
    assert_eq!(m.max_clients, 64);
    assert_eq!(m.idle_timeout, Duration::from_secs(60));
    assert_eq!(m.frame_timeout, Duration::from_secs(2));
    assert_eq!(m.units, vec![1, 7, 3]);
    assert_eq!(m.node_of_unit(7), Some(1));
    assert_eq!(m.node_of_unit(2), None);
    assert_eq!(
        m.describe(),
        "Modbus TCP on 127.0.0.1:5020 (unit(s) 1,7,3, read-only, stale after 10 s, at most \
         64 clients)"
    );
}

#[test]
fn every_key_is_read() {
    let m = resolve(&format!(
        "[modbus]\nenabled = true\nlisten = \"[::1]:1502\"\ncommands = true\n\
         stale_after_s = 2.5\nmax_clients = 100\n\
         idle_timeout_s = 5\nframe_timeout_s = 0.5\n{NODES}"
    ))
    .unwrap()
    .unwrap();
    assert_eq!(m.listen, "[::1]:1502".parse().unwrap());
    assert!(m.commands);
    assert_eq!(m.stale_after, Duration::from_millis(2500));
    assert_eq!(m.max_clients, 100);
    assert_eq!(m.idle_timeout, Duration::from_secs(5));
    assert_eq!(m.frame_timeout, Duration::from_millis(500));
}

#[test]
fn bad_values_are_refused_with_the_reason() {
    let bad = |text: &str, needle: &str| {
        let err = resolve(text).unwrap_err().to_string();
        assert!(err.contains(needle), "{text:?}: {err}");
    };
    let on = "[modbus]\nenabled = true\n";
    // The section is checked even while it is off.
    bad(
        "[modbus]\nlisten = \"x\"\n[[node]]\nport = \"/a\"\n",
        "not an address",
    );
    bad(
        &format!("{on}listen = \"localhost\"\n{NODES}"),
        "not an address and port",
    );
    bad(&format!("{on}listen = \"127.0.0.1:0\"\n{NODES}"), "port 0");
    bad(&format!("{on}stale_after_s = 0\n{NODES}"), "stale_after_s");
    bad(&format!("{on}max_clients = 0\n{NODES}"), "max_clients");
    bad(
        &format!("{on}idle_timeout_s = 0.5\n{NODES}"),
        "idle_timeout_s",
    );
    bad(
        &format!("{on}frame_timeout_s = 61\n{NODES}"),
        "frame_timeout_s",
    );
    bad(&format!("{on}colour = 1\n{NODES}"), "unknown field");
    // The third node's default unit is 3: taken by the first.
    bad(
        "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 3\n[[node]]\nport = \"/b\"\n\
         [[node]]\nport = \"/c\"\n",
        "nodes 1 and 3 both have Modbus unit 3",
    );
    bad(
        "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 248\n",
        "Modbus unit 248 is outside 1..=247",
    );
    bad(
        "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 0\n",
        "Modbus unit 0 is outside",
    );
}

#[test]
fn the_packaged_example_with_its_modbus_lines_uncommented_is_the_default() {
    let example = include_str!("../../../debian/gateway.toml");
    let mut in_section = false;
    let text: String = example
        .lines()
        .map(|l| {
            if l == "#[modbus]" {
                in_section = true;
            } else if l.is_empty() {
                in_section = false;
            }
            if in_section || l.starts_with("#modbus_unit") {
                format!("{}\n", &l[1..])
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let m = resolve(&text).unwrap().expect("enabled");
    assert_eq!(m.listen, DEFAULT_LISTEN.parse().unwrap());
    assert!(!m.commands);
    assert_eq!(m.stale_after.as_secs_f64(), DEFAULT_STALE_AFTER_S);
    assert_eq!(m.max_clients, DEFAULT_MAX_CLIENTS);
    assert_eq!(m.units, vec![1]);
    // As shipped, commented: off.
    assert_eq!(resolve(example).unwrap(), None);
}
