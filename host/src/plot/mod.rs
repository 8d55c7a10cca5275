//! The figures `foisctl` draws (PNG, plotters' bitmap backend):
//!
//! - [`log`]: a monitor log's currents over time (`foisctl plot`);
//! - [`comparison`]: logged currents against the simulator's band (`foisctl compare --plot`);
//! - [`series`]: curves over ice thickness in the thesis's layout (`foisctl sim ... --plot`).

pub mod comparison;
pub mod log;
pub mod series;

/// Size of the log and comparison figures, pixels.
pub const WIDE: (u32, u32) = (1200, 700);

/// A plotters error as an `anyhow` error.
pub(crate) fn draw_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing failed: {e:?}")
}
