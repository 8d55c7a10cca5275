//! The response table of the node's ice estimator: for each medium the estimator knows
//! (water, glazed, rime), the smoothed mean μ(d) and covariance Σ(d) of the two currents from
//! the Monte Carlo of thesis §5.4, packed into fixed point and written as Rust source that the
//! firmware embeds at build time (`firmware/src/estimator/table.rs`).
//!
//! * μ(d), Σ(d): [`monte_carlo`] over accretions, then the same smoothing as [`crlb`] (local
//!   quadratic for μ, tricube kernel average for Σ, half-width 0.6 mm).
//! * Water is deterministic in the simulator (flat surface, no bubbles: every run is the same
//!   curve, Σ = 0). A real film is not a plane (drops, ripples, run-off, a meniscus at the
//!   face's edge) and the LED/responsivity calibration is not exact, so the table gives water
//!   a variance floor: σ_k ≥ √((f·μ_k)² + a²) per channel, uncorrelated ([`MediumSpec`]).
//!   Without it a water film that is not exactly the simulated plane would be excluded, and
//!   one that is would get a σ of zero.
//! * Packing per row (10 bytes): μ₁, μ₂ in nA (`u16`, ≤ 65.535 µA), σ₁, σ₂ in nA (`u16`),
//!   the correlation ρ in units of 1/32767 (`i16`). Row i is the thickness (i + 1)·step;
//!   thickness 0 is the dry face, which the estimator models on its own.
//!
//! The seeds of the table must differ from the seeds any evaluation of the estimator uses
//! (the hardware-in-loop scenarios and the firmware's accuracy tests use run 0 of small
//! seeds): [`TABLE_SEED`].

use std::fmt::Write as _;

use crate::geometry::Geometry;
use crate::model::{IceKind, SensorKind, SimConfig, SimError};
use crate::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, crlb, monte_carlo};

/// Version of the table's content and format. Bump it whenever the spec, the simulator's
/// physics, its random streams or the packing changes, so a node's estimate can be traced
/// to its table. 2: the rime bubbles from counter-based streams.
pub const TABLE_VERSION: u16 = 2;

/// The command that rewrites the checked-in table (quoted in its header;
/// `foisctl sim table` writes the same file).
pub const REGENERATE: &str = "FOIS_BLESS=1 cargo test -p fois-firmware --test estimator_table";

/// Seed of every Monte Carlo of the table (runs 0..M). Evaluations use other seeds.
pub const TABLE_SEED: u64 = 900_001;

/// Largest value a `u16` field in nA can hold, µA.
const MAX_U16_UA: f64 = 65.535;

/// One medium of the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumSpec {
    /// The simulator's medium.
    pub kind: IceKind,
    /// Number of accretions of the Monte Carlo.
    pub runs: u64,
    /// Relative standard-deviation floor f (fraction of μ per channel).
    pub floor_rel: f64,
    /// Absolute standard-deviation floor a, µA.
    pub floor_ua: f64,
    /// Take the spread Σ of this other medium of the table (added to the
    /// floor): a water film has the surface slopes of glaze, which the
    /// simulator's flat water lacks (thesis §5.2.3: water and glazed ice are
    /// optically alike).
    pub spread_like: Option<IceKind>,
}

/// What the table is built from.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSpec {
    /// Table version written into the source.
    pub version: u16,
    /// Seed of the Monte Carlo runs.
    pub seed: u64,
    /// Sensor construction (the estimator assumes Sensor B: a dry face reads 0).
    pub sensor: SensorKind,
    /// Face geometry.
    pub geometry: Geometry,
    /// Largest thickness, mm.
    pub max_mm: f64,
    /// Thickness step of the Monte Carlo, mm.
    pub step_mm: f64,
    /// Keep every `every`-th smoothed thickness in the table: the estimator's
    /// grid is `every · step_mm` (the smoothing half-width is several steps,
    /// so the dropped rows carry no extra information).
    pub every: usize,
    /// Half-width of the smoothing kernels, mm.
    pub half_width_mm: f64,
    /// The media, in the order of `fois_protocol::Medium` (water, glazed, rime).
    pub media: Vec<MediumSpec>,
}

