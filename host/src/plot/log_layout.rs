//! What `foisctl plot` draws from a log's time series, in axis units: each
//! line, band and span cut into runs of consecutive measurements
//! ([`super::runs`]), so nothing crosses a gap, a link loss, a restart or a
//! time jump; long runs decimated with their extremes kept. Pure: the test
//! of "no line through a gap" reads it.

use std::ops::Range;

use super::log_series::{State, TimePoint, TimeSeries};
use super::runs::{max_step_s, runs, runs_where};

/// A line of (t, y) points.
pub type Line = Vec<(f64, f64)>;

/// Everything the figure draws, in axis units (s), each piece within one
/// run of consecutive measurements.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Drawn {
    /// I1 and I2, one line per run (decimated to ~3000 points each).
    pub currents: [Vec<Line>; 2],
    /// The air temperature, one line per run.
    pub temperature: Vec<Line>,
    /// The estimate (t, thickness, σ), one piece per run of measurements
    /// that have one: its line and its ±2σ band.
    pub estimate: Vec<Vec<(f64, f64, f64)>>,
    /// Alarm periods (start, end).
    pub alarm: Vec<(f64, f64)>,
    /// The node's state as spans (start, end, state).
    pub states: Vec<(f64, f64, State)>,
    /// The estimated medium as spans (start, end, medium).
    pub media: Vec<(f64, f64, &'static str)>,
}

/// Spans of equal `value` within each run: from a measurement to the next
/// one of the run (the last one's span ends at its own time).
fn spans<T: Copy + PartialEq>(
    pts: &[TimePoint],
    runs: &[Range<usize>],
    value: impl Fn(&TimePoint) -> Option<T>,
) -> Vec<(f64, f64, T)> {
    let mut out = Vec::new();
    for r in runs {
        let mut open: Option<(f64, T)> = None;
        for i in r.clone() {
            let t = pts[i].t_s;
            let v = value(&pts[i]);
            match (open, v) {
                (Some((_, a)), Some(b)) if a == b => {}
                (Some((s, a)), _) => {
                    out.push((s, t, a));
                    open = v.map(|b| (t, b));
                }
                (None, Some(b)) => open = Some((t, b)),
                (None, None) => {}
            }
        }
        if let Some((s, a)) = open {
            let end = pts[r.end - 1].t_s;
            if end > s {
                out.push((s, end, a));
            }
        }
    }
    out
}

/// What to draw for `ts`: every line, band and span split at the breaks.
pub fn layout(ts: &TimeSeries) -> Drawn {
    let pts = &ts.points;
    let t: Vec<f64> = pts.iter().map(|p| p.t_s).collect();
    let seq: Vec<Option<u32>> = pts.iter().map(|p| p.seq).collect();
    let runs = runs(&t, &seq, &ts.breaks_s, max_step_s(&t));
    let line = |r: &Range<usize>, y: &dyn Fn(&TimePoint) -> f64| -> Line {
        decimate(
            &pts[r.clone()]
                .iter()
                .map(|p| (p.t_s, y(p)))
                .collect::<Vec<_>>(),
            3000,
        )
    };
    let currents = [0, 1].map(|c| runs.iter().map(|r| line(r, &|p| p.i_ua[c])).collect());
    let temperature = runs_where(&runs, |i| pts[i].temp_c.is_some())
        .iter()
        .map(|r| line(r, &|p| p.temp_c.unwrap_or(f64::NAN)))
        .collect();
    let est_runs = runs_where(&runs, |i| pts[i].est_mm.is_some());
    let n_est: usize = est_runs.iter().map(|r| r.len()).sum();
    let stride = n_est.div_ceil(3000).max(1);
    let estimate = est_runs
        .iter()
        .map(|r| {
            let mut v: Vec<(f64, f64, f64)> = pts[r.clone()]
                .iter()
                .step_by(stride)
                .filter_map(|p| p.est_mm.map(|(d, s)| (p.t_s, d, s)))
                .collect();
            // Keep the run's last point so a piece ends where its data ends.
            if let Some(last) = pts[r.end - 1]
                .est_mm
                .map(|(d, s)| (pts[r.end - 1].t_s, d, s))
                && v.last() != Some(&last)
            {
                v.push(last);
            }
            v
        })
        .collect();
    let alarm = spans(pts, &runs, |p| p.alarm.then_some(()))
        .into_iter()
        .map(|(a, b, ())| (a, b))
        .collect();
    Drawn {
        currents,
        temperature,
        estimate,
        alarm,
        states: spans(pts, &runs, |p| p.state),
        media: spans(pts, &runs, |p| p.medium),
    }
}

