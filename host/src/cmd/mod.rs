//! The `foisctl` commands, one module each, every one owning its clap
//! arguments and its `run`; [`Cli`] is the whole command line and
//! [`Cli::run`] dispatches it. The library modules they use (link, log,
//! plots, comparison maths, exit codes) live beside `cmd`, not in it.

pub mod args;
pub mod bench_decode;
pub mod compare;
pub mod config;
pub mod demo;
pub mod estimate;
pub mod icing_report;
pub mod modbus;
pub mod monitor;
pub mod plot;
pub mod request;
pub mod scene;
pub mod sign;
pub mod sim;
pub mod update;
pub mod virtual_node;

use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Parser, Subcommand};

use crate::exit;

/// Monitor, log and configure a FOIS ice-sensor node; run a virtual node;
/// carry a fleet of nodes to an MQTT broker; run the thesis ray tracer.
#[derive(Debug, Parser)]
#[command(name = "foisctl", version, about, long_about = None, after_help = exit::TABLE)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// Live view of a node (I1, I2, ambient, temperature, state, alarm, frames
    /// lost and rejected), optionally logged to CSV. Reconnects when the port
    /// returns; Ctrl-C exits.
    #[command(after_help = exit::TABLE)]
    Monitor(monitor::MonitorArgs),
    /// Read or change the node's configuration.
    #[command(after_help = exit::TABLE)]
    Config(config::ConfigArgs),
    /// Take the current readings of a dry, clean sensor face as the dark
    /// baseline. The node checks that the channels are steady, that the face
    /// reads dry and (protocol-4 nodes) that the baseline moves by no more
    /// than the noise allows (a quarter of the onset rise) from the stored one.
    #[command(after_help = exit::CALIBRATE_DARK_TABLE)]
    CalibrateDark(request::CalibrateDarkArgs),
    /// With a reference target of known response on the clean face, measure
    /// the sensor's optical gain (LED, fibres, phototransistors) against the
    /// target's expected currents; the node keeps it as its gain prior.
    /// Protocol-3 nodes; the procedure is in firmware/README.md.
    #[command(after_help = exit::TABLE)]
    CalibrateGain(request::CalibrateGainArgs),
    /// Make the node forget its learned optical gain (back to its wide
    /// prior), e.g. after cleaning the face or replacing the LED.
    #[command(after_help = exit::TABLE)]
    ResetGain(request::RequestArgs),
    /// Acknowledge the ice alarm (the output stays on while ice remains).
    /// Says so, with its own exit code, when there is no alarm.
    #[command(after_help = exit::ACK_TABLE)]
    Ack(request::RequestArgs),
    /// A node on Modbus RTU (protocol 5): switch one to it (`enable`, over
    /// the framed link), read and write its registers, or switch it back
    /// (`framed`).
    #[command(after_help = exit::TABLE)]
    Modbus(modbus::ModbusArgs),
    /// Send a signed image (`foisctl sign`) to the node over its link:
    /// checked against the node first (board, size, version rule), sent in
    /// 256-byte chunks with a progress bar, verified by the node (digest,
    /// signature), committed; the node boots it on trial and confirms it
    /// after its self-test, or rolls back. Running it again after a cut
    /// continues where the node is. Protocol-6 nodes.
    #[command(after_help = exit::UPDATE_TABLE)]
    Update(update::UpdateArgs),
    /// Make the update key pair: DIR/fois-update.key (the secret seed, hex,
    /// mode 0600) and DIR/fois-update.pub (the public key the firmware is
    /// built with). Never overwrites.
    #[command(after_help = exit::SIGN_TABLE)]
    Keygen(sign::KeygenArgs),
    /// Sign an application binary into an image for `foisctl update`:
    /// body | trailer (version, board, downgrade flag, body length) |
    /// ed25519 signature of the SHA-512 of body and trailer.
    #[command(after_help = exit::SIGN_TABLE)]
    Sign(sign::SignArgs),
    /// What a signed image says (version, board, flags, sizes, digest) and,
    /// with --key, whether its signature verifies.
    #[command(after_help = exit::SIGN_TABLE)]
    ImageInfo(sign::ImageInfoArgs),
    /// Run the firmware's own logic on simulated hardware (ray-traced ice
    /// accretion, analog front end, ambient light) and serve it on a
    /// pseudo-terminal. Prints the pty path on the first line of stdout; talk
    /// to it with `foisctl monitor --port PATH` or any serial tool. Defaults:
    /// rime at 2 mm/h after 30 s dry, -5 °C, sensor b, real time.
    #[command(after_help = exit::SERVE_TABLE)]
    VirtualNode(virtual_node::VirtualNodeArgs),
    /// A virtual node and the monitor in one process: watch rime accrete and
    /// trip the alarm. Defaults: 60 s dry, then rime at 3 mm/h, -5 °C, speed
    /// x20, ends after 40 s (the alarm trips after about 5 s).
    #[command(after_help = exit::SERVE_TABLE)]
    Demo(demo::DemoArgs),
    /// Put logged currents beside the simulator's Monte Carlo band μ(d) ±
    /// kσ(d); prints the RMS deviation, the fraction of samples inside the
    /// band and a one-line verdict. The thickness of each sample comes from
    /// a log column (--thickness-col) or a constant rate (--rate-mm-per-h).
    #[command(after_help = exit::OFFLINE_TABLE)]
    Compare(compare::CompareArgs),
    /// Draw a log for a report (PNG or SVG by the --out extension): I1 and
    /// I2 with alarm periods shaded, the node's state and estimated medium
    /// as bands, the air temperature, the ice estimate with its ±2σ band,
    /// over UTC time (or node uptime); lines stop at gaps and restarts.
    #[command(after_help = exit::OFFLINE_TABLE)]
    Plot(plot::PlotArgs),
    /// Replay a monitor log or a `sim curve` CSV, row by row as consecutive
    /// frames, through the node's own ice estimator and write it with the
    /// estimate appended (thickness ± sigma in mm, medium, its probability).
    #[command(after_help = exit::OFFLINE_TABLE)]
    Estimate(estimate::EstimateArgs),
    /// An icing report from one node's logs (monitor or gateway, `.csv` or
    /// `.csv.gz`): the icing events (start, end, meteorological and
    /// instrumental icing hours, peak thickness ± σ, peak and mean rate,
    /// medium), monthly totals, the share of the period with each kind of
    /// icing and the IEA Wind (Task 19) ice class it implies; a timeline
    /// figure with --plot. Meteorological icing is the node's own
    /// `est_accreting`; in older logs it is derived from the thickness
    /// series' growth (said so). Streams the files: a year at 1 Hz in
    /// bounded memory (--bench measures it).
    #[command(after_help = exit::OFFLINE_TABLE)]
    IcingReport(icing_report::IcingReportArgs),
    /// Decoder throughput: encode a stream of measurement frames and decode
    /// it, print frames/s and MB/s.
    #[command(after_help = exit::OFFLINE_TABLE)]
    BenchDecode(bench_decode::BenchDecodeArgs),
    /// Ray-trace simulator of the sensor (thesis chapters 3 and 5).
    #[command(after_help = exit::OFFLINE_TABLE)]
    Sim(sim::SimArgs),
}

