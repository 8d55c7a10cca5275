//! The icing rate and the icing period against the truth, per accuracy
//! scenario (every seed together): the columns the growth history adds to
//! the estimator's accuracy table ([`crate::accuracy`]).
//!
//! - **Rate** over the frames in which ice has grown without a pause for at
//!   least [`RATE_AFTER_S`] (60 min) since growth last started: the mean
//!   estimate, the mean truth, the mean σ, the RMS of ln(est/true) (the
//!   estimate floored at [`RATE_FLOOR_MM_PER_H`]: a node that reads 0 while
//!   ice grows is wrong by a large factor, not by infinity) and the share
//!   of those frames with |est − true| ≤ 2σ.
//! - **Onset**: from each start of growth (a dry face or a pause that
//!   starts to grow) to the first frame with the icing flag on, while the
//!   ice still grows (never: `∞`).
//! - **Clearing**: from each stop of growth with the ice staying (a pause,
//!   the end of an event) to the first frame with the flag off, and to the
//!   first with P(accreting) ≤ [`ACCRETING_OFF`] (*not accreting*), before
//!   growth starts again (`None`: not within the time the run leaves).
//! - **Shed → dry**: from each shed (ice growing, then a dry face) to the
//!   first frame whose medium is dry.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use fois_firmware::estimator::ACCRETING_OFF;
use fois_protocol::Medium;
use fois_vnode::Cover;

use crate::outcome::{EstSample, Outcome};

/// Growth that has lasted this long counts for the rate columns, s.
pub const RATE_AFTER_S: f64 = 3600.0;
/// The estimate below this counts as this in ln(est/true), mm/h.
pub const RATE_FLOOR_MM_PER_H: f64 = 0.01;

/// The rate over the frames of long-enough growth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateStat {
    /// Frames counted.
    pub frames: u64,
    /// Mean estimate, mm/h.
    pub est_mean: f64,
    /// Mean truth, mm/h.
    pub true_mean: f64,
    /// Mean σ the node reported, mm/h.
    pub sigma_mean: f64,
    /// RMS of ln(est/true).
    pub rms_ln: f64,
    /// Share of the frames with |est − true| ≤ 2σ.
    pub within_2sigma: f64,
}

/// After one stop of growth with the ice staying.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearing {
    /// True thickness at the stop, mm.
    pub thickness_mm: f64,
    /// The medium on the face.
    pub cover: Cover,
    /// Minutes to the flag off (`None`: not within `observed_min`).
    pub flag_off_min: Option<f64>,
    /// Minutes to P(accreting) ≤ [`ACCRETING_OFF`].
    pub not_accreting_min: Option<f64>,
    /// Minutes the run watched (to the next start or its end).
    pub observed_min: f64,
}

/// One scenario's icing columns.
#[derive(Debug, Clone, PartialEq)]
pub struct IcingRow {
    /// Scenario name (without the seed).
    pub name: String,
    /// Seeds (runs).
    pub runs: usize,
    /// The rate after [`RATE_AFTER_S`] of growth (`None`: no such frame).
    pub rate: Option<RateStat>,
    /// Minutes from each first start of growth (from the dry face a run
    /// begins with) to the flag on (∞: not while growing).
    pub onset_min: Vec<f64>,
    /// The same for each later start (after a pause, or regrowth after a
    /// shed).
    pub restart_onset_min: Vec<f64>,
    /// At [`RATE_AFTER_S`] into each growth that lasts that long: (est,
    /// true, σ), mm/h — the "rate at 60 min" (one look per growth).
    pub at_60_min: Vec<(f64, f64, f64)>,
    /// Each stop of growth with the ice staying.
    pub clearings: Vec<Clearing>,
    /// Minutes from each shed to the medium dry (`None`: not before the next
    /// start or the end).
    pub shed_dry_min: Vec<Option<f64>>,
}

impl IcingRow {
    /// RMS of ln(est/true) at 60 min of growth and the share of those
    /// looks with |est − true| ≤ 2σ (`None`: no growth lasted 60 min).
    pub fn at_60_min_stats(&self) -> Option<(f64, f64)> {
        let n = self.at_60_min.len();
        (n > 0).then(|| {
            let ln2: f64 = self
                .at_60_min
                .iter()
                .map(|(e, t, _)| (e.max(RATE_FLOOR_MM_PER_H) / t).ln().powi(2))
                .sum();
            let within = self
                .at_60_min
                .iter()
                .filter(|(e, t, sd)| (e - t).abs() <= 2.0 * sd)
                .count();
            ((ln2 / n as f64).sqrt(), within as f64 / n as f64)
        })
    }

    /// The worst onset over every start, first or later, min (`None`: no
    /// start).
    pub fn worst_onset_min(&self) -> Option<f64> {
        self.onset_min
            .iter()
            .chain(&self.restart_onset_min)
            .copied()
            .reduce(f64::max)
    }
}

