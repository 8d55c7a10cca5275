//! The maths of `foisctl compare`: logged currents beside the simulator's
//! Monte Carlo band μ(d) ± k·σ(d), with the RMS deviation and the fraction of samples
//! inside the band.
//!
//! The reference thickness of each logged sample comes from a column of the
//! log (`--thickness-col`, mm: e.g. a laser distance sensor, as in the
//! thesis) or from a constant accretion rate and a start time
//! (`--rate-mm-per-h`, `--start-s`: d = rate × (uptime − start)).

use std::path::{Path, PathBuf};

use anyhow::bail;
use fois_sim::{Geometry, IceKind, McPoint, SensorKind, SimConfig, monte_carlo};

use crate::csvlog::LogReader;

/// How the thickness of each sample is known.
#[derive(Debug, Clone, PartialEq)]
pub enum ThicknessSource {
    /// A column of the log, mm.
    Column(String),
    /// Constant rate, mm/h, from node uptime `start_s` on.
    Rate {
        /// mm/h.
        mm_per_h: f64,
        /// Node uptime at which accretion started, s (None: the first sample).
        start_s: Option<f64>,
    },
}

/// What to compare.
#[derive(Debug, Clone)]
pub struct CompareOptions {
    /// The log (a foisctl CSV, or any CSV with `i1_ua`, `i2_ua` and the
    /// thickness or `uptime_ms` columns).
    pub log: PathBuf,
    /// The medium simulated.
    pub ice: IceKind,
    /// Sensor construction.
    pub sensor: SensorKind,
    /// Thickness of each sample.
    pub thickness: ThicknessSource,
    /// Monte Carlo accretions.
    pub runs: u64,
    /// Seed of the Monte Carlo.
    pub seed: u64,
    /// Band half-width in σ.
    pub k_sigma: f64,
    /// Measurement noise of one logged sample, rms µA: added in quadrature
    /// to the Monte Carlo spread (which holds only the ice's randomness).
    pub noise_ua: f64,
}

/// One logged sample with its reference thickness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Logged (I1, I2), µA.
    pub i_ua: [f64; 2],
}

/// Per-channel result.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChannelStats {
    /// RMS of logged − μ(d), µA.
    pub rms_ua: f64,
    /// Mean of logged − μ(d), µA.
    pub bias_ua: f64,
    /// Fraction of samples with |logged − μ| ≤ k·σ.
    pub inside: f64,
}

/// The comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Samples used (thickness within the simulated range).
    pub samples: Vec<Sample>,
    /// I1, I2.
    pub channels: [ChannelStats; 2],
    /// The band: thickness, μ, σ per channel.
    pub band: Vec<McPoint>,
    /// k.
    pub k_sigma: f64,
}

/// μ and σ at thickness `d` by linear interpolation of the Monte Carlo grid.
pub fn band_at(band: &[McPoint], d: f64) -> ([f64; 2], [f64; 2]) {
    let sig = |p: &McPoint| {
        [
            p.cov_ua2[0][0].max(0.0).sqrt(),
            p.cov_ua2[1][1].max(0.0).sqrt(),
        ]
    };
    let Some(first) = band.first() else {
        return ([f64::NAN; 2], [f64::NAN; 2]);
    };
    if d <= first.thickness_mm {
        return (first.mean_ua, sig(first));
    }
    let last = band[band.len() - 1];
    if d >= last.thickness_mm {
        return (last.mean_ua, sig(&last));
    }
    let k = band.partition_point(|p| p.thickness_mm <= d);
    let (a, b) = (&band[k - 1], &band[k]);
    let w = (d - a.thickness_mm) / (b.thickness_mm - a.thickness_mm);
    let (sa, sb) = (sig(a), sig(b));
    (
        [0, 1].map(|c| a.mean_ua[c] + w * (b.mean_ua[c] - a.mean_ua[c])),
        [0, 1].map(|c| sa[c] + w * (sb[c] - sa[c])),
    )
}

/// Statistics of samples against a band.
pub fn compare_samples(samples: Vec<Sample>, band: Vec<McPoint>, k_sigma: f64) -> Comparison {
    let mut channels = [ChannelStats::default(); 2];
    let n = samples.len().max(1) as f64;
    for (c, ch) in channels.iter_mut().enumerate() {
        let (mut sq, mut sum, mut inside) = (0.0, 0.0, 0usize);
        for s in &samples {
            let (mu, sigma) = band_at(&band, s.thickness_mm);
            let dev = s.i_ua[c] - mu[c];
            sq += dev * dev;
            sum += dev;
            if dev.abs() <= k_sigma * sigma[c] {
                inside += 1;
            }
        }
        *ch = ChannelStats {
            rms_ua: (sq / n).sqrt(),
            bias_ua: sum / n,
            inside: inside as f64 / n,
        };
    }
    Comparison {
        samples,
        channels,
        band,
        k_sigma,
    }
}

