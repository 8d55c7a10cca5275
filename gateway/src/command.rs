//! The node command vocabulary shared by every front end: [`NodeCommand`]
//! (the words `ack` and `calibrate-dark`, their parser, the protocol command
//! the serial reader sends), how an MQTT command message names its word
//! ([`command_word`]), and [`FrontEndCommand`], a command from a front end
//! other than MQTT (Modbus) on its way to the state machine.

use fois_link::versioned;
use fois_protocol::Command;

/// The longest command message read, bytes: anything longer is skipped
/// (the longest command, `{"command": "calibrate-dark"}` with blanks, is
/// far below).
pub const MAX_COMMAND_BYTES: usize = 256;

/// A command for a node, from any front end (MQTT, Modbus).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeCommand {
    /// Acknowledge the ice alarm.
    AckAlarm,
    /// Take the dark baseline.
    CalibrateDark,
}

impl NodeCommand {
    /// Parse a command payload (`ack`, `calibrate-dark`; case and
    /// surrounding blanks ignored).
    pub fn parse(s: &str) -> Option<NodeCommand> {
        match s.trim().to_ascii_lowercase().as_str() {
            "ack" | "ack-alarm" | "ack_alarm" => Some(NodeCommand::AckAlarm),
            "calibrate-dark" | "calibrate_dark" => Some(NodeCommand::CalibrateDark),
            _ => None,
        }
    }

    /// The command's name.
    pub fn name(self) -> &'static str {
        match self {
            NodeCommand::AckAlarm => "ack",
            NodeCommand::CalibrateDark => "calibrate-dark",
        }
    }

    /// The protocol command the reader sends to a node of protocol
    /// `node_version`: the guarded, unforced dark calibration and the
    /// acknowledgement that answers `NoAlarm` from version 4, the older
    /// commands before (a forced calibration is for `foisctl` at the node).
    pub fn wire_command(self, node_version: u16) -> Command {
        match self {
            NodeCommand::AckAlarm => versioned::ack_command(node_version),
            NodeCommand::CalibrateDark => {
                versioned::dark_command(node_version, false).unwrap_or(Command::CalibrateDark)
            }
        }
    }
}

/// The command word of an MQTT command message: `{"command": "ack"}` or
/// plain `ack` (the text itself when it is not such a JSON object).
pub fn command_word(text: &str) -> String {
    serde_json::from_str::<serde_json::Value>(text)
        .ok()
        .and_then(|v| {
            v.get("command")
                .and_then(|c| c.as_str())
                .map(str::to_string)
        })
        .unwrap_or_else(|| text.to_string())
}

/// A command for a node from a front end other than MQTT; its answer is
/// published on `<node>/command/result` and logged like an MQTT command's.
#[derive(Debug)]
pub struct FrontEndCommand {
    /// The node's index in the config.
    pub node: usize,
    /// The command.
    pub command: NodeCommand,
    /// Where the state machine says whether it handed the command to the
    /// node (`None`: nobody waits). A command whose waiter has gone (it
    /// answered the client already) is not carried out.
    pub reply: Option<tokio::sync::oneshot::Sender<Result<(), Refusal>>>,
}

/// Why the state machine refused a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// The node is offline (or not configured).
    Offline,
    /// The node's previous command was less than `[commands]
    /// min_interval_ms` ago.
    RateLimit,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_words_parse() {
        assert_eq!(NodeCommand::parse(" ACK\n"), Some(NodeCommand::AckAlarm));
        assert_eq!(
            NodeCommand::parse("calibrate-dark"),
            Some(NodeCommand::CalibrateDark)
        );
        assert_eq!(NodeCommand::parse("reset"), None);
        assert_eq!(NodeCommand::parse(""), None);
        assert_eq!(command_word(r#"{"command": "ack"}"#), "ack");
        assert_eq!(command_word(" calibrate-dark\n"), " calibrate-dark\n");
        assert_eq!(command_word(r#"{"cmd": "ack"}"#), r#"{"cmd": "ack"}"#);
    }

    #[test]
    fn an_older_node_gets_the_commands_it_knows() {
        assert_eq!(NodeCommand::AckAlarm.wire_command(3), Command::AckAlarm);
        assert_eq!(NodeCommand::AckAlarm.wire_command(4), Command::AckAlarmV4);
        assert_eq!(
            NodeCommand::CalibrateDark.wire_command(2),
            Command::CalibrateDark
        );
        assert_eq!(
            NodeCommand::CalibrateDark.wire_command(4),
            Command::CalibrateDarkV4 { force: false }
        );
    }
}
