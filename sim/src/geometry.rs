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

    /// The signal bundles as a branch-free test, for the tracer's inner loops.
    pub(crate) fn bundles(self) -> Bundles {
        let r = self.radius_mm();
        Bundles {
            r,
            b: self.length_b_mm(),
            r2: r * r,
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

/// The two signal bundles of a face: [`Bundles::slot`] answers like [`Geometry::region`]
/// with the same comparisons, but without branches (a landing point is unpredictable).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bundles {
    r: f64,
    b: f64,
    r2: f64,
}

impl Bundles {
    /// R, mm.
    pub(crate) fn radius_mm(&self) -> f64 {
        self.r
    }

    /// R², mm² (as `slot_f64` compares it).
    pub(crate) fn radius2_mm2(&self) -> f64 {
        self.r2
    }

    /// B, mm.
    pub(crate) fn length_b_mm(&self) -> f64 {
        self.b
    }

    /// 0 on signal bundle 1, 1 on signal bundle 2, 2 elsewhere (source, outside).
    #[inline(always)]
    pub(crate) fn slot(&self, x_mm: f64, y_mm: f64) -> usize {
        self.slot_f64(x_mm, y_mm) as usize
    }

    /// [`Bundles::slot`] as 0.0, 1.0 or 2.0: selects between floats only, so that loops
    /// over many landing points vectorise.
    // The negated comparisons keep `region`'s answer for NaN coordinates too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    pub(crate) fn slot_f64(&self, x_mm: f64, y_mm: f64) -> f64 {
        // Exactly the tests of `Geometry::region`, NaN included.
        let face = !(y_mm.abs() > self.r) & !(x_mm < 0.0);
        let dx = x_mm - self.b;
        let disc = if dx * dx + y_mm * y_mm <= self.r2 {
            1.0
        } else {
            2.0
        };
        let on = if x_mm <= self.b { 0.0 } else { disc };
        if face { on } else { 2.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slot_of(r: Region) -> usize {
        match r {
            Region::Bundle1 => 0,
            Region::Bundle2 => 1,
            _ => 2,
        }
    }

    #[test]
    fn bundle_slot_agrees_with_region_on_and_off_the_edges() {
        for geo in [Geometry::ThesisCh3, Geometry::ThesisCh5] {
            let bundles = geo.bundles();
            let (r, b) = (geo.radius_mm(), geo.length_b_mm());
            // A fine grid, the edges themselves and their neighbouring floats, and NaN.
            let mut xs: Vec<f64> = (-400..=900).map(|i| i as f64 * 0.0173).collect();
            let mut ys: Vec<f64> = (-400..=400).map(|i| i as f64 * 0.0131).collect();
            for e in [0.0, b, b + r, -r] {
                xs.extend([e, e.next_down(), e.next_up()]);
            }
            for e in [r, -r, 0.0] {
                ys.extend([e, e.next_down(), e.next_up()]);
            }
            xs.push(f64::NAN);
            ys.push(f64::NAN);
            let mut counts = [0usize; 3];
            for &x in &xs {
                for &y in &ys {
                    let want = slot_of(geo.region(x, y));
                    assert_eq!(bundles.slot(x, y), want, "{geo:?} ({x}, {y})");
                    counts[want] += 1;
                }
            }
            // Every answer occurs many times.
            assert!(counts.iter().all(|&c| c > 10_000), "{counts:?}");
            // A point on the arc of bundle 2: x² + y² = r² exactly for a 3-4-5 triangle.
            let (x, y) = (b + 0.6 * r, 0.8 * r);
            assert_eq!(bundles.slot(x, y), slot_of(geo.region(x, y)));
        }
    }
}
