//! Sensor face geometry (thesis Fig. 3.13; the coordinates of ARCHITECTURE.md).
//!
//! Sensor face at z = 0. Source bundle: half-disc of radius R centred at the origin, x ≤ 0.
//! Signal bundle 1: rectangle 0 ≤ x ≤ B, |y| ≤ R. Signal bundle 2: half-disc of radius R
//! centred at (B, 0), x ≥ B. The sensor centre (the point the ice surface plane passes
//! above, §5.3.1) is the centre of this approximate ellipse, (B/2, 0).

/// Sensor geometry presets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Geometry {
    /// Thesis chapter 3 (§3.3): R = 2 mm, B = 4 mm.
    ThesisCh3,
    /// Thesis chapter 5 (§5.3.2): R = 4 mm, B = 3.2 mm. The sensor the measurements of
    /// chapter 5 (Fig. 5.7, rime I1 ≈ 30 µA at 15 mm) were made with, hence the default.
    #[default]
    ThesisCh5,
}

/// Which area of the face a point lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// The source half-disc.
    Source,
    /// Signal bundle 1 (rectangle).
    Bundle1,
    /// Signal bundle 2 (half-disc).
    Bundle2,
    /// Outside the sensor face.
    Outside,
}

impl Geometry {
    /// Radius R of the source bundle and of signal bundle 2, mm.
    pub fn radius_mm(self) -> f64 {
        match self {
            Geometry::ThesisCh3 => 2.0,
            Geometry::ThesisCh5 => 4.0,
        }
    }

    /// Length B of signal bundle 1, mm.
    pub fn length_b_mm(self) -> f64 {
        match self {
            Geometry::ThesisCh3 => 4.0,
            Geometry::ThesisCh5 => 3.2,
        }
    }

    /// The x coordinate of the sensor centre, mm.
    pub fn centre_x_mm(self) -> f64 {
        0.5 * self.length_b_mm()
    }

    /// Name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Geometry::ThesisCh3 => "thesis-ch3",
            Geometry::ThesisCh5 => "thesis-ch5",
        }
    }

    /// The region of the face at (x, y), mm. Boundaries: bundle 1 includes x = 0 and x = B.
    #[inline]
    pub fn region(self, x_mm: f64, y_mm: f64) -> Region {
        let r = self.radius_mm();
        let b = self.length_b_mm();
        if y_mm.abs() > r {
            return Region::Outside;
        }
        if x_mm < 0.0 {
            if x_mm * x_mm + y_mm * y_mm <= r * r {
                Region::Source
            } else {
                Region::Outside
            }
        } else if x_mm <= b {
            Region::Bundle1
        } else {
            let dx = x_mm - b;
            if dx * dx + y_mm * y_mm <= r * r {
                Region::Bundle2
            } else {
                Region::Outside
            }
        }
    }

    /// Source fibre positions (x, y) in mm: a uniform square grid of pitch R/40 over the
    /// source half-disc (x ≤ 0, including the x = 0 column). 2553 fibres, close to the
    /// thesis's N = 2546 (§3.3), whose grid convention is not given.
    pub fn source_grid_mm(self) -> Vec<(f64, f64)> {
        let r = self.radius_mm();
        let k: i32 = SOURCE_GRID_STEPS;
        let pitch = r / k as f64;
        let mut pts = Vec::with_capacity(2600);
        for i in -k..=0 {
            for j in -k..=k {
                if i * i + j * j <= k * k {
                    pts.push((i as f64 * pitch, j as f64 * pitch));
                }
            }
        }
        pts
    }
}

/// Grid steps per radius of the source grid.
pub const SOURCE_GRID_STEPS: i32 = 40;
