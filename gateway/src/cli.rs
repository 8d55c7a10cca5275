//! The command line of `fois-gateway`: its flags (each overrides the
//! config file's value), the parsers that refuse a bad value before anything
//! is opened (exit code 2), `--print-config`, `--check-config`, and the run
//! with its summary.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Parser;
use fois_link::numbers::{f64_in, non_negative};
use tracing::info;

use crate::config::{
    BrokerAddr, FileConfig, GatewayConfig, MAX_INTERVAL_MS, MIN_QUEUE_MAX_BYTES, NodeSpec,
    Overrides, is_valid_name,
};
use crate::driver::{NameConflict, RunLimits, Service};
use crate::logging::{LogTime, LogTo};

/// Exit code of a bad command line or config.
pub const EXIT_USAGE: i32 = 2;
/// Exit code when another gateway of the same name runs (it started first).
pub const EXIT_NAME_CONFLICT: i32 = 3;

const AFTER_HELP: &str = "\
Logs carry levels (error, warn, info, debug); RUST_LOG filters them (e.g.
RUST_LOG=debug, RUST_LOG=fois_gateway=debug). Under systemd they go into the
journal with their priority, elsewhere to stdout. Ctrl-C or SIGTERM stops the
gateway cleanly: nodes and gateway marked offline, the last records acknowledged.

Exit codes: 0 stopped as asked; 1 a failure while running (the queue directory
cannot be opened or is used by another gateway, the broker was never reached
within --duration); 2 a bad command line or config (nothing was opened); 3
another gateway of the same name runs and started first (this one stopped).";

/// A bad command line or config: exit code [`EXIT_USAGE`].
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// A gateway name usable as one MQTT topic level and in Home Assistant ids:
/// 1 to 64 letters, digits, `-` or `_`.
fn topic_name(s: &str) -> Result<String, String> {
    if is_valid_name(s) {
        Ok(s.to_string())
    } else {
        Err(format!(
            "`{s}` is not usable in topics: use 1 to 64 letters, digits, `-` or `_`"
        ))
    }
}

/// An MQTT broker, `HOST[:PORT]` ([`BrokerAddr::parse`]).
fn broker_addr(s: &str) -> Result<BrokerAddr, String> {
    BrokerAddr::parse(s).map_err(|e| format!("{e:#}"))
}

/// A gateway node, `PATH[=NAME]` ([`NodeSpec::parse_flag`]).
fn gateway_node(s: &str) -> Result<NodeSpec, String> {
    NodeSpec::parse_flag(s).map_err(|e| format!("{e:#}"))
}

/// `fois-gateway`: many FOIS nodes to an MQTT broker.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "fois-gateway",
    version,
    about = "The FOIS fleet gateway: reads many FOIS nodes on their serial ports and publishes \
             them to an MQTT broker (state, measurements, events, availability, Home Assistant \
             discovery), with a bounded on-disk queue while the broker is away.",
    after_help = AFTER_HELP
)]
pub struct GatewayArgs {
    /// The gateway's config (TOML: broker, nodes, queue, Home Assistant,
    /// commands; every key in gateway/README.md and the packaged example
    /// /etc/fois/gateway.toml). Without it, --node and the flags below are
    /// the whole config.
    #[arg(long, short = 'c', value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Gateway name: a topic level (<prefix>/<name>/...) and part of every
    /// Home Assistant id; 1 to 64 letters, digits, - and _ [default: the
    /// host name].
    #[arg(long, value_name = "NAME", value_parser = topic_name)]
    pub name: Option<String>,
    /// The broker, HOST, HOST:PORT or [IPv6]:PORT [default: 127.0.0.1:1883,
    /// 8883 with TLS].
    #[arg(long, value_name = "HOST[:PORT]", value_parser = broker_addr)]
    pub broker: Option<BrokerAddr>,
    /// Broker user name.
    #[arg(long, value_name = "USER")]
    pub username: Option<String>,
    /// A file whose first line is the broker password (there is no password
    /// flag: other users can read a command line).
    #[arg(long, value_name = "FILE")]
    pub password_file: Option<PathBuf>,
    /// Connect with TLS, trusting the CA certificate(s) in this PEM file.
    #[arg(long, value_name = "FILE.pem")]
    pub ca_file: Option<PathBuf>,
    /// Client certificate (PEM) for mutual TLS, with --client-key.
    #[arg(long, value_name = "FILE.pem", requires = "client_key")]
    pub client_cert: Option<PathBuf>,
    /// Private key (PEM) of the client certificate.
    #[arg(long, value_name = "FILE.pem", requires = "client_cert")]
    pub client_key: Option<PathBuf>,
    /// A node: serial port (or pty) path, optionally =NAME for its topics
    /// [default name: the node's unique id, hex]. Repeat for more nodes;
    /// added to the config file's [[node]] tables.
    #[arg(long = "node", value_name = "PATH[=NAME]", value_parser = gateway_node)]
    pub nodes: Vec<NodeSpec>,
    /// At most one measurement per node per this many ms of node time while
    /// the broker is connected; 0 publishes every frame (10 per second per
    /// node); at most 86400000 (a day) [default: 1000].
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(..=MAX_INTERVAL_MS))]
    pub measurement_interval_ms: Option<u64>,
    /// The same while the broker is unreachable: what goes to the disk
    /// queue [default: 10000].
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(..=MAX_INTERVAL_MS))]
    pub offline_measurement_interval_ms: Option<u64>,
    /// Directory of the store-and-forward queue [default:
    /// $XDG_STATE_HOME/fois/gateway-<name>, else ~/.local/state/fois/...].
    #[arg(long, value_name = "DIR")]
    pub queue_dir: Option<PathBuf>,
    /// Bound of the disk queue, bytes, at least 65536; the oldest records
    /// are dropped first and counted [default: 268435456 = 256 MiB].
    #[arg(long, value_name = "BYTES", value_parser = clap::value_parser!(u64).range(MIN_QUEUE_MAX_BYTES..))]
    pub queue_max_bytes: Option<u64>,
    /// Do not publish Home Assistant discovery configs.
    #[arg(long)]
    pub no_homeassistant: bool,
    /// Print a status line every this many seconds (0.1 to 86400).
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS", value_parser = f64_in(0.1, 86_400.0))]
    pub status_interval_s: f64,
    /// Stop after this many seconds [default: run until Ctrl-C].
    #[arg(long, value_name = "SECONDS", value_parser = non_negative)]
    pub duration: Option<f64>,
    /// Print the resolved config (secrets shown as ***) and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Check the config (file, flags, password file, TLS certificates and
    /// key) without opening a serial port or the broker; exit 0 when it is
    /// usable, 2 with the reason when not.
    #[arg(long, conflicts_with = "print_config")]
    pub check_config: bool,
    /// Log only warnings and errors (RUST_LOG, when set, decides instead).
    #[arg(long, short = 'q')]
    pub quiet: bool,
    /// Timestamps on log lines: `auto` writes them only when stdout is a
    /// terminal (under systemd, journald stamps every line itself).
    #[arg(long, value_enum, default_value_t = LogTime::Auto, value_name = "WHEN")]
    pub log_time: LogTime,
    /// Where logs go: `auto` = the systemd journal (with each entry's
    /// priority) when systemd connected the output to it, else stdout.
    #[arg(long, value_enum, default_value_t = LogTo::Auto, value_name = "WHERE")]
    pub log_to: LogTo,
}

