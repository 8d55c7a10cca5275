//! [`FileConfig::resolve`]: the flags over the file over the defaults,
//! one section at a time, each checked before anything is opened.

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::discovery::HaVersion;

use super::file::{
    BrokerFile, CommandsFile, FileConfig, HomeAssistantFile, NodeFile, Overrides, PublishFile,
    QueueFile,
};
use super::located::KeyError;
use super::{
    BrokerConfig, DEFAULT_COMMAND_MIN_INTERVAL_MS, DEFAULT_QUEUE_MAX_BYTES, GatewayConfig,
    MAX_INTERVAL_MS, MIN_QUEUE_MAX_BYTES, NodeSpec, Secret, TlsConfig, check_name, check_topic,
    is_valid_name,
};

/// This machine's host name, as a valid gateway name (`gateway` if none).
pub fn default_gateway_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_default();
    let s: String = raw
        .trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .take(64)
        .collect();
    if is_valid_name(&s) {
        s
    } else {
        "gateway".into()
    }
}

fn default_queue_dir(name: &str) -> PathBuf {
    let base = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state")))
        .unwrap_or_else(|| PathBuf::from("."));
    base.join("fois").join(format!("gateway-{name}"))
}

fn read_password_file(p: &Path) -> anyhow::Result<Secret> {
    let text = std::fs::read_to_string(p)
        .map_err(|e| anyhow::anyhow!("cannot read the password file {}: {e}", p.display()))?;
    let line = text.lines().next().unwrap_or("").trim_end_matches('\r');
    if line.is_empty() {
        anyhow::bail!("the password file {} is empty", p.display());
    }
    Ok(Secret::new(line))
}

/// `[publish]`, resolved.
struct Publish {
    measurement_interval_ms: u64,
    offline_measurement_interval_ms: u64,
    state_interval_ms: u64,
    silence_timeout: Duration,
}

/// `[commands]`, resolved: the topic template (None: off) and the spacing.
struct Commands {
    topic: Option<String>,
    min_interval: Duration,
}

impl FileConfig {
    /// Apply the flags, fill in defaults, check everything; an error of a
    /// value from the file names its line and key.
    pub fn resolve(mut self, o: &Overrides) -> anyhow::Result<GatewayConfig> {
        let source = self.source.take();
        self.resolve_values(o)
            .map_err(|e| super::located::at_key(source.as_ref().map(|s| s.0.as_str()), e))
    }

    fn resolve_values(self, o: &Overrides) -> anyhow::Result<GatewayConfig> {
        let name = o
            .name
            .clone()
            .or(self.name)
            .unwrap_or_else(default_gateway_name);
        check_name("gateway name", &name)?;
        let topic_prefix = self.topic_prefix.unwrap_or_else(|| "fois".into());
        check_topic("topic_prefix", &topic_prefix)?;
        let broker = resolve_broker(self.broker, o, &name)?;
        let publish = resolve_publish(self.publish, o)?;
        let (queue_dir, queue_max_bytes) = resolve_queue(self.queue, o, &name)?;
        let (homeassistant_prefix, homeassistant_version) =
            resolve_homeassistant(self.homeassistant, o)?;
        let commands = resolve_commands(self.commands, &topic_prefix, &name)?;
        // The file's nodes first, then the flags' (which have no unit).
        let mut units: Vec<Option<u8>> = self.nodes.iter().map(|n| n.modbus_unit).collect();
        let nodes = resolve_nodes(self.nodes, o)?;
        units.resize(nodes.len(), None);
        let modbus = super::modbus::resolve_modbus(self.modbus, &units)?;
        if let Some(m) = &modbus
            && same_socket(m.listen, &broker.host, broker.port)
        {
            return Err(KeyError::at(
                "modbus.listen",
                format!(
                    "[modbus] listen {} is the broker's own address and port ({}:{}): give \
                     Modbus another port (e.g. 5020)",
                    m.listen, broker.host, broker.port
                ),
            ));
        }
        let log = super::log::resolve_log(self.log)?;
        let firmware = super::firmware::resolve_firmware(self.firmware, commands.topic.is_some())?;
        Ok(GatewayConfig {
            name,
            topic_prefix,
            broker,
            measurement_interval_ms: publish.measurement_interval_ms,
            offline_measurement_interval_ms: publish.offline_measurement_interval_ms,
            state_interval_ms: publish.state_interval_ms,
            silence_timeout: publish.silence_timeout,
            queue_dir,
            queue_max_bytes,
            homeassistant_prefix,
            homeassistant_version,
            command_topic: commands.topic,
            command_min_interval: commands.min_interval,
            nodes,
            modbus,
            log,
            firmware,
        })
    }
}

