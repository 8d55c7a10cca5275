//! Where a figure's lines and bands must break: the runs of consecutive
//! measurements with no link loss, gap, restart or time jump between them.
//! Pure functions over times and sequence numbers, so a test can check that
//! nothing drawn spans a gap.

use std::ops::Range;

/// The largest step between two measurements that still counts as
/// consecutive, s: five frame periods (the median step of `t_s`), and at
/// least 1 s so the host's scheduling jitter does not break a 10 Hz line.
pub fn max_step_s(t_s: &[f64]) -> f64 {
    let mut steps: Vec<f64> = t_s
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    if steps.is_empty() {
        return 1.0;
    }
    steps.sort_by(f64::total_cmp);
    let median = steps[steps.len() / 2];
    (5.0 * median).max(1.0)
}

/// The runs of `t_s` (one entry per measurement, in log order) between
/// which a line may be drawn. A run ends before a measurement that
/// - comes after a break (a `gap`, `link_lost` or `node_restart` row at a
///   time after the previous measurement and up to this one),
/// - is more than `max_step_s` later than the previous one,
/// - goes back in time (node uptime after a restart), or
/// - has a sequence number below the previous one (a restarted node).
///
/// `breaks_s` must be sorted. Every returned range is non-empty; together
/// they cover `0..t_s.len()` in order.
pub fn runs(
    t_s: &[f64],
    seq: &[Option<u32>],
    breaks_s: &[f64],
    max_step_s: f64,
) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..t_s.len() {
        let (a, b) = (t_s[i - 1], t_s[i]);
        let broken = breaks_s.iter().any(|&x| x > a && x <= b)
            || b - a > max_step_s
            || b < a
            || matches!(
                (seq.get(i - 1).copied().flatten(), seq.get(i).copied().flatten()),
                (Some(p), Some(q)) if q < p
            );
        if broken {
            out.push(start..i);
            start = i;
        }
    }
    if start < t_s.len() {
        out.push(start..t_s.len());
    }
    out
}

/// Split each run further where `keep` is false (e.g. a measurement
/// without an estimate): the sub-runs where it holds throughout.
pub fn runs_where(runs: &[Range<usize>], keep: impl Fn(usize) -> bool) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    for r in runs {
        let mut start: Option<usize> = None;
        for i in r.clone() {
            match (keep(i), start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    out.push(s..i);
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(s) = start {
            out.push(s..r.end);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tenth(from: f64, n: usize) -> Vec<f64> {
        (0..n).map(|i| from + 0.1 * i as f64).collect()
    }

    #[test]
    fn a_link_loss_a_time_jump_and_a_restart_each_end_a_run() {
        // 10 Hz: 0–9.9 s, a link loss at 10.5 s with the node back at 10.6 s,
        // then 10.6–19.5 s, a 30 s hole, 50–59.9 s.
        let mut t = tenth(0.0, 100);
        t.extend(tenth(10.6, 90));
        t.extend(tenth(50.0, 100));
        let seq: Vec<Option<u32>> = (0..t.len() as u32).map(Some).collect();
        let step = max_step_s(&t);
        assert!((step - 1.0).abs() < 1e-9, "{step}");
        let r = runs(&t, &seq, &[10.5], step);
        assert_eq!(r, vec![0..100, 100..190, 190..290]);
        // Without the break row the 0.7 s step is still consecutive.
        assert_eq!(runs(&t, &seq, &[], step), vec![0..190, 190..290]);
        // A restart: the sequence starts over at 0, no time jump.
        let mut seq2 = seq.clone();
        for (k, s) in seq2.iter_mut().enumerate().skip(150) {
            *s = Some((k - 150) as u32);
        }
        assert_eq!(runs(&t, &seq2, &[], step), vec![0..150, 150..190, 190..290]);
        // Node uptime going back (a restart on the node axis).
        let back = [5.0, 5.1, 5.2, 0.1, 0.2];
        assert_eq!(runs(&back, &[None; 5], &[], 1.0), vec![0..3, 3..5]);
    }

    #[test]
    fn a_slow_node_s_period_sets_the_step() {
        let t: Vec<f64> = (0..10).map(|i| 60.0 * f64::from(i)).collect();
        assert_eq!(max_step_s(&t), 300.0);
        assert_eq!(runs(&t, &[None; 10], &[], 300.0), vec![0..10]);
        assert_eq!(max_step_s(&[]), 1.0);
        assert!(runs(&[], &[], &[], 1.0).is_empty());
    }

    #[test]
    fn sub_runs_keep_only_the_measurements_that_hold() {
        let r = runs_where(&[0..6, 6..9], |i| ![2, 3, 7].contains(&i));
        assert_eq!(r, vec![0..2, 4..6, 6..7, 8..9]);
    }
}
