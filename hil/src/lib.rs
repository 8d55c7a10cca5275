//! Hardware-in-loop scenario runner: the firmware's own `Node` on the host's
//! virtual hardware (sim curves → analog front end → simulated ADC), in
//! virtual time; its UART bytes decoded by the host's `FrameDecoder`; the
//! decoded frames checked against each scenario file's expectations, with
//! the environment's truth (thickness at each instant) beside them.
//!
//! - [`scenario`]: the TOML format (`hil/scenarios/*.toml`) → a timeline.
//! - [`run`]: one scenario → an [`run::Outcome`] (decoded frames only).
//! - [`check`]: the file's expectations against the outcome.
//! - [`report`]: the results table and the goals.

pub mod check;
pub mod report;
pub mod run;
pub mod scenario;

pub use run::{Outcome, run, run_all};
pub use scenario::{Scenario, load, load_dir};
