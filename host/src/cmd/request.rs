//! Commands that send one request and wait for the node's `Ack` or `Error`:
//! `calibrate-dark` and `ack` here, and the connection and reply handling
//! that `config get|set` shares.

use std::time::Duration;

use clap::Args;
use fois_protocol::{AckResult, Command};

use super::args::PortArgs;
use crate::exit::{self, Exit};
use crate::link::{Link, Reply, open_port};
use crate::text::ack_text;

/// The port and how long to wait for each answer.
#[derive(Debug, Clone, Args)]
pub struct RequestArgs {
    /// The serial port of the node.
    #[command(flatten)]
    pub port: PortArgs,
    /// How long to wait for the node's answer, ms.
    #[arg(long, default_value_t = 3000, value_name = "MS",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub timeout_ms: u64,
}

impl RequestArgs {
    /// The answer timeout.
    pub fn timeout(&self) -> Duration {
        Duration::from_millis(self.timeout_ms)
    }

    /// Open the port and handshake (refuses another protocol version).
    pub fn connect(&self) -> anyhow::Result<Link<Box<dyn serialport::SerialPort>>> {
        let port = open_port(&self.port.port, self.port.baud)?;
        let mut link = Link::new(port, self.port.port.clone());
        let _ = link.port_mut().clear(serialport::ClearBuffer::Input);
        link.handshake(self.timeout())?;
        Ok(link)
    }
}

/// Print an `Ack` and give its result; an `Error` becomes exit code 6.
pub fn expect_ack(reply: Reply) -> anyhow::Result<AckResult> {
    match reply {
        Reply::Ack(a) => {
            println!("ack: {}", ack_text(&a));
            Ok(a.result)
        }
        Reply::Error(e) => Err(Exit::new(
            exit::REFUSED,
            format!(
                "the node refused the command: {}",
                crate::text::error_text(&e)
            ),
        )
        .into()),
    }
}

/// Send `cmd`, print the answer.
pub fn request(args: &RequestArgs, cmd: Command) -> anyhow::Result<AckResult> {
    let mut link = args.connect()?;
    let r = link.request(cmd, args.timeout())?;
    expect_ack(r)
}

/// `foisctl calibrate-dark`.
pub fn calibrate_dark(args: &RequestArgs) -> anyhow::Result<()> {
    request(args, Command::CalibrateDark).map(|_| ())
}

/// `foisctl ack`: acknowledge the alarm.
pub fn ack(args: &RequestArgs) -> anyhow::Result<()> {
    request(args, Command::AckAlarm).map(|_| ())
}
