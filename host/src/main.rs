//! `foisctl`: the FOIS host tool.

use clap::{Parser, Subcommand};

/// Monitor, log and configure a FOIS ice-sensor node; run a virtual node; run
/// the thesis ray tracer.
#[derive(Debug, Parser)]
#[command(name = "foisctl", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Ray-trace simulator of the sensor (thesis chapters 3 and 5).
    Sim(fois_host::sim_cmd::SimArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Sim(args) => fois_host::sim_cmd::run(args),
    }
}
