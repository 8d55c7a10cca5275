//! `foisctl` as a library: every subcommand lives in its own module so the
//! hardware-in-loop suite and the benchmarks can drive the same code.

pub mod bench;
pub mod cmd;
pub mod compare;
pub mod csvlog;
pub mod exit;
pub mod link;
pub mod monitor;
pub mod plot;
pub mod serve;
pub mod text;
pub mod timefmt;