/// Set by Ctrl-C: the long-running commands stop cleanly.
static STOP: AtomicBool = AtomicBool::new(false);

/// The first Ctrl-C sets [`STOP`]; a second one exits at once.
fn install_ctrlc() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
}

impl Cli {
    /// Run the command.
    pub fn run(self) -> anyhow::Result<()> {
        match self.cmd {
            Cmd::Monitor(a) => {
                install_ctrlc();
                monitor::run(a, &STOP)
            }
            Cmd::Config(a) => config::run(a),
            Cmd::CalibrateDark(a) => request::calibrate_dark(&a),
            Cmd::CalibrateGain(a) => request::calibrate_gain(&a),
            Cmd::ResetGain(a) => request::reset_gain(&a),
            Cmd::Ack(a) => request::ack(&a),
            Cmd::Modbus(a) => modbus::run(a),
            Cmd::Update(a) => update::run(&a),
            Cmd::Keygen(a) => sign::keygen(&a),
            Cmd::Sign(a) => sign::sign(&a),
            Cmd::ImageInfo(a) => sign::image_info(&a),
            Cmd::VirtualNode(a) => {
                install_ctrlc();
                virtual_node::run(a, &STOP)
            }
            Cmd::Demo(a) => {
                install_ctrlc();
                demo::run(a, &STOP).map(|_| ())
            }
            Cmd::Compare(a) => compare::run(a),
            Cmd::Plot(a) => plot::run(a),
            Cmd::Estimate(a) => estimate::run(a),
            Cmd::IcingReport(a) => icing_report::run(a),
            Cmd::BenchDecode(a) => bench_decode::run(a),
            Cmd::Sim(a) => sim::run(a),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }

    /// Every command and subcommand states its exit codes in `--help`.
    #[test]
    fn every_subcommand_documents_its_exit_codes() {
        fn walk(cmd: &mut clap::Command, path: &str, missing: &mut Vec<String>) {
            let name = format!("{path} {}", cmd.get_name());
            let help = cmd.render_long_help().to_string();
            if !help.contains("Exit codes: 0") {
                missing.push(name.clone());
            }
            for sub in cmd.get_subcommands_mut() {
                if sub.get_name() != "help" {
                    walk(sub, &name, missing);
                }
            }
        }
        let mut missing = Vec::new();
        let mut cli = Cli::command();
        cli.build();
        for sub in cli.get_subcommands_mut() {
            if sub.get_name() != "help" {
                walk(sub, "foisctl", &mut missing);
            }
        }
        assert!(missing.is_empty(), "no exit codes in --help: {missing:?}");
    }
}
