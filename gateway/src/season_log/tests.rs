//! The daily logs: roll-over at midnight UTC with an injected clock,
//! compression, pruning, continuing after a restart, disk errors, and
//! `foisctl icing-report` on the files.

use std::io::Read;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use fois_link::log_row::{HEADER, Row, row_fields};
use fois_protocol::{
    DetectorState, DeviceMsg, IceEstimate, Measurement, MeasurementV3, Medium, flags,
};

use super::daily::{DAY_MS, DailyFiles, compress, date_text, file_day};
use super::{ERROR_EVERY, ErrorLimiter, SeasonLog};
use crate::config::LogConfig;

/// 2026-03-01 00:00 UTC, day 20 513.
const DAY0_MS: u64 = 1_772_323_200_000;
const DAY0: i64 = 20_513;

/// A measurement row at `t_ms` with `thickness_um` of rime (dry at 0).
fn row(t_ms: u64, seq: u32, thickness_um: u16) -> Row {
    let ice = thickness_um > 0;
    let m = Measurement {
        uptime_ms: u64::from(seq) * 1000,
        i1_na: 25_000,
        i2_na: 8_000,
        ambient1_na: 1_200,
        ambient2_na: 900,
        temperature_centi_c: -500,
        vdda_mv: 3300,
        flags: if ice { flags::ALARM } else { 0 },
        state: if ice {
            DetectorState::Ice
        } else {
            DetectorState::Dry
        },
    };
    let msg = DeviceMsg::MeasurementV3(MeasurementV3 {
        measurement: m,
        estimate: Some(IceEstimate {
            thickness_um,
            sigma_um: 100 + thickness_um / 20,
            medium: if ice { Medium::Rime } else { Medium::Dry },
            probability_permille: 950,
        }),
        gain: None,
    });
    Row {
        host_unix_ms: t_ms,
        ..Row::device(seq, &msg)
    }
}

fn csv_line(r: &Row) -> String {
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::new());
    w.write_record(row_fields(r.host_unix_ms, r)).unwrap();
    String::from_utf8(w.into_inner().unwrap()).unwrap()
}

fn gunzip(p: &Path) -> String {
    let mut s = String::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(p).unwrap())
        .read_to_string(&mut s)
        .unwrap();
    s
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn file_names_carry_the_day() {
    assert_eq!(date_text(DAY0), "2026-03-01");
    assert_eq!((DAY0_MS / DAY_MS) as i64, DAY0);
    assert_eq!(file_day("n-1", "n-1-2026-03-01.csv"), Some((DAY0, false)));
    assert_eq!(file_day("n-1", "n-1-2026-03-01.csv.gz"), Some((DAY0, true)));
    assert_eq!(file_day("n-1", "n-1-2026-03-01.2.csv"), Some((DAY0, false)));
    assert_eq!(file_day("n-1", "n-1-2026-13-01.csv"), None);
    assert_eq!(file_day("n-1", "n-1-2026-03-01.csv.gz.tmp"), None);
    assert_eq!(file_day("n", "n-1-2026-03-01.csv"), None);
    assert_eq!(file_day("n-1", "notes.txt"), None);
}

