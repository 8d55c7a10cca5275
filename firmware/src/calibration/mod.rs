//! Calibrations the node runs on command: the dark baseline under noise
//! ([`dark`]) and the optical gain against a known target ([`gain`], with
//! the kept gain's bookkeeping).

pub mod dark;
pub mod gain;