/// Samples of a log: measurement rows (if the log has `kind`) that are
/// valid (if it has `valid`), with their thickness. Reads row by row.
pub fn samples_from_log(path: &Path, src: &ThicknessSource) -> anyhow::Result<Vec<Sample>> {
    let mut rd = LogReader::open(path)?;
    let (i1, i2) = (rd.need("i1_ua")?, rd.need("i2_ua")?);
    let kind = rd.col("kind");
    let valid = rd.col("valid");
    let thick_col = match src {
        ThicknessSource::Column(name) => Some(rd.need(name)?),
        ThicknessSource::Rate { .. } => None,
    };
    let uptime = match src {
        ThicknessSource::Rate { .. } => Some(rd.need("uptime_ms")?),
        _ => None,
    };
    let num = |s: &str| s.trim().parse::<f64>().ok().filter(|x| x.is_finite());
    let mut start = match src {
        ThicknessSource::Rate { start_s, .. } => start_s.map(|s| s * 1000.0),
        _ => None,
    };
    let mut out = Vec::new();
    let mut r = csv::StringRecord::new();
    while rd.next_row(&mut r)? {
        if kind.is_some_and(|k| &r[k] != "measurement") {
            continue;
        }
        if valid.is_some_and(|v| r[v].trim() == "0") {
            continue;
        }
        let (Some(a), Some(b)) = (num(&r[i1]), num(&r[i2])) else {
            continue;
        };
        let d = match (src, thick_col, uptime) {
            (_, Some(c), _) => num(&r[c]),
            (ThicknessSource::Rate { mm_per_h, .. }, None, Some(u)) => num(&r[u]).map(|ms| {
                let s0 = *start.get_or_insert(ms);
                mm_per_h * (ms - s0) / 3_600_000.0
            }),
            _ => None,
        };
        if let Some(d) = d.filter(|d| (0.0..=15.0).contains(d)) {
            out.push(Sample {
                thickness_mm: d,
                i_ua: [a, b],
            });
        }
    }
    Ok(out)
}

/// Run the whole comparison (reads the log, runs the Monte Carlo).
pub fn run(opts: &CompareOptions) -> anyhow::Result<Comparison> {
    let samples = samples_from_log(&opts.log, &opts.thickness)?;
    if samples.is_empty() {
        bail!(
            "log {} has no valid measurement with a thickness in 0..=15 mm to compare",
            opts.log.display()
        );
    }
    if !(1..=100_000).contains(&opts.runs) {
        bail!("--runs must be in 1..=100000");
    }
    let cfg = SimConfig::new(opts.ice, opts.sensor, Geometry::default());
    let mc = monte_carlo(&cfg, opts.runs, opts.seed, &|| {});
    let band = with_noise(mc.points, opts.noise_ua);
    Ok(compare_samples(samples, band, opts.k_sigma))
}

/// The band widened by a sample's measurement noise: σ² + noise² on the
/// diagonal of each Σ(d) (the noise of I1 and I2 is independent).
pub fn with_noise(mut band: Vec<McPoint>, noise_ua: f64) -> Vec<McPoint> {
    let var = noise_ua * noise_ua;
    for p in &mut band {
        p.cov_ua2[0][0] += var;
        p.cov_ua2[1][1] += var;
    }
    band
}