#[test]
fn a_day_rolls_over_at_midnight_utc_and_is_compressed() {
    let tmp = tempfile::tempdir().unwrap();
    let mut f = DailyFiles::new(tmp.path().to_path_buf(), 30);
    let before = [
        row(DAY0_MS + DAY_MS - 2000, 1, 0),
        row(DAY0_MS + DAY_MS - 1000, 2, 0),
    ];
    for r in &before {
        f.write("north", r).unwrap();
    }
    // Housekeeping during the day leaves today's file alone.
    assert!(f.housekeeping(DAY0_MS + DAY_MS - 500).is_empty());
    let dir = tmp.path().join("north");
    assert_eq!(names(&dir), ["north-2026-03-01.csv"]);
    // The first row of the next day closes and compresses the day before.
    let after = row(DAY0_MS + DAY_MS, 3, 0);
    f.write("north", &after).unwrap();
    f.flush().unwrap();
    assert_eq!(
        names(&dir),
        ["north-2026-03-01.csv.gz", "north-2026-03-02.csv"]
    );
    let day1 = gunzip(&dir.join("north-2026-03-01.csv.gz"));
    assert_eq!(
        day1,
        format!("{HEADER}\n{}{}", csv_line(&before[0]), csv_line(&before[1]))
    );
    assert!(day1.contains("\n2026-03-01T23:59:59.000Z,"));
    let day2 = std::fs::read_to_string(dir.join("north-2026-03-02.csv")).unwrap();
    assert_eq!(day2, format!("{HEADER}\n{}", csv_line(&after)));
    // A quiet node: its day is compressed by the clock after midnight.
    f.write("south", &row(DAY0_MS + DAY_MS + 3_600_000, 1, 0))
        .unwrap();
    assert!(f.housekeeping(DAY0_MS + 2 * DAY_MS - 1).is_empty());
    assert_eq!(names(&tmp.path().join("south")), ["south-2026-03-02.csv"]);
    assert!(f.housekeeping(DAY0_MS + 2 * DAY_MS + 1).is_empty());
    assert_eq!(
        names(&tmp.path().join("south")),
        ["south-2026-03-02.csv.gz"]
    );
    assert_eq!(
        names(&dir),
        ["north-2026-03-01.csv.gz", "north-2026-03-02.csv.gz"]
    );
    assert_eq!(f.rows, 4);
}

#[test]
fn days_beyond_the_days_kept_are_deleted_and_strays_compressed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("n1");
    std::fs::create_dir_all(&dir).unwrap();
    for back in 0..10i64 {
        let name = format!("n1-{}.csv", date_text(DAY0 - back));
        std::fs::write(dir.join(name), format!("{HEADER}\n")).unwrap();
    }
    std::fs::write(dir.join("notes.txt"), "keep me").unwrap();
    std::fs::write(tmp.path().join("README"), "keep me too").unwrap();
    let mut f = DailyFiles::new(tmp.path().to_path_buf(), 3);
    assert!(f.housekeeping(DAY0_MS + 60_000).is_empty());
    // Three days kept, today's included: today's file stays as it is, the
    // two before are compressed (left by a crash), the rest deleted.
    assert_eq!(
        names(&dir),
        [
            "n1-2026-02-27.csv.gz",
            "n1-2026-02-28.csv.gz",
            "n1-2026-03-01.csv",
            "notes.txt"
        ]
    );
    assert_eq!(
        gunzip(&dir.join("n1-2026-02-28.csv.gz")),
        format!("{HEADER}\n")
    );
    assert!(tmp.path().join("README").exists());
    // The next day: one more goes.
    assert!(f.housekeeping(DAY0_MS + DAY_MS).is_empty());
    assert_eq!(
        names(&dir),
        ["n1-2026-02-28.csv.gz", "n1-2026-03-01.csv.gz", "notes.txt"]
    );
}

#[test]
fn a_restart_continues_the_day_and_another_layout_is_left_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("n");
    let t = DAY0_MS + 3_600_000;
    {
        let mut f = DailyFiles::new(tmp.path().to_path_buf(), 5);
        f.write("n", &row(t, 1, 0)).unwrap();
        f.close_all().unwrap();
    }
    // Killed mid-row.
    let p = dir.join("n-2026-03-01.csv");
    let mut text = std::fs::read_to_string(&p).unwrap();
    text.push_str("2026-03-01T01:00:01");
    std::fs::write(&p, &text).unwrap();
    {
        let mut f = DailyFiles::new(tmp.path().to_path_buf(), 5);
        f.write("n", &row(t + 1000, 2, 0)).unwrap();
        f.close_all().unwrap();
    }
    let text = std::fs::read_to_string(&p).unwrap();
    assert_eq!(text.matches("host_time_utc").count(), 1);
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.ends_with(&csv_line(&row(t + 1000, 2, 0))));
    // A file of another layout (an older gateway): the day goes on in .2.
    std::fs::write(dir.join("n-2026-03-02.csv"), "a,b\n1,2\n").unwrap();
    let mut f = DailyFiles::new(tmp.path().to_path_buf(), 5);
    f.write("n", &row(DAY0_MS + DAY_MS + 5, 3, 0)).unwrap();
    f.close_all().unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.join("n-2026-03-02.csv")).unwrap(),
        "a,b\n1,2\n"
    );
    assert!(
        std::fs::read_to_string(dir.join("n-2026-03-02.2.csv"))
            .unwrap()
            .starts_with(HEADER)
    );
}

