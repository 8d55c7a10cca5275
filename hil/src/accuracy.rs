//! The ice estimator's accuracy table: per scenario (every seed of an
//! `accuracy = true` file together), the estimate's error at 0.5, 1, 2, 5 and
//! 10 mm of true thickness — bias and RMS over the seeds, each seed's error
//! being its mean over the frames within ±0.05 mm of that thickness — the
//! fraction of frames beyond 0.5 mm whose |error| ≤ 2σ (is the reported σ
//! honest?), √CRLB at the same thicknesses (thesis §5.4, from a Monte Carlo
//! whose seed is neither the response table's nor a scenario's), and how
//! often the medium is right once the ice is ≥ 1 mm.
//!
//! The gain columns compare the node's estimate of its relative optical
//! gain (`MeasurementV3::gain`: LED × coupling × responsivity against the
//! response table's) with the truth of the virtual hardware (LED factor ×
//! temperature factor × face transmission², `fois_vnode::optics`): the true
//! gain at the first and last frame with ice, the estimate and its σ at the
//! last frame (mean over seeds), the RMS of its error and the fraction of
//! frames with |error| ≤ 2σ, over the frames with ice on the face; "—" while
//! the node sends no gain. And how many frames from [`THIN_FROM_MM`] are
//! *confidently thin* (est + 2σ below half the truth).
//!
//! The scenarios' seeds are the ray-traced accretions: the response table
//! is built from seed 900 001 (`fois_sim::table::TABLE_SEED`), which no
//! scenario uses.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use fois_protocol::Medium;
use fois_sim::{Geometry, IceKind, SensorKind, SimConfig};
use fois_vnode::Cover;

use crate::outcome::{EstSample, Outcome};

/// The true thicknesses of the table, mm.
pub const THICKNESSES_MM: [f64; 5] = [0.5, 1.0, 2.0, 5.0, 10.0];
/// Frames within this of a thickness count for it, mm.
pub const WINDOW_MM: f64 = 0.05;
/// Seed of the Monte Carlo behind √CRLB (not the table's, not a scenario's).
pub const CRLB_SEED: u64 = 4242;
/// Frames from this true thickness count for the confidently-thin column, mm.
pub const THIN_FROM_MM: f64 = 4.0;

/// The node's gain estimate against the truth, over one scenario's seeds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainStat {
    /// The estimate at each seed's last frame with ice, mean over seeds.
    pub end_gain: f64,
    /// Its σ, mean over seeds.
    pub end_sigma: f64,
    /// RMS of (estimate − truth) over the frames with ice.
    pub rms_err: f64,
    /// Fraction of those frames with |estimate − truth| ≤ 2σ.
    pub within_2sigma: f64,
}

/// Bias and RMS over seeds at one thickness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStat {
    /// Mean error over seeds, mm.
    pub bias_mm: f64,
    /// RMS error over seeds, mm.
    pub rms_mm: f64,
    /// Seeds that reached this thickness.
    pub seeds: usize,
    /// Mean reported σ, mm.
    pub sigma_mm: f64,
}

/// One row of the table: one scenario, all its seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyRow {
    /// Scenario name (without the seed).
    pub name: String,
    /// The medium that grows in it (the first ice or water of the runs).
    pub cover: Option<Cover>,
    /// Seeds (runs).
    pub runs: usize,
    /// Per thickness of [`THICKNESSES_MM`] (`None`: no run reached it).
    pub at: [Option<ErrorStat>; 5],
    /// Fraction of frames beyond 0.5 mm with |error| ≤ 2σ (`None`: none).
    pub within_2sigma: Option<f64>,
    /// Fraction of frames with ≥ 1 mm whose medium is right.
    pub medium_right: Option<f64>,
    /// Frames of water above the freezing band called ice / all such frames.
    pub warm_water_called_ice: (u64, u64),
    /// The true optical gain at the first and the last frame with ice (of
    /// the first seed: the truth is the same for every seed).
    pub true_gain: Option<(f64, f64)>,
    /// The node's gain estimate (`None`: it sent none).
    pub gain: Option<GainStat>,
    /// Frames with ice ≥ [`THIN_FROM_MM`] confidently thin / all such frames.
    pub confidently_thin: (u64, u64),
}

/// The medium an estimate should name for a cover.
pub fn expected_medium(c: Cover) -> Medium {
    match c {
        Cover::Dry => Medium::Dry,
        Cover::Water => Medium::Water,
        Cover::Flat | Cover::Glazed => Medium::Glazed,
        Cover::Rime => Medium::Rime,
    }
}

fn base_name(name: &str) -> &str {
    name.split("@seed").next().unwrap_or(name)
}

