//! The figures `foisctl` draws (PNG or SVG by the `--out` extension,
//! plotters' bitmap and SVG backends; [`output`] checks the path):
//!
//! - [`log`]: a monitor log over time (`foisctl plot`), its lines broken at
//!   gaps by [`runs`];
//! - [`icing`]: the icing report's timeline (`foisctl icing-report --plot`);
//! - [`comparison`]: logged currents against the simulator's band (`foisctl compare --plot`);
//! - [`series`]: curves over ice thickness in the thesis's layout (`foisctl sim ... --plot`).

pub mod comparison;
pub mod icing;
pub mod log;
pub mod log_layout;
pub mod log_series;
pub mod output;
pub mod runs;
pub mod series;

use std::sync::Once;

use plotters::style::{FontStyle, register_font};

/// The font of every figure: DejaVu Sans, embedded (no system font library
/// or font file is needed; licence in `host/assets/fonts/`).
const DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Register the embedded font as "sans-serif", once per process. Every
/// figure calls it before drawing.
pub fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded file is a valid TrueType font (a test draws text with it).
        let _ = register_font("sans-serif", FontStyle::Normal, DEJAVU_SANS);
    });
}

/// Size of the log and comparison figures, pixels.
pub const WIDE: (u32, u32) = (1200, 700);

/// The legend of every figure: white, framed, `font_px` sans-serif, at
/// `position`.
pub(crate) fn draw_legend<'a, DB, CT>(
    chart: &mut plotters::chart::ChartContext<'a, DB, CT>,
    position: plotters::chart::SeriesLabelPosition,
    font_px: u32,
) -> anyhow::Result<()>
where
    DB: plotters::prelude::DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    use plotters::style::{BLACK, Color, WHITE};
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", font_px))
        .position(position)
        .draw()
        .map_err(draw_err)
}

/// A plotters error as an `anyhow` error.
pub(crate) fn draw_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing failed: {e:?}")
}

#[cfg(test)]
mod tests {
    use plotters::prelude::*;

    /// Text is drawn with the embedded font: a caption changes pixels.
    #[test]
    fn figures_render_text_with_the_embedded_font() {
        super::register_fonts();
        let dark = |caption: Option<&str>| -> usize {
            let mut buf = vec![0u8; 300 * 60 * 3];
            {
                let root = BitMapBackend::with_buffer(&mut buf, (300, 60)).into_drawing_area();
                root.fill(&WHITE).unwrap();
                if let Some(c) = caption {
                    root.draw_text(c, &("sans-serif", 30).into_font().color(&BLACK), (5, 10))
                        .unwrap();
                }
                root.present().unwrap();
            }
            buf.chunks(3).filter(|p| p[0] < 128).count()
        };
        assert_eq!(dark(None), 0);
        let n = dark(Some("I1 µA σ Σ δ"));
        assert!(n > 300, "only {n} dark pixels: no glyphs drawn");
    }
}
