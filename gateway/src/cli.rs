//! The command line of `fois-gateway`: the flags of the run (the flags
//! that override the config file are [`Overrides`], declared there and
//! flattened in), `--print-config`, `--check-config`, and the run with its
//! summary. A bad value is refused before anything is opened (exit code 2).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Parser;
use fois_link::numbers::{f64_in, non_negative};
use tracing::info;

use crate::config::GatewayConfig;
use crate::config::file::{FileConfig, Overrides};
use crate::logging::{LogTime, LogTo};
use crate::service::{NameConflict, RunLimits, Service};

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
    /// The flags that override the config file.
    #[command(flatten)]
    pub overrides: Overrides,
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
    /// usable, 2 with the reason when not. A serial port that does not
    /// exist is a warning on stderr, not an error (exit 0: a USB adapter
    /// may be plugged in later).
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
        Ok(file.resolve(&self.overrides).map_err(usage)?)
    }
}

/// `--check-config`: everything that can be checked without the serial
/// ports and the broker. Returns the line to print.
pub fn check_config(cfg: &GatewayConfig) -> anyhow::Result<String> {
    if let Some(t) = &cfg.broker.tls {
        crate::mqtt::rustls_config(t).map_err(|e| UsageError(format!("{e:#}")))?;
    }
    if let Some(m) = &cfg.modbus {
        // The address, not the port: a running gateway may hold the port.
        let ip = m.listen.ip();
        if let Err(e) = std::net::TcpListener::bind((ip, 0)) {
            return Err(UsageError(format!(
                "key `modbus.listen`: the gateway cannot listen on {ip} ({e}): not an address \
                 of this machine? (127.0.0.1 for this machine only, 0.0.0.0 for every \
                 interface)"
            ))
            .into());
        }
    }
    Ok(format!(
        "config OK: gateway {}, {} node(s), broker {}, queue {} (at most {} bytes), \
         Home Assistant discovery {}, MQTT commands {}, {}, {}",
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
        match &cfg.log {
            Some(l) => format!(
                "daily logs in {} ({} day(s) kept)",
                l.dir.display(),
                l.days_kept
            ),
            None => "daily logs off".to_string(),
        },
    ))
}

/// `--check-config`'s warnings: each configured serial port that does not
/// exist (now). Not an error: a USB adapter may be plugged in later, and
/// the gateway keeps trying to open the port.
pub fn missing_ports(cfg: &GatewayConfig) -> Vec<String> {
    cfg.nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| !std::path::Path::new(&n.port).exists())
        .map(|(k, n)| {
            let who = match &n.name {
                Some(name) => format!("node {name}"),
                None => format!("node {}", k + 1),
            };
            format!(
                "{who}: the serial port {} does not exist. Not an error (a USB adapter may be \
                 plugged in later; the gateway starts and tries to open it every {} ms), but \
                 check the path if the node is connected (`ls /dev/serial/by-id/`)",
                n.port,
                crate::reader::RETRY_INTERVAL.as_millis()
            )
        })
        .collect()
}

/// Run the gateway until `stop` or the duration; prints the totals.
pub fn run(args: GatewayArgs, stop: &'static AtomicBool) -> anyhow::Result<()> {
    let cfg = args.resolve()?;
    if args.print_config {
        println!("{cfg:#?}");
        return Ok(());
    }
    if args.check_config {
        let ok = check_config(&cfg)?;
        for w in missing_ports(&cfg) {
            eprintln!("warning: {w}");
        }
        println!("{ok}");
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
