//! Icing events from a stream of samples: meteorological icing (ice
//! accreting now) and instrumental icing (ice on the sensor), each with
//! hysteresis, gathered into events, per-month totals and the periods the
//! timeline shades. One pass, state of a few numbers plus one entry per
//! event, month and period.
//!
//! The definitions (README "Icing report"):
//!
//! - **Instrumental icing** (ice on the sensor) starts when the node's most
//!   likely medium is glazed or rime and its thickness reaches
//!   [`Thresholds::ice_on_mm`]; it stops when the medium is no longer ice
//!   or the thickness falls below [`Thresholds::ice_off_mm`]. Logs without
//!   the estimate use the node's detector state `Ice`.
//! - **Meteorological icing** (ice accreting) is the node's own
//!   `est_accreting` (≥ 0.5) where the log has it. Older logs: derived from
//!   the thickness series — the growth between one-minute means
//!   [`GROWTH_WINDOW_MIN`] minutes apart — on at
//!   [`Thresholds::rate_on_mm_per_h`], off below
//!   [`Thresholds::rate_off_mm_per_h`] or when no ice is on the face.
//! - An **event** starts with the first sample of either and ends when
//!   neither has been seen for [`Thresholds::hold_ms`] (its end is the end
//!   of the last icing sample), or at a gap longer than that.
//! - Each sample stands for the time to the next one; a step longer than
//!   [`Thresholds::gap_ms`] is a **gap**: counted apart, never as icing or
//!   as ice-free time.

use std::collections::{BTreeMap, VecDeque};

use fois_link::timefmt::{days_from_civil, utc_date};

use super::input::{Medium, Sample};
use super::timeline::Timeline;

/// The thresholds of the event definitions.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Thresholds {
    /// Ice on the sensor from this thickness, mm.
    pub ice_on_mm: f64,
    /// Ice gone below this thickness, mm.
    pub ice_off_mm: f64,
    /// Derived accretion (older logs) from this growth rate, mm/h.
    pub rate_on_mm_per_h: f64,
    /// Derived accretion stops below this growth rate, mm/h.
    pub rate_off_mm_per_h: f64,
    /// An event ends after this long without icing, ms.
    pub hold_ms: u64,
    /// A step between samples longer than this is a gap, ms.
    pub gap_ms: u64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            ice_on_mm: 0.3,
            ice_off_mm: 0.15,
            rate_on_mm_per_h: 0.2,
            rate_off_mm_per_h: 0.1,
            hold_ms: 10 * 60_000,
            gap_ms: 60_000,
        }
    }
}

/// Derived accretion: the growth between one-minute mean thicknesses this
/// many minutes apart.
pub const GROWTH_WINDOW_MIN: u64 = 20;

/// At most this many shaded periods are kept (later ones extend the last).
pub const MAX_PERIODS: usize = 100_000;

const MS_PER_H: f64 = 3_600_000.0;

/// One icing event.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct IcingEvent {
    /// Its first icing sample, Unix ms.
    pub start_ms: u64,
    /// The end of its last icing sample, Unix ms.
    pub end_ms: u64,
    /// Hours of meteorological icing (accreting).
    pub meteorological_h: f64,
    /// Hours of instrumental icing (ice on the sensor).
    pub instrumental_h: f64,
    /// The largest thickness, mm.
    pub peak_thickness_mm: Option<f64>,
    /// Its standard deviation, mm.
    pub peak_sigma_mm: Option<f64>,
    /// The largest icing rate while accreting, mm/h.
    pub peak_rate_mm_per_h: Option<f64>,
    /// The mean icing rate over the accreting time, mm/h.
    pub mean_rate_mm_per_h: Option<f64>,
    /// The medium on the sensor most of the instrumental time.
    pub medium: Medium,
    /// Still icing at the end of the data.
    pub ongoing: bool,
}

/// Hours of one month (UTC).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct MonthTotals {
    /// Year.
    pub year: i64,
    /// Month 1–12.
    pub month: u32,
    /// Hours with data.
    pub covered_h: f64,
    /// Hours in gaps.
    pub gap_h: f64,
    /// Hours of meteorological icing.
    pub meteorological_h: f64,
    /// Hours of instrumental icing.
    pub instrumental_h: f64,
    /// Events that started in the month.
    pub events: u32,
}

