//! Commands typed into a running `foisctl monitor` or `foisctl demo` (a
//! letter and Enter on its terminal), so the node can be acknowledged or
//! dark-calibrated without freeing its port: `a` acknowledges the alarm,
//! `d` takes the dark baseline, `l` prints the legend again. Read on a
//! thread of its own, only when stdin is a terminal.

use std::io::{BufRead, IsTerminal};
use std::sync::mpsc::{Receiver, channel};

use fois_link::versioned;
use fois_protocol::Command;

/// What a typed line asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key {
    /// `a`: `AckAlarmV4` (`AckAlarm` to an older node).
    Ack,
    /// `d`: `CalibrateDarkV4` unforced (`CalibrateDark` to an older node).
    CalibrateDark,
    /// `l`: print the legend.
    Legend,
}

/// The keys, for the monitor's first line.
pub const HELP: &str =
    "keys (letter + Enter): a acknowledge the alarm, d dark-calibrate (dry, clean face), l legend";

impl Key {
    /// The key a typed line means (`None`: not a key; said so by the caller).
    pub fn parse(line: &str) -> Option<Key> {
        match line.trim().to_ascii_lowercase().as_str() {
            "a" | "ack" => Some(Key::Ack),
            "d" | "dark" => Some(Key::CalibrateDark),
            "l" | "legend" | "?" | "h" => Some(Key::Legend),
            _ => None,
        }
    }

    /// The command it sends to a node of protocol `node_version` (`None`
    /// for the legend). The dark calibration is never forced from a key:
    /// that takes `foisctl calibrate-dark --force`.
    pub fn command(self, node_version: u16) -> Option<Command> {
        match self {
            Key::Ack => Some(versioned::ack_command(node_version)),
            Key::CalibrateDark => versioned::dark_command(node_version, false).ok(),
            Key::Legend => None,
        }
    }
}

/// Read lines from stdin on a thread of its own when it is a terminal;
/// each line arrives as `Ok(key)` or, when it is no key, `Err(line)`.
pub fn spawn() -> Option<Receiver<Result<Key, String>>> {
    if !std::io::stdin().is_terminal() {
        return None;
    }
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            if line.trim().is_empty() {
                continue;
            }
            let k = Key::parse(&line).ok_or(line);
            if tx.send(k).is_err() {
                break;
            }
        }
    });
    Some(rx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_map_to_the_node_s_commands() {
        assert_eq!(Key::parse(" a\n"), Some(Key::Ack));
        assert_eq!(Key::parse("D"), Some(Key::CalibrateDark));
        assert_eq!(Key::parse("l"), Some(Key::Legend));
        assert_eq!(Key::parse("x"), None);
        assert_eq!(Key::Ack.command(4), Some(Command::AckAlarmV4));
        assert_eq!(
            Key::CalibrateDark.command(4),
            Some(Command::CalibrateDarkV4 { force: false })
        );
        assert_eq!(Key::Ack.command(3), Some(Command::AckAlarm));
        assert_eq!(Key::CalibrateDark.command(3), Some(Command::CalibrateDark));
        assert_eq!(Key::Legend.command(4), None);
    }
}