impl Default for TableSpec {
    /// The table the firmware embeds: Sensor B, thesis chapter-5 geometry, Monte Carlo over
    /// 0–15 mm in 0.1 mm, smoothed, kept every 0.2 mm (the estimator's grid); rime 256 accretions, glazed 64 (its spread is large and the thesis finds its
    /// thickness not measurable, so a coarser Σ costs nothing), water one run (deterministic:
    /// flat, no bubbles) with the spread of glaze plus a 10 % ⊕ 0.1 µA floor.
    fn default() -> Self {
        TableSpec {
            version: TABLE_VERSION,
            seed: TABLE_SEED,
            sensor: SensorKind::B,
            geometry: Geometry::ThesisCh5,
            max_mm: 15.0,
            step_mm: 0.1,
            every: 2,
            half_width_mm: DEFAULT_FIT_HALF_WIDTH_MM,
            media: vec![
                MediumSpec {
                    kind: IceKind::Water,
                    runs: 1,
                    floor_rel: 0.10,
                    floor_ua: 0.10,
                    spread_like: Some(IceKind::Glazed),
                },
                MediumSpec {
                    kind: IceKind::Glazed,
                    runs: 64,
                    floor_rel: 0.0,
                    floor_ua: 0.0,
                    spread_like: None,
                },
                MediumSpec {
                    kind: IceKind::Rime,
                    runs: 256,
                    floor_rel: 0.0,
                    floor_ua: 0.0,
                    spread_like: None,
                },
            ],
        }
    }
}

impl TableSpec {
    /// Total accretions to trace (for a progress bar).
    pub fn total_runs(&self) -> u64 {
        self.media.iter().map(|m| m.runs).sum()
    }
}

/// One thickness of one medium (before packing).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TableRow {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Smoothed mean (I1, I2), µA (clamped at 0).
    pub mu_ua: [f64; 2],
    /// Standard deviations of I1, I2 (smoothed Σ, with the medium's floor), µA.
    pub sd_ua: [f64; 2],
    /// Correlation of I1 and I2 (clamped to ±0.999 so Σ stays positive definite).
    pub rho: f64,
}

/// The rows of one medium.
#[derive(Clone, Debug, PartialEq)]
pub struct MediumTable {
    /// What it was built from.
    pub spec: MediumSpec,
    /// Rows at every·step, 2·every·step, …, max (thickness 0, the dry face, is not a row).
    pub rows: Vec<TableRow>,
}

/// The whole table.
#[derive(Clone, Debug, PartialEq)]
pub struct ResponseTable {
    /// What it was built from.
    pub spec: TableSpec,
    /// One entry per medium, in the spec's order.
    pub media: Vec<MediumTable>,
}

/// A row in the firmware's fixed point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PackedRow {
    /// μ₁, μ₂, nA.
    pub mu_na: [u16; 2],
    /// σ₁, σ₂, nA.
    pub sd_na: [u16; 2],
    /// ρ · 32767.
    pub rho_q15: i16,
}

impl TableRow {
    /// Pack into the firmware's fixed point. Errors when a value does not fit.
    pub fn pack(&self) -> Result<PackedRow, SimError> {
        let na = |ua: f64, what: &str| -> Result<u16, SimError> {
            if !ua.is_finite() || !(0.0..=MAX_U16_UA).contains(&ua) {
                return Err(SimError::BadParam(format!(
                    "{what} = {ua} µA at {} mm does not fit the table's u16 nA field (0–{MAX_U16_UA} µA)",
                    self.thickness_mm
                )));
            }
            Ok((ua * 1000.0).round() as u16)
        };
        if !self.rho.is_finite() {
            return Err(SimError::BadParam(format!(
                "correlation is not finite at {} mm",
                self.thickness_mm
            )));
        }
        Ok(PackedRow {
            mu_na: [na(self.mu_ua[0], "μ1")?, na(self.mu_ua[1], "μ2")?],
            sd_na: [na(self.sd_ua[0], "σ1")?, na(self.sd_ua[1], "σ2")?],
            rho_q15: (self.rho.clamp(-1.0, 1.0) * 32767.0).round() as i16,
        })
    }
}

