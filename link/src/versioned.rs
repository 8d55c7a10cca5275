//! The command a host sends for an action, in the shape the node's protocol
//! version reads: a version-4 node gets the guarded dark calibration and
//! the acknowledgement that answers `NoAlarm`; an older node the commands
//! it knows (it cannot decode a newer variant).

use fois_protocol::Command;

/// The first protocol version with `CalibrateDarkV4` and `AckAlarmV4`.
pub const GUARDED_COMMANDS_SINCE: u16 = 4;

/// The dark calibration for a node of `node_version`; `Err` (why, in
/// words) when `force` is asked of a node that cannot be forced.
pub fn dark_command(node_version: u16, force: bool) -> Result<Command, String> {
    if node_version >= GUARDED_COMMANDS_SINCE {
        Ok(Command::CalibrateDarkV4 { force })
    } else if force {
        Err(format!(
            "the node speaks protocol version {node_version}: a forced dark calibration needs \
             version {GUARDED_COMMANDS_SINCE} (update its firmware); without --force it \
             calibrates with its own checks"
        ))
    } else {
        Ok(Command::CalibrateDark)
    }
}

/// The alarm acknowledgement for a node of `node_version`.
pub fn ack_command(node_version: u16) -> Command {
    if node_version >= GUARDED_COMMANDS_SINCE {
        Command::AckAlarmV4
    } else {
        Command::AckAlarm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn older_nodes_get_the_commands_they_know() {
        for v in 1..=3 {
            assert_eq!(dark_command(v, false), Ok(Command::CalibrateDark));
            assert!(dark_command(v, true).unwrap_err().contains("version 4"));
            assert_eq!(ack_command(v), Command::AckAlarm);
        }
        assert_eq!(
            dark_command(4, true),
            Ok(Command::CalibrateDarkV4 { force: true })
        );
        assert_eq!(
            dark_command(4, false),
            Ok(Command::CalibrateDarkV4 { force: false })
        );
        assert_eq!(ack_command(4), Command::AckAlarmV4);
    }
}