/// The Modbus server listening on `listen` would take the socket of a
/// broker on this machine at `host`:`port` (the same port, and the broker
/// on loopback, on the listening address, or Modbus on every address and
/// the broker on this machine's name).
fn same_socket(listen: std::net::SocketAddr, host: &str, port: u16) -> bool {
    if listen.port() != port {
        return false;
    }
    let host = host.trim_start_matches('[').trim_end_matches(']');
    match host.parse::<std::net::IpAddr>() {
        Ok(ip) => {
            ip.is_loopback()
                || ip.is_unspecified()
                || ip == listen.ip()
                || listen.ip().is_unspecified() && local_ip(ip)
        }
        Err(_) => {
            host.eq_ignore_ascii_case("localhost")
                || listen.ip().is_unspecified() && host_is_this_machine(host)
        }
    }
}

/// `ip` is an address of this machine (a socket binds to it).
fn local_ip(ip: std::net::IpAddr) -> bool {
    std::net::UdpSocket::bind((ip, 0)).is_ok()
}

/// `host` names this machine (resolves to one of its addresses).
fn host_is_this_machine(host: &str) -> bool {
    use std::net::ToSocketAddrs;
    (host, 0)
        .to_socket_addrs()
        .is_ok_and(|mut a| a.any(|a| a.ip().is_loopback() || local_ip(a.ip())))
}

/// `[broker]` and `[broker.tls]` with `--broker`, `--username`,
/// `--password-file`, `--ca-file`, `--client-cert`, `--client-key`.
fn resolve_broker(b: BrokerFile, o: &Overrides, name: &str) -> anyhow::Result<BrokerConfig> {
    let (mut host, mut port) = (b.host.unwrap_or_else(|| "127.0.0.1".into()), b.port);
    if let Some(addr) = &o.broker {
        host = addr.host.clone();
        port = addr.port.or(port);
    }
    if host.is_empty() {
        anyhow::bail!("the broker host is empty");
    }
    let tls_file = b.tls.unwrap_or_default();
    let ca = o.ca_file.clone().or(tls_file.ca_file);
    let cert = o.client_cert_file.clone().or(tls_file.client_cert_file);
    let key = o.client_key_file.clone().or(tls_file.client_key_file);
    let tls = match (ca, cert, key) {
        (None, None, None) => None,
        (None, _, _) => anyhow::bail!("a client certificate needs the broker's CA: ca_file"),
        (Some(ca), None, None) => Some(TlsConfig {
            ca_file: ca,
            client_auth: None,
        }),
        (Some(ca), Some(c), Some(k)) => Some(TlsConfig {
            ca_file: ca,
            client_auth: Some((c, k)),
        }),
        _ => anyhow::bail!("client_cert_file and client_key_file go together"),
    };
    let port = port.unwrap_or(if tls.is_some() { 8883 } else { 1883 });
    if port == 0 {
        anyhow::bail!("broker port 0 is not a port");
    }
    let username = o.username.clone().or(b.username);
    let password = match (&o.password_file, b.password_file, b.password) {
        (Some(f), _, _) => Some(read_password_file(f)?),
        (None, Some(f), _) => Some(read_password_file(&f)?),
        (None, None, p) => p,
    };
    if password.is_some() && username.is_none() {
        anyhow::bail!("a broker password needs a username");
    }
    let keep_alive_s = b.keep_alive_s.unwrap_or(5);
    if !(1..=3600).contains(&keep_alive_s) {
        anyhow::bail!("keep_alive_s must be within 1..=3600");
    }
    let client_id = b
        .client_id
        .unwrap_or_else(|| format!("fois-gateway-{name}"));
    if client_id.is_empty() || client_id.len() > 64 {
        anyhow::bail!("client_id must be 1 to 64 characters");
    }
    Ok(BrokerConfig {
        host,
        port,
        client_id,
        username,
        password,
        keep_alive: Duration::from_secs(keep_alive_s),
        tls,
    })
}

