//! `foisctl icing-report`: icing events, monthly totals and the IEA Wind
//! ice class from monitor or gateway logs.

use std::path::PathBuf;

use clap::Args;

use crate::icing::events::Thresholds;
use crate::icing::{bench, render, report};

/// `foisctl icing-report`.
#[derive(Debug, Args)]
pub struct IcingReportArgs {
    /// One node's logs: `foisctl monitor --log` files or the gateway's
    /// daily files (`.csv` or `.csv.gz`, told by content), in any order
    /// (sorted by their first measurement). Rows overlapping an earlier
    /// file are skipped and counted.
    #[arg(long, value_name = "FILE", num_args = 1.., required_unless_present = "bench")]
    pub log: Vec<PathBuf>,
    /// Print the events as CSV (one row each) instead of the table.
    #[arg(long, conflicts_with = "json")]
    pub csv: bool,
    /// Print the whole report as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Draw the timeline (thickness ± σ, icing periods shaded) to FILE.png
    /// or FILE.svg.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// A step between measurements longer than this is a gap (no data), s.
    #[arg(long, value_name = "S", default_value_t = 60, value_parser = clap::value_parser!(u64).range(1..))]
    pub gap_s: u64,
    /// An event ends after this long without icing, min.
    #[arg(long, value_name = "MIN", default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub hold_min: u64,
    /// Ice on the sensor from this thickness, mm (off below half of it).
    #[arg(long, value_name = "MM", default_value_t = 0.3, value_parser = positive_mm)]
    pub ice_on_mm: f64,
    /// Measure the report's speed instead: a synthetic year at 1 Hz
    /// (31.5 M rows, generated on the fly), on one thread; prints rows/s.
    #[arg(long, conflicts_with_all = ["log", "csv", "json", "plot"])]
    pub bench: bool,
    /// Days of the benchmark's synthetic log.
    #[arg(long, value_name = "DAYS", default_value_t = 365, requires = "bench", value_parser = clap::value_parser!(u64).range(1..=3650))]
    pub bench_days: u64,
}

fn positive_mm(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 50.0 => Ok(v),
        _ => Err(format!("`{s}` is not a thickness in (0, 50] mm")),
    }
}

/// Run `foisctl icing-report`.
pub fn run(a: IcingReportArgs) -> anyhow::Result<()> {
    if a.bench {
        let b = bench(a.bench_days)?;
        println!(
            "icing-report: {} rows ({:.2} GB of CSV, {} days at 1 Hz) in {:.2} s on one thread: {:.0} rows/s, {:.0} MB/s; {} events, {:.1} h meteorological icing; peak memory {}",
            b.rows,
            b.bytes as f64 / 1e9,
            a.bench_days,
            b.seconds,
            b.rows_per_s(),
            b.bytes as f64 / 1e6 / b.seconds.max(1e-9),
            b.events,
            b.meteorological_h,
            b.peak_rss_kib.map_or("unknown".to_string(), |k| format!(
                "{:.1} MiB",
                k as f64 / 1024.0
            ))
        );
        return Ok(());
    }
    if let Some(p) = &a.plot {
        // A bad figure path is refused before the logs are read.
        crate::plot::output::format_of(p)?;
    }
    let th = Thresholds {
        ice_on_mm: a.ice_on_mm,
        ice_off_mm: a.ice_on_mm / 2.0,
        hold_ms: a.hold_min * 60_000,
        gap_ms: a.gap_s * 1000,
        ..Thresholds::default()
    };
    let r = report::analyse(&a.log, th)?;
    if a.json {
        println!("{}", render::json(&r)?);
    } else if a.csv {
        print!("{}", render::events_csv(&r)?);
    } else {
        print!("{}", render::table(&r));
    }
    if let Some(p) = &a.plot {
        crate::plot::icing::plot_icing(&r, p)?;
        eprintln!("timeline drawn to {}", p.display());
    }
    Ok(())
}