/// Run the Monte Carlo of every medium of `spec` and smooth it. `on_done` is called once per
/// finished accretion. Deterministic: the same spec gives the same table on any thread count.
pub fn build_table(
    spec: &TableSpec,
    on_done: &(dyn Fn() + Sync),
) -> Result<ResponseTable, SimError> {
    if spec.media.is_empty() {
        return Err(SimError::BadParam(
            "the table needs at least one medium".into(),
        ));
    }
    if spec.every == 0 {
        return Err(SimError::BadParam("every must be ≥ 1".into()));
    }
    if !(spec.half_width_mm.is_finite() && spec.half_width_mm > 0.0) {
        return Err(SimError::BadParam(format!(
            "half_width_mm = {} must be > 0",
            spec.half_width_mm
        )));
    }
    // Smoothed μ and Σ of every medium first (a medium may borrow another's Σ).
    let mut smoothed = Vec::with_capacity(spec.media.len());
    for m in &spec.media {
        if m.runs == 0 {
            return Err(SimError::BadParam(format!(
                "{}: the Monte Carlo needs at least one run",
                m.kind.name()
            )));
        }
        if !(m.floor_rel >= 0.0 && m.floor_ua >= 0.0) {
            return Err(SimError::BadParam(format!(
                "{}: floors must be ≥ 0",
                m.kind.name()
            )));
        }
        let mut cfg = SimConfig::new(m.kind, spec.sensor, spec.geometry);
        cfg.max_mm = spec.max_mm;
        cfg.step_mm = spec.step_mm;
        cfg.validate()?;
        let mc = monte_carlo(&cfg, m.runs, spec.seed, on_done);
        smoothed.push(crlb(&mc.points, spec.half_width_mm));
    }
    let mut media = Vec::with_capacity(spec.media.len());
    for (m, fit) in spec.media.iter().zip(&smoothed) {
        let borrowed = match m.spread_like {
            None => None,
            Some(kind) => Some(
                spec.media
                    .iter()
                    .position(|o| o.kind == kind)
                    .and_then(|j| smoothed.get(j))
                    .ok_or_else(|| {
                        SimError::BadParam(format!(
                            "{} borrows the spread of {}, which the table does not have",
                            m.kind.name(),
                            kind.name()
                        ))
                    })?,
            ),
        };
        let rows = fit
            .iter()
            .enumerate()
            .skip(spec.every) // thickness 0 is the dry face
            .step_by(spec.every)
            .map(|(i, f)| {
                let mu = [f.mu_ua[0].max(0.0), f.mu_ua[1].max(0.0)];
                let mut cov = f.sigma_ua2;
                if let Some(b) = borrowed.and_then(|b| b.get(i)) {
                    for (row, brow) in cov.iter_mut().zip(&b.sigma_ua2) {
                        for (x, y) in row.iter_mut().zip(brow) {
                            *x += y;
                        }
                    }
                }
                let floor = |k: usize| (m.floor_rel * mu[k]).hypot(m.floor_ua);
                let sd_raw = [cov[0][0].max(0.0).sqrt(), cov[1][1].max(0.0).sqrt()];
                let sd = [sd_raw[0].max(floor(0)), sd_raw[1].max(floor(1))];
                // The correlation of the smoothed Σ; a floored channel keeps the raw
                // covariance, so ρ shrinks with it. Zero where a channel has no spread.
                let rho = if sd[0] > 0.0 && sd[1] > 0.0 {
                    (cov[0][1] / (sd[0] * sd[1])).clamp(-0.999, 0.999)
                } else {
                    0.0
                };
                TableRow {
                    thickness_mm: f.thickness_mm,
                    mu_ua: mu,
                    sd_ua: sd,
                    rho: if rho.is_finite() { rho } else { 0.0 },
                }
            })
            .collect();
        media.push(MediumTable { spec: *m, rows });
    }
    Ok(ResponseTable {
        spec: spec.clone(),
        media,
    })
}