/// The text report.
pub fn report(c: &Comparison) -> String {
    let mut s = format!(
        "{} samples, thickness {:.2}..{:.2} mm; band μ(d) ± {}σ(d) \
         (σ: Monte Carlo spread and measurement noise in quadrature)\n",
        c.samples.len(),
        c.samples
            .iter()
            .map(|x| x.thickness_mm)
            .fold(f64::INFINITY, f64::min),
        c.samples
            .iter()
            .map(|x| x.thickness_mm)
            .fold(f64::NEG_INFINITY, f64::max),
        c.k_sigma
    );
    for (name, ch) in ["I1", "I2"].iter().zip(c.channels.iter()) {
        s.push_str(&format!(
            "{name}: RMS deviation {:.3} µA, mean deviation {:+.3} µA, {:.1} % of samples inside the band\n",
            ch.rms_ua,
            ch.bias_ua,
            100.0 * ch.inside
        ));
    }
    s.push_str("  d (mm)     n   I1 log     μ1      σ1 |  I2 log     μ2      σ2   (µA)\n");
    for lo in 0..15 {
        let lo = f64::from(lo);
        let bin: Vec<&Sample> = c
            .samples
            .iter()
            .filter(|x| x.thickness_mm >= lo && x.thickness_mm < lo + 1.0)
            .collect();
        if bin.is_empty() {
            continue;
        }
        let n = bin.len() as f64;
        let mean = |k: usize| bin.iter().map(|x| x.i_ua[k]).sum::<f64>() / n;
        let dm = bin.iter().map(|x| x.thickness_mm).sum::<f64>() / n;
        let (mu, sg) = band_at(&c.band, dm);
        s.push_str(&format!(
            "{:5.1}-{:<4.1} {:5} {:7.2} {:7.2} {:7.2} | {:7.2} {:7.2} {:7.2}\n",
            lo,
            lo + 1.0,
            bin.len(),
            mean(0),
            mu[0],
            sg[0],
            mean(1),
            mu[1],
            sg[1]
        ));
    }
    s.push_str(&verdict(c));
    s.push('\n');
    s
}

/// Percentage points a channel's fraction inside the band may fall short
/// of a Gaussian band's coverage and still agree: a log's samples are
/// correlated from frame to frame (the ice and the gain drift slowly), so
/// their fraction inside scatters far more than independent draws would.
pub const VERDICT_MARGIN_POINTS: f64 = 10.0;

/// The fraction of a normal distribution within ±k standard deviations
/// (erf(k/√2)), by Simpson's rule on the density (error < 1e-9 for k ≤ 10).
pub fn normal_coverage(k: f64) -> f64 {
    let k = k.clamp(0.0, 10.0);
    let n = 2000;
    let h = k / f64::from(n);
    let f = |x: f64| (-0.5 * x * x).exp();
    let mut sum = f(0.0) + f(k);
    for i in 1..n {
        let w = if i % 2 == 1 { 4.0 } else { 2.0 };
        sum += w * f(f64::from(i) * h);
    }
    2.0 * sum * h / 3.0 / (2.0 * std::f64::consts::PI).sqrt()
}

