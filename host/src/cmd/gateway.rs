//! `foisctl gateway`: many nodes to an MQTT broker (the library is
//! [`crate::gateway`]).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Args;

use super::args::{broker_addr, f64_in, gateway_node, non_negative, topic_name};
use crate::exit;
use crate::gateway::config::{
    BrokerAddr, FileConfig, GatewayConfig, MAX_INTERVAL_MS, MIN_QUEUE_MAX_BYTES, NodeSpec,
    Overrides,
};
use crate::gateway::publisher;

/// `foisctl gateway` flags. Every flag overrides the config file's value.
#[derive(Debug, Clone, Args)]
pub struct GatewayArgs {
    /// The gateway's config (TOML: broker, nodes, queue, Home Assistant,
    /// commands; format in host/README.md). Without it, --node and the
    /// flags below are the whole config.
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
    /// Print only errors and the summary.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

impl GatewayArgs {
    /// The config from the file (if any) and the flags, checked; a bad file
    /// or value is a usage error (exit 2).
    pub fn resolve(&self) -> anyhow::Result<GatewayConfig> {
        let usage = |e: anyhow::Error| exit::Exit::new(exit::USAGE, format!("{e:#}"));
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

/// Run `foisctl gateway` until `stop` or the duration; prints the totals.
pub fn run(args: GatewayArgs, stop: &'static AtomicBool) -> anyhow::Result<()> {
    let cfg = args.resolve()?;
    if args.print_config {
        println!("{cfg:#?}");
        return Ok(());
    }
    let duration = args.duration.map(Duration::from_secs_f64);
    let status_interval = Duration::from_secs_f64(args.status_interval_s);
    let log = publisher::Log { quiet: args.quiet };
    let sum = publisher::run(cfg, stop, duration, status_interval, log)?;
    println!(
        "gateway: {} frame(s) received, {} lost on the serial links, {} record(s) queued, {} acknowledged by the broker, {} left in the queue, {} dropped by its bound, {} published without it (disk failure), {} broker connection(s)",
        sum.frames,
        sum.frames_lost,
        sum.records_queued,
        sum.records_acked,
        sum.records_pending,
        sum.records_dropped,
        sum.records_unqueued,
        sum.broker_connects
    );
    Ok(())
}