/// The table as the Rust source of `firmware/src/estimator/table.rs`: a header stating the
/// version, seeds, runs and simulation parameters, then one `static` array per medium of
/// `super::table_entry::TableEntry` (fields `mu_na`, `sd_na`, `rho_q15`; the table reads only
/// that file of the estimator). `regenerate` is the command line that rewrites the file (quoted
/// in the header).
pub fn to_rust_source(table: &ResponseTable, regenerate: &str) -> Result<String, SimError> {
    let spec = &table.spec;
    let rows = table.media.first().map_or(0, |m| m.rows.len());
    if table.media.iter().any(|m| m.rows.len() != rows) {
        return Err(SimError::BadParam(
            "every medium needs the same number of rows".into(),
        ));
    }
    let step_um = (spec.step_mm * spec.every as f64 * 1000.0).round();
    if !(1.0..=65_535.0).contains(&step_um) {
        return Err(SimError::BadParam(format!(
            "step {} mm does not fit",
            spec.step_mm
        )));
    }
    let mut s = String::new();
    let w = &mut s;
    let _ = writeln!(
        w,
        "//! Response table of the ice estimator, version {} — GENERATED, do not edit.",
        spec.version
    );
    let _ = writeln!(w, "//!");
    let _ = writeln!(
        w,
        "//! Generator: `fois_sim::table` (`build_table` + `to_rust_source`). Regenerate with"
    );
    let _ = writeln!(w, "//! `{regenerate}`.");
    let _ = writeln!(w, "//!");
    let _ = writeln!(
        w,
        "//! Simulation: Sensor {:?}, geometry {} (R = {} mm, B = {} mm), thesis-literal coupling,",
        spec.sensor,
        spec.geometry.name(),
        spec.geometry.radius_mm(),
        spec.geometry.length_b_mm()
    );
    let _ = writeln!(
        w,
        "//! thesis fibre spread (default fibre seed); thickness 0–{} mm in {} mm (thesis §5.3, §5.4).",
        spec.max_mm, spec.step_mm
    );
    let _ = writeln!(
        w,
        "//! Monte Carlo seed {} (runs 0..M): evaluations of the estimator must use other seeds.",
        spec.seed
    );
    for m in &table.media {
        let p = m.spec.kind.params();
        let _ = writeln!(
            w,
            "//! - {}: M = {} runs; n = {}, P_B = {}, δ_S ~ U(±{:.0}°), δ_R ~ U(±{:.0}°); σ floor {} % of μ ⊕ {} µA{}.",
            m.spec.kind.name(),
            m.spec.runs,
            p.n_medium,
            p.p_bubble,
            p.slope_max_rad.to_degrees(),
            p.diffuse_max_rad.to_degrees(),
            m.spec.floor_rel * 100.0,
            m.spec.floor_ua,
            m.spec
                .spread_like
                .map(|k| format!("; Σ of {} added", k.name()))
                .unwrap_or_default()
        );
    }
    let _ = writeln!(w, "//!");
    let _ = writeln!(
        w,
        "//! Smoothing: μ local quadratic, Σ tricube kernel average, half-width {} mm (as the CRLB);",
        spec.half_width_mm
    );
    let _ = writeln!(
        w,
        "//! kept every {} mm (the estimator's grid).",
        step_um / 1000.0
    );
    let _ = writeln!(
        w,
        "//! Packing: μ and σ of I1, I2 in nA (u16), correlation ρ · 32767 (i16); row i is the"
    );
    let _ = writeln!(
        w,
        "//! thickness (i + 1) · STEP_UM µm (thickness 0, the dry face, is modelled by the estimator)."
    );
    let _ = writeln!(w);
    let _ = writeln!(w, "use super::table_entry::TableEntry as E;");
    let _ = writeln!(w);
    let _ = writeln!(w, "/// Table version (content and format).");
    let _ = writeln!(w, "pub const VERSION: u16 = {};", spec.version);
    let _ = writeln!(w, "/// Monte Carlo seed of the table.");
    let _ = writeln!(w, "pub const SEED: u64 = {};", spec.seed);
    let _ = writeln!(w, "/// Thickness step between rows, µm.");
    let _ = writeln!(w, "pub const STEP_UM: u16 = {};", step_um as u16);
    let _ = writeln!(w, "/// Rows per medium.");
    let _ = writeln!(w, "pub const ROWS: usize = {rows};");
    for m in &table.media {
        let name = m.spec.kind.name().to_ascii_uppercase();
        let _ = writeln!(w);
        let _ = writeln!(
            w,
            "/// {}: μ, σ, ρ of (I1, I2) at {} µm, {} µm, …",
            m.spec.kind.name(),
            step_um as u32,
            2 * step_um as u32
        );
        let _ = writeln!(w, "#[rustfmt::skip]");
        let _ = writeln!(w, "pub static {name}: [E; ROWS] = [");
        for r in &m.rows {
            let p = r.pack()?;
            let _ = writeln!(
                w,
                "    E::new({}, {}, {}, {}, {}), // {:.1} mm",
                p.mu_na[0], p.mu_na[1], p.sd_na[0], p.sd_na[1], p.rho_q15, r.thickness_mm
            );
        }
        let _ = writeln!(w, "];");
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(mu: [f64; 2], sd: [f64; 2], rho: f64) -> TableRow {
        TableRow {
            thickness_mm: 1.0,
            mu_ua: mu,
            sd_ua: sd,
            rho,
        }
    }

    #[test]
    fn packing_rounds_to_nanoamps_and_refuses_what_does_not_fit() {
        let p = row([12.3456, 0.0004], [0.2104, 65.535], -0.5)
            .pack()
            .unwrap();
        assert_eq!(p.mu_na, [12_346, 0]);
        assert_eq!(p.sd_na, [210, 65_535]);
        assert_eq!(p.rho_q15, -16_384);
        assert!(row([65.6, 0.0], [1.0, 1.0], 0.0).pack().is_err());
        assert!(row([1.0, -0.1], [1.0, 1.0], 0.0).pack().is_err());
        assert!(row([1.0, 1.0], [f64::NAN, 1.0], 0.0).pack().is_err());
        assert!(row([1.0, 1.0], [1.0, 1.0], f64::NAN).pack().is_err());
    }

    #[test]
    fn water_gets_its_floor_and_the_source_names_version_seed_and_runs() {
        let spec = TableSpec {
            max_mm: 2.0,
            every: 1,
            media: vec![MediumSpec {
                kind: IceKind::Water,
                runs: 2,
                floor_rel: 0.1,
                floor_ua: 0.1,
                spread_like: None,
            }],
            ..TableSpec::default()
        };
        let t = build_table(&spec, &|| {}).unwrap();
        assert_eq!(t.media[0].rows.len(), 20);
        for r in &t.media[0].rows {
            // Two identical runs: no spread, the floor is the whole σ.
            for k in 0..2 {
                let floor = (0.1 * r.mu_ua[k]).hypot(0.1);
                assert!((r.sd_ua[k] - floor).abs() < 1e-9, "{r:?}");
            }
            assert!(r.rho.abs() < 1e-9);
        }
        let src = to_rust_source(&t, "cargo test").unwrap();
        assert!(src.contains("pub const VERSION: u16 = 2;"));
        assert!(src.contains(&format!("pub const SEED: u64 = {TABLE_SEED};")));
        assert!(src.contains("- water: M = 2 runs"));
        assert!(src.contains("pub const ROWS: usize = 20;"));
        assert!(src.contains("pub static WATER: [E; ROWS] = ["));
        assert_eq!(src.matches("E::new(").count(), 20);
    }

    #[test]
    fn bad_specs_are_refused() {
        let mut spec = TableSpec::default();
        spec.media[0].runs = 0;
        assert!(build_table(&spec, &|| {}).is_err());
        let spec = TableSpec {
            media: vec![],
            ..TableSpec::default()
        };
        assert!(build_table(&spec, &|| {}).is_err());
        let spec = TableSpec {
            half_width_mm: 0.0,
            ..TableSpec::default()
        };
        assert!(build_table(&spec, &|| {}).is_err());
        let spec = TableSpec {
            every: 0,
            ..TableSpec::default()
        };
        assert!(build_table(&spec, &|| {}).is_err());
        // Water borrows the spread of glaze, which this spec lacks.
        let mut spec = TableSpec::default();
        spec.media.remove(1);
        spec.max_mm = 1.0;
        assert!(build_table(&spec, &|| {}).is_err());
    }
}
