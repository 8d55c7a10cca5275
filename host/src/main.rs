//! `foisctl`: the FOIS host tool.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use clap::{Args, Parser, Subcommand};
use fois_host::{commands, exit, monitor, vnode_cmd};

/// Monitor, log and configure a FOIS ice-sensor node; run a virtual node; run
/// the thesis ray tracer.
#[derive(Debug, Parser)]
#[command(name = "foisctl", version, about, long_about = None, after_help = exit::TABLE)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

/// The serial port of a node.
#[derive(Debug, Clone, Args)]
struct PortArgs {
    /// Serial port of the node: /dev/ttyACM0 for a NUCLEO board, or the
    /// /dev/pts/N path a `foisctl virtual-node` prints.
    #[arg(long, short = 'p', value_name = "PATH")]
    port: String,
    /// Baud rate, 8N1 (the node's UART runs at 115200).
    #[arg(long, default_value_t = fois_protocol::BAUD_RATE, value_name = "BAUD")]
    baud: u32,
}

/// Options of commands that wait for an answer.
#[derive(Debug, Clone, Args)]
struct CmdArgs {
    #[command(flatten)]
    port: PortArgs,
    /// How long to wait for the node's answer, ms.
    #[arg(long, default_value_t = 3000, value_name = "MS")]
    timeout_ms: u64,
}

impl CmdArgs {
    fn target(&self) -> commands::Target {
        commands::Target {
            port: self.port.port.clone(),
            baud: self.port.baud,
            timeout: Duration::from_millis(self.timeout_ms),
        }
    }
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Live view of a node (I1, I2, ambient, temperature, state, alarm, frames
    /// lost and rejected), optionally logged to CSV. Reconnects when the port
    /// returns; Ctrl-C exits.
    Monitor {
        #[command(flatten)]
        port: PortArgs,
        /// Append every measurement, event, gap and error to this CSV file
        /// (created with a header if new; columns in host/README.md).
        #[arg(long, value_name = "FILE")]
        log: Option<PathBuf>,
        /// Stop after this many seconds (default: run until Ctrl-C).
        #[arg(long, value_name = "SECONDS")]
        duration: Option<f64>,
        /// Print a plain status line each second instead of a redrawn one.
        #[arg(long)]
        plain: bool,
    },
    /// Read or change the node's configuration.
    Config {
        #[command(subcommand)]
        cmd: ConfigCmd,
    },
    /// Take the current readings of a dry, clean sensor face as the dark
    /// baseline (the node checks that the channels are steady).
    CalibrateDark(CmdArgs),
    /// Acknowledge the ice alarm (the output stays on while ice remains).
    Ack(CmdArgs),
    /// Run the firmware's own logic on simulated hardware (ray-traced ice
    /// accretion, analog front end, ambient light) and serve it on a
    /// pseudo-terminal. Prints the pty path on the first line of stdout; talk
    /// to it with `foisctl monitor --port PATH` or any serial tool. Defaults:
    /// rime at 2 mm/h after 30 s dry, -5 °C, sensor b, real time.
    VirtualNode {
        #[command(flatten)]
        scene: vnode_cmd::SceneArgs,
        /// Also create this symlink to the pty: a stable name across restarts
        /// (e.g. /tmp/fois-node), so a monitor reconnects after a restart.
        #[arg(long, value_name = "PATH")]
        link: Option<PathBuf>,
    },
    /// A virtual node and the monitor in one process: watch rime accrete and
    /// trip the alarm. Defaults: 60 s dry, then rime at 3 mm/h, -5 °C, speed
    /// x20, ends after 40 s (alarm after about 15 s).
    Demo {
        #[command(flatten)]
        scene: vnode_cmd::SceneArgs,
        /// Also log to this CSV file.
        #[arg(long, value_name = "FILE")]
        log: Option<PathBuf>,
        /// Print a plain status line each second instead of a redrawn one.
        #[arg(long)]
        plain: bool,
    },
    /// Ray-trace simulator of the sensor (thesis chapters 3 and 5).
    Sim(fois_host::sim_cmd::SimArgs),
}

#[derive(Debug, Subcommand)]
enum ConfigCmd {
    /// Print every config field with its value, unit and allowed range.
    Get(CmdArgs),
    /// Change fields: KEY=VALUE ... (integers in the field's unit, see `config
    /// get`). Checked on the host with the node's own rule before sending.
    Set {
        #[command(flatten)]
        args: CmdArgs,
        /// KEY=VALUE pairs, e.g. onset_rise_na=1500 frame_period_ms=200.
        #[arg(value_name = "KEY=VALUE", required = true)]
        pairs: Vec<String>,
    },
}

static STOP: AtomicBool = AtomicBool::new(false);

fn install_ctrlc() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            // Second Ctrl-C: leave now.
            std::process::exit(130);
        }
    });
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.cmd {
        Cmd::Sim(args) => fois_host::sim_cmd::run(args),
        Cmd::Monitor {
            port,
            log,
            duration,
            plain,
        } => {
            install_ctrlc();
            let mut opts = monitor::MonitorOptions::new(port.port);
            opts.baud = port.baud;
            opts.log = log;
            opts.plain = plain;
            opts.duration = duration.map(Duration::from_secs_f64);
            let sum = monitor::run(&opts, &STOP)?;
            println!(
                "monitor: {} frames, {} measurements, {} lost, {} rejected, {} disconnect(s){}",
                sum.frames,
                sum.measurements,
                sum.lost,
                sum.rejected,
                sum.disconnects,
                opts.log
                    .as_ref()
                    .map(|p| format!(", {} rows appended to {}", sum.log_rows, p.display()))
                    .unwrap_or_default()
            );
            Ok(())
        }
        Cmd::VirtualNode { scene, link } => {
            install_ctrlc();
            vnode_cmd::run_virtual_node(&scene, link, &STOP)
        }
        Cmd::Demo { scene, log, plain } => {
            install_ctrlc();
            vnode_cmd::run_demo(&scene, log, plain, &STOP).map(|_| ())
        }
        Cmd::Config { cmd } => match cmd {
            ConfigCmd::Get(a) => commands::config_get(&a.target()).map(|_| ()),
            ConfigCmd::Set { args, pairs } => {
                commands::config_set(&args.target(), &pairs).map(|_| ())
            }
        },
        Cmd::CalibrateDark(a) => commands::calibrate_dark(&a.target()).map(|_| ()),
        Cmd::Ack(a) => commands::ack_alarm(&a.target()).map(|_| ()),
    }
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("foisctl: error: {e:#}");
        std::process::exit(exit::code_of(&e));
    }
}