/// The rows, one per accuracy scenario, in name order.
pub fn rows(outcomes: &[Outcome]) -> Vec<AccuracyRow> {
    let mut groups: BTreeMap<&str, Vec<&Outcome>> = BTreeMap::new();
    for o in outcomes.iter().filter(|o| !o.estimates.is_empty()) {
        groups.entry(base_name(&o.name)).or_default().push(o);
    }
    groups
        .into_iter()
        .map(|(name, runs)| row(name, &runs))
        .collect()
}

fn row(name: &str, runs: &[&Outcome]) -> AccuracyRow {
    let on_face = |s: &&EstSample| s.cover != Cover::Dry && s.true_mm > 0.0;
    let cover = runs
        .iter()
        .flat_map(|o| o.estimates.iter())
        .find(on_face)
        .map(|s| s.cover);
    let at = THICKNESSES_MM.map(|d| {
        let per_run: Vec<(f64, f64)> = runs
            .iter()
            .filter_map(|o| {
                let near: Vec<&EstSample> = o
                    .estimates
                    .iter()
                    .filter(on_face)
                    .filter(|s| (s.true_mm - d).abs() <= WINDOW_MM)
                    .collect();
                (!near.is_empty()).then(|| {
                    let n = near.len() as f64;
                    (
                        near.iter().map(|s| s.est_mm - s.true_mm).sum::<f64>() / n,
                        near.iter().map(|s| s.sigma_mm).sum::<f64>() / n,
                    )
                })
            })
            .collect();
        (!per_run.is_empty()).then(|| {
            let n = per_run.len() as f64;
            ErrorStat {
                bias_mm: per_run.iter().map(|e| e.0).sum::<f64>() / n,
                rms_mm: (per_run.iter().map(|e| e.0 * e.0).sum::<f64>() / n).sqrt(),
                seeds: per_run.len(),
                sigma_mm: per_run.iter().map(|e| e.1).sum::<f64>() / n,
            }
        })
    });
    let fraction = |keep: &dyn Fn(&EstSample) -> bool, good: &dyn Fn(&EstSample) -> bool| {
        let (mut n, mut k) = (0u64, 0u64);
        for s in runs.iter().flat_map(|o| o.estimates.iter()).filter(on_face) {
            if keep(s) {
                n += 1;
                k += u64::from(good(s));
            }
        }
        (n > 0).then(|| k as f64 / n as f64)
    };
    AccuracyRow {
        name: name.to_string(),
        cover,
        runs: runs.len(),
        at,
        within_2sigma: fraction(&|s| s.true_mm > 0.5, &|s| {
            (s.est_mm - s.true_mm).abs() <= 2.0 * s.sigma_mm
        }),
        medium_right: fraction(&|s| s.true_mm >= 1.0, &|s| {
            s.medium == expected_medium(s.cover)
        }),
        warm_water_called_ice: runs.iter().fold((0, 0), |(a, b), o| {
            (a + o.warm_water_called_ice, b + o.warm_water_frames)
        }),
        true_gain: runs.first().and_then(|o| {
            let ice: Vec<&EstSample> = o.estimates.iter().filter(on_face).collect();
            Some((ice.first()?.true_gain, ice.last()?.true_gain))
        }),
        gain: gain_stat(runs),
        confidently_thin: runs
            .iter()
            .flat_map(|o| o.estimates.iter())
            .filter(on_face)
            .filter(|s| s.true_mm >= THIN_FROM_MM)
            .fold((0, 0), |(k, n), s| {
                (k + u64::from(s.confidently_thin()), n + 1)
            }),
    }
}

fn gain_stat(runs: &[&Outcome]) -> Option<GainStat> {
    let on_face = |s: &&EstSample| s.cover != Cover::Dry && s.true_mm > 0.0;
    let with_gain = |o: &&Outcome| -> Vec<(f64, f64, f64)> {
        o.estimates
            .iter()
            .filter(on_face)
            .filter_map(|s| s.gain.map(|(g, sd)| (s.true_gain, g, sd)))
            .collect()
    };
    let per_run: Vec<Vec<(f64, f64, f64)>> = runs
        .iter()
        .map(with_gain)
        .filter(|v| !v.is_empty())
        .collect();
    let ends: Vec<(f64, f64, f64)> = per_run.iter().filter_map(|v| v.last().copied()).collect();
    let all: Vec<&(f64, f64, f64)> = per_run.iter().flatten().collect();
    if all.is_empty() {
        return None;
    }
    let n = all.len() as f64;
    let m = ends.len() as f64;
    Some(GainStat {
        end_gain: ends.iter().map(|e| e.1).sum::<f64>() / m,
        end_sigma: ends.iter().map(|e| e.2).sum::<f64>() / m,
        rms_err: (all.iter().map(|e| (e.1 - e.0).powi(2)).sum::<f64>() / n).sqrt(),
        within_2sigma: all
            .iter()
            .filter(|e| (e.1 - e.0).abs() <= 2.0 * e.2)
            .count() as f64
            / n,
    })
}

