//! Evaluation of the ice estimator on ray-traced accretions: a timeline of
//! segments (dry face, or a medium accreting at a rate, air temperature), the
//! simulator's curve of one accretion per medium (seeds that the response
//! table does not use), frames with noise and a persistent offset, the LED
//! gain; per frame the truth and the estimate; per thickness the error
//! statistics. Shared by `tests/estimator_accuracy.rs` and
//! `examples/estimator_eval.rs`.
#![allow(dead_code)]

use fois_firmware::estimator::{Estimator, EstimatorParams, Gain, IcingState, Posterior, Rate};
use fois_protocol::Medium;
use fois_sim::{Curve, Geometry, IceKind, SensorKind, SimConfig, accretion_curve};
use rand_core::Rng;
use rand_pcg::Pcg32;

/// One stretch of constant conditions.
#[derive(Debug, Clone, Copy)]
pub struct Segment {
    /// `None`: the dry face (thickness 0).
    pub cover: Option<IceKind>,
    /// Length, s.
    pub duration_s: f64,
    /// Accretion rate, mm/h (negative: melting).
    pub rate_mm_per_h: f64,
    /// Air temperature at the start and the end (linear), °C.
    pub temp_c: (f64, f64),
    /// Standard deviation of ln(rate) of a rate that varies (an
    /// Ornstein–Uhlenbeck process in ln r with a 1 h time constant around
    /// `rate_mm_per_h`); 0: constant.
    pub rate_sd_ln: f64,
}

impl Segment {
    pub fn dry(duration_s: f64, temp_c: f64) -> Self {
        Segment {
            cover: None,
            duration_s,
            rate_mm_per_h: 0.0,
            temp_c: (temp_c, temp_c),
            rate_sd_ln: 0.0,
        }
    }
    /// `kind` on the face, not growing, for `duration_s`.
    pub fn pause(kind: IceKind, duration_s: f64, temp_c: f64) -> Self {
        Segment {
            cover: Some(kind),
            duration_s,
            rate_mm_per_h: 0.0,
            temp_c: (temp_c, temp_c),
            rate_sd_ln: 0.0,
        }
    }
    /// Grow `kind` from the current thickness to `to_mm` at `rate`.
    pub fn grow(kind: IceKind, from_mm: f64, to_mm: f64, rate_mm_per_h: f64, temp_c: f64) -> Self {
        Segment {
            cover: Some(kind),
            duration_s: (to_mm - from_mm).abs() / rate_mm_per_h.abs() * 3600.0,
            rate_mm_per_h,
            temp_c: (temp_c, temp_c),
            rate_sd_ln: 0.0,
        }
    }
}

/// A run: segments, the accretion seed, and the front end.
#[derive(Debug, Clone)]
pub struct Run {
    pub segments: Vec<Segment>,
    /// Accretion seed (run 0 of it), one curve per medium.
    pub seed: u64,
    /// LED output relative to what the table assumes (0.7 = −30 %): the
    /// sensor's optical gain at the start.
    pub led: f64,
    /// The gain at the end of the run (linear drift); `None`: constant.
    pub led_end: Option<f64>,
    /// The estimator's gain prior (gain, relative sd); `None`: unknown.
    pub gain_prior: Option<(f32, f32)>,
    /// Frame period, s.
    pub frame_s: f64,
    /// White noise per frame and channel, µA (rms).
    pub noise_ua: f64,
    /// Persistent offset per channel (baseline error, flicker residual), rms µA,
    /// drawn once per run.
    pub offset_ua: f64,
    /// Fail the NTC (no temperature evidence).
    pub ntc_failed: bool,
}

impl Run {
    pub fn new(seed: u64, segments: Vec<Segment>) -> Self {
        Run {
            segments,
            seed,
            led: 1.0,
            led_end: None,
            gain_prior: None,
            frame_s: 0.1,
            noise_ua: 0.04,
            offset_ua: 0.05,
            ntc_failed: false,
        }
    }
}

/// One frame's truth and estimate.
#[derive(Debug, Clone, Copy)]
pub struct FrameRecord {
    pub t_s: f64,
    pub thickness_mm: f64,
    pub medium: Medium,
    pub temp_c: f64,
    pub currents_ua: [f64; 2],
    pub est: Option<Posterior>,
    /// The true optical gain of the frame.
    pub gain: f64,
    /// The estimator's gain after the frame.
    pub est_gain: Option<Gain>,
    /// The true growth rate of the frame, mm/h (0: dry or not growing).
    pub rate_mm_per_h: f64,
    /// The estimator's growth rate after the frame.
    pub est_rate: Option<Rate>,
    /// The estimator's icing-period flag after the frame.
    pub accreting: bool,
    /// The estimator's icing state after the frame.
    pub icing: Option<IcingState>,
    /// The bank's ln odds of rime against glaze after the frame.
    pub rime_odds: f32,
}

/// The goals' "confidently thin": at 4 mm or more, the estimate plus two
/// standard deviations below half the true thickness.
pub fn confidently_thin(est_mm: f64, sigma_mm: f64, true_mm: f64) -> bool {
    true_mm >= 4.0 && est_mm + 2.0 * sigma_mm < true_mm / 2.0
}

