//! Version 5: which protocol the node speaks on its host link, and its
//! Modbus RTU settings. A type of its own (not [`Config`](crate::Config)
//! fields): it is set and read by its own commands
//! ([`Command::SetLinkSettings`](crate::Command::SetLinkSettings),
//! [`Command::GetLinkSettings`](crate::Command::GetLinkSettings)) and kept in
//! the node's record beside the config, so every older config shape and
//! command keeps its bytes.
//!
//! The baud rate is still no setting (the field link's strap sets it:
//! `fois_firmware::platform::field_link`).

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

/// The protocol on the host link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkProtocol {
    /// This crate's framed protocol (COBS + CRC-32 frames): the default.
    #[default]
    Framed,
    /// Modbus RTU (a slave at [`LinkSettings::modbus_address`]), serving
    /// the register map of [`crate::registers`].
    ModbusRtu,
}

/// Parity and stop bits of the Modbus RTU link (8 data bits always).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Parity {
    /// 8 data bits, even parity, 1 stop bit: the Modbus serial line
    /// specification's default.
    #[default]
    Even8E1,
    /// No parity, 2 stop bits (the specification's alternative).
    None8N2,
    /// No parity, 1 stop bit (common, outside the specification).
    None8N1,
}

impl Parity {
    /// Bits on the wire per character: start, 8 data, parity or a second
    /// stop bit, stop (8N1: 10).
    pub const fn bits_per_char(self) -> u32 {
        match self {
            Parity::Even8E1 | Parity::None8N2 => 11,
            Parity::None8N1 => 10,
        }
    }

    /// Its short name (`8E1`, `8N2`, `8N1`).
    pub const fn name(self) -> &'static str {
        match self {
            Parity::Even8E1 => "8E1",
            Parity::None8N2 => "8N2",
            Parity::None8N1 => "8N1",
        }
    }

    /// The register code ([`crate::registers::PARITY`]).
    pub const fn code(self) -> u16 {
        match self {
            Parity::Even8E1 => 0,
            Parity::None8N2 => 1,
            Parity::None8N1 => 2,
        }
    }

    /// The parity of a register code.
    pub const fn from_code(code: u16) -> Option<Parity> {
        match code {
            0 => Some(Parity::Even8E1),
            1 => Some(Parity::None8N2),
            2 => Some(Parity::None8N1),
            _ => None,
        }
    }
}

/// The lowest and highest Modbus slave address (0 is broadcast, 248–255
/// are reserved by the specification).
pub const MODBUS_ADDRESS_RANGE: core::ops::RangeInclusive<u8> = 1..=247;

/// The host link's protocol and Modbus settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkSettings {
    /// The protocol spoken.
    pub protocol: LinkProtocol,
    /// The node's Modbus address, 1–247.
    pub modbus_address: u8,
    /// Parity and stop bits of the Modbus link (the framed protocol runs 8N1).
    pub parity: Parity,
}

impl Default for LinkSettings {
    /// Framed; address 1, 8E1 ready for a switch to Modbus.
    fn default() -> Self {
        LinkSettings {
            protocol: LinkProtocol::Framed,
            modbus_address: 1,
            parity: Parity::Even8E1,
        }
    }
}

impl LinkSettings {
    /// The one rule: the address is 1–247.
    pub fn validate(&self) -> Result<(), LinkSettingsError> {
        if MODBUS_ADDRESS_RANGE.contains(&self.modbus_address) {
            Ok(())
        } else {
            Err(LinkSettingsError::AddressOutOfRange)
        }
    }

    /// The same settings speaking the framed protocol (the way back).
    pub fn framed(self) -> LinkSettings {
        LinkSettings {
            protocol: LinkProtocol::Framed,
            ..self
        }
    }
}

/// Why link settings were refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkSettingsError {
    /// The Modbus address is outside 1–247.
    AddressOutOfRange,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_address_rule_and_the_defaults() {
        let d = LinkSettings::default();
        assert_eq!(d.protocol, LinkProtocol::Framed);
        assert_eq!(d.parity, Parity::Even8E1);
        for (a, ok) in [
            (0, false),
            (1, true),
            (247, true),
            (248, false),
            (255, false),
        ] {
            let s = LinkSettings {
                modbus_address: a,
                ..d
            };
            assert_eq!(s.validate().is_ok(), ok, "{a}");
        }
        for p in [Parity::Even8E1, Parity::None8N2, Parity::None8N1] {
            assert_eq!(Parity::from_code(p.code()), Some(p));
        }
        assert_eq!(Parity::from_code(3), None);
        assert_eq!(Parity::None8N1.bits_per_char(), 10);
        assert_eq!(Parity::Even8E1.bits_per_char(), 11);
    }
}