impl GatewayArgs {
    /// The config from the file (if any) and the flags, checked; a bad file
    /// or value is a usage error (exit 2).
    pub fn resolve(&self) -> anyhow::Result<GatewayConfig> {
        let usage = |e: anyhow::Error| UsageError(format!("{e:#}"));
        let file = match &self.config {
            Some(p) => FileConfig::load(p).map_err(usage)?,
            None => FileConfig::default(),
        };
        let o = Overrides {
            name: self.name.clone(),
            broker: self.broker.clone(),
            username: self.username.clone(),
            password_file: self.password_file.clone(),
            ca_file: self.ca_file.clone(),
            client_cert_file: self.client_cert.clone(),
            client_key_file: self.client_key.clone(),
            nodes: self.nodes.clone(),
            measurement_interval_ms: self.measurement_interval_ms,
            offline_measurement_interval_ms: self.offline_measurement_interval_ms,
            queue_dir: self.queue_dir.clone(),
            queue_max_bytes: self.queue_max_bytes,
            no_homeassistant: self.no_homeassistant,
        };
        Ok(file.resolve(&o).map_err(usage)?)
    }
}

/// `--check-config`: everything that can be checked without the serial
/// ports and the broker. Returns the line to print.
pub fn check_config(cfg: &GatewayConfig) -> anyhow::Result<String> {
    if let Some(t) = &cfg.broker.tls {
        crate::mqtt::rustls_config(t).map_err(|e| UsageError(format!("{e:#}")))?;
    }
    Ok(format!(
        "config OK: gateway {}, {} node(s), broker {}, queue {} (at most {} bytes), \
         Home Assistant discovery {}, MQTT commands {}, {}",
        cfg.name,
        cfg.nodes.len(),
        cfg.broker.describe(),
        cfg.queue_dir.display(),
        cfg.queue_max_bytes,
        if cfg.homeassistant_prefix.is_some() {
            format!(
                "on (for Home Assistant {} and later)",
                cfg.homeassistant_version
            )
        } else {
            "off".to_string()
        },
        if cfg.command_topic.is_some() {
            "on"
        } else {
            "off"
        },
        match &cfg.modbus {
            Some(m) => m.describe(),
            None => "Modbus TCP off".to_string(),
        },
    ))
}

/// Run the gateway until `stop` or the duration; prints the totals.
pub fn run(args: GatewayArgs, stop: &'static AtomicBool) -> anyhow::Result<()> {
    let cfg = args.resolve()?;
    if args.print_config {
        println!("{cfg:#?}");
        return Ok(());
    }
    if args.check_config {
        println!("{}", check_config(&cfg)?);
        return Ok(());
    }
    let limits = RunLimits {
        stop,
        duration: args.duration.map(Duration::from_secs_f64),
        status_every: Duration::from_secs_f64(args.status_interval_s),
    };
    let (sum, conflict) = match Service::new(cfg).run(limits) {
        Ok(sum) => (sum, None),
        Err(e) => match e.downcast::<NameConflict>() {
            Ok(c) => (c.summary.clone(), Some(c)),
            Err(e) => return Err(e),
        },
    };
    let line = format!(
        "gateway: {} frame(s) received, {} lost on the serial links, {} record(s) queued, {} acknowledged by the broker, {} left in the queue, {} lost by the queue, {} broker connection(s)",
        sum.frames,
        sum.frames_lost,
        sum.records_queued,
        sum.records_acked,
        sum.records_pending,
        sum.records_dropped,
        sum.broker_connects
    );
    info!("{line}");
    println!("{line}");
    if let Some(c) = conflict {
        return Err(c.into());
    }
    if args.duration.is_some() && sum.broker_connects == 0 {
        anyhow::bail!(
            "the broker was never reached in {} s: nothing was published ({} record(s) wait in \
             the queue)",
            args.duration.unwrap_or_default(),
            sum.records_pending
        );
    }
    Ok(())
}