pub fn medium_of(kind: Option<IceKind>) -> Medium {
    match kind {
        None => Medium::Dry,
        Some(IceKind::Water) => Medium::Water,
        Some(IceKind::Rime) => Medium::Rime,
        Some(_) => Medium::Glazed,
    }
}

fn gaussian(rng: &mut Pcg32) -> f64 {
    let u1 = ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The simulator's curve of run 0 of `seed` for `kind` (Sensor B, chapter-5 geometry).
pub fn curve(kind: IceKind, seed: u64) -> Curve {
    assert_ne!(
        seed,
        fois_sim::table::TABLE_SEED,
        "evaluation seeds must differ from the table's"
    );
    accretion_curve(
        &SimConfig::new(kind, SensorKind::B, Geometry::default()),
        seed,
        0,
    )
}

/// Run the estimator over the run's frames; every frame is recorded.
pub fn simulate(run: &Run, params: EstimatorParams) -> Vec<FrameRecord> {
    let mut kinds: Vec<IceKind> = run.segments.iter().filter_map(|s| s.cover).collect();
    kinds.dedup();
    let curves: Vec<(IceKind, Curve)> = kinds.iter().map(|&k| (k, curve(k, run.seed))).collect();
    let mut rng = Pcg32::new(run.seed ^ 0x5EED_E571, 0xE57);
    let offset = [
        gaussian(&mut rng) * run.offset_ua,
        gaussian(&mut rng) * run.offset_ua,
    ];
    let mut est = Estimator::new(params);
    if let Some((g, sd)) = run.gain_prior {
        est.set_gain_prior(g, sd);
    }
    let total_s: f64 = run.segments.iter().map(|s| s.duration_s).sum();
    // The varying rate's process has its own generator (the noise stays
    // that of a constant rate).
    let mut rate_rng = Pcg32::new(run.seed ^ 0x0A7E_0A7E, 0xA7E);
    let mut rate_x = 0.0f64;
    let mut out = Vec::new();
    let mut d = 0.0f64;
    let mut t = 0.0f64;
    for seg in &run.segments {
        let n = (seg.duration_s / run.frame_s).round() as u64;
        if seg.cover.is_none() {
            d = 0.0;
        }
        let rate_a = (-run.frame_s / 3600.0).exp();
        if seg.rate_sd_ln > 0.0 {
            rate_x = seg.rate_sd_ln * gaussian(&mut rate_rng);
        }
        for i in 0..n {
            let w = i as f64 / n.max(1) as f64;
            let rate_now = if seg.rate_sd_ln > 0.0 {
                rate_x = rate_x * rate_a
                    + seg.rate_sd_ln * (1.0 - rate_a * rate_a).sqrt() * gaussian(&mut rate_rng);
                seg.rate_mm_per_h * (rate_x - 0.5 * seg.rate_sd_ln * seg.rate_sd_ln).exp()
            } else {
                seg.rate_mm_per_h
            };
            let temp = seg.temp_c.0 + (seg.temp_c.1 - seg.temp_c.0) * w;
            let signal = match seg.cover {
                None => [0.0, 0.0],
                Some(k) => {
                    let c = &curves.iter().find(|(kk, _)| *kk == k).expect("curve").1;
                    let (a, b) = c.currents_at(d);
                    [a, b]
                }
            };
            let gain = match run.led_end {
                Some(end) => run.led + (end - run.led) * (t / total_s.max(1e-9)),
                None => run.led,
            };
            let x =
                [0, 1].map(|ch| signal[ch] * gain + offset[ch] + run.noise_ua * gaussian(&mut rng));
            let temp_in = if run.ntc_failed {
                None
            } else {
                Some(temp as f32)
            };
            let dt = if out.is_empty() {
                0.0
            } else {
                run.frame_s as f32
            };
            est.step(dt, Some([x[0] as f32, x[1] as f32]), temp_in);
            out.push(FrameRecord {
                t_s: t,
                thickness_mm: d,
                medium: medium_of(seg.cover),
                temp_c: temp,
                currents_ua: x,
                est: est.posterior(),
                gain,
                est_gain: est.gain(),
                rate_mm_per_h: if seg.cover.is_some() { rate_now } else { 0.0 },
                est_rate: est.rate(),
                accreting: est.accreting(),
                icing: est.icing_state(),
                rime_odds: est.rime_odds(),
            });
            t += run.frame_s;
            if seg.cover.is_some() {
                d = (d + rate_now * run.frame_s / 3600.0).clamp(0.0, 15.0);
            }
        }
    }
    out
}

/// Statistics of one scenario class over its runs.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    /// Per target thickness: the error of each run (mean over the frames
    /// within ±`window` of the target while that medium is on the face).
    pub errors: Vec<(f64, Vec<f64>)>,
    /// Per target: the mean reported σ of each run.
    pub sigmas: Vec<(f64, Vec<f64>)>,
    /// Frames beyond 0.5 mm with an estimate, and those with |error| ≤ 2σ.
    pub calib: (u64, u64),
    /// Frames with ice or water ≥ 1 mm, and those whose medium is right.
    pub medium: (u64, u64),
    /// Frames whose truth is water and whose estimate says ice (glazed/rime).
    pub water_called_ice: u64,
    /// Frames whose truth is water.
    pub water_frames: u64,
}

