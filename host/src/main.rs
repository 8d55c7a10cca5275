//! `foisctl`: the FOIS host tool.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use clap::{Args, Parser, Subcommand};
use fois_host::cmd::{config as commands, scene as vnode_cmd};
use fois_host::{exit, monitor};

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
    #[command(after_help = exit::TABLE)]
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
    #[command(after_help = exit::TABLE)]
    CalibrateDark(CmdArgs),
    /// Acknowledge the ice alarm (the output stays on while ice remains).
    #[command(after_help = exit::TABLE)]
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
        /// Keep the node's flash record (config, dark baseline) in this file,
        /// so it survives a restart of the virtual node as it survives a power
        /// cycle on a board [default: RAM only].
        #[arg(long, value_name = "FILE")]
        state: Option<PathBuf>,
    },
    /// A virtual node and the monitor in one process: watch rime accrete and
    /// trip the alarm. Defaults: 60 s dry, then rime at 3 mm/h, -5 °C, speed
    /// x20, ends after 40 s (the alarm trips after about 5 s).
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
    /// Put logged currents beside the simulator's Monte Carlo band mu(d) +/-
    /// k*sigma(d); prints the RMS deviation and the fraction of samples
    /// inside the band. The thickness of each sample comes from a log column
    /// (--thickness-col) or a constant rate (--rate-mm-per-h).
    Compare {
        /// The log: a `foisctl monitor` CSV, or any CSV with i1_ua, i2_ua and
        /// the thickness (or uptime_ms) column.
        #[arg(long, value_name = "FILE")]
        log: PathBuf,
        /// The medium to simulate.
        #[arg(long, value_name = "rime|glazed|water|flat", value_parser = parse_ice)]
        ice: fois_sim::IceKind,
        /// Column holding the reference thickness, mm (e.g. a laser distance sensor).
        #[arg(
            long,
            value_name = "NAME",
            conflicts_with = "rate_mm_per_h",
            required_unless_present = "rate_mm_per_h"
        )]
        thickness_col: Option<String>,
        /// Constant accretion rate, mm/h: d = rate x (uptime - start).
        #[arg(long, value_name = "MM_PER_H")]
        rate_mm_per_h: Option<f64>,
        /// With --rate-mm-per-h: node uptime at which accretion started, s
        /// (default: the first measurement in the log).
        #[arg(long, value_name = "SECONDS", requires = "rate_mm_per_h")]
        start_s: Option<f64>,
        /// Monte Carlo accretions.
        #[arg(long, default_value_t = 100, value_name = "N")]
        runs: u64,
        /// Seed of the Monte Carlo.
        #[arg(long, default_value_t = 1, value_name = "N")]
        seed: u64,
        /// Band half-width, in sigma.
        #[arg(long, default_value_t = 1.0, value_name = "K")]
        k_sigma: f64,
        /// Measurement noise of one logged sample, rms µA, added in
        /// quadrature to the Monte Carlo spread (which models only the ice).
        /// The node's frame noise at the default config is about 0.035 µA.
        #[arg(long, default_value_t = 0.035, value_name = "UA")]
        noise_ua: f64,
        /// Sensor construction: a or b.
        #[arg(long, default_value = "b", value_name = "a|b", value_parser = parse_sensor)]
        sensor: fois_sim::SensorKind,
        /// Also draw the comparison (PNG).
        #[arg(long, value_name = "FILE.png")]
        plot: Option<PathBuf>,
    },
    /// Draw I1 and I2 of a log over host time, alarm periods shaded, link
    /// breaks marked (PNG).
    Plot {
        /// A `foisctl monitor` CSV log.
        #[arg(long, value_name = "FILE")]
        log: PathBuf,
        /// The PNG to write.
        #[arg(long, value_name = "FILE.png")]
        out: PathBuf,
        /// Time axis: host (host clock since the first row) or node (node
        /// uptime: the virtual time of a virtual node) [default: host].
        #[arg(long, value_name = "host|node", default_value = "host", value_parser = parse_axis)]
        time: fois_host::plot::TimeAxis,
    },
    /// Decoder throughput: encode a stream of measurement frames and decode
    /// it, print frames/s and MB/s.
    BenchDecode {
        /// Frames in the stream.
        #[arg(long, default_value_t = 1_000_000, value_name = "N")]
        frames: u32,
    },
    /// Ray-trace simulator of the sensor (thesis chapters 3 and 5).
    Sim(fois_host::cmd::sim::SimArgs),
}