/// At most `2 * buckets` points: the minimum and the maximum of each run of
/// consecutive points, in their order (spikes survive, a day at 10 Hz draws
/// fast).
pub fn decimate(points: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * buckets.max(1) {
        return points.to_vec();
    }
    let size = points.len().div_ceil(buckets.max(1));
    let mut out = Vec::with_capacity(2 * buckets);
    for chunk in points.chunks(size) {
        let mut lo = 0;
        let mut hi = 0;
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[lo].1 {
                lo = i;
            }
            if p.1 > chunk[hi].1 {
                hi = i;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_is_drawn_across_a_link_loss_a_time_jump_or_a_restart() {
        // 10 Hz, iced with an estimate: 0–20 s, a link loss at 20.05 s, back
        // at 20.2 s until 40 s, a 200 s hole, 240–260 s, then the node
        // restarts (seq from 0) with no time jump, 260–280 s.
        let mut pts = Vec::new();
        let mut seq = 0;
        for (from, to) in [(0.0, 20.0), (20.2, 40.0), (240.0, 260.0)] {
            let mut t: f64 = from;
            while t < to - 1e-9 {
                pts.push(point(t, seq, t > 5.0, Some(1.0 + t / 100.0)));
                seq += 1;
                t += 0.1;
            }
        }
        for k in 0..200u32 {
            pts.push(point(260.0 + 0.1 * f64::from(k), k, true, Some(4.7)));
        }
        let ts = TimeSeries {
            points: pts,
            breaks_s: vec![20.05],
            ..TimeSeries::default()
        };
        let d = layout(&ts);
        assert_eq!(d.currents[0].len(), 4, "one line per run");
        assert_eq!(d.estimate.len(), 4);
        assert_nothing_spans(&d, 19.95, 20.2);
        assert_nothing_spans(&d, 39.95, 240.0);
        assert_nothing_spans(&d, 259.95, 260.0);
        // The bands cover the data: ice from 5 s to the gap, and after it.
        assert!(
            d.states
                .iter()
                .any(|&(a, b, s)| s == State::Ice && a > 5.0 && a < 5.2 && b > 19.8)
        );

        // Measurements without an estimate (a v1 stretch) have no band.
        let mut ts2 = ts.clone();
        for p in ts2
            .points
            .iter_mut()
            .filter(|p| p.t_s > 10.0 && p.t_s < 15.0)
        {
            p.est_mm = None;
        }
        let d2 = layout(&ts2);
        assert_eq!(d2.estimate.len(), 5);
        assert!(
            d2.estimate
                .iter()
                .all(|p| p.iter().all(|q| q.0 <= 10.0 || q.0 >= 15.0)
                    && !(p[0].0 <= 10.0 && p[p.len() - 1].0 >= 15.0)),
            "no band where the estimate is missing"
        );
    }

    #[test]
    fn decimation_keeps_extremes_in_order() {
        let pts: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                (
                    f64::from(i),
                    if i == 4321 { 99.0 } else { f64::from(i % 7) },
                )
            })
            .collect();
        let d = decimate(&pts, 100);
        assert!(d.len() <= 200);
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(d.contains(&(4321.0, 99.0)));
        assert_eq!(decimate(&pts[..50], 100).len(), 50);
    }

    fn point(t_s: f64, seq: u32, alarm: bool, est: Option<f64>) -> TimePoint {
        TimePoint {
            t_s,
            seq: Some(seq),
            i_ua: [1.0, 0.5],
            alarm,
            est_mm: est.map(|d| (d, 0.3)),
            temp_c: Some(-5.0),
            state: Some(if alarm { State::Ice } else { State::Dry }),
            medium: est.map(|_| "rime"),
        }
    }

    /// Nothing drawn has points on both sides of (a, b).
    fn assert_nothing_spans(d: &Drawn, a: f64, b: f64) {
        let across = |lo: f64, hi: f64| lo < a + 1e-9 && hi > b - 1e-9;
        let line = |l: &[(f64, f64)]| {
            let (lo, hi) = l
                .iter()
                .fold((f64::MAX, f64::MIN), |(x, y), p| (x.min(p.0), y.max(p.0)));
            across(lo, hi)
        };
        for l in d.currents.iter().flatten().chain(&d.temperature) {
            assert!(!line(l), "a line spans the gap {a}..{b}");
        }
        for piece in &d.estimate {
            let pts: Vec<(f64, f64)> = piece.iter().map(|p| (p.0, p.1)).collect();
            assert!(
                !line(&pts),
                "the estimate (and its ±2σ band) spans the gap {a}..{b}"
            );
        }
        assert!(
            d.alarm.iter().all(|&(x, y)| !across(x, y)),
            "alarm shading spans the gap"
        );
        assert!(
            d.states.iter().all(|&(x, y, _)| !across(x, y)),
            "a state band spans the gap"
        );
        assert!(
            d.media.iter().all(|&(x, y, _)| !across(x, y)),
            "a medium band spans the gap"
        );
    }
}