fn base_name(name: &str) -> &str {
    name.split("@seed").next().unwrap_or(name)
}

/// The rows, one per accuracy scenario whose node sent an icing rate, in
/// name order.
pub fn rows(outcomes: &[Outcome]) -> Vec<IcingRow> {
    let mut groups: BTreeMap<&str, Vec<&Outcome>> = BTreeMap::new();
    for o in outcomes
        .iter()
        .filter(|o| o.estimates.iter().any(|s| s.icing.is_some()))
    {
        groups.entry(base_name(&o.name)).or_default().push(o);
    }
    groups
        .into_iter()
        .map(|(name, runs)| row(name, &runs))
        .collect()
}

#[derive(Default)]
struct RateSums {
    n: u64,
    est: f64,
    truth: f64,
    sigma: f64,
    ln2: f64,
    within: u64,
}

fn row(name: &str, runs: &[&Outcome]) -> IcingRow {
    let mut r = IcingRow {
        name: name.to_string(),
        runs: runs.len(),
        rate: None,
        onset_min: Vec::new(),
        restart_onset_min: Vec::new(),
        at_60_min: Vec::new(),
        clearings: Vec::new(),
        shed_dry_min: Vec::new(),
    };
    let mut sums = RateSums::default();
    for o in runs {
        one_run(&o.estimates, &mut r, &mut sums);
    }
    if sums.n > 0 {
        let n = sums.n as f64;
        r.rate = Some(RateStat {
            frames: sums.n,
            est_mean: sums.est / n,
            true_mean: sums.truth / n,
            sigma_mean: sums.sigma / n,
            rms_ln: (sums.ln2 / n).sqrt(),
            within_2sigma: sums.within as f64 / n,
        });
    }
    r
}

/// The first sample from `from` on (until growth starts again) that `hit`
/// accepts: its delay after `t0`, min.
fn delay_until(
    s: &[EstSample],
    from: usize,
    t0: f64,
    hit: &dyn Fn(&EstSample) -> bool,
) -> Option<f64> {
    s[from..]
        .iter()
        .take_while(|x| x.true_rate_mm_per_h <= 0.0)
        .find(|x| hit(x))
        .map(|x| (x.t_s - t0) / 60.0)
}

/// Minutes from `t0` to the last sample before growth starts again.
fn watched_min(s: &[EstSample], from: usize, t0: f64) -> f64 {
    s[from..]
        .iter()
        .take_while(|x| x.true_rate_mm_per_h <= 0.0)
        .last()
        .map_or(0.0, |x| (x.t_s - t0) / 60.0)
}

fn one_run(s: &[EstSample], r: &mut IcingRow, sums: &mut RateSums) {
    let flag = |x: &EstSample| x.icing.is_some_and(|i| i.accreting);
    let mut growing_since: Option<f64> = None;
    let mut started = false;
    for (i, x) in s.iter().enumerate() {
        let grows = x.true_rate_mm_per_h > 0.0;
        match (growing_since, grows) {
            (None, true) => {
                growing_since = Some(x.t_s);
                // Onset: the flag on while the ice still grows.
                let on = s[i..]
                    .iter()
                    .take_while(|y| y.true_rate_mm_per_h > 0.0)
                    .find(|y| flag(y))
                    .map_or(f64::INFINITY, |y| (y.t_s - x.t_s) / 60.0);
                if started {
                    r.restart_onset_min.push(on);
                } else {
                    r.onset_min.push(on);
                }
                started = true;
            }
            (Some(_), false) => {
                growing_since = None;
                let prev = &s[i.saturating_sub(1)];
                if x.cover != Cover::Dry {
                    let off = delay_until(s, i, x.t_s, &|y| !flag(y));
                    let not_acc = delay_until(s, i, x.t_s, &|y| {
                        y.icing
                            .is_some_and(|i| i.p_accreting <= f64::from(ACCRETING_OFF))
                    });
                    r.clearings.push(Clearing {
                        thickness_mm: prev.true_mm,
                        cover: prev.cover,
                        flag_off_min: off,
                        not_accreting_min: not_acc,
                        observed_min: watched_min(s, i, x.t_s),
                    });
                }
            }
            _ => {}
        }
        // A shed: ice on the face, then a dry one (growing or not before).
        if i > 0 && x.cover == Cover::Dry && s[i - 1].cover != Cover::Dry {
            r.shed_dry_min
                .push(delay_until(s, i, x.t_s, &|y| y.medium == Medium::Dry));
        }
        if let (Some(t0), Some(ic)) = (growing_since, x.icing)
            && x.t_s - t0 >= RATE_AFTER_S
        {
            if i > 0 && s[i - 1].t_s - t0 < RATE_AFTER_S {
                r.at_60_min
                    .push((ic.rate_mm_per_h, x.true_rate_mm_per_h, ic.sigma_mm_per_h));
            }
            let truth = x.true_rate_mm_per_h;
            let est = ic.rate_mm_per_h;
            sums.n += 1;
            sums.est += est;
            sums.truth += truth;
            sums.sigma += ic.sigma_mm_per_h;
            sums.ln2 += (est.max(RATE_FLOOR_MM_PER_H) / truth).ln().powi(2);
            sums.within += u64::from((est - truth).abs() <= 2.0 * ic.sigma_mm_per_h);
        }
    }
}

