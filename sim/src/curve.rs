//! The tracer's output: the two currents (reflection and scattering apart) as a function of
//! the ice thickness.

/// Currents at one thickness. `i1_ua = i1_refl_ua + i1_scat_ua` (eq. 3.26); the dry-face leak
/// of Sensor A is reflection at the fibre face and is counted in `i*_refl_ua`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct CurvePoint {
    /// Mean ice thickness d, mm.
    pub thickness_mm: f64,
    /// Current of phototransistor 1, µA.
    pub i1_ua: f64,
    /// Current of phototransistor 2, µA.
    pub i2_ua: f64,
    /// Part of I1 from reflection (ice/air surface, and the leak of Sensor A), µA.
    pub i1_refl_ua: f64,
    /// Part of I1 from bubble scattering, µA.
    pub i1_scat_ua: f64,
    /// Part of I2 from reflection, µA.
    pub i2_refl_ua: f64,
    /// Part of I2 from bubble scattering, µA.
    pub i2_scat_ua: f64,
}

/// Currents as a function of thickness.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Curve {
    /// Points in increasing thickness.
    pub points: Vec<CurvePoint>,
}

impl Curve {
    /// (I1, I2) in µA at `thickness_mm`: linear interpolation, clamped at the ends.
    /// Thickness 0 is the dry face (Sensor A shows its dry offset there, Sensor B ~0).
    pub fn currents_at(&self, thickness_mm: f64) -> (f64, f64) {
        let p = &self.points;
        match p.len() {
            0 => return (0.0, 0.0),
            1 => return (p[0].i1_ua, p[0].i2_ua),
            _ => {}
        }
        if thickness_mm.is_nan() || thickness_mm <= p[0].thickness_mm {
            return (p[0].i1_ua, p[0].i2_ua);
        }
        let last = p[p.len() - 1];
        if thickness_mm >= last.thickness_mm {
            return (last.i1_ua, last.i2_ua);
        }
        let k = p.partition_point(|q| q.thickness_mm <= thickness_mm);
        let (a, b) = (p[k - 1], p[k]);
        let w = (thickness_mm - a.thickness_mm) / (b.thickness_mm - a.thickness_mm);
        (
            a.i1_ua + w * (b.i1_ua - a.i1_ua),
            a.i2_ua + w * (b.i2_ua - a.i2_ua),
        )
    }

    /// The thicknesses, mm.
    pub fn thicknesses_mm(&self) -> Vec<f64> {
        self.points.iter().map(|p| p.thickness_mm).collect()
    }
}