#[test]
fn compressing_onto_an_existing_gz_appends_a_member() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("x-2026-03-01.csv");
    std::fs::write(&p, "one\n").unwrap();
    compress(&p).unwrap();
    std::fs::write(&p, "two\n").unwrap();
    compress(&p).unwrap();
    assert!(!p.exists());
    assert_eq!(
        gunzip(&tmp.path().join("x-2026-03-01.csv.gz")),
        "one\ntwo\n"
    );
}

#[test]
fn disk_errors_are_logged_at_most_once_a_minute_and_do_not_stop_the_log() {
    let mut l = ErrorLimiter::default();
    let t0 = Instant::now();
    assert_eq!(l.admit("full", t0).as_deref(), Some("full"));
    assert_eq!(l.admit("full", t0 + Duration::from_secs(1)), None);
    assert_eq!(l.admit("full", t0 + Duration::from_secs(59)), None);
    assert_eq!(
        l.admit("full", t0 + ERROR_EVERY).as_deref(),
        Some("full (2 more log error(s) since the last one shown)")
    );
    // The directory cannot be made (a file is in the way): every write
    // fails, the thread goes on, `record` never blocks.
    let tmp = tempfile::tempdir().unwrap();
    let blocked = tmp.path().join("file");
    std::fs::write(&blocked, "x").unwrap();
    let cfg = LogConfig {
        dir: blocked.join("logs"),
        days_kept: 3,
    };
    let mut f = DailyFiles::new(cfg.dir.clone(), 3);
    assert!(f.write("n", &row(DAY0_MS, 1, 0)).is_err());
    let mut log = SeasonLog::start_with_clock(&cfg, Arc::new(|| DAY0_MS)).unwrap();
    let start = Instant::now();
    for k in 0..50_000u32 {
        log.record("n", vec![row(DAY0_MS + u64::from(k), k, 0)]);
    }
    assert!(start.elapsed() < Duration::from_secs(5));
    log.stop();
}

#[test]
fn the_log_thread_writes_rolls_over_and_stops_with_an_injected_clock() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = LogConfig {
        dir: tmp.path().to_path_buf(),
        days_kept: 7,
    };
    let now = Arc::new(std::sync::atomic::AtomicU64::new(DAY0_MS + DAY_MS - 10_000));
    let clock = now.clone();
    let mut log = SeasonLog::start_with_clock(
        &cfg,
        Arc::new(move || clock.load(std::sync::atomic::Ordering::SeqCst)),
    )
    .unwrap();
    for k in 0..5u32 {
        log.record(
            "west",
            vec![row(DAY0_MS + DAY_MS - 5000 + u64::from(k) * 1000, k, 0)],
        );
    }
    now.store(DAY0_MS + DAY_MS + 2000, std::sync::atomic::Ordering::SeqCst);
    log.record("west", vec![row(DAY0_MS + DAY_MS + 1000, 5, 0)]);
    log.stop();
    let dir = tmp.path().join("west");
    assert_eq!(
        names(&dir),
        ["west-2026-03-01.csv.gz", "west-2026-03-02.csv"]
    );
    assert_eq!(
        gunzip(&dir.join("west-2026-03-01.csv.gz")).lines().count(),
        6
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("west-2026-03-02.csv"))
            .unwrap()
            .lines()
            .count(),
        2
    );
}

