//! The report on synthetic logs of known icing: exact hours, classes,
//! gaps, bad lines, gzip, partial files.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::events::Thresholds;
use super::input::Medium;
use super::report::{Report, analyse};
use super::synthetic::{BASE_MS, DAY_MS, synthetic_bytes};

/// 40 days at one row a minute, an icing day (2 mm/h of rime 06:00–09:00,
/// shed at 18:00) on day 0 and day 20.
fn forty_days(with_rate: bool) -> Vec<u8> {
    synthetic_bytes(40, 60, 20, with_rate)
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn report_of(bytes: &[u8]) -> Report {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "log.csv", bytes);
    analyse(&[p], Thresholds::default()).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn two_known_events_give_exact_hours_and_the_class() {
    let r = report_of(&forty_days(true));
    assert_eq!(r.measurements, 40 * 1440);
    assert_eq!(r.events.len(), 2);
    for (e, day) in r.events.iter().zip([0u64, 20]) {
        assert_eq!(e.start_ms, BASE_MS + day * DAY_MS + 6 * 3_600_000);
        assert_eq!(e.end_ms, BASE_MS + day * DAY_MS + 18 * 3_600_000);
        assert!(close(e.meteorological_h, 3.0), "{e:?}");
        // Ice on the sensor from 0.3 mm (06:09) to the shedding (18:00).
        assert!(close(e.instrumental_h, 11.85), "{e:?}");
        assert_eq!(e.peak_thickness_mm, Some(6.0));
        assert_eq!(e.peak_sigma_mm, Some(0.4));
        assert_eq!(e.peak_rate_mm_per_h, Some(2.0));
        assert!(close(e.mean_rate_mm_per_h.unwrap(), 2.0));
        assert_eq!(e.medium, Medium::Rime);
        assert!(!e.ongoing);
    }
    let covered = 40.0 * 24.0 - 1.0 / 60.0;
    assert!(close(r.covered_h, covered));
    assert!(close(r.gap_h, 0.0));
    assert!(close(r.meteorological_h, 6.0));
    assert!(close(r.instrumental_h, 23.7));
    assert!(close(r.meteorological_pct, 600.0 / covered));
    // 0.625 % meteorological: class 2 (0.5–3 %); 2.47 % instrumental: class 2 (1–9 %).
    assert_eq!(r.iea_class, 2);
    assert_eq!(r.iea_instrumental_classes, [2]);
    assert_eq!(r.meteorological_source.derived, 0);
    // Day 0 (2026-01-01) and day 20 (2026-01-21) in January; February
    // holds days 31–39.
    assert_eq!(r.months.len(), 2);
    assert_eq!((r.months[0].year, r.months[0].month), (2026, 1));
    assert_eq!(r.months[0].events, 2);
    assert!(close(r.months[0].meteorological_h, 6.0));
    assert!(close(r.months[0].covered_h, 31.0 * 24.0));
    assert!(close(r.months[1].covered_h, 9.0 * 24.0 - 1.0 / 60.0));
    assert_eq!(r.months[1].events, 0);
    let table = super::render::table(&r);
    assert!(table.contains("IEA Wind ice class"), "{table}");
    assert!(table.contains("2026-01-21 06:00:00"), "{table}");
    let csv = super::render::events_csv(&r).unwrap();
    assert_eq!(csv.lines().count(), 3);
    assert!(
        csv.lines()
            .nth(1)
            .unwrap()
            .contains(",3.0000,11.8500,6.0000,0.4000,2.0000,2.0000,rime,0"),
        "{csv}"
    );
    let json: serde_json::Value = serde_json::from_str(&super::render::json(&r).unwrap()).unwrap();
    assert_eq!(json["iea_class"], 2);
    assert_eq!(json["events"][1]["medium"], "rime");
}

#[test]
fn accreting_as_a_0_1_flag_reads_as_the_probability() {
    let text = String::from_utf8(forty_days(true)).unwrap();
    // est_accreting, the only column of 0.970 / 0.020 in these rows: → 1 / 0.
    let flags = text
        .replace(",0.970\n", ",1\n")
        .replace(",0.020\n", ",0\n")
        .replace(",0.970,", ",1,")
        .replace(",0.020,", ",0,");
    assert_ne!(flags, text);
    let r = report_of(flags.as_bytes());
    assert_eq!(r.events, report_of(text.as_bytes()).events);
    assert!(close(r.meteorological_h, 6.0));
}

#[test]
fn older_logs_derive_meteorological_icing_from_the_growth_and_say_so() {
    let r = report_of(&forty_days(false));
    assert_eq!(r.meteorological_source.node, 0);
    assert!(r.meteorological_source.derived > 0);
    assert!(r.source_text().contains("derived"), "{}", r.source_text());
    assert_eq!(r.events.len(), 2);
    for e in &r.events {
        // The 20-minute growth window between one-minute means: on at
        // 06:03 (0.2 mm/h reached), off at 09:20 (growth ended at 09:00:
        // the window holds less than 0.1 mm/h of it): 197 min, the ramps
        // of the window pulling the mean rate below the true 2 mm/h.
        assert_eq!(
            e.start_ms,
            BASE_MS + (e.start_ms - BASE_MS) / DAY_MS * DAY_MS + 363 * 60_000
        );
        assert!(close(e.meteorological_h, 197.0 / 60.0), "{e:?}");
        assert!(close(e.instrumental_h, 11.85), "{e:?}");
        let mean = e.mean_rate_mm_per_h.unwrap();
        assert!((mean - 1.826).abs() < 1e-3, "{e:?}");
        assert!((e.peak_rate_mm_per_h.unwrap() - 2.0).abs() < 0.01, "{e:?}");
    }
    assert_eq!(r.iea_class, 2);
}

#[test]
fn a_gap_is_counted_apart_and_splits_an_event() {
    let text = String::from_utf8(forty_days(true)).unwrap();
    // Drop 12:00–12:59 of day 0 (ice on the sensor).
    let from = BASE_MS + 12 * 3_600_000;
    let to = from + 3_600_000;
    let kept: String = text
        .lines()
        .filter(|l| {
            let t: Option<u64> = l.split(',').nth(1).and_then(|v| v.parse().ok());
            !t.is_some_and(|t| t >= from && t < to)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let r = report_of(kept.as_bytes());
    // From the 11:59 row to the 13:00 row: 61 min without data.
    assert!(close(r.gap_h, 61.0 / 60.0), "{}", r.gap_h);
    assert!(close(r.covered_h, 40.0 * 24.0 - 1.0 / 60.0 - 61.0 / 60.0));
    assert!(close(r.instrumental_h, 23.7 - 61.0 / 60.0));
    assert!(close(r.meteorological_h, 6.0));
    // The gap is longer than the 10-minute hold: the event ends at it.
    assert_eq!(r.events.len(), 3);
    assert_eq!(r.events[0].end_ms, from - 60_000);
    assert_eq!(r.events[1].start_ms, to);
    assert!(super::render::table(&r).contains("gaps 1.02 h"));
}

#[test]
fn a_bad_line_is_an_error_naming_file_and_line() {
    let text = String::from_utf8(forty_days(true)).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // Line 101 of the file (the header is line 1).
    lines[100] = lines[100].replacen(",1767", ",17x7", 1);
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "bad.csv", (lines.join("\n") + "\n").as_bytes());
    let err = analyse(std::slice::from_ref(&p), Thresholds::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains(&format!("{}, line 101", p.display())), "{err}");
    assert!(err.contains("host_unix_ms `17x7"), "{err}");

    lines[100] = text.lines().nth(100).unwrap().to_string();
    // A thickness that is not a number.
    let mut fields: Vec<&str> = lines[600].split(',').collect();
    fields[18] = "thick";
    lines[600] = fields.join(",");
    let p = write(dir.path(), "bad2.csv", (lines.join("\n") + "\n").as_bytes());
    let err = analyse(&[p], Thresholds::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("line 601: est_thickness_mm `thick` is not a number"),
        "{err}"
    );

    let p = write(dir.path(), "other.csv", b"a,b\n1,2\n");
    let err = analyse(&[p], Thresholds::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("line 1: no column `host_unix_ms`"), "{err}");
}

#[test]
fn gzip_split_and_cut_files_read_the_same() {
    let bytes = forty_days(true);
    let whole = report_of(&bytes);
    let text = String::from_utf8(bytes).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let rows: Vec<&str> = lines.collect();
    let dir = tempfile::tempdir().unwrap();
    // Three files, as the gateway's daily files: the first compressed,
    // the last cut mid-line by a killed logger (a row it never finished).
    let part = |rs: &[&str]| format!("{header}\n{}\n", rs.join("\n"));
    let a = part(&rows[..20_000]);
    let b = part(&rows[20_000..40_000]);
    let c = part(&rows[40_000..]) + "2026-02-10T00:00:00.000Z,17";
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(a.as_bytes()).unwrap();
    let pa = write(dir.path(), "a.csv.gz", &gz.finish().unwrap());
    let pb = write(dir.path(), "b.csv", b.as_bytes());
    let pc = write(dir.path(), "c.csv", c.as_bytes());
    // In any order on the command line.
    let r = analyse(&[pc, pa, pb], Thresholds::default()).unwrap();
    assert_eq!(r.measurements, whole.measurements);
    assert_eq!(r.events, whole.events);
    assert!(close(r.covered_h, whole.covered_h));
    assert!(close(r.meteorological_h, whole.meteorological_h));
    assert_eq!(r.files.iter().filter(|f| f.cut_last_line).count(), 1);
    assert!(r.files[2].cut_last_line);
}

#[test]
fn the_timeline_figure_is_drawn() {
    let r = report_of(&forty_days(true));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.png");
    crate::plot::icing::plot_icing(&r, &out).unwrap();
    assert!(std::fs::metadata(&out).unwrap().len() > 10_000);
    assert!(r.timeline.buckets().len() <= super::timeline::MAX_BUCKETS);
}

#[test]
fn the_bench_path_counts_every_row_of_its_synthetic_days() {
    let b = super::bench(3).unwrap();
    assert_eq!(b.rows, 3 * 86_400);
    // Icing on day 0 only (every 10th day).
    assert_eq!(b.events, 1);
    assert!(close(b.meteorological_h, 3.0));
}
