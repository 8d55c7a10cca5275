//! A growth rate that varies: ln r an Ornstein–Uhlenbeck process (seeded),
//! laid on a segment as piecewise-constant sub-segments. Real icing does
//! not grow at one rate for hours; the node's growth history assumes a rate
//! that walks (`fois_firmware::estimator::HistoryParams`), and a scenario
//! with this walk is how the hardware-in-loop suite checks it follows one.
//!
//! ln r(t) has mean ln(r̄) − sd²/2 (so that the rate's mean is the
//! segment's `rate_mm_per_h`), stationary standard deviation `sd` and
//! correlation time `corr_s`; it starts from its stationary distribution
//! and is held constant over each `step_s`.

use rand_core::Rng;
use rand_pcg::Pcg32;

use crate::environment::Segment;

/// The walk of ln r over one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateWalk {
    /// Stationary standard deviation of ln r.
    pub sd_ln: f64,
    /// Correlation time, s.
    pub corr_s: f64,
    /// Length of each constant-rate sub-segment, s.
    pub step_s: f64,
    /// Seed of the draws.
    pub seed: u64,
}

/// Default length of a sub-segment, s.
pub const DEFAULT_STEP_S: f64 = 60.0;

fn gaussian(rng: &mut Pcg32) -> f64 {
    // Box–Muller on two uniforms in (0, 1].
    let u = |rng: &mut Pcg32| ((rng.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
    let (a, b) = (u(rng), u(rng));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

/// `seg` (finite, rate > 0) as sub-segments of `walk.step_s` (the last one
/// shorter) whose rates follow the walk around `seg.rate_mm_per_h`; the
/// first keeps `seg`'s start thickness, the others continue.
pub fn expand(seg: &Segment, walk: RateWalk) -> Vec<Segment> {
    let mut rng = Pcg32::new(walk.seed ^ 0x5851_F42D_4C95_7F2D, 0x1CE);
    let mean_ln = seg.rate_mm_per_h.ln() - 0.5 * walk.sd_ln * walk.sd_ln;
    let rho = (-walk.step_s / walk.corr_s).exp();
    let innovation = walk.sd_ln * (1.0 - rho * rho).sqrt();
    let mut x = walk.sd_ln * gaussian(&mut rng);
    let mut out = Vec::new();
    let mut t = 0.0;
    while t < seg.duration_s {
        let d = walk.step_s.min(seg.duration_s - t);
        let w0 = t / seg.duration_s;
        let w1 = (t + d) / seg.duration_s;
        let lerp = |a: f64, b: Option<f64>, w: f64| b.map_or(a, |b| a + (b - a) * w);
        let mut s = seg.clone();
        s.duration_s = d;
        s.rate_mm_per_h = (mean_ln + x).exp();
        if !out.is_empty() {
            s.start_thickness_mm = None;
        }
        // Ramps are split into sub-ramps.
        s.air_temp_c = lerp(seg.air_temp_c, seg.air_temp_end_c, w0);
        s.air_temp_end_c = seg
            .air_temp_end_c
            .map(|_| lerp(seg.air_temp_c, seg.air_temp_end_c, w1));
        s.led_factor = lerp(seg.led_factor, seg.led_factor_end, w0);
        s.led_factor_end = seg
            .led_factor_end
            .map(|_| lerp(seg.led_factor, seg.led_factor_end, w1));
        s.face_transmission = lerp(seg.face_transmission, seg.face_transmission_end, w0);
        s.face_transmission_end = seg
            .face_transmission_end
            .map(|_| lerp(seg.face_transmission, seg.face_transmission_end, w1));
        out.push(s);
        x = rho * x + innovation * gaussian(&mut rng);
        t += d;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::environment::Cover;

    #[test]
    fn the_walk_keeps_the_mean_rate_the_spread_and_the_seed() {
        let seg = Segment::new(400.0 * 3600.0, Cover::Rime)
            .rate(2.0)
            .thickness(1.0);
        let walk = RateWalk {
            sd_ln: 0.5,
            corr_s: 3600.0,
            step_s: 60.0,
            seed: 7,
        };
        let subs = expand(&seg, walk);
        assert_eq!(subs.len(), 24_000);
        assert_eq!(subs[0].start_thickness_mm, Some(1.0));
        assert!(subs[1..].iter().all(|s| s.start_thickness_mm.is_none()));
        let total: f64 = subs.iter().map(|s| s.duration_s).sum();
        assert!((total - seg.duration_s).abs() < 1e-6);
        let n = subs.len() as f64;
        let mean = subs.iter().map(|s| s.rate_mm_per_h).sum::<f64>() / n;
        let lns: Vec<f64> = subs.iter().map(|s| s.rate_mm_per_h.ln()).collect();
        let m_ln = lns.iter().sum::<f64>() / n;
        let sd_ln = (lns.iter().map(|l| (l - m_ln).powi(2)).sum::<f64>() / n).sqrt();
        // 400 correlation times: the mean within ~5 %, the sd within ~10 %.
        assert!((mean - 2.0).abs() < 0.15, "mean rate {mean}");
        assert!((sd_ln - 0.5).abs() < 0.06, "sd of ln r {sd_ln}");
        // One correlation time apart, ln r keeps ~e⁻¹ of its deviation.
        let lag = 60;
        let c: f64 = lns
            .windows(lag + 1)
            .map(|w| (w[0] - m_ln) * (w[lag] - m_ln))
            .sum::<f64>()
            / (n - lag as f64)
            / (sd_ln * sd_ln);
        assert!(
            (c - (-1.0f64).exp()).abs() < 0.12,
            "lag-1 h correlation {c}"
        );
        assert_eq!(expand(&seg, walk), subs);
        let other = expand(&seg, RateWalk { seed: 8, ..walk });
        assert_ne!(other[0].rate_mm_per_h, subs[0].rate_mm_per_h);
    }
}