/// √CRLB (thesis §5.4) of `kind` on Sensor B at [`THICKNESSES_MM`], mm,
/// from `runs` accretions of seed [`CRLB_SEED`].
pub fn sqrt_crlb(kind: IceKind, runs: u64) -> [f64; 5] {
    let cfg = SimConfig::new(kind, SensorKind::B, Geometry::default());
    let mc = fois_sim::monte_carlo(&cfg, runs, CRLB_SEED, &|| {});
    let bound = fois_sim::crlb(&mc.points, fois_sim::montecarlo::DEFAULT_FIT_HALF_WIDTH_MM);
    THICKNESSES_MM.map(|d| {
        bound
            .iter()
            .min_by(|a, b| {
                (a.thickness_mm - d)
                    .abs()
                    .total_cmp(&(b.thickness_mm - d).abs())
            })
            .map_or(f64::NAN, |p| p.crlb_std_mm)
    })
}

/// √CRLB of rime and of glazed ice (the rows [`table`] adds).
pub fn crlb_rows(runs: u64) -> Vec<(IceKind, [f64; 5])> {
    [IceKind::Rime, IceKind::Glazed]
        .into_iter()
        .map(|k| (k, sqrt_crlb(k, runs)))
        .collect()
}

fn cover_name(c: Option<Cover>) -> &'static str {
    match c {
        Some(Cover::Rime) => "rime",
        Some(Cover::Glazed) => "glazed",
        Some(Cover::Flat) => "flat ice",
        Some(Cover::Water) => "water",
        Some(Cover::Dry) | None => "—",
    }
}

fn pct(x: Option<f64>) -> String {
    x.map_or("—".into(), |x| format!("{:.1} %", 100.0 * x))
}

