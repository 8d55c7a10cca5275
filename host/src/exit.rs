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

/// `foisctl update`: the node's protocol has no update commands (< 6).
pub const NODE_TOO_OLD: i32 = 10;
/// `foisctl update` / `image-info`: the file is not a signed image.
pub const BAD_IMAGE: i32 = 11;
/// `foisctl update`: the image is for another board.
pub const WRONG_BOARD: i32 = 12;
/// `foisctl update`: the image is not newer and not a signed downgrade.
pub const OLDER_VERSION: i32 = 13;
/// `foisctl update` / `image-info --key`: the signature does not verify.
pub const BAD_SIGNATURE: i32 = 14;
/// `foisctl update`: the image does not fit the node's update slot.
pub const TOO_LARGE: i32 = 15;
/// `foisctl update`: the node's copy does not match the image (digest,
/// trailer, a chunk's CRC): the slot was abandoned, run it again.
pub const CORRUPTED: i32 = 16;
/// `foisctl update`: the node cannot take an update now (busy, or its own
/// image still on trial): try again later.
pub const NODE_BUSY: i32 = 17;
/// `foisctl update`: erasing or programming the node's update slot failed.
pub const FLASH_FAILED: i32 = 18;
/// `foisctl update`: the new image failed its trial boot; the node rolled
/// back to the old one.
pub const ROLLED_BACK: i32 = 19;
/// `foisctl update`: the node did not come back, or did not confirm the new
/// image, in time.
pub const NOT_CONFIRMED: i32 = 20;

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

/// The exit codes of `update`, for its `--help` (and README.md).
pub const UPDATE_TABLE: &str = "Exit codes: 0 the node runs the image, confirmed (or ran it \
already); 1 other failure; 2 bad command line; 3 serial port cannot be opened; 4 the link stayed \
down (no answer, port gone) longer than --resume-timeout-s: run the same command again to \
continue where the node is; 5 node speaks an incompatible protocol version; 6 the node refused \
a step for another reason (named); 10 the node's protocol is older than 6 (no updates over the \
link: flash it once with a probe); 11 the file is not a signed image; 12 the image is for \
another board; 13 the image is not newer than the node's and not signed as a downgrade; 14 the \
signature does not verify with the node's key; 15 the image does not fit the node's update \
slot; 16 the node's copy did not match (digest, trailer, chunk CRC; the copy was abandoned); \
17 the node cannot take an update now (busy, or its own image still on trial); 18 erasing or \
programming the node's update slot failed; 19 the new image failed its trial boot and the node \
rolled back; 20 the node did not come back or did not confirm the new image in time.";

/// The exit codes of `keygen`, `sign` and `image-info`, for their `--help`.
pub const SIGN_TABLE: &str = "Exit codes: 0 success (image-info --key: the signature \
verifies); 1 failure (a file cannot be read or written, a key file that is not 64 hex digits, \
keygen: a key file exists already); 2 bad command line (a version that is not X.Y.Z); 7 sign: \
the body is over 128 KiB less the trailer, empty, or the board name over 16 characters; \
11 image-info: not a signed image; 14 image-info --key: the signature does not verify.";

/// The exit code of an update's failure.
pub fn update_code(e: &fois_link::update::UpdateError) -> i32 {
    use fois_link::update::UpdateError as E;
    use fois_protocol::UpdateRefusal as R;
    match e {
        E::Link(l) => link_code(l),
        E::NodeTooOld { .. } => NODE_TOO_OLD,
        E::Refused { refusal, .. } => match refusal {
            R::WrongBoard => WRONG_BOARD,
            R::OlderVersion { .. } => OLDER_VERSION,
            R::BadSignature => BAD_SIGNATURE,
            R::BadLength { .. } => TOO_LARGE,
            R::DigestMismatch | R::BadTrailer | R::ChunkCrc => CORRUPTED,
            R::Busy | R::OnTrial => NODE_BUSY,
            R::FlashFailed => FLASH_FAILED,
            R::NoTransfer | R::OutOfOrder { .. } | R::Incomplete { .. } | R::NotVerified => REFUSED,
        },
        E::NodeError { .. } | E::Unexpected { .. } => REFUSED,
        E::LinkDown { .. } => TIMEOUT,
        E::NoBoot { .. } | E::NotConfirmed { .. } => NOT_CONFIRMED,
        E::RolledBack { .. } => ROLLED_BACK,
    }
}

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
            err.chain().find_map(|e| {
                e.downcast_ref::<fois_link::update::UpdateError>()
                    .map(update_code)
            })
        })
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
    fn every_update_refusal_has_its_named_exit_code() {
        use fois_link::update::{Step, UpdateError};
        use fois_protocol::UpdateRefusal as R;
        let refused = |refusal| UpdateError::Refused {
            step: Step::Verify,
            refusal,
            by_host: false,
        };
        for (refusal, code) in [
            (R::WrongBoard, WRONG_BOARD),
            (
                R::OlderVersion {
                    running: [1, 0, 0],
                    image: [0, 9, 0],
                },
                OLDER_VERSION,
            ),
            (R::BadSignature, BAD_SIGNATURE),
            (R::BadLength { max_bytes: 1 }, TOO_LARGE),
            (R::DigestMismatch, CORRUPTED),
            (R::BadTrailer, CORRUPTED),
            (R::ChunkCrc, CORRUPTED),
            (R::Busy, NODE_BUSY),
            (R::OnTrial, NODE_BUSY),
            (R::FlashFailed, FLASH_FAILED),
            (R::NoTransfer, REFUSED),
            (R::NotVerified, REFUSED),
        ] {
            let e = anyhow::Error::from(refused(refusal)).context("update");
            assert_eq!(code_of(&e), code, "{refusal:?}");
            // Every code is in the --help table.
            assert!(UPDATE_TABLE.contains(&format!(" {code} ")), "{code}");
        }
        let rolled = UpdateError::RolledBack {
            failed: [0, 7, 0],
            running: [0, 6, 0],
        };
        assert_eq!(code_of(&rolled.into()), ROLLED_BACK);
        assert_eq!(
            code_of(&UpdateError::NodeTooOld { node: 5, since: 6 }.into()),
            NODE_TOO_OLD
        );
        assert_eq!(
            code_of(&UpdateError::NoBoot { waited_ms: 1 }.into()),
            NOT_CONFIRMED
        );
        let down = UpdateError::LinkDown {
            step: Step::Transfer,
            offset: 1024,
            total: 2048,
            waited_ms: 60_000,
            cause: "gone".into(),
        };
        assert!(down.to_string().contains("run the update again"), "{down}");
        assert_eq!(code_of(&down.into()), TIMEOUT);
    }

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
