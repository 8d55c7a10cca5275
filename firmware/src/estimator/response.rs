//! The response table as the filter reads it: the media in table order
//! ([`MEDIA`]), the rows per medium ([`ROWS`]) and their thickness step
//! ([`STEP_MM`]), a medium's rows by index and a row's thickness.

use fois_protocol::Medium;

use super::table;
use super::table_entry::TableEntry;

/// Rows per medium (thicknesses 0.1 … 15.0 mm).
pub const ROWS: usize = table::ROWS;

/// Thickness step between rows, mm.
pub const STEP_MM: f32 = table::STEP_UM as f32 / 1000.0;

/// The media of the grid, in table order.
pub const MEDIA: [Medium; 3] = [Medium::Water, Medium::Glazed, Medium::Rime];

/// The rows of medium `k` (an index into [`MEDIA`]).
pub(super) fn table_of(k: usize) -> &'static [TableEntry; ROWS] {
    match k {
        0 => &table::WATER,
        1 => &table::GLAZED,
        _ => &table::RIME,
    }
}

/// Thickness of row `i`, mm.
#[inline]
pub(super) fn row_mm(i: usize) -> f32 {
    (i + 1) as f32 * STEP_MM
}