/// `[publish]` with the interval flags.
fn resolve_publish(p: PublishFile, o: &Overrides) -> anyhow::Result<Publish> {
    let measurement_interval_ms = o
        .measurement_interval_ms
        .or(p.measurement_interval_ms)
        .unwrap_or(1000);
    let offline_measurement_interval_ms = o
        .offline_measurement_interval_ms
        .or(p.offline_measurement_interval_ms)
        .unwrap_or(10_000);
    let state_interval_ms = p.state_interval_ms.unwrap_or(5000);
    let silence_ms = p
        .silence_timeout_ms
        .unwrap_or(fois_protocol::REPLY_TIMEOUT_MS);
    if !(500..=600_000).contains(&silence_ms) {
        anyhow::bail!("silence_timeout_ms must be within 500..=600000");
    }
    for (what, v) in [
        ("measurement_interval_ms", measurement_interval_ms),
        (
            "offline_measurement_interval_ms",
            offline_measurement_interval_ms,
        ),
        ("state_interval_ms", state_interval_ms),
    ] {
        if v > MAX_INTERVAL_MS {
            anyhow::bail!("{what} must be at most one day ({MAX_INTERVAL_MS})");
        }
    }
    Ok(Publish {
        measurement_interval_ms,
        offline_measurement_interval_ms,
        state_interval_ms,
        silence_timeout: Duration::from_millis(silence_ms),
    })
}

/// `[queue]` with `--queue-dir` and `--queue-max-bytes`: (dir, bound).
fn resolve_queue(q: QueueFile, o: &Overrides, name: &str) -> anyhow::Result<(PathBuf, u64)> {
    let max_bytes = o
        .queue_max_bytes
        .or(q.max_bytes)
        .unwrap_or(DEFAULT_QUEUE_MAX_BYTES);
    if max_bytes < MIN_QUEUE_MAX_BYTES {
        anyhow::bail!("queue max_bytes must be at least {MIN_QUEUE_MAX_BYTES}");
    }
    let dir = o
        .queue_dir
        .clone()
        .or(q.dir)
        .unwrap_or_else(|| default_queue_dir(name));
    Ok((dir, max_bytes))
}

/// `[homeassistant]` with `--no-homeassistant`: the discovery prefix, or
/// `None` when discovery is off; the release the messages suit.
fn resolve_homeassistant(
    h: HomeAssistantFile,
    o: &Overrides,
) -> anyhow::Result<(Option<String>, HaVersion)> {
    let version = match &h.version {
        Some(v) => {
            HaVersion::parse(v).map_err(|e| anyhow::anyhow!("[homeassistant] version: {e}"))?
        }
        None => HaVersion::OLDEST,
    };
    if o.no_homeassistant || h.enabled == Some(false) {
        return Ok((None, version));
    }
    let p = h.prefix.unwrap_or_else(|| "homeassistant".into());
    check_topic("homeassistant prefix", &p)?;
    Ok((Some(p), version))
}

/// `[commands]` (no flag turns commands on).
fn resolve_commands(c: CommandsFile, topic_prefix: &str, name: &str) -> anyhow::Result<Commands> {
    let min_interval_ms = c.min_interval_ms.unwrap_or(DEFAULT_COMMAND_MIN_INTERVAL_MS);
    if min_interval_ms > MAX_INTERVAL_MS {
        return Err(KeyError::at(
            "commands.min_interval_ms",
            format!("[commands] min_interval_ms must be at most one day ({MAX_INTERVAL_MS})"),
        ));
    }
    let topic = if c.enabled.unwrap_or(false) {
        let t = c
            .topic
            .unwrap_or_else(|| format!("{topic_prefix}/{name}/{{node}}/command"));
        check_topic("commands topic", &t)?;
        if t.matches("{node}").count() != 1 {
            anyhow::bail!("the commands topic `{t}` must contain `{{node}}` exactly once");
        }
        Some(t)
    } else {
        if c.topic.is_some() {
            anyhow::bail!(
                "[commands] topic is set but commands are not enabled: add `enabled = true` \
                 or remove the topic"
            );
        }
        None
    };
    Ok(Commands {
        topic,
        min_interval: Duration::from_millis(min_interval_ms),
    })
}

