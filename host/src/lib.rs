//! `foisctl` as a library: every subcommand lives in its own module so the
//! hardware-in-loop suite and the benchmarks can drive the same code.

pub mod sim_cmd;
