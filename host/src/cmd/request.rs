//! Commands that send one request and wait for the node's `Ack` or `Error`:
//! `calibrate-dark` (with `--force`), `calibrate-gain`, `reset-gain` and
//! `ack` here (refusals of a calibration say what to do next), and the
//! connection and reply handling that `config get|set` shares.

use std::time::Duration;

use clap::Args;
use fois_link::advice::{Calibration, calibration_advice};
use fois_link::versioned;
use fois_protocol::{AckResult, Command, GainTarget, Hello};

use super::args::PortArgs;
use crate::exit::{self, Exit};
use fois_link::text::ack_text;
use fois_link::{Link, Reply, open_port};

/// The port and how long to wait for each answer.
#[derive(Debug, Clone, Args)]
pub struct RequestArgs {
    /// The serial port of the node.
    #[command(flatten)]
    pub port: PortArgs,
    /// How long to wait for the node's answer, ms. The default covers the
    /// node's worst case (5.83 s: a dark calibration of its longest averaging
    /// time behind a save that erases a flash sector) with 2 s to spare.
    #[arg(long, default_value_t = fois_protocol::REPLY_TIMEOUT_MS, value_name = "MS",
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
        self.connect_hello().map(|(link, _)| link)
    }

    /// [`RequestArgs::connect`], with the node's hello (its protocol
    /// version picks the shape of a command).
    pub fn connect_hello(&self) -> anyhow::Result<(Link<Box<dyn serialport::SerialPort>>, Hello)> {
        let port = open_port(&self.port.port, self.port.baud)?;
        let mut link = Link::new(port, self.port.port.clone());
        let _ = link.port_mut().clear(serialport::ClearBuffer::Input);
        let hello = link.handshake(self.timeout())?;
        Ok((link, hello))
    }
}

/// Print an `Ack` and give its result; an `Error` becomes exit code 6.
pub fn expect_ack(reply: Reply) -> anyhow::Result<AckResult> {
    if let Reply::Ack(a) = &reply {
        println!("ack: {}", ack_text(a));
    }
    ack_result(reply)
}

/// The result of an `Ack`, or the node's refusal as exit code 6, printing
/// nothing (the caller says what the answer means).
pub fn ack_result(reply: Reply) -> anyhow::Result<AckResult> {
    match reply {
        Reply::Ack(a) => Ok(a.result),
        Reply::Error(e) => Err(Exit::new(
            exit::REFUSED,
            format!(
                "the node refused the command: {}",
                fois_link::text::error_text(&e)
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

/// Send `cmd` for calibration `cal`, print the answer; a refusal (exit
/// code 6) says what to do next.
fn calibration_request(
    link: &mut Link<Box<dyn serialport::SerialPort>>,
    args: &RequestArgs,
    cal: Calibration,
    cmd: Command,
) -> anyhow::Result<AckResult> {
    let reply = link.request(cmd, args.timeout())?;
    if let Reply::Error(e) = &reply
        && let Some(advice) = calibration_advice(cal, &e.code)
    {
        return Err(Exit::new(
            exit::REFUSED,
            format!(
                "the node refused the calibration: {}\nwhat to do: {advice}",
                fois_link::text::error_text(e)
            ),
        )
        .into());
    }
    expect_ack(reply)
}

/// `foisctl calibrate-dark`: the port, the answer timeout and `--force`.
#[derive(Debug, Clone, Args)]
pub struct CalibrateDarkArgs {
    /// The port and the answer timeout.
    #[command(flatten)]
    pub request: RequestArgs,
    /// Take the reading even if the face does not read dry or the baseline
    /// moves further than the noise allows from the stored one: only when
    /// the face is clean and dry and the change is real (a new LED, a
    /// cleaned window). The checks of the reading itself (steady, not
    /// saturated) still apply. Protocol-4 nodes.
    #[arg(long)]
    pub force: bool,
}

/// `foisctl calibrate-dark [--force]`.
pub fn calibrate_dark(args: &CalibrateDarkArgs) -> anyhow::Result<()> {
    let (mut link, hello) = args.request.connect_hello()?;
    let cmd = versioned::dark_command(hello.protocol_version, args.force)
        .map_err(|why| Exit::new(exit::USAGE, why))?;
    calibration_request(&mut link, &args.request, Calibration::Dark, cmd).map(|_| ())
}

/// `foisctl ack`: acknowledge the alarm; exit code 8 when there is none.
pub fn ack(args: &RequestArgs) -> anyhow::Result<()> {
    let (mut link, hello) = args.connect_hello()?;
    let cmd = versioned::ack_command(hello.protocol_version);
    match expect_ack(link.request(cmd, args.timeout())?)? {
        AckResult::NoAlarm => {
            Err(Exit::new(exit::NO_ALARM, "no alarm to acknowledge: nothing changed").into())
        }
        _ => Ok(()),
    }
}

/// `foisctl calibrate-gain`: the reference target and the node.
#[derive(Debug, Clone, Args)]
pub struct CalibrateGainArgs {
    /// The port and the answer timeout.
    #[command(flatten)]
    pub request: RequestArgs,
    /// The target's expected channel-1 net current at gain 1, µA (from its
    /// data sheet or a reference node).
    #[arg(long, value_name = "UA", value_parser = target_ua)]
    pub i1_ua: f64,
    /// The target's expected channel-2 net current at gain 1, µA.
    #[arg(long, value_name = "UA", value_parser = target_ua)]
    pub i2_ua: f64,
}

/// A target current: finite, > 0 and < 1 A (nA on the wire, as a u32).
fn target_ua(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number of µA"))?;
    if !(v.is_finite() && v > 0.0 && v * 1000.0 < f64::from(u32::MAX)) {
        return Err(format!(
            "{s} µA is not a usable target current (0 < I < 4.29e6 µA)"
        ));
    }
    Ok(v)
}

impl CalibrateGainArgs {
    /// The target as the wire carries it (nA).
    pub fn target(&self) -> GainTarget {
        let na = |ua: f64| (ua * 1000.0).round() as u32;
        GainTarget {
            i1_na: na(self.i1_ua),
            i2_na: na(self.i2_ua),
        }
    }
}

/// `foisctl calibrate-gain`: with the reference target on the face, the
/// node measures its optical gain against the target's expected currents.
pub fn calibrate_gain(args: &CalibrateGainArgs) -> anyhow::Result<()> {
    let mut link = args.request.connect()?;
    let cmd = Command::CalibrateGain(args.target());
    calibration_request(&mut link, &args.request, Calibration::Gain, cmd).map(|_| ())
}

/// `foisctl reset-gain`: the node forgets its learned optical gain.
pub fn reset_gain(args: &RequestArgs) -> anyhow::Result<()> {
    request(args, Command::ResetGain).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_currents_are_checked_and_rounded_to_na() {
        assert!(target_ua("0").is_err());
        assert!(target_ua("-3").is_err());
        assert!(target_ua("nan").is_err());
        assert!(target_ua("1e9").is_err());
        assert!(target_ua("x").unwrap_err().contains("not a number"));
        assert_eq!(target_ua(" 25.2 "), Ok(25.2));
    }
}