/// The file's `[[node]]` tables, then the `--node` flags: at least one,
/// no port or name twice.
fn resolve_nodes(file: Vec<NodeFile>, o: &Overrides) -> anyhow::Result<Vec<NodeSpec>> {
    let mut nodes: Vec<NodeSpec> = file
        .into_iter()
        .map(|n| NodeSpec {
            port: n.port,
            name: n.name,
            baud: n.baud.unwrap_or(fois_protocol::BAUD_RATE),
        })
        .collect();
    nodes.extend(o.nodes.iter().cloned());
    if nodes.is_empty() {
        anyhow::bail!("no nodes: add [[node]] tables to the config or --node PATH[=NAME]");
    }
    // Ports compared as the files they are (a /dev/serial/by-id link and
    // its target are one port); names without case (Home Assistant's ids
    // and many brokers' ACLs do not tell `Tower` from `tower`).
    let mut seen_ports: Vec<(PathBuf, &str)> = Vec::new();
    let mut seen_names: Vec<(String, &str)> = Vec::new();
    for (k, n) in nodes.iter().enumerate() {
        if n.port.is_empty() {
            anyhow::bail!("a [[node]] has an empty port");
        }
        let real = std::fs::canonicalize(&n.port).unwrap_or_else(|_| PathBuf::from(&n.port));
        if let Some((_, first)) = seen_ports.iter().find(|(p, _)| *p == real) {
            let detail = if *first == n.port {
                format!("the port {} is listed twice", n.port)
            } else {
                format!(
                    "one serial port listed twice: {first} and {} are both {}",
                    n.port,
                    real.display()
                )
            };
            return Err(KeyError::at(format!("node[{k}].port"), detail));
        }
        seen_ports.push((real, &n.port));
        if let Some(name) = &n.name {
            check_name("node name", name)?;
            let folded = name.to_lowercase();
            if let Some((_, first)) = seen_names.iter().find(|(f, _)| *f == folded) {
                let detail = if first == name {
                    format!("the node name `{name}` is used twice")
                } else {
                    format!(
                        "the node names `{first}` and `{name}` differ only in case (Home \
                         Assistant ids and topics would collide)"
                    )
                };
                return Err(KeyError::at(format!("node[{k}].name"), detail));
            }
            seen_names.push((folded, name));
        }
        if n.baud == 0 {
            anyhow::bail!("node {}: baud 0", n.port);
        }
    }
    Ok(nodes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::BrokerAddr;

    const FULL: &str = r#"
name = "farm-7"
topic_prefix = "wind"
[broker]
host = "broker.local"
port = 8884
username = "gw"
password = "hunter2-secret"
keep_alive_s = 10
[broker.tls]
ca_file = "ca.pem"
client_cert_file = "gw.pem"
client_key_file = "gw.key"
[publish]
measurement_interval_ms = 2000
offline_measurement_interval_ms = 30000
[queue]
dir = "q"
max_bytes = 1000000
[homeassistant]
prefix = "ha"
version = "2024.3.3"
[commands]
enabled = true
[[node]]
port = "/dev/ttyACM0"
name = "tower-3"
[[node]]
port = "/dev/ttyACM1"
baud = 57600
"#;

    #[test]
    fn full_file_resolves_with_every_value() {
        let c = FileConfig::parse(FULL)
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        assert_eq!(c.name, "farm-7");
        assert_eq!(c.topic_prefix, "wind");
        assert_eq!(c.broker.host, "broker.local");
        assert_eq!(c.broker.port, 8884);
        assert_eq!(c.broker.client_id, "fois-gateway-farm-7");
        assert_eq!(
            c.broker.password.as_ref().unwrap().expose(),
            "hunter2-secret"
        );
        assert_eq!(c.broker.keep_alive, Duration::from_secs(10));
        let tls = c.broker.tls.as_ref().unwrap();
        assert_eq!(tls.ca_file, PathBuf::from("ca.pem"));
        assert_eq!(
            tls.client_auth,
            Some((PathBuf::from("gw.pem"), PathBuf::from("gw.key")))
        );
        assert_eq!(c.measurement_interval_ms, 2000);
        assert_eq!(c.offline_measurement_interval_ms, 30000);
        assert_eq!(c.queue_max_bytes, 1_000_000);
        assert_eq!(c.homeassistant_prefix.as_deref(), Some("ha"));
        assert_eq!(c.homeassistant_version, HaVersion::new(2024, 3));
        assert_eq!(
            c.command_topic.as_deref(),
            Some("wind/farm-7/{node}/command")
        );
        assert_eq!(c.nodes.len(), 2);
        assert_eq!(c.nodes[0].name.as_deref(), Some("tower-3"));
        assert_eq!(c.nodes[1].name, None);
        assert_eq!(c.nodes[1].baud, 57600);
    }

    #[test]
    fn debug_output_redacts_the_password() {
        let c = FileConfig::parse(FULL)
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        let text = format!("{c:?} {c:#?}");
        assert!(!text.contains("hunter2"), "{text}");
        assert!(text.contains("Secret(***)"), "{text}");
        let f = FileConfig::parse(FULL).unwrap();
        assert!(!format!("{f:?}").contains("hunter2"));
    }

    #[test]
    fn flags_override_the_file() {
        let o = Overrides {
            name: Some("gw2".into()),
            broker: Some(BrokerAddr::parse("10.0.0.5:1999").unwrap()),
            nodes: vec![NodeSpec::parse_flag("/dev/pts/9=extra").unwrap()],
            measurement_interval_ms: Some(0),
            no_homeassistant: true,
            ..Overrides::default()
        };
        let c = FileConfig::parse(FULL).unwrap().resolve(&o).unwrap();
        assert_eq!(c.name, "gw2");
        assert_eq!((c.broker.host.as_str(), c.broker.port), ("10.0.0.5", 1999));
        assert_eq!(c.measurement_interval_ms, 0);
        assert_eq!(c.homeassistant_prefix, None);
        assert_eq!(c.nodes.len(), 3);
        assert_eq!(c.nodes[2].port, "/dev/pts/9");
        assert_eq!(c.nodes[2].name.as_deref(), Some("extra"));
    }

    #[test]
    fn defaults_without_a_file() {
        let o = Overrides {
            nodes: vec![NodeSpec::parse_flag("/dev/ttyACM0").unwrap()],
            ..Overrides::default()
        };
        let c = FileConfig::default().resolve(&o).unwrap();
        assert_eq!(c.topic_prefix, "fois");
        assert_eq!((c.broker.host.as_str(), c.broker.port), ("127.0.0.1", 1883));
        assert_eq!(c.broker.tls, None);
        assert_eq!(c.measurement_interval_ms, 1000);
        assert_eq!(c.offline_measurement_interval_ms, 10_000);
        assert_eq!(c.queue_max_bytes, DEFAULT_QUEUE_MAX_BYTES);
        assert_eq!(c.homeassistant_prefix.as_deref(), Some("homeassistant"));
        assert_eq!(c.homeassistant_version, HaVersion::OLDEST);
        assert_eq!(c.command_topic, None, "commands are off by default");
        assert_eq!(c.command_min_interval, Duration::from_secs(5));
        assert!(is_valid_name(&c.name));
    }

    #[test]
    fn bad_values_are_refused_with_the_reason() {
        let bad = |text: &str, needle: &str| {
            let err = FileConfig::parse(text)
                .and_then(|f| f.resolve(&Overrides::default()))
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle), "{text:?}: {err}");
        };
        let node = "[[node]]\nport = \"/dev/x\"\n";
        bad("", "no nodes");
        bad(&format!("name = \"a/b\"\n{node}"), "not usable in topics");
        bad(&format!("{node}name = \"x+y\""), "not usable in topics");
        bad(&format!("colour = 3\n{node}"), "unknown field");
        bad(
            &format!("[commands]\ntopic = \"x/{{node}}\"\n{node}"),
            "not enabled",
        );
        bad(
            &format!("[commands]\nenabled = true\ntopic = \"x/#\"\n{node}"),
            "not a valid topic",
        );
        bad(
            &format!("[commands]\nenabled = true\ntopic = \"x/cmd\"\n{node}"),
            "exactly once",
        );
        bad(
            &format!("[broker]\npassword = \"pw\"\n{node}"),
            "needs a username",
        );
        bad(
            &format!("[broker.tls]\nclient_cert_file = \"c\"\n{node}"),
            "needs the broker's CA",
        );
        bad(&format!("[queue]\nmax_bytes = 10\n{node}"), "at least");
        // `$` topics are the broker's: nothing published there is delivered.
        bad(
            &format!("topic_prefix = \"$SYS/fois\"\n{node}"),
            "starts with `$`",
        );
        bad(
            &format!("[homeassistant]\nprefix = \"$ha\"\n{node}"),
            "starts with `$`",
        );
        bad(
            &format!("[homeassistant]\nversion = \"2023.12\"\n{node}"),
            "[homeassistant] version: 2023.12 is older than 2024.1",
        );
        bad(
            &format!("[homeassistant]\nversion = \"latest\"\n{node}"),
            "[homeassistant] version: `latest` is not a Home Assistant release",
        );
        bad(
            &format!("[commands]\nenabled = true\ntopic = \"$x/{{node}}\"\n{node}"),
            "starts with `$`",
        );
        bad(
            &format!("[commands]\nmin_interval_ms = 86400001\n{node}"),
            "at most one day",
        );
        bad(&format!("{node}{node}"), "listed twice");
        bad(
            "[[node]]\nport = \"/a\"\nname = \"n\"\n[[node]]\nport = \"/b\"\nname = \"n\"\n",
            "used twice",
        );
    }

    #[test]
    fn broker_and_node_flags_parse_or_say_why() {
        let b = |s: &str| BrokerAddr::parse(s).map(|a| (a.host, a.port));
        assert_eq!(b("10.0.0.5").unwrap(), ("10.0.0.5".into(), None));
        assert_eq!(
            b("broker.local:8883").unwrap(),
            ("broker.local".into(), Some(8883))
        );
        assert_eq!(b("[::1]:1884").unwrap(), ("::1".into(), Some(1884)));
        assert_eq!(b("::1").unwrap(), ("::1".into(), None));
        for bad in ["", ":1883", "h:0", "h:65536", "h:x"] {
            assert!(b(bad).is_err(), "{bad}");
        }
        let n = NodeSpec::parse_flag("/dev/pts/3=tower-3").unwrap();
        assert_eq!(
            (n.port.as_str(), n.name.as_deref()),
            ("/dev/pts/3", Some("tower-3"))
        );
        assert_eq!(n.baud, fois_protocol::BAUD_RATE);
        assert_eq!(NodeSpec::parse_flag("/dev/ttyACM0").unwrap().name, None);
        for bad in ["", "=x", "/dev/x=a b", "/dev/x="] {
            assert!(NodeSpec::parse_flag(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_parse_error_does_not_echo_the_password() {
        let err = FileConfig::parse("[broker]\npassword = \"hunter2\"\nport = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(!err.contains("hunter2"), "{err}");
    }

    #[test]
    fn a_firmware_section_needs_commands_and_names_its_line() {
        let node = "[[node]]\nport = \"/dev/x\"\n";
        let err = |text: &str| {
            FileConfig::parse(text)
                .and_then(|f| f.resolve(&Overrides::default()))
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            err(&format!("{node}[firmware]\ndir = \"/srv/fw\"\n")),
            "line 4, key `firmware.dir`: [firmware] dir is set but commands are not enabled: a \
             roll-out is a command, add `enabled = true` to [commands] (or remove [firmware])"
        );
        assert_eq!(
            err(&format!(
                "[commands]\nenabled = true\n{node}[firmware]\ndir = \"d\"\nconfirm_timeout_s = 0\n"
            )),
            "line 7, key `firmware.confirm_timeout_s`: [firmware] confirm_timeout_s = 0: give 1 to \
             3600 s"
        );
        assert!(err(&format!("{node}[firmware]\ndirectory = \"d\"\n")).contains("unknown field"));
        let c = FileConfig::parse(&format!(
            "[commands]\nenabled = true\n{node}[firmware]\ndir = \"/srv/fw\"\nconfirm_timeout_s = 300\n"
        ))
        .and_then(|f| f.resolve(&Overrides::default()))
        .unwrap();
        let fw = c.firmware.unwrap();
        assert_eq!(fw.dir, std::path::PathBuf::from("/srv/fw"));
        assert_eq!(fw.confirm_timeout, Duration::from_secs(300));
    }

    #[test]
    fn the_packaged_example_with_its_firmware_lines_uncommented_is_the_default() {
        let example = include_str!("../../debian/gateway.toml");
        let mut in_section = false;
        let text: String = example
            .lines()
            .map(|l| {
                if l == "#[firmware]" {
                    in_section = true;
                } else if l.is_empty() {
                    in_section = false;
                }
                match l {
                    "enabled = false" => "enabled = true\n".to_string(),
                    _ if in_section => format!("{}\n", &l[1..]),
                    _ => format!("{l}\n"),
                }
            })
            .collect();
        let c = FileConfig::parse(&text)
            .and_then(|f| f.resolve(&Overrides::default()))
            .unwrap();
        let fw = c.firmware.unwrap();
        assert_eq!(
            fw.dir,
            std::path::PathBuf::from("/var/lib/fois-gateway/firmware")
        );
        assert_eq!(
            fw.confirm_timeout.as_secs(),
            super::super::firmware::DEFAULT_CONFIRM_TIMEOUT_S
        );
        // As shipped: off.
        let shipped = FileConfig::parse(example)
            .and_then(|f| f.resolve(&Overrides::default()))
            .unwrap();
        assert_eq!(shipped.firmware, None);
    }
}