#[derive(Debug, Clone, Copy, Default)]
struct MonthMs {
    covered: u64,
    gap: u64,
    met: u64,
    instr: u64,
    events: u32,
}

/// The month key and its bounds, Unix ms.
fn month_of(t_ms: u64) -> ((i64, u32), u64, u64) {
    let (y, m, _) = utc_date(t_ms);
    let start = days_from_civil(y, m, 1) * 86_400_000;
    let (ny, nm) = if m == 12 { (y + 1, 1) } else { (y, m + 1) };
    let end = days_from_civil(ny, nm, 1) * 86_400_000;
    ((y, m), start.max(0) as u64, end.max(0) as u64)
}

/// Per-month sums, the current month cached (no map look-up per sample).
#[derive(Debug, Default)]
struct Months {
    done: BTreeMap<(i64, u32), MonthMs>,
    cur: Option<((i64, u32), u64, u64, MonthMs)>,
}

#[derive(Debug, Clone, Copy)]
enum Span {
    Gap,
    Data { met: bool, instr: bool },
}

impl Months {
    fn slot(&mut self, t: u64) -> (u64, &mut MonthMs) {
        if self.cur.is_some_and(|(_, s, e, _)| t < s || t >= e)
            && let Some((k, _, _, v)) = self.cur.take()
        {
            self.done.insert(k, v);
        }
        let done = &mut self.done;
        let (_, _, end, v) = self.cur.get_or_insert_with(|| {
            let (k, s, e) = month_of(t);
            (k, s, e, done.remove(&k).unwrap_or_default())
        });
        (*end, v)
    }

    /// Add the span [a, b), split at month ends.
    fn add(&mut self, mut a: u64, b: u64, span: Span) {
        while a < b {
            let (end, m) = self.slot(a);
            let to = b.min(end);
            let d = to - a;
            match span {
                Span::Gap => m.gap += d,
                Span::Data { met, instr } => {
                    m.covered += d;
                    if met {
                        m.met += d;
                    }
                    if instr {
                        m.instr += d;
                    }
                }
            }
            a = to;
        }
    }

    fn event_started(&mut self, t: u64) {
        self.slot(t).1.events += 1;
    }

    fn finish(mut self) -> Vec<MonthTotals> {
        if let Some((k, _, _, v)) = self.cur.take() {
            self.done.insert(k, v);
        }
        let h = |ms: u64| ms as f64 / MS_PER_H;
        self.done
            .into_iter()
            .map(|((year, month), v)| MonthTotals {
                year,
                month,
                covered_h: h(v.covered),
                gap_h: h(v.gap),
                meteorological_h: h(v.met),
                instrumental_h: h(v.instr),
                events: v.events,
            })
            .collect()
    }
}

/// Growth from the thickness series (logs without the node's rate).
#[derive(Debug, Default)]
struct Growth {
    minute: Option<u64>,
    sum: f64,
    n: u32,
    means: VecDeque<(u64, f64)>,
    rate: Option<f64>,
}

