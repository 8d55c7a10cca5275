//! The report as text: a readable table (stdout), the events as CSV, the
//! whole report as JSON.

use std::fmt::Write as _;

use fois_link::timefmt::iso_utc;

use super::iea::{IEA_ICE_CLASSES, class_of_meteorological};
use super::report::Report;

/// `2026-01-05 03:00:00` (UTC).
pub fn utc_text(ms: u64) -> String {
    let s = iso_utc(ms);
    s.get(..19).unwrap_or(&s).replace('T', " ")
}

fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.decimals$}"))
}

fn range(from: f64, to: f64) -> String {
    if to.is_infinite() {
        format!("> {from}")
    } else {
        format!("{from}–{to}")
    }
}

/// The readable report.
pub fn table(r: &Report) -> String {
    let mut o = String::new();
    let span = match (r.first_ms, r.last_ms) {
        (Some(a), Some(b)) => format!("{} – {} UTC", utc_text(a), utc_text(b)),
        _ => "no measurements".to_string(),
    };
    let _ = writeln!(
        o,
        "Icing report: {} file(s), {} measurements, {span}",
        r.files.len(),
        r.measurements
    );
    let lost: u64 = r.files.iter().map(|f| f.frames_lost).sum();
    let short: u64 = r.files.iter().map(|f| f.short_rows).sum();
    let cut = r.files.iter().filter(|f| f.cut_last_line).count();
    let order: u64 = r.files.iter().map(|f| f.out_of_order).sum();
    let _ = writeln!(
        o,
        "Covered {:.2} h; gaps {:.2} h (steps over {} s without a measurement); frames lost {lost}; \
         rows of another width skipped {short}; cut last lines ignored {cut}; rows out of time order skipped {order}",
        r.covered_h,
        r.gap_h,
        r.thresholds.gap_ms / 1000
    );
    let _ = writeln!(
        o,
        "Meteorological icing (ice accreting), from {}: {:.2} h = {:.3} % of the covered time",
        r.source_text(),
        r.meteorological_h,
        r.meteorological_pct
    );
    let _ = writeln!(
        o,
        "Instrumental icing (ice on the sensor): {:.2} h = {:.3} % of the covered time",
        r.instrumental_h, r.instrumental_pct
    );
    let c = class_of_meteorological(r.meteorological_pct);
    let instr = r
        .iea_instrumental_classes
        .iter()
        .map(u8::to_string)
        .collect::<Vec<_>>()
        .join(" or ");
    let _ = writeln!(
        o,
        "IEA Wind ice class (Task 19, by meteorological icing {} % of the year): {} \
         (typical production loss {} %); the instrumental share fits class {instr}",
        range(c.met_from_pct, c.met_to_pct),
        r.iea_class,
        c.production_loss,
    );
    if r.shorter_than_a_year() {
        let _ = writeln!(
            o,
            "  note: the classes are defined on a year; these shares are of {:.1} days of data \
             (a winter alone overstates the class)",
            r.covered_h / 24.0
        );
    }
    let _ = writeln!(o, "\nEvents ({})", r.events.len());
    let _ = writeln!(
        o,
        "{:>4}  {:<19}  {:<19}  {:>7}  {:>7}  {:>14}  {:>9}  {:>9}  {:<6}",
        "#",
        "start (UTC)",
        "end (UTC)",
        "met h",
        "instr h",
        "peak mm ± σ",
        "peak mm/h",
        "mean mm/h",
        "medium"
    );
    for (k, e) in r.events.iter().enumerate() {
        let peak = match (e.peak_thickness_mm, e.peak_sigma_mm) {
            (Some(d), Some(s)) => format!("{d:.2} ± {s:.2}"),
            (Some(d), None) => format!("{d:.2}"),
            _ => "-".to_string(),
        };
        let _ = writeln!(
            o,
            "{:>4}  {:<19}  {:<19}  {:>7.2}  {:>7.2}  {:>14}  {:>9}  {:>9}  {:<6}{}",
            k + 1,
            utc_text(e.start_ms),
            utc_text(e.end_ms),
            e.meteorological_h,
            e.instrumental_h,
            peak,
            opt(e.peak_rate_mm_per_h, 2),
            opt(e.mean_rate_mm_per_h, 2),
            e.medium.name(),
            if e.ongoing { "  (ongoing)" } else { "" }
        );
    }
    let _ = writeln!(o, "\nMonths (UTC)");
    let _ = writeln!(
        o,
        "{:<7}  {:>9}  {:>7}  {:>7}  {:>7}  {:>7}  {:>7}  {:>6}",
        "month", "covered h", "gap h", "met h", "met %", "instr h", "instr %", "events"
    );
    for m in &r.months {
        let p = |h: f64| {
            if m.covered_h > 0.0 {
                100.0 * h / m.covered_h
            } else {
                0.0
            }
        };
        let _ = writeln!(
            o,
            "{:04}-{:02}  {:>9.2}  {:>7.2}  {:>7.2}  {:>7.3}  {:>7.2}  {:>7.3}  {:>6}",
            m.year,
            m.month,
            m.covered_h,
            m.gap_h,
            m.meteorological_h,
            p(m.meteorological_h),
            m.instrumental_h,
            p(m.instrumental_h),
            m.events
        );
    }
    let _ = writeln!(
        o,
        "\nIEA Wind Task 19 ice classes (% of the year): class: meteorological / instrumental / production loss"
    );
    for c in &IEA_ICE_CLASSES {
        let _ = writeln!(
            o,
            "  {}: {} / {} / {}",
            c.class,
            range(c.met_from_pct, c.met_to_pct),
            range(c.instr_from_pct, c.instr_to_pct),
            c.production_loss
        );
    }
    o
}

/// The events as CSV (one row each; times in UTC and Unix ms).
pub fn events_csv(r: &Report) -> anyhow::Result<String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "start_utc",
        "end_utc",
        "start_unix_ms",
        "end_unix_ms",
        "meteorological_h",
        "instrumental_h",
        "peak_thickness_mm",
        "peak_sigma_mm",
        "peak_rate_mm_per_h",
        "mean_rate_mm_per_h",
        "medium",
        "ongoing",
    ])?;
    let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for e in &r.events {
        w.write_record([
            utc_text(e.start_ms),
            utc_text(e.end_ms),
            e.start_ms.to_string(),
            e.end_ms.to_string(),
            format!("{:.4}", e.meteorological_h),
            format!("{:.4}", e.instrumental_h),
            f(e.peak_thickness_mm),
            f(e.peak_sigma_mm),
            f(e.peak_rate_mm_per_h),
            f(e.mean_rate_mm_per_h),
            e.medium.name().to_string(),
            u8::from(e.ongoing).to_string(),
        ])?;
    }
    Ok(String::from_utf8(w.into_inner()?)?)
}

/// The whole report as JSON.
pub fn json(r: &Report) -> anyhow::Result<String> {
    Ok(serde_json::to_string_pretty(r)?)
}