pub const TARGETS_MM: [f64; 5] = [0.5, 1.0, 2.0, 5.0, 10.0];

impl Stats {
    pub fn new() -> Self {
        Stats {
            errors: TARGETS_MM.iter().map(|&d| (d, Vec::new())).collect(),
            sigmas: TARGETS_MM.iter().map(|&d| (d, Vec::new())).collect(),
            ..Stats::default()
        }
    }

    /// Add one run's frames.
    pub fn add(&mut self, frames: &[FrameRecord], window_mm: f64) {
        for ((target, errs), (_, sigs)) in self.errors.iter_mut().zip(self.sigmas.iter_mut()) {
            let near: Vec<&FrameRecord> = frames
                .iter()
                .filter(|f| {
                    f.medium != Medium::Dry && (f.thickness_mm - *target).abs() <= window_mm
                })
                .filter(|f| f.est.is_some())
                .collect();
            if near.is_empty() {
                continue;
            }
            let n = near.len() as f64;
            let e = near
                .iter()
                .map(|f| f64::from(f.est.expect("est").thickness_mm) - f.thickness_mm)
                .sum::<f64>()
                / n;
            let s = near
                .iter()
                .map(|f| f64::from(f.est.expect("est").sigma_mm))
                .sum::<f64>()
                / n;
            errs.push(e);
            sigs.push(s);
        }
        for f in frames {
            let Some(est) = f.est else { continue };
            let err = f64::from(est.thickness_mm) - f.thickness_mm;
            if f.thickness_mm > 0.5 {
                self.calib.0 += 1;
                if err.abs() <= 2.0 * f64::from(est.sigma_mm) {
                    self.calib.1 += 1;
                }
            }
            if f.medium != Medium::Dry && f.thickness_mm >= 1.0 {
                self.medium.0 += 1;
                if est.medium().0 == f.medium {
                    self.medium.1 += 1;
                }
            }
            if f.medium == Medium::Water {
                self.water_frames += 1;
                if matches!(est.medium().0, Medium::Glazed | Medium::Rime) {
                    self.water_called_ice += 1;
                }
            }
        }
    }

    /// (bias, rms, mean σ, runs) at a target.
    pub fn at(&self, target: f64) -> Option<(f64, f64, f64, usize)> {
        let (_, e) = self.errors.iter().find(|(d, _)| *d == target)?;
        let (_, s) = self.sigmas.iter().find(|(d, _)| *d == target)?;
        if e.is_empty() {
            return None;
        }
        let n = e.len() as f64;
        let bias = e.iter().sum::<f64>() / n;
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let sig = s.iter().sum::<f64>() / n;
        Some((bias, rms, sig, e.len()))
    }

    pub fn calibration(&self) -> f64 {
        self.calib.1 as f64 / self.calib.0.max(1) as f64
    }

    pub fn medium_accuracy(&self) -> f64 {
        self.medium.1 as f64 / self.medium.0.max(1) as f64
    }
}

/// √CRLB of rime at `d` from a Monte Carlo of `runs` accretions (seed `seed`).
pub fn rime_crlb(runs: u64, seed: u64) -> Vec<(f64, f64)> {
    let cfg = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::default());
    let mc = fois_sim::monte_carlo(&cfg, runs, seed, &|| {});
    fois_sim::crlb(&mc.points, fois_sim::montecarlo::DEFAULT_FIT_HALF_WIDTH_MM)
        .iter()
        .map(|p| (p.thickness_mm, p.crlb_std_mm))
        .collect()
}

pub fn crlb_at(crlb: &[(f64, f64)], d: f64) -> f64 {
    crlb.iter()
        .min_by(|a, b| (a.0 - d).abs().total_cmp(&(b.0 - d).abs()))
        .map_or(f64::NAN, |p| p.1)
}

/// Water that freezes: 0.3 mm of water at +5 °C, the air to 0 °C, then glaze
/// at 1 mm/h while the air falls to −5 °C (the accuracy test and
/// `estimator_eval trace-freeze SEED`).
pub fn freeze_run(seed: u64) -> Run {
    Run::new(
        seed,
        vec![
            Segment::dry(600.0, 5.0),
            Segment::grow(IceKind::Water, 0.0, 0.3, 1.8, 5.0),
            Segment {
                cover: Some(IceKind::Water),
                duration_s: 1200.0,
                rate_mm_per_h: 0.0,
                temp_c: (5.0, 0.0),
                rate_sd_ln: 0.0,
            },
            Segment {
                cover: Some(IceKind::Glazed),
                duration_s: 3600.0,
                rate_mm_per_h: 1.0,
                temp_c: (0.0, -5.0),
                rate_sd_ln: 0.0,
            },
        ],
    )
}