/// The Markdown table; `crlb` gives √CRLB per medium (rime, glazed rows
/// are added for those given).
pub fn table(rows: &[AccuracyRow], crlb: &[(IceKind, [f64; 5])]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| scenario | medium | seeds | 0.5 mm bias / RMS | 1 mm | 2 mm | 5 mm | 10 mm | \\|err\\| ≤ 2σ (> 0.5 mm) | medium right (≥ 1 mm) | warm water called ice | true gain (first → last) | est. gain (σ), last frame | gain RMS err | gain \\|err\\| ≤ 2σ | confidently thin (≥ {THIN_FROM_MM} mm) |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for r in rows {
        let cells: Vec<String> =
            r.at.iter()
                .map(|e| match e {
                    Some(e) => format!("{:+.2} / {:.2} (σ {:.2})", e.bias_mm, e.rms_mm, e.sigma_mm),
                    None => "—".into(),
                })
                .collect();
        let (ice, warm) = r.warm_water_called_ice;
        let (gain_est, gain_rms, gain_cov) = match r.gain {
            Some(g) => (
                format!("{:.3} (σ {:.3})", g.end_gain, g.end_sigma),
                format!("{:.3}", g.rms_err),
                pct(Some(g.within_2sigma)),
            ),
            None => ("—".into(), "—".into(), "—".into()),
        };
        let true_gain = match r.true_gain {
            Some((a, b)) if (a - b).abs() < 0.005 => format!("{a:.2}"),
            Some((a, b)) => format!("{a:.2} → {b:.2}"),
            None => "—".into(),
        };
        let thin = match r.confidently_thin {
            (_, 0) => "—".to_string(),
            (k, n) => format!("{k} of {n}"),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.name,
            cover_name(r.cover),
            r.runs,
            cells[0],
            cells[1],
            cells[2],
            cells[3],
            cells[4],
            pct(r.within_2sigma),
            pct(r.medium_right),
            if warm == 0 {
                "—".to_string()
            } else {
                format!("{ice} of {warm}")
            },
            true_gain,
            gain_est,
            gain_rms,
            gain_cov,
            thin,
        );
    }
    for (kind, c) in crlb {
        let _ = writeln!(
            s,
            "| √CRLB ({}) | | | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | | | | | | | | |",
            kind.name(),
            c[0],
            c[1],
            c[2],
            c[3],
            c[4]
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(true_mm: f64, est_mm: f64, sigma_mm: f64, medium: Medium) -> EstSample {
        EstSample {
            t_s: 0.0,
            cover: Cover::Rime,
            true_mm,
            est_mm,
            sigma_mm,
            medium,
            true_gain: 1.0,
            gain: None,
            true_rate_mm_per_h: 0.0,
            icing: None,
        }
    }

    #[test]
    fn bias_rms_over_seeds_and_fractions_over_frames() {
        let mut a = crate::outcome::tests_support::outcome("acc@seed1");
        let mut b = crate::outcome::tests_support::outcome("acc@seed2");
        // Seed 1 reads +0.2 at 2 mm, seed 2 −0.4: bias −0.1, RMS √0.1.
        a.estimates = vec![
            sample(1.98, 2.18, 0.3, Medium::Rime),
            sample(2.02, 2.22, 0.3, Medium::Rime),
            sample(0.3, 0.3, 0.1, Medium::Glazed),
        ];
        b.estimates = vec![
            sample(2.0, 1.6, 0.1, Medium::Glazed),
            sample(5.0, 5.0, 0.1, Medium::Rime),
        ];
        let r = rows(&[a, b]);
        assert_eq!(r.len(), 1);
        let r = &r[0];
        assert_eq!((r.name.as_str(), r.runs), ("acc", 2));
        let e = r.at[2].unwrap();
        assert!((e.bias_mm + 0.1).abs() < 1e-9, "{e:?}");
        assert!((e.rms_mm - 0.1f64.sqrt()).abs() < 1e-9, "{e:?}");
        assert_eq!(e.seeds, 2);
        assert_eq!(r.at[3].unwrap().seeds, 1);
        assert!(r.at[0].is_none() && r.at[4].is_none());
        // Beyond 0.5 mm: 3 of 4 frames within 2σ (−0.4 > 2 × 0.1 is not).
        assert_eq!(r.within_2sigma, Some(0.75));
        // From 1 mm: 3 of 4 named rime.
        assert_eq!(r.medium_right, Some(0.75));
        assert!(table(&rows(&[]), &[]).lines().count() == 2);
        // No gain sent: the gain columns say so.
        assert_eq!(r.gain, None);
        assert_eq!(r.true_gain, Some((1.0, 1.0)));
        // 5 mm read as 5.0 ± 0.1: not thin (1 frame from 4 mm).
        assert_eq!(r.confidently_thin, (0, 1));
        let t = table(std::slice::from_ref(r), &[]);
        assert!(
            t.lines()
                .nth(2)
                .unwrap()
                .ends_with("| 1.00 | — | — | — | 0 of 1 |"),
            "{t}"
        );
    }

    #[test]
    fn gain_columns_compare_the_estimate_with_the_truth() {
        let mut a = crate::outcome::tests_support::outcome("g@seed1");
        let mut b = crate::outcome::tests_support::outcome("g@seed2");
        let with = |true_mm, est_mm, sigma_mm, true_gain, gain| EstSample {
            true_gain,
            gain,
            ..sample(true_mm, est_mm, sigma_mm, Medium::Rime)
        };
        // The LED drifts 1.0 → 0.8; seed 1 tracks it within σ, seed 2 sends
        // 0.9 ± 0.01 at the end (error 0.1 > 2σ) and reads 2 mm at 6 mm.
        a.estimates = vec![
            with(0.0, 0.0, 0.1, 1.0, Some((1.0, 0.05))),
            with(1.0, 1.0, 0.1, 1.0, Some((1.02, 0.05))),
            with(6.0, 6.0, 0.5, 0.8, Some((0.78, 0.02))),
        ];
        b.estimates = vec![
            with(1.0, 1.0, 0.1, 1.0, Some((1.0, 0.05))),
            with(6.0, 2.0, 0.4, 0.8, Some((0.9, 0.01))),
        ];
        let r = &rows(&[a, b])[0];
        assert_eq!(r.true_gain, Some((1.0, 0.8)));
        let g = r.gain.unwrap();
        // Last frames: (0.78 + 0.9) / 2 = 0.84, σ (0.02 + 0.01) / 2.
        assert!((g.end_gain - 0.84).abs() < 1e-12, "{g:?}");
        assert!((g.end_sigma - 0.015).abs() < 1e-12, "{g:?}");
        // Errors over the 4 frames with ice: 0.02, −0.02, 0, 0.1.
        let rms = ((0.02f64.powi(2) * 2.0 + 0.01) / 4.0).sqrt();
        assert!((g.rms_err - rms).abs() < 1e-12, "{g:?}");
        assert_eq!(g.within_2sigma, 0.75);
        // 2.0 + 0.8 < 3.0: seed 2's 6 mm frame is confidently thin.
        assert_eq!(r.confidently_thin, (1, 2));
        let t = table(std::slice::from_ref(r), &[]);
        assert!(
            t.contains("| 1.00 → 0.80 | 0.840 (σ 0.015) | 0.052 | 75.0 % | 1 of 2 |"),
            "{t}"
        );
    }
}
