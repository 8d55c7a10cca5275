//! Which Home Assistant release the discovery messages are made for.
//!
//! Home Assistant refuses a whole discovery message when its `device`
//! object holds a key the release does not know ("extra keys not allowed"):
//! 2024.1 refuses `serial_number`, so every entity of a node would be lost.
//! The config names the oldest release the site runs
//! (`[homeassistant] version`, default [`HaVersion::OLDEST`]) and newer keys
//! are added only when that release takes them. Checked by `cargo xtask
//! ha-check` against real releases (gateway README, "Home Assistant").

use std::fmt;

/// A Home Assistant release, `YEAR.MONTH` (the patch level never changes
/// the discovery schema).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct HaVersion {
    /// Year, e.g. 2024.
    pub year: u16,
    /// Month release, 1–12.
    pub month: u8,
}

impl HaVersion {
    /// The oldest release the discovery is checked with (and the default).
    pub const OLDEST: HaVersion = HaVersion::new(2024, 1);
    /// `device.serial_number` is accepted from this release on (2024.1
    /// refuses the whole message).
    pub const SERIAL_NUMBER: HaVersion = HaVersion::new(2024, 2);
    /// MQTT enum sensors take `options` (their possible states) from this
    /// release on; earlier ones drop the key. Read from the release's
    /// source: releases after 2024.3 need Python 3.12, so the check cannot
    /// run them on Python 3.11.
    pub const ENUM_OPTIONS: HaVersion = HaVersion::new(2024, 9);

    /// `year.month`.
    pub const fn new(year: u16, month: u8) -> HaVersion {
        HaVersion { year, month }
    }

    /// Parse `2024.3` or `2024.3.3` (the patch is ignored). Refuses other
    /// shapes and releases older than [`HaVersion::OLDEST`].
    pub fn parse(s: &str) -> Result<HaVersion, String> {
        let mut parts = s.trim().split('.');
        let (Some(y), Some(m)) = (parts.next(), parts.next()) else {
            return Err(format!(
                "`{s}` is not a Home Assistant release: write YEAR.MONTH, e.g. 2024.3"
            ));
        };
        let patch_ok = match parts.next() {
            None => true,
            Some(p) => p.parse::<u32>().is_ok() && parts.next().is_none(),
        };
        let year = y.parse::<u16>().ok().filter(|y| (2000..=2999).contains(y));
        let month = m.parse::<u8>().ok().filter(|m| (1..=12).contains(m));
        let (Some(year), Some(month), true) = (year, month, patch_ok) else {
            return Err(format!(
                "`{s}` is not a Home Assistant release: write YEAR.MONTH, e.g. 2024.3"
            ));
        };
        let v = HaVersion { year, month };
        if v < HaVersion::OLDEST {
            return Err(format!(
                "{v} is older than {}, the oldest release the discovery messages are checked with",
                HaVersion::OLDEST
            ));
        }
        Ok(v)
    }

    /// The release takes `device.serial_number`.
    pub fn serial_number(self) -> bool {
        self >= HaVersion::SERIAL_NUMBER
    }

    /// The release takes `options` on MQTT enum sensors.
    pub fn enum_options(self) -> bool {
        self >= HaVersion::ENUM_OPTIONS
    }
}

impl Default for HaVersion {
    fn default() -> Self {
        HaVersion::OLDEST
    }
}

impl fmt::Display for HaVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.year, self.month)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn releases_parse_compare_and_gate_their_keys() {
        assert_eq!(HaVersion::parse("2024.3").unwrap(), HaVersion::new(2024, 3));
        assert_eq!(
            HaVersion::parse("2024.3.3").unwrap(),
            HaVersion::new(2024, 3)
        );
        assert_eq!(
            HaVersion::parse(" 2025.11 ").unwrap(),
            HaVersion::new(2025, 11)
        );
        assert!(HaVersion::new(2024, 12) < HaVersion::new(2025, 1));
        assert!(HaVersion::new(2024, 10) > HaVersion::new(2024, 9));
        for bad in [
            "2024",
            "2024.13",
            "2024.0",
            "24.1",
            "2024.1.x",
            "2024.1.2.3",
            "latest",
        ] {
            let e = HaVersion::parse(bad).unwrap_err();
            assert!(e.contains("YEAR.MONTH"), "{bad}: {e}");
        }
        let e = HaVersion::parse("2023.12").unwrap_err();
        assert!(e.contains("older than 2024.1"), "{e}");
        assert!(!HaVersion::OLDEST.serial_number());
        assert!(HaVersion::new(2024, 2).serial_number());
        assert!(!HaVersion::new(2024, 8).enum_options());
        assert!(HaVersion::new(2024, 9).enum_options());
        assert_eq!(HaVersion::default().to_string(), "2024.1");
    }
}