#[derive(Debug, Subcommand)]
enum ConfigCmd {
    /// Print every config field with its value, unit and allowed range.
    #[command(after_help = exit::TABLE)]
    Get(CmdArgs),
    /// Change fields: KEY=VALUE ... (integers in the field's unit, see `config
    /// get`). Checked on the host with the node's own rule before sending.
    #[command(after_help = exit::TABLE)]
    Set {
        #[command(flatten)]
        args: CmdArgs,
        /// KEY=VALUE pairs, e.g. onset_rise_na=1500 frame_period_ms=200.
        #[arg(value_name = "KEY=VALUE", required = true)]
        pairs: Vec<String>,
    },
}

fn parse_ice(s: &str) -> Result<fois_sim::IceKind, String> {
    use fois_sim::IceKind;
    match s.trim().to_ascii_lowercase().as_str() {
        "rime" => Ok(IceKind::Rime),
        "glazed" => Ok(IceKind::Glazed),
        "water" => Ok(IceKind::Water),
        "flat" => Ok(IceKind::Flat),
        _ => Err(format!("`{s}` is not one of rime, glazed, water, flat")),
    }
}

fn parse_sensor(s: &str) -> Result<fois_sim::SensorKind, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "a" => Ok(fois_sim::SensorKind::A),
        "b" => Ok(fois_sim::SensorKind::B),
        _ => Err(format!("`{s}` is not a or b")),
    }
}

fn parse_axis(s: &str) -> Result<fois_host::plot::TimeAxis, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "host" => Ok(fois_host::plot::TimeAxis::Host),
        "node" => Ok(fois_host::plot::TimeAxis::Node),
        _ => Err(format!("`{s}` is not host or node")),
    }
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
        Cmd::Sim(args) => fois_host::cmd::sim::run(args),
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
            opts.duration = match duration {
                Some(d) if !(d.is_finite() && d >= 0.0) => {
                    return Err(
                        exit::Exit::new(exit::USAGE, "--duration must be >= 0 seconds").into(),
                    );
                }
                d => d.map(Duration::from_secs_f64),
            };
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
        Cmd::VirtualNode { scene, link, state } => {
            install_ctrlc();
            vnode_cmd::run_virtual_node(&scene, link, state, &STOP)
        }
        Cmd::Demo { scene, log, plain } => {
            install_ctrlc();
            vnode_cmd::run_demo(&scene, log, plain, &STOP).map(|_| ())
        }
        Cmd::Compare {
            log,
            ice,
            thickness_col,
            rate_mm_per_h,
            start_s,
            runs,
            seed,
            k_sigma,
            noise_ua,
            sensor,
            plot,
        } => {
            use fois_host::compare::{self, CompareOptions, ThicknessSource};
            let thickness = match (thickness_col, rate_mm_per_h) {
                (Some(c), _) => ThicknessSource::Column(c),
                (None, Some(r)) => ThicknessSource::Rate {
                    mm_per_h: r,
                    start_s,
                },
                (None, None) => anyhow::bail!("give --thickness-col or --rate-mm-per-h"),
            };
            if !(k_sigma.is_finite() && k_sigma > 0.0) {
                return Err(exit::Exit::new(exit::USAGE, "--k-sigma must be > 0").into());
            }
            if !(noise_ua.is_finite() && noise_ua >= 0.0) {
                return Err(exit::Exit::new(exit::USAGE, "--noise-ua must be >= 0").into());
            }
            if rate_mm_per_h.is_some_and(|r| !(r.is_finite() && r > 0.0)) {
                return Err(exit::Exit::new(exit::USAGE, "--rate-mm-per-h must be > 0").into());
            }
            let opts = CompareOptions {
                log,
                ice,
                sensor,
                thickness,
                runs,
                seed,
                k_sigma,
                noise_ua,
                plot,
            };
            let c = compare::run(&opts)?;
            print!("{}", compare::report(&c));
            if let Some(p) = &opts.plot {
                println!("figure: {}", p.display());
            }
            Ok(())
        }
        Cmd::Plot { log, out, time } => {
            let n = fois_host::plot::plot_log(&log, &out, time)?;
            println!("{n} measurements drawn to {}", out.display());
            Ok(())
        }
        Cmd::BenchDecode { frames } => {
            let r = fois_host::bench::decode_throughput(frames);
            println!(
                "decoded {} frames ({} bytes) in {:.3} s: {:.0} frames/s, {:.1} MB/s",
                r.frames,
                r.bytes,
                r.seconds,
                r.frames_per_s(),
                r.bytes as f64 / r.seconds / 1e6
            );
            Ok(())
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
    // Die quietly on a closed pipe (`foisctl config get | head -1`) like
    // other Unix tools, instead of failing to print.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE at start-up,
    // before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("foisctl: error: {e:#}");
        std::process::exit(exit::code_of(&e));
    }
}