impl Growth {
    /// Feed a thickness; the rate, mm/h, of the last completed minute
    /// against the one [`GROWTH_WINDOW_MIN`] before (None: not enough
    /// history).
    fn push(&mut self, t_ms: u64, thickness_mm: f64) -> Option<f64> {
        let minute = t_ms / 60_000;
        if self.minute != Some(minute) {
            if let Some(m) = self.minute
                && self.n > 0
            {
                let mean = self.sum / f64::from(self.n);
                while self
                    .means
                    .front()
                    .is_some_and(|&(k, _)| k + GROWTH_WINDOW_MIN + 5 < m)
                {
                    self.means.pop_front();
                }
                self.rate = self
                    .means
                    .iter()
                    .rev()
                    .find(|&&(k, _)| k + GROWTH_WINDOW_MIN <= m)
                    .map(|&(k, old)| (mean - old) * 60.0 / (m - k) as f64);
                self.means.push_back((m, mean));
            }
            self.minute = Some(minute);
            self.sum = 0.0;
            self.n = 0;
        }
        self.sum += thickness_mm;
        self.n += 1;
        self.rate
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Flags {
    met: bool,
    instr: bool,
    rate: Option<f64>,
}

#[derive(Debug, Clone)]
struct Open {
    start: u64,
    active_end: u64,
    met_ms: u64,
    instr_ms: u64,
    peak: Option<(f64, Option<f64>)>,
    peak_rate: Option<f64>,
    rate_integral: f64,
    rate_ms: u64,
    glazed_ms: u64,
    rime_ms: u64,
}

/// Where meteorological icing came from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct MetSources {
    /// Samples with the node's `est_accreting`.
    pub node: u64,
    /// Samples where it was derived from the thickness growth.
    pub derived: u64,
    /// Samples with neither (no thickness estimate).
    pub none: u64,
}

/// The one-pass analysis.
#[derive(Debug)]
pub struct Tracker {
    th: Thresholds,
    prev: Option<(Sample, Flags)>,
    instr: bool,
    derived_met: bool,
    growth: Growth,
    open: Option<Open>,
    events: Vec<IcingEvent>,
    months: Months,
    met_periods: Vec<(u64, u64)>,
    instr_periods: Vec<(u64, u64)>,
    /// Where meteorological icing came from.
    pub sources: MetSources,
    /// The first sample's time.
    pub first_ms: Option<u64>,
    timeline: Timeline,
}

/// What the pass found.
#[derive(Debug, Clone)]
pub struct Findings {
    /// The events in time order.
    pub events: Vec<IcingEvent>,
    /// Per-month totals.
    pub months: Vec<MonthTotals>,
    /// Periods of meteorological icing, Unix ms.
    pub met_periods: Vec<(u64, u64)>,
    /// Periods of instrumental icing, Unix ms.
    pub instr_periods: Vec<(u64, u64)>,
    /// Where meteorological icing came from.
    pub sources: MetSources,
    /// First and last sample, Unix ms.
    pub span_ms: Option<(u64, u64)>,
    /// The decimated thickness series.
    pub timeline: Timeline,
}

fn extend(periods: &mut Vec<(u64, u64)>, a: u64, b: u64) {
    let full = periods.len() >= MAX_PERIODS;
    match periods.last_mut() {
        Some(last) if a <= last.1 || full => last.1 = last.1.max(b),
        _ => periods.push((a, b)),
    }
}

impl Tracker {
    /// A pass with these thresholds.
    pub fn new(th: Thresholds) -> Tracker {
        Tracker {
            th,
            prev: None,
            instr: false,
            derived_met: false,
            growth: Growth::default(),
            open: None,
            events: Vec::new(),
            months: Months::default(),
            met_periods: Vec::new(),
            instr_periods: Vec::new(),
            sources: MetSources::default(),
            first_ms: None,
            timeline: Timeline::default(),
        }
    }

    fn flags(&mut self, s: &Sample) -> Flags {
        let th = self.th;
        self.instr = match s.thickness_mm {
            Some(d) if s.medium.is_ice() => {
                d >= if self.instr {
                    th.ice_off_mm
                } else {
                    th.ice_on_mm
                }
            }
            Some(_) => false,
            None => s.state_ice,
        };
        let derived = s.thickness_mm.map(|d| self.growth.push(s.t_ms, d));
        let (met, rate) = match (s.accreting, derived) {
            (Some(a), _) => {
                self.sources.node += 1;
                (a, s.rate_mm_per_h)
            }
            (None, Some(r)) => {
                self.sources.derived += 1;
                self.derived_met = match r {
                    Some(r) if self.instr || s.medium.is_ice() => {
                        r >= if self.derived_met {
                            th.rate_off_mm_per_h
                        } else {
                            th.rate_on_mm_per_h
                        }
                    }
                    _ => false,
                };
                (self.derived_met, s.rate_mm_per_h.or(r))
            }
            (None, None) => {
                self.sources.none += 1;
                (false, None)
            }
        };
        Flags {
            met,
            instr: self.instr,
            rate,
        }
    }