fn minutes(v: Option<f64>) -> String {
    match v {
        Some(m) if m.is_finite() => format!("{m:.1}"),
        Some(_) => "never".into(),
        None => "—".into(),
    }
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

/// Median / worst of delays (`None` = not within the watched time: worst
/// "> watched").
fn delays(v: &[Option<f64>], watched: &[f64]) -> String {
    if v.is_empty() {
        return "—".into();
    }
    let missing: Vec<f64> = v
        .iter()
        .zip(watched)
        .filter(|(d, _)| d.is_none())
        .map(|(_, w)| *w)
        .collect();
    let got: Vec<f64> = v.iter().flatten().copied().collect();
    let worst = if missing.is_empty() {
        minutes(got.iter().copied().reduce(f64::max))
    } else {
        format!(
            "none in {:.0} ({} of {})",
            missing.iter().copied().fold(f64::INFINITY, f64::min),
            missing.len(),
            v.len()
        )
    };
    format!("{} / {worst}", minutes(median(got)))
}

/// The Markdown table of the icing columns.
pub fn table(rows: &[IcingRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| scenario | seeds | rate at 60 min of growth: RMS ln(est/true), \\|err\\| ≤ 2σ (looks) | rate ≥ 60 min of growth: est / true, mean (σ) mm/h | RMS ln(est/true) | rate \\|err\\| ≤ 2σ | flag on after growth starts, median / worst min | growth stops at (mm) | flag off, median / worst min | not accreting (P ≤ {ACCRETING_OFF}), median / worst min | shed → dry, worst min |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for r in rows {
        let (rate, rms, within) = match r.rate {
            Some(x) => (
                format!(
                    "{:.2} / {:.2} (σ {:.2})",
                    x.est_mean, x.true_mean, x.sigma_mean
                ),
                format!("{:.2}", x.rms_ln),
                format!("{:.1} %", 100.0 * x.within_2sigma),
            ),
            None => ("—".into(), "—".into(), "—".into()),
        };
        let at60 = match r.at_60_min_stats() {
            Some((rms, within)) => {
                format!("{rms:.2}, {:.0} % ({})", 100.0 * within, r.at_60_min.len())
            }
            None => "—".into(),
        };
        let med_worst = |v: &[f64]| {
            format!(
                "{} / {}",
                minutes(median(v.to_vec())),
                minutes(v.iter().copied().reduce(f64::max))
            )
        };
        let mut onset = if r.onset_min.is_empty() {
            "—".to_string()
        } else {
            med_worst(&r.onset_min)
        };
        if !r.restart_onset_min.is_empty() {
            let _ = write!(onset, "; again: {}", med_worst(&r.restart_onset_min));
        }
        // The stops grouped by thickness (to 0.5 mm): a pause at 5 mm and
        // the end at 8 mm are not one figure.
        let mut groups: BTreeMap<i64, Vec<&Clearing>> = BTreeMap::new();
        for c in &r.clearings {
            groups
                .entry((c.thickness_mm * 2.0).round() as i64)
                .or_default()
                .push(c);
        }
        let cell = |f: &dyn Fn(&Clearing) -> String| -> String {
            if groups.is_empty() {
                return "—".into();
            }
            groups
                .values()
                .map(|g| f(g[0]).to_string())
                .collect::<Vec<_>>()
                .join("; ")
        };
        let stops = cell(&|c| format!("{:.1}", c.thickness_mm));
        let per_group = |pick: &dyn Fn(&Clearing) -> Option<f64>| -> String {
            groups
                .values()
                .map(|g| {
                    let v: Vec<Option<f64>> = g.iter().map(|c| pick(c)).collect();
                    let w: Vec<f64> = g.iter().map(|c| c.observed_min).collect();
                    delays(&v, &w)
                })
                .collect::<Vec<_>>()
                .join("; ")
        };
        let (off, not_acc) = if groups.is_empty() {
            ("—".to_string(), "—".to_string())
        } else {
            (
                per_group(&|c| c.flag_off_min),
                per_group(&|c| c.not_accreting_min),
            )
        };
        let shed = if r.shed_dry_min.is_empty() {
            "—".to_string()
        } else if r.shed_dry_min.iter().any(Option::is_none) {
            "never".to_string()
        } else {
            minutes(r.shed_dry_min.iter().flatten().copied().reduce(f64::max))
        };
        let _ = writeln!(
            s,
            "| {} | {} | {at60} | {rate} | {rms} | {within} | {onset} | {stops} | {} | {} | {shed} |",
            r.name, r.runs, off, not_acc,
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::outcome::IcingSample;

    /// One frame a minute: `cover`, true rate, the node's rate, σ, P, flag.
    fn frame(t_min: f64, cover: Cover, rate: f64, est: f64, p: f64, on: bool) -> EstSample {
        EstSample {
            t_s: 60.0 * t_min,
            cover,
            true_mm: if cover == Cover::Dry { 0.0 } else { 1.0 },
            est_mm: 1.0,
            sigma_mm: 0.3,
            medium: if cover == Cover::Dry {
                Medium::Dry
            } else {
                Medium::Rime
            },
            true_gain: 1.0,
            gain: None,
            true_rate_mm_per_h: rate,
            icing: Some(IcingSample {
                rate_mm_per_h: est,
                sigma_mm_per_h: 0.5,
                p_accreting: p,
                accreting: on,
            }),
        }
    }

    #[test]
    fn onset_rate_clearing_and_shed_against_the_truth() {
        let mut o = crate::outcome::tests_support::outcome("h@seed1");
        let mut s = vec![frame(0.0, Cover::Dry, 0.0, 0.0, 0.5, false)];
        // Growth at 2 mm/h from minute 1 to 90; the flag on at minute 8;
        // the node reads 1.5 ± 0.5 until minute 70, then 3.5.
        for m in 1..90 {
            let est = if m < 70 { 1.5 } else { 3.5 };
            s.push(frame(f64::from(m), Cover::Rime, 2.0, est, 0.9, m >= 8));
        }
        // Stop at minute 90: the flag off at 102, P ≤ 0.3 at 110; to 120.
        for m in 90..=120 {
            s.push(frame(
                f64::from(m),
                Cover::Rime,
                0.0,
                0.1,
                if m >= 110 { 0.2 } else { 0.5 },
                m < 102,
            ));
        }
        // Shed at 121: dry named at 124; then no more growth.
        for m in 121..=130 {
            let mut f = frame(f64::from(m), Cover::Dry, 0.0, 0.0, 0.1, false);
            f.medium = if m >= 124 { Medium::Dry } else { Medium::Rime };
            s.push(f);
        }
        // Regrowth from minute 131 (flag on at 135) to 140, then 10 min at
        // rest with the flag on.
        for m in 131..=150 {
            let rate = if m <= 140 { 2.0 } else { 0.0 };
            s.push(frame(f64::from(m), Cover::Rime, rate, 2.0, 0.9, m >= 135));
        }
        o.estimates = s;
        let r = &rows(&[o])[0];
        assert_eq!(r.onset_min, vec![7.0]);
        assert_eq!(r.restart_onset_min, vec![4.0]);
        assert_eq!(r.worst_onset_min(), Some(7.0));
        // Minutes 61–89 count (29 frames): 9 at 1.5, 20 at 3.5 (|1.5 − 2| ≤
        // 2σ = 1, |3.5 − 2| is not).
        let x = r.rate.unwrap();
        assert_eq!(x.frames, 29);
        let rms = ((9.0 * (0.75f64).ln().powi(2) + 20.0 * (1.75f64).ln().powi(2)) / 29.0).sqrt();
        assert!((x.rms_ln - rms).abs() < 1e-12, "{x:?}");
        assert!((x.within_2sigma - 9.0 / 29.0).abs() < 1e-12, "{x:?}");
        // At 60 min (minute 61): 1.5 against 2, within 2σ.
        assert_eq!(r.at_60_min, vec![(1.5, 2.0, 0.5)]);
        let (rms60, within60) = r.at_60_min_stats().unwrap();
        assert!((rms60 - (0.75f64).ln().abs()).abs() < 1e-12 && within60 == 1.0);
        assert_eq!(r.clearings.len(), 2);
        assert_eq!(r.clearings[1].flag_off_min, None);
        assert_eq!(r.clearings[1].observed_min, 9.0);
        let c = r.clearings[0];
        assert_eq!(
            (c.flag_off_min, c.not_accreting_min),
            (Some(12.0), Some(20.0))
        );
        assert_eq!(c.observed_min, 40.0);
        assert_eq!(r.shed_dry_min, vec![Some(3.0)]);
        let t = table(std::slice::from_ref(r));
        assert!(
            t.lines()
                .nth(2)
                .unwrap()
                .ends_with("| 7.0 / 7.0; again: 4.0 / 4.0 | 1.0 | 12.0 / none in 9 (1 of 2) | 20.0 / none in 9 (1 of 2) | 3.0 |"),
            "{t}"
        );
    }
}
