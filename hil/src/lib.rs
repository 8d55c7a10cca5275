#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`scenario`]: the TOML format (`hil/scenarios/*.toml`) → a timeline.
//! - [`mod@run`]: one scenario → an [`Outcome`].
//! - [`outcome`]: what a run produced, from decoded frames only (plus the truth).
//! - [`check`]: the file's expectations against the outcome.
//! - [`report`]: the results table and the goals.
//! - [`accuracy`]: the ice estimator's accuracy table (bias, RMS, σ honesty, √CRLB, medium).
//! - [`icing_accuracy`]: the icing rate and the icing period against the truth (the growth history).

pub mod accuracy;
pub mod check;
pub mod icing_accuracy;
pub mod outcome;
pub mod report;
pub mod run;
pub mod scenario;

pub use outcome::Outcome;
pub use run::{run, run_all};
pub use scenario::{Scenario, load, load_dir};