    /// Take the next sample (in time order).
    pub fn push(&mut self, s: Sample) {
        let f = self.flags(&s);
        self.first_ms.get_or_insert(s.t_ms);
        if let Some(d) = s.thickness_mm {
            self.timeline.push(s.t_ms, d, s.sigma_mm.unwrap_or(0.0));
        }
        if let Some((p, pf)) = self.prev {
            let dt = s.t_ms.saturating_sub(p.t_ms);
            if dt > self.th.gap_ms {
                self.months.add(p.t_ms, s.t_ms, Span::Gap);
                if dt > self.th.hold_ms {
                    self.close(false);
                }
            } else {
                self.months.add(
                    p.t_ms,
                    s.t_ms,
                    Span::Data {
                        met: pf.met,
                        instr: pf.instr,
                    },
                );
                if pf.met {
                    extend(&mut self.met_periods, p.t_ms, s.t_ms);
                }
                if pf.instr {
                    extend(&mut self.instr_periods, p.t_ms, s.t_ms);
                }
                if let Some(o) = &mut self.open
                    && (pf.met || pf.instr)
                {
                    o.active_end = s.t_ms;
                    if pf.met {
                        o.met_ms += dt;
                        if let Some(r) = pf.rate {
                            o.rate_integral += r * dt as f64;
                            o.rate_ms += dt;
                        }
                    }
                    if pf.instr {
                        o.instr_ms += dt;
                        match p.medium {
                            Medium::Glazed => o.glazed_ms += dt,
                            Medium::Rime => o.rime_ms += dt,
                            _ => {}
                        }
                    }
                }
            }
        }
        let active = f.met || f.instr;
        if active && self.open.is_none() {
            self.months.event_started(s.t_ms);
            self.open = Some(Open {
                start: s.t_ms,
                active_end: s.t_ms,
                met_ms: 0,
                instr_ms: 0,
                peak: None,
                peak_rate: None,
                rate_integral: 0.0,
                rate_ms: 0,
                glazed_ms: 0,
                rime_ms: 0,
            });
        }
        if let Some(o) = &mut self.open {
            if active {
                if let Some(d) = s.thickness_mm.filter(|_| f.instr)
                    && o.peak.is_none_or(|(pd, _)| d > pd)
                {
                    o.peak = Some((d, s.sigma_mm));
                }
                if let Some(r) = f.rate.filter(|_| f.met)
                    && o.peak_rate.is_none_or(|pr| r > pr)
                {
                    o.peak_rate = Some(r);
                }
            } else if s.t_ms.saturating_sub(o.active_end) >= self.th.hold_ms {
                self.close(false);
            }
        }
        self.prev = Some((s, f));
    }

    fn close(&mut self, ongoing: bool) {
        let Some(o) = self.open.take() else {
            return;
        };
        let h = |ms: u64| ms as f64 / MS_PER_H;
        let medium = if o.glazed_ms == 0 && o.rime_ms == 0 {
            Medium::Unknown
        } else if o.glazed_ms > o.rime_ms {
            Medium::Glazed
        } else {
            Medium::Rime
        };
        self.events.push(IcingEvent {
            start_ms: o.start,
            end_ms: o.active_end,
            meteorological_h: h(o.met_ms),
            instrumental_h: h(o.instr_ms),
            peak_thickness_mm: o.peak.map(|p| p.0),
            peak_sigma_mm: o.peak.and_then(|p| p.1),
            peak_rate_mm_per_h: o.peak_rate,
            mean_rate_mm_per_h: (o.rate_ms > 0).then(|| o.rate_integral / o.rate_ms as f64),
            medium,
            ongoing,
        });
    }

    /// The end of the data: an event still open is closed (marked ongoing
    /// when the last sample was icing).
    pub fn finish(mut self) -> Findings {
        let ongoing = self.prev.is_some_and(|(_, f)| f.met || f.instr);
        self.close(ongoing);
        let span_ms = self.first_ms.zip(self.prev.map(|(p, _)| p.t_ms));
        self.timeline.finish();
        Findings {
            events: self.events,
            months: self.months.finish(),
            met_periods: self.met_periods,
            instr_periods: self.instr_periods,
            sources: self.sources,
            span_ms,
            timeline: self.timeline,
        }
    }
}
