//! `foisctl sim ...`: the front end of the `fois-sim` ray tracer.

use clap::{Args, Subcommand};

/// Arguments of `foisctl sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    #[command(subcommand)]
    pub cmd: SimCmd,
}

/// The simulator's subcommands.
#[derive(Debug, Subcommand)]
pub enum SimCmd {
    /// Print ray evaluations per second.
    Bench,
}

/// Run `foisctl sim`.
pub fn run(args: SimArgs) -> anyhow::Result<()> {
    match args.cmd {
        SimCmd::Bench => anyhow::bail!("not implemented yet"),
    }
}
