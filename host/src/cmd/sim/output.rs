//! The CSV files of the simulator commands (csv crate): one header line,
//! currents in µA, variances in µA², thicknesses in mm.

use std::fs::File;
use std::path::Path;

use anyhow::{Context, Result};
use fois_sim::{CrlbPoint, Curve, McPoint};

/// Header of `sim curve`.
pub const CURVE_HEADER: [&str; 8] = [
    "run",
    "thickness_mm",
    "i1_ua",
    "i2_ua",
    "i1_refl_ua",
    "i1_scat_ua",
    "i2_refl_ua",
    "i2_scat_ua",
];
/// Header of `sim analytic`.
pub const ANALYTIC_HEADER: [&str; 3] = ["thickness_mm", "i1_ua", "i2_ua"];
/// Header of `sim montecarlo`.
pub const MONTECARLO_HEADER: [&str; 6] = [
    "thickness_mm",
    "mean_i1_ua",
    "mean_i2_ua",
    "var_i1",
    "var_i2",
    "cov_i1_i2",
];
/// Header of `sim crlb`.
pub const CRLB_HEADER: [&str; 3] = ["thickness_mm", "crlb_std_mm", "crlb_no_dsigma_std_mm"];
/// Header of `sim crlb --gain-sd S`: the known-gain bound, then the bound with the gain
/// unknown (with and without the dΣ/dd terms).
pub const CRLB_GAIN_HEADER: [&str; 5] = [
    "thickness_mm",
    "crlb_std_mm",
    "crlb_no_dsigma_std_mm",
    "crlb_gain_std_mm",
    "crlb_gain_no_dsigma_std_mm",
];

/// A CSV file being written (created at once, so a bad path fails before a
/// long run).
pub struct CsvOut {
    path: std::path::PathBuf,
    w: csv::Writer<File>,
    /// Rows written, the header included.
    rows: u64,
}

impl CsvOut {
    /// Create `path` and write the header.
    pub fn create(path: &Path, header: &[&str]) -> Result<CsvOut> {
        let w = csv::Writer::from_path(path)
            .with_context(|| format!("cannot write {}", path.display()))?;
        let mut out = CsvOut {
            path: path.to_path_buf(),
            w,
            rows: 0,
        };
        out.row(header)?;
        Ok(out)
    }

    fn row<I, T>(&mut self, fields: I) -> Result<()>
    where
        I: IntoIterator<Item = T>,
        T: AsRef<[u8]>,
    {
        self.rows += 1;
        self.w
            .write_record(fields)
            .with_context(|| format!("cannot write {}", self.path.display()))
    }

    /// Flush to the file and say what was written (path, data rows).
    pub fn finish(mut self) -> Result<()> {
        self.w
            .flush()
            .with_context(|| format!("cannot write {}", self.path.display()))?;
        println!(
            "wrote {} ({} data rows and a header)",
            self.path.display(),
            self.rows.saturating_sub(1)
        );
        Ok(())
    }
}

fn num(x: f64, decimals: usize) -> String {
    format!("{x:.decimals$}")
}

/// `sim curve`: one row per run and thickness.
pub fn write_curves(out: CsvOut, curves: &[Curve]) -> Result<()> {
    let mut out = out;
    for (r, c) in curves.iter().enumerate() {
        for p in &c.points {
            out.row([
                r.to_string(),
                num(p.thickness_mm, 4),
                num(p.i1_ua, 6),
                num(p.i2_ua, 6),
                num(p.i1_refl_ua, 6),
                num(p.i1_scat_ua, 6),
                num(p.i2_refl_ua, 6),
                num(p.i2_scat_ua, 6),
            ])?;
        }
    }
    out.finish()
}

/// `sim analytic`: (thickness, I1, I2) rows.
pub fn write_analytic(out: CsvOut, rows: &[(f64, f64, f64)]) -> Result<()> {
    let mut out = out;
    for (d, i1, i2) in rows {
        out.row([num(*d, 4), num(*i1, 6), num(*i2, 6)])?;
    }
    out.finish()
}

/// `sim montecarlo`: mean and covariance per thickness.
pub fn write_montecarlo(out: CsvOut, points: &[McPoint]) -> Result<()> {
    let mut out = out;
    for p in points {
        out.row([
            num(p.thickness_mm, 4),
            num(p.mean_ua[0], 6),
            num(p.mean_ua[1], 6),
            num(p.cov_ua2[0][0], 6),
            num(p.cov_ua2[1][1], 6),
            num(p.cov_ua2[0][1], 6),
        ])?;
    }
    out.finish()
}

/// `sim crlb`: the bound with and without the dΣ/dd term; with `gain` (one pair per point),
/// also the unknown-gain bound with and without it.
pub fn write_crlb(out: CsvOut, bound: &[CrlbPoint], gain: Option<&[(f64, f64)]>) -> Result<()> {
    let mut out = out;
    for (i, p) in bound.iter().enumerate() {
        let mut row = vec![
            num(p.thickness_mm, 4),
            num(p.crlb_std_mm, 6),
            num(p.crlb_no_dsigma_std_mm, 6),
        ];
        if let Some(g) = gain {
            let (full, mean_only) = g.get(i).copied().unwrap_or((f64::NAN, f64::NAN));
            row.extend([num(full, 6), num(mean_only, 6)]);
        }
        out.row(row)?;
    }
    out.finish()
}

/// Check early that a figure's path is writable (a long run must not fail
/// at its end).
pub fn check_writable(path: Option<&Path>) -> Result<()> {
    if let Some(p) = path {
        crate::plot::output::format_of(p)?;
        File::create(p).with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}
