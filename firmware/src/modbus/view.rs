//! What the Modbus server sees of the node ([`ModbusView`], a copy taken
//! after each frame and command) and what it asks the node to do
//! ([`Action`]): the server answers from the copy at once, without waiting
//! for the node (a frame or a flash erase may hold it), and the node
//! carries the actions out after the answer.

use fois_protocol::registers::{self, CommandResult, NODE_REGISTERS, REGISTERS};
use fois_protocol::{AckResult, Command, Config, ErrorCode, LinkSettings};

/// The node as the registers show it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusView {
    /// The measurement block (`fois_protocol::registers::measurement_registers`).
    pub registers: [u16; REGISTERS],
    /// The config in force (the writable setpoints are part of it).
    pub config: Config,
    /// The link settings in force.
    pub link: LinkSettings,
}

impl Default for ModbusView {
    fn default() -> Self {
        ModbusView {
            registers: registers::not_available(),
            config: Config::default(),
            link: LinkSettings::default(),
        }
    }
}

impl ModbusView {
    /// The node block's registers (the server fills in its own: write
    /// enable and the last result).
    pub fn node_block(&self, write_enabled: bool, last: CommandResult) -> [u16; NODE_REGISTERS] {
        let c = &self.config;
        [
            u16::from(write_enabled),
            0,
            last as u16,
            match self.link.protocol {
                fois_protocol::LinkProtocol::Framed => 0,
                fois_protocol::LinkProtocol::ModbusRtu => 1,
            },
            u16::from(self.link.modbus_address),
            self.link.parity.code(),
            c.freeze_limit_centi_c as u16,
            c.thaw_limit_centi_c as u16,
            c.onset_frames,
            c.clear_frames,
        ]
    }
}

/// What a write asks the node to do, after the answer.
// A `Command` can carry an update chunk (256 bytes): an `Action` lives on
// the stack for one write only, and there is no heap to box it on.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Acknowledge the alarm (`AckAlarmV4`).
    AckAlarm,
    /// A guarded dark calibration (`CalibrateDarkV4`, not forced).
    CalibrateDark,
    /// A new config (setpoints written), already validated.
    SetConfig(Config),
    /// New link settings (protocol, address, parity), already validated.
    SetLink(LinkSettings),
}

impl Action {
    /// The node command that carries it out.
    pub fn command(self) -> Command {
        match self {
            Action::AckAlarm => Command::AckAlarmV4,
            Action::CalibrateDark => Command::CalibrateDarkV4 { force: false },
            Action::SetConfig(c) => Command::SetConfigV3(c),
            Action::SetLink(l) => Command::SetLinkSettings(l),
        }
    }
}

/// The [`CommandResult`] register's value for a command's outcome.
pub fn command_result(r: &Result<AckResult, ErrorCode>) -> CommandResult {
    match r {
        Ok(AckResult::NoAlarm) => CommandResult::NoAlarm,
        Ok(_) => CommandResult::Done,
        Err(ErrorCode::InvalidConfig(_) | ErrorCode::InvalidLinkSettings(_)) => {
            CommandResult::InvalidConfig
        }
        Err(_) => CommandResult::Refused,
    }
}