/// The gateway's files of a day of icing that crosses midnight, as
/// checked in under `tests/fixtures/daily-log/`: `foisctl icing-report`
/// is run on exactly these by fois-host's `tests/icing_report_cli.rs`
/// (neither crate depends on the other). `FOIS_BLESS=1` rewrites them.
#[test]
fn the_daily_files_of_an_icing_night_match_the_fixture_the_report_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let mut f = DailyFiles::new(tmp.path().to_path_buf(), 30);
    // Rime at 2 mm/h from 20:00 for 3 h (6 mm), shed at 02:00 the next
    // day; a row a minute from 12:00 to 04:00.
    let grow_from = DAY0_MS + 20 * 3_600_000;
    let shed = DAY0_MS + DAY_MS + 2 * 3_600_000;
    let mut seq = 0;
    let mut t = DAY0_MS + 12 * 3_600_000;
    while t < DAY0_MS + DAY_MS + 4 * 3_600_000 {
        let um = if t >= grow_from && t < shed {
            // 2 mm/h = 2000 µm per 3 600 000 ms.
            ((t - grow_from).min(3 * 3_600_000) / 1800) as u16
        } else {
            0
        };
        f.write("ridge", &row(t, seq, um)).unwrap();
        assert!(f.housekeeping(t).is_empty());
        seq += 1;
        t += 60_000;
    }
    f.close_all().unwrap();
    assert_eq!(f.rows, 16 * 60);
    let dir = tmp.path().join("ridge");
    let files = names(&dir);
    assert_eq!(files, ["ridge-2026-03-01.csv.gz", "ridge-2026-03-02.csv"]);
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/daily-log/ridge");
    let text = |p: &Path| {
        if p.extension().is_some_and(|e| e == "gz") {
            gunzip(p)
        } else {
            std::fs::read_to_string(p).unwrap()
        }
    };
    if std::env::var_os("FOIS_BLESS").is_some() {
        std::fs::create_dir_all(&fixture).unwrap();
        for n in &files {
            std::fs::copy(dir.join(n), fixture.join(n)).unwrap();
        }
    }
    assert_eq!(names(&fixture), files);
    for n in &files {
        assert!(
            text(&dir.join(n)) == text(&fixture.join(n)),
            "{n} differs from tests/fixtures/daily-log/ridge/{n}: FOIS_BLESS=1 cargo test -p fois-gateway --lib season_log rewrites it"
        );
    }
    // The day before midnight: 12:00 to 23:59, the header first.
    let day1 = text(&fixture.join("ridge-2026-03-01.csv.gz"));
    assert_eq!(day1.lines().count(), 1 + 12 * 60);
    assert!(day1.starts_with(&format!("{HEADER}\n")));
}

#[test]
fn a_node_report_becomes_the_rows_the_monitor_writes() {
    use crate::reader::{NodeMsg, NodeUpdate};
    use fois_protocol::{DeviceFrame, SeqEvent};
    let frame = DeviceFrame {
        seq: 42,
        msg: DeviceMsg::MeasurementV3(MeasurementV3 {
            measurement: Measurement {
                uptime_ms: 9,
                i1_na: 25_000,
                i2_na: 8_000,
                ambient1_na: 0,
                ambient2_na: 0,
                temperature_centi_c: -500,
                vdda_mv: 3300,
                flags: 0,
                state: DetectorState::Dry,
            },
            estimate: None,
            gain: None,
        }),
    };
    let msg = |update| NodeMsg {
        node: 0,
        host_unix_ms: DAY0_MS + 7,
        update,
    };
    let rows = super::rows_of(&msg(NodeUpdate::Frame(frame.clone(), SeqEvent::Gap(3))));
    let kinds: Vec<&str> = rows.iter().map(|r| r.kind).collect();
    assert_eq!(kinds, ["gap", "measurement"]);
    assert_eq!(rows[0].frames_lost, Some(3));
    assert!(rows.iter().all(|r| r.host_unix_ms == DAY0_MS + 7));
    let line = csv_line(&rows[1]);
    assert!(
        line.starts_with(
            "2026-03-01T00:00:00.007Z,1772323200007,measurement,42,9,25.000,8.000,0.000,0.000,-5.00,3300,Dry,0,1,0,,,,"
        ),
        "{line}"
    );
    assert_eq!(line.split(',').count(), HEADER.split(',').count());
    let rows = super::rows_of(&msg(NodeUpdate::Frame(frame, SeqEvent::Restart)));
    assert_eq!(rows[0].kind, "node_restart");
    let rows = super::rows_of(&msg(NodeUpdate::Down("port gone".into())));
    assert_eq!(
        (rows[0].kind, rows[0].detail.as_str()),
        ("link_lost", "port gone")
    );
    assert_eq!(
        super::rows_of(&msg(NodeUpdate::Rejected))[0].kind,
        "rejected"
    );
    assert!(super::rows_of(&msg(NodeUpdate::Unreachable("x".into()))).is_empty());
}
