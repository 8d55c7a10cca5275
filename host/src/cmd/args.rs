//! Argument types shared by several commands: the serial port, one clap
//! `ValueEnum` per domain enum of the simulator and the virtual node, and the
//! number parsers that make clap refuse out-of-range values (exit code 2)
//! before a command runs.

use clap::{Args, ValueEnum};
use fois_sim::{IceKind, SensorKind};
use fois_vnode::Cover;

/// The serial port of a node.
#[derive(Debug, Clone, Args)]
pub struct PortArgs {
    /// Serial port of the node: /dev/ttyACM0 for a NUCLEO board, or the
    /// /dev/pts/N path a `foisctl virtual-node` prints.
    #[arg(long, short = 'p', value_name = "PATH")]
    pub port: String,
    /// Baud rate, 8N1 (the node's UART runs at 115200).
    #[arg(long, default_value_t = fois_protocol::BAUD_RATE, value_name = "BAUD",
          value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
}

/// The accreted medium ([`fois_sim::IceKind`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum IceArg {
    /// Ideal clear ice: flat surface, no bubbles (thesis §3.3).
    Flat,
    /// Glazed ice: slopes ±15°, P_B = 0.0015, diffuse ±30° (§5.3.3).
    Glazed,
    /// Rime ice: slopes ±10°, P_B = 0.21, no diffuse (§5.3.4).
    Rime,
    /// Clear water, n = 1.33, flat (§5.2.3).
    Water,
}

impl From<IceArg> for IceKind {
    fn from(a: IceArg) -> Self {
        match a {
            IceArg::Flat => IceKind::Flat,
            IceArg::Glazed => IceKind::Glazed,
            IceArg::Rime => IceKind::Rime,
            IceArg::Water => IceKind::Water,
        }
    }
}

/// Sensor construction ([`fois_sim::SensorKind`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SensorArg {
    /// Transparent separation: dry offset in I1 (thesis §5.2.1).
    A,
    /// Opaque separation: dry face reads ~0.
    B,
}

impl From<SensorArg> for SensorKind {
    fn from(a: SensorArg) -> Self {
        match a {
            SensorArg::A => SensorKind::A,
            SensorArg::B => SensorKind::B,
        }
    }
}

/// What covers the virtual node's face ([`fois_vnode::Cover`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CoverArg {
    /// Clean, dry face.
    Dry,
    /// Ideal clear ice.
    Flat,
    /// Glazed ice.
    Glazed,
    /// Rime ice.
    Rime,
    /// A clear water film.
    Water,
}

impl From<CoverArg> for Cover {
    fn from(a: CoverArg) -> Self {
        match a {
            CoverArg::Dry => Cover::Dry,
            CoverArg::Flat => Cover::Flat,
            CoverArg::Glazed => Cover::Glazed,
            CoverArg::Rime => Cover::Rime,
            CoverArg::Water => Cover::Water,
        }
    }
}

// The finite-number parsers are fois-link's (the gateway's command line
// uses them too).
pub use fois_link::numbers::{f64_in, non_negative, positive};

/// A worker-thread count ≥ 1.
pub fn threads(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        Ok(_) => Err("must be >= 1".into()),
        Err(_) => Err(format!("`{s}` is not a whole number")),
    }
}

/// `UA` (both channels) or `UA1,UA2`, each a finite number ≥ 0.
pub fn ua_pair(s: &str) -> Result<[f64; 2], String> {
    let nums: Result<Vec<f64>, String> = s.split(',').map(non_negative).collect();
    match nums.as_deref() {
        Ok([a]) => Ok([*a, *a]),
        Ok([a, b]) => Ok([*a, *b]),
        _ => Err(format!("`{s}` is not UA or UA1,UA2 (non-negative µA)")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_counts_and_current_pairs_refuse_bad_values() {
        assert_eq!(threads("2"), Ok(2));
        assert!(threads("0").is_err() && threads("-1").is_err());
        assert_eq!(ua_pair("3"), Ok([3.0, 3.0]));
        assert_eq!(ua_pair("3, 1.5"), Ok([3.0, 1.5]));
        for bad in ["-1", "1,2,3", "1,-2", "a"] {
            assert!(ua_pair(bad).is_err(), "{bad}");
        }
    }
}