/// The one-line verdict: the log agrees with the simulation when each
/// channel has at least the Gaussian coverage of the ±kσ band
/// ([`normal_coverage`], 68.3 % at k = 1) less [`VERDICT_MARGIN_POINTS`]
/// of its samples inside the band.
pub fn verdict(c: &Comparison) -> String {
    let expected = 100.0 * normal_coverage(c.k_sigma);
    let need = expected - VERDICT_MARGIN_POINTS;
    let pct: Vec<f64> = c.channels.iter().map(|ch| 100.0 * ch.inside).collect();
    let shown = ["I1", "I2"]
        .iter()
        .zip(&pct)
        .map(|(n, p)| format!("{n} {p:.1} %"))
        .collect::<Vec<_>>()
        .join(", ");
    let why = format!(
        "inside the ±{}σ band; at least {need:.1} % needed: a Gaussian band holds {expected:.1} %, \
         {VERDICT_MARGIN_POINTS:.0} points allowed because a log's samples are correlated",
        c.k_sigma
    );
    if pct.iter().all(|&p| p >= need) {
        format!("verdict: AGREES with the simulation ({shown} {why})")
    } else {
        format!(
            "verdict: DIFFERS from the simulation ({shown} {why}); check the medium (--ice), the \
             thickness source, the node's gain calibration and dark baseline"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band() -> Vec<McPoint> {
        (0..=150)
            .map(|i| {
                let d = f64::from(i) * 0.1;
                McPoint {
                    thickness_mm: d,
                    mean_ua: [10.0 * d, d],
                    cov_ua2: [[4.0, 0.0], [0.0, 0.25]],
                }
            })
            .collect()
    }

    #[test]
    fn the_verdict_compares_the_fraction_inside_with_the_gaussian_coverage() {
        assert!((normal_coverage(1.0) - 0.682_689_492).abs() < 1e-8);
        assert!((normal_coverage(2.0) - 0.954_499_736).abs() < 1e-8);
        let with = |inside: [f64; 2]| Comparison {
            samples: Vec::new(),
            band: Vec::new(),
            k_sigma: 1.0,
            channels: inside.map(|f| ChannelStats {
                rms_ua: 0.0,
                bias_ua: 0.0,
                inside: f,
            }),
        };
        let v = verdict(&with([0.74, 0.60]));
        assert!(v.starts_with("verdict: AGREES"), "{v}");
        assert!(
            v.contains("I1 74.0 %") && v.contains("58.3 % needed"),
            "{v}"
        );
        let v = verdict(&with([0.74, 0.58]));
        assert!(v.starts_with("verdict: DIFFERS"), "{v}");
        assert_eq!(v.lines().count(), 1);
    }

    #[test]
    fn samples_on_the_mean_are_inside_and_far_ones_outside() {
        let on: Vec<Sample> = (0..100)
            .map(|i| {
                let d = f64::from(i) * 0.137;
                Sample {
                    thickness_mm: d,
                    i_ua: [10.0 * d, d],
                }
            })
            .collect();
        let c = compare_samples(on, band(), 1.0);
        assert!(c.channels[0].rms_ua < 1e-9);
        assert_eq!(c.channels[0].inside, 1.0);
        // +3 µA on I1 (1.5 σ): outside a 1σ band, inside a 2σ band; I2 +1 µA (2 σ).
        let off: Vec<Sample> = (0..100)
            .map(|i| {
                let d = f64::from(i) * 0.137;
                Sample {
                    thickness_mm: d,
                    i_ua: [10.0 * d + 3.0, d + 1.0],
                }
            })
            .collect();
        let c1 = compare_samples(off.clone(), band(), 1.0);
        assert!((c1.channels[0].rms_ua - 3.0).abs() < 1e-9);
        assert!((c1.channels[0].bias_ua - 3.0).abs() < 1e-9);
        assert_eq!(c1.channels[0].inside, 0.0);
        let c2 = compare_samples(off, band(), 2.0);
        assert_eq!(c2.channels[0].inside, 1.0);
        assert!((c2.channels[1].rms_ua - 1.0).abs() < 1e-9);
        // Interpolation between grid points.
        let (mu, sg) = band_at(&band(), 0.25);
        assert!((mu[0] - 2.5).abs() < 1e-9 && (sg[0] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn measurement_noise_widens_the_band_in_quadrature() {
        // σ1 = 2 µA, σ2 = 0.5 µA; noise 1.5 µA → σ1 = 2.5, σ2 = √2.5.
        let wide = with_noise(band(), 1.5);
        let (_, sg) = band_at(&wide, 0.3);
        assert!((sg[0] - 2.5).abs() < 1e-12, "{sg:?}");
        assert!((sg[1] - 2.5f64.sqrt()).abs() < 1e-12, "{sg:?}");
        // An I2 sample 1 µA off: outside the bare 1σ band, inside the widened one.
        let s = vec![Sample {
            thickness_mm: 0.3,
            i_ua: [3.0, 1.3],
        }];
        assert_eq!(
            compare_samples(s.clone(), band(), 1.0).channels[1].inside,
            0.0
        );
        assert_eq!(compare_samples(s, wide, 1.0).channels[1].inside, 1.0);
    }

    #[test]
    fn thickness_from_rate_and_from_a_column() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("l.csv");
        std::fs::write(
            &p,
            "kind,uptime_ms,i1_ua,i2_ua,valid,laser_mm\n\
             measurement,0,1,0.1,1,0.5\n\
             event,1800000,9,9,,\n\
             measurement,1800000,2,0.2,1,20\n\
             measurement,3600000,3,0.3,0,1.0\n\
             measurement,7200000,4,0.4,1,2.0\n",
        )
        .unwrap();
        let by_rate = samples_from_log(
            &p,
            &ThicknessSource::Rate {
                mm_per_h: 2.0,
                start_s: None,
            },
        )
        .unwrap();
        let d: Vec<f64> = by_rate.iter().map(|s| s.thickness_mm).collect();
        assert_eq!(d, [0.0, 1.0, 4.0]);
        let by_col = samples_from_log(&p, &ThicknessSource::Column("laser_mm".into())).unwrap();
        let d: Vec<f64> = by_col.iter().map(|s| s.thickness_mm).collect();
        assert_eq!(
            d,
            [0.5, 2.0],
            "20 mm is out of range, the invalid row is skipped"
        );
        let err = samples_from_log(&p, &ThicknessSource::Column("nope".into())).unwrap_err();
        assert!(err.to_string().contains("no column `nope`"), "{err}");
    }
}
