//! Exit codes of `foisctl`, the error type that carries one, and the codes
//! of the link's errors.

use std::fmt;

use fois_link::LinkError;

/// Success.
pub const OK: i32 = 0;
/// Any other failure (I/O, unreadable log, plotting).
pub const FAILURE: i32 = 1;
/// Bad command line (clap's own code).
pub const USAGE: i32 = 2;
/// The serial port could not be opened.
pub const PORT: i32 = 3;
/// The node did not answer in time (or the link was lost).
pub const TIMEOUT: i32 = 4;
/// The node speaks another protocol version.
pub const INCOMPATIBLE: i32 = 5;
/// The node answered with an `Error` (command refused).
pub const REFUSED: i32 = 6;
/// A `KEY=VALUE` was refused on the host (unknown key, not a number, out of range).
pub const INVALID_VALUE: i32 = 7;
/// `foisctl ack`: the node has no alarm to acknowledge (nothing changed).
pub const NO_ALARM: i32 = 8;

/// The exit-code table, for `--help`.
pub const TABLE: &str = "Exit codes: 0 success; 1 other failure (I/O, unreadable file); \
2 bad command line; 3 serial port cannot be opened; 4 no answer from the node in time; \
5 node speaks an incompatible protocol version; 6 node refused the command (Error reply); \
7 KEY=VALUE refused on the host (unknown key, not a number, out of range).";

/// The exit codes of `calibrate-dark`, for its `--help`.
pub const CALIBRATE_DARK_TABLE: &str = "Exit codes: 0 calibrated (the new baseline is printed); \
1 other failure; 2 bad command line, or --force asked of a node older than protocol version 4; \
3 serial port cannot be opened; 4 no answer from the node in time; 5 node speaks an \
incompatible protocol version; 6 the node refused the calibration: the face is not dry \
(FaceNotDry/NotDry), the baseline would move further than the noise allows (BaselineShift: \
old → new, use --force only if the change is real), or the reading was not steady \
(CalibrationRefused: step, trend, noise, saturation); what to do is printed.";

/// The exit codes of `ack`, for its `--help`.
pub const ACK_TABLE: &str = "Exit codes: 0 the alarm was acknowledged; 1 other failure; \
2 bad command line; 3 serial port cannot be opened; 4 no answer from the node in time; \
5 node speaks an incompatible protocol version; 6 node refused the command; 8 there was no \
alarm to acknowledge (NoAlarm, nothing changed; a node older than protocol version 4 cannot \
tell and answers AlarmAcknowledged).";

/// The exit codes of the commands that work on files only (plot, compare,
/// estimate, sim, bench-decode), for their `--help`.
pub const OFFLINE_TABLE: &str = "Exit codes: 0 success; 1 failure (an input cannot be read or is \
not the file expected, an output cannot be written, a figure cannot be drawn); 2 bad command line \
(unknown flag, value out of range or negative where it must not be, figure format other than .png \
or .svg).";

/// The exit codes of `virtual-node` and `demo`, for their `--help`.
pub const SERVE_TABLE: &str = "Exit codes: 0 success (a first Ctrl-C stops cleanly and exits 0); \
1 failure (no pseudo-terminal, a bad scenario or --state file, a log that cannot be written); \
2 bad command line; demo only: 3, 4, 5 as for `foisctl monitor` if its monitor cannot open or talk \
to the node's pseudo-terminal; 130 a second Ctrl-C (stops at once).";

/// An error with the exit code it maps to.
#[derive(Debug)]
pub struct Exit {
    /// Process exit code.
    pub code: i32,
    /// What to tell the user.
    pub message: String,
}

impl Exit {
    /// An error with a code.
    pub fn new(code: i32, message: impl Into<String>) -> Exit {
        Exit {
            code,
            message: message.into(),
        }
    }
}

impl fmt::Display for Exit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Exit {}

/// The exit code of a link error.
pub fn link_code(e: &LinkError) -> i32 {
    match e {
        LinkError::Open { .. } => PORT,
        LinkError::Lost(..) | LinkError::Timeout { .. } => TIMEOUT,
        LinkError::Incompatible { .. } => INCOMPATIBLE,
    }
}

/// The exit code of an `anyhow` error: the [`Exit`] code inside it, else
/// that of a [`LinkError`] inside it, else 1.
pub fn code_of(err: &anyhow::Error) -> i32 {
    err.chain()
        .find_map(|e| e.downcast_ref::<Exit>().map(|x| x.code))
        .or_else(|| {
            err.chain()
                .find_map(|e| e.downcast_ref::<LinkError>().map(link_code))
        })
        .unwrap_or(FAILURE)
}

/// A hint for an error a user can fix, printed after it: a port held by
/// another program (serialport's "Unable to acquire exclusive lock", or
/// the kernel's "busy") names what usually holds it.
pub fn hint(err: &anyhow::Error) -> Option<String> {
    let port = err
        .chain()
        .find_map(|e| match e.downcast_ref::<LinkError>() {
            Some(LinkError::Open { port, reason }) => Some((port.clone(), reason.to_lowercase())),
            _ => None,
        })?;
    let (port, reason) = port;
    (reason.contains("exclusive lock") || reason.contains("busy")).then(|| {
        format!(
            "{port} is held by another program, most likely a running `foisctl monitor` \
             (or `foisctl demo`) or the fleet gateway (`fois-gateway`, systemd unit \
             fois-gateway) that has it in its config. Stop that program (Ctrl-C in the \
             monitor's terminal; `sudo systemctl stop fois-gateway`), run this command, \
             then start it again; `fuser {port}` or `lsof {port}` shows the process."
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_port_gets_a_hint_naming_monitor_and_gateway() {
        let held = anyhow::Error::from(LinkError::Open {
            port: "/dev/ttyACM0".into(),
            reason: "Unable to acquire exclusive lock on serial port".into(),
        })
        .context("calibrate-dark");
        let h = hint(&held).unwrap();
        assert!(
            h.contains("foisctl monitor") && h.contains("fois-gateway"),
            "{h}"
        );
        assert!(h.contains("/dev/ttyACM0"), "{h}");
        let missing = anyhow::Error::from(LinkError::Open {
            port: "/dev/ttyACM0".into(),
            reason: "No such file or directory".into(),
        });
        assert_eq!(hint(&missing), None);
        assert_eq!(hint(&anyhow::anyhow!("disk full")), None);
    }

    #[test]
    fn link_errors_and_wrapped_exits_map_to_their_codes() {
        let open = LinkError::Open {
            port: "p".into(),
            reason: "r".into(),
        };
        let timeout = LinkError::Timeout {
            port: "p".into(),
            waited_ms: 1,
            hint: String::new(),
        };
        let other = LinkError::Incompatible {
            node: 9,
            host: 2,
            oldest: 1,
            hello: String::new(),
        };
        let lost = LinkError::Lost("p".into(), "gone".into());
        for (e, code) in [
            (open, PORT),
            (timeout, TIMEOUT),
            (lost, TIMEOUT),
            (other, INCOMPATIBLE),
        ] {
            let wrapped = anyhow::Error::from(e).context("while talking to the node");
            assert_eq!(code_of(&wrapped), code);
        }
        let e = anyhow::Error::from(Exit::new(REFUSED, "no")).context("config set");
        assert_eq!(code_of(&e), REFUSED);
        assert_eq!(code_of(&anyhow::anyhow!("disk full")), FAILURE);
    }
}
