//! The queue against real files: order across memory and disk, kills,
//! torn and corrupt records, the bound, the lock, a removed directory, and
//! a full disk (a child process under a file-size limit: the kernel's own
//! write errors).

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::Path;

use super::segment::seg_path;
use super::*;

/// Record `i`: every tenth an event, the others measurements.
fn rec(i: u64) -> Record {
    let kind = if i.is_multiple_of(10) {
        "event"
    } else {
        "measurement"
    };
    Record {
        topic: format!("fois/gw/n{}/{kind}", i % 3),
        payload: format!(
            "{{\"seq\":{i},\"pad\":\"{}\"}}",
            "x".repeat((i % 50) as usize)
        )
        .into_bytes(),
    }
}

fn small(max: u64) -> QueueLimits {
    QueueLimits {
        max_bytes: max,
        segment_bytes: max / 8,
        mem_bytes: 2048,
        unsaved_bytes: 1 << 20,
    }
}

fn drain(q: &mut Queue) -> Vec<(u64, Record)> {
    let mut out = vec![];
    let mut at = q.acked();
    while let Some((i, r)) = q.get(at) {
        out.push((i, r));
        at = i + 1;
    }
    out
}

#[test]
fn records_come_back_in_order_from_memory_and_disk_and_after_reopen() {
    let dir = tempfile::tempdir().unwrap();
    let (mut q, rec0) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    assert_eq!(rec0.pending, 0);
    for i in 0..500 {
        assert_eq!(q.push(rec(i)), i);
    }
    q.tick(); // on disk now: the cache may let them go
    // 2 KiB of memory holds only the newest few: most come from disk.
    assert!(q.mem.len() < 50, "{}", q.mem.len());
    let got = drain(&mut q);
    assert_eq!(got.len(), 500);
    for (k, (i, r)) in got.iter().enumerate() {
        assert_eq!(*i, k as u64);
        assert_eq!(*r, rec(k as u64));
    }
    q.ack_through(200);
    q.close().unwrap();
    let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    assert_eq!(r.pending, 300);
    assert_eq!(q.acked(), 200);
    let got = drain(&mut q);
    assert_eq!(got.first().map(|g| g.0), Some(200));
    assert_eq!(got.last().map(|g| g.0), Some(499));
    assert_eq!(q.push(rec(500)), 500, "indexes continue");
}

#[test]
fn a_torn_tail_is_cut_and_what_was_ticked_survives_a_kill() {
    let dir = tempfile::tempdir().unwrap();
    let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    for i in 0..40 {
        q.push(rec(i));
    }
    q.tick(); // 40 records reach the kernel
    for i in 40..45 {
        q.push(rec(i)); // these stay in the process's buffer
    }
    // SIGKILL: no destructor, no flush; the kernel drops the lock.
    drop(std::mem::replace(
        &mut q._lock,
        fs::File::open(dir.path()).unwrap(),
    ));
    std::mem::forget(q);
    // And a half-written record at the end of the segment.
    let seg = fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "seg"))
        .unwrap();
    let mut f = OpenOptions::new().append(true).open(&seg).unwrap();
    f.write_all(&rec(999).encode()[..20]).unwrap();
    drop(f);
    let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    assert_eq!(r.pending, 40);
    assert_eq!(r.truncated_bytes, 20);
    let got = drain(&mut q);
    assert_eq!(got.len(), 40);
    assert_eq!(got[39].1, rec(39));
    assert_eq!(q.push(rec(40)), 40);
    assert_eq!(drain(&mut q).len(), 41);
}

#[test]
fn a_corrupt_record_ends_its_segment_and_is_not_delivered() {
    let dir = tempfile::tempdir().unwrap();
    let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    for i in 0..10 {
        q.push(rec(i));
    }
    q.close().unwrap();
    let seg = seg_path(dir.path(), 0);
    let mut bytes = fs::read(&seg).unwrap();
    let at = rec(0).encode().len() + rec(1).encode().len() + 12;
    bytes[at] ^= 0xff; // inside record 2's body: its CRC fails
    fs::write(&seg, &bytes).unwrap();
    let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    assert_eq!(r.pending, 2);
    let got = drain(&mut q);
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 1]);
}

/// The `seq` in a record's payload.
fn seq_of(r: &Record) -> u64 {
    let text = String::from_utf8_lossy(&r.payload);
    let digits: String = text["{\"seq\":".len()..]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().unwrap()
}

/// Every event of `0..n` is in `got`; the measurements missing from it
/// are one contiguous run (what was lost went oldest first, once the
/// queue had to drop); `got` plus what the queue counted is everything.
fn check_losses(got: &[(u64, Record)], n: u64, dropped: u64) {
    let seqs: Vec<u64> = got.iter().map(|(_, r)| seq_of(r)).collect();
    let mut sorted = seqs.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), seqs.len(), "a record came twice");
    assert_eq!(
        got.len() as u64 + dropped,
        n,
        "every record is kept or counted"
    );
    for e in (0..n).filter(|i| i % 10 == 0) {
        assert!(sorted.binary_search(&e).is_ok(), "event {e} was dropped");
    }
    let missing: Vec<u64> = (0..n)
        .filter(|i| sorted.binary_search(i).is_err())
        .collect();
    assert!(missing.iter().all(|i| i % 10 != 0));
    if let (Some(a), Some(b)) = (missing.first(), missing.last()) {
        let kept_between = (*a..=*b).filter(|i| i % 10 != 0 && sorted.binary_search(i).is_ok());
        assert_eq!(
            kept_between.count(),
            0,
            "the lost measurements are one run: {missing:?}"
        );
    }
}

#[test]
fn the_bound_drops_the_oldest_measurements_counts_them_and_keeps_every_event() {
    let dir = tempfile::tempdir().unwrap();
    let limits = small(64 * 1024);
    let (mut q, _) = Queue::open(dir.path(), limits).unwrap();
    let n = 3000u64;
    for i in 0..n {
        q.push(rec(i));
        assert!(
            q.bytes() <= limits.max_bytes + limits.segment_bytes + 200,
            "{} bytes",
            q.bytes()
        );
    }
    let got = drain(&mut q);
    assert!(q.dropped() > 2000, "{}", q.dropped());
    check_losses(&got, n, q.dropped());
    // The newest are all there, the oldest measurements gone.
    assert_eq!(seq_of(&got.last().unwrap().1), n - 1);
    assert!(
        got.iter()
            .all(|(_, r)| r.is_measurement() || seq_of(r).is_multiple_of(10))
    );
    // The counter survives a restart.
    let dropped = q.dropped();
    q.close().unwrap();
    let (q, _) = Queue::open(dir.path(), limits).unwrap();
    assert_eq!(q.dropped(), dropped);
}

#[test]
fn dropping_is_told_in_the_log_once_then_at_most_once_a_minute() {
    let log = crate::test_log::Capture::start();
    let dir = tempfile::tempdir().unwrap();
    let limits = small(64 * 1024);
    let (mut q, _) = Queue::open(dir.path(), limits).unwrap();
    let dropping = |log: &crate::test_log::Capture| {
        log.lines()
            .iter()
            .filter(|l| l.contains("dropping"))
            .cloned()
            .collect::<Vec<_>>()
    };
    for i in 0..500 {
        q.push(rec(i));
    }
    q.tick();
    assert_eq!(q.dropped(), 0);
    assert!(dropping(&log).is_empty());
    // Past the bound: one warning, with the count and the cause; the
    // ticks of the next seconds, dropping on, say nothing more.
    let mut lines = Vec::new();
    for i in 500..3_000 {
        q.push(rec(i));
        if i % 100 == 0 {
            q.tick();
            lines = dropping(&log);
        }
    }
    q.tick();
    assert!(q.dropped() > 2_000, "{}", q.dropped());
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(
        lines[0].contains("WARN")
            && lines[0].contains("dropping the oldest measurements")
            && lines[0].contains("bound of 65536 bytes"),
        "{}",
        lines[0]
    );
    assert_eq!(dropping(&log).len(), 1);
}

#[test]
fn a_second_queue_on_the_same_directory_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    let err = Queue::open(dir.path(), small(1 << 20)).err().unwrap();
    let text = format!("{err:#}");
    assert!(text.contains("in use by another running gateway"), "{text}");
    assert!(
        text.contains(&format!("pid {}", std::process::id())),
        "{text}"
    );
    drop(q);
    assert!(Queue::open(dir.path(), small(1 << 20)).is_ok());
}

#[test]
fn a_removed_directory_is_made_again_nothing_twice_and_what_is_lost_is_counted() {
    let dir = tempfile::tempdir().unwrap();
    let qdir = dir.path().join("q");
    let (mut q, _) = Queue::open(&qdir, small(1 << 20)).unwrap();
    for i in 0..300 {
        q.push(rec(i));
    }
    q.tick();
    q.ack_through(100);
    fs::remove_dir_all(&qdir).unwrap();
    for i in 300..400 {
        q.push(rec(i));
    }
    q.tick(); // notices: records now held in memory
    assert!(
        q.failing().is_some_and(|w| w.contains("removed")),
        "{:?}",
        q.failing()
    );
    std::thread::sleep(RETRY_INTERVAL + Duration::from_millis(50));
    q.tick(); // makes the directory again, writes what memory holds
    assert_eq!(q.failing(), None);
    assert!(qdir.join("ack").exists() && qdir.join("lock").exists());
    // Records 100..300 were on disk only (the 2 KiB cache gave them up for
    // the 100 records that had not reached the disk): all lost, counted.
    let lost = q.dropped();
    assert_eq!(lost, 200);
    let got = drain(&mut q);
    let seqs: Vec<u64> = got.iter().map(|(_, r)| seq_of(r)).collect();
    assert_eq!(seqs.len() as u64 + lost, 300, "kept or counted");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "in order, once");
    assert_eq!(*seqs.last().unwrap(), 399);
    for i in 400..410 {
        q.push(rec(i));
    }
    q.close().unwrap();
    let (mut q, r) = Queue::open(&qdir, small(1 << 20)).unwrap();
    assert_eq!(r.pending, 310 - lost);
    assert_eq!(q.dropped(), lost);
    assert_eq!(drain(&mut q).len() as u64, 310 - lost);
}

const FULL_DISK_CHILD: &str = "FOIS_QUEUE_FULL_DISK_CHILD";
const FULL_DISK_TEST: &str =
    "queue::tests::a_full_disk_loses_only_the_oldest_measurements_counts_them_and_recovers";

/// Set the soft limit of the size of any file this process writes.
fn file_size_limit(bytes: Option<u64>) {
    // SAFETY: plain system calls on this (child) process's own limits.
    unsafe {
        let mut l = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        assert_eq!(libc::getrlimit(libc::RLIMIT_FSIZE, &mut l), 0);
        l.rlim_cur = bytes.unwrap_or(l.rlim_max);
        assert_eq!(libc::setrlimit(libc::RLIMIT_FSIZE, &l), 0);
    }
}

/// In the child: the queue under a file-size limit of 8 KiB (writes past
/// it fail with EFBIG, as on a full disk), then without.
fn full_disk_child(dir: &Path) {
    // SAFETY: ignoring SIGXFSZ at the start of this single-purpose child,
    // so the kernel answers EFBIG instead of killing it.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    let limits = QueueLimits {
        max_bytes: 1 << 20,
        segment_bytes: 64 * 1024,
        mem_bytes: 4096,
        unsaved_bytes: 16 * 1024,
    };
    let log = crate::test_log::Capture::start();
    let (mut q, _) = Queue::open(dir, limits).unwrap();
    file_size_limit(Some(8 * 1024));
    let n = 600;
    for i in 0..n {
        q.push(rec(i));
        if i % 10 == 9 {
            q.tick();
        }
    }
    assert!(q.failing().is_some(), "the limit was hit");
    assert!(q.dropped() > 0, "16 KiB of held records overflowed");
    let told: Vec<String> = log
        .lines()
        .into_iter()
        .filter(|l| l.contains("dropping"))
        .collect();
    assert_eq!(told.len(), 1, "{told:?}");
    assert!(
        told[0].contains("the disk fails") && told[0].contains("reached 16384 bytes"),
        "{}",
        told[0]
    );
    let got = drain(&mut q);
    check_losses(&got, n, q.dropped());
    // The disk takes writes again: everything held goes to disk.
    file_size_limit(None);
    std::thread::sleep(RETRY_INTERVAL + Duration::from_millis(50));
    q.tick();
    assert_eq!(q.failing(), None);
    println!("dropped {} kept {}", q.dropped(), got.len());
    q.close().unwrap();
}

#[test]
fn a_full_disk_loses_only_the_oldest_measurements_counts_them_and_recovers() {
    if let Some(dir) = std::env::var_os(FULL_DISK_CHILD) {
        full_disk_child(Path::new(&dir));
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", FULL_DISK_TEST, "--nocapture", "--test-threads=1"])
        .env(FULL_DISK_CHILD, dir.path())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("1 passed"),
        "the child ran the scenario: {text}"
    );
    if let Some(at) = text.find("dropped ") {
        let line = text[at..].lines().next().unwrap_or("");
        println!("full disk (8 KiB file-size limit, 16 KiB held in memory): {line}");
    }
    // What the child kept is on disk now, the count with it.
    let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    let got = drain(&mut q);
    assert!(q.dropped() > 0);
    check_losses(&got, 600, q.dropped());
    assert!(
        text.contains(&format!("dropped {} kept {}", q.dropped(), got.len())),
        "{text}"
    );
}

#[test]
fn acknowledged_segments_are_deleted() {
    let dir = tempfile::tempdir().unwrap();
    let (mut q, _) = Queue::open(dir.path(), small(256 * 1024)).unwrap();
    for i in 0..2000 {
        q.push(rec(i));
    }
    let before = q.segment_count();
    assert!(before > 3, "{before}");
    q.ack_through(2000);
    assert_eq!(q.segment_count(), 1);
    assert_eq!(q.pending(), 0);
    let files = fs::read_dir(dir.path())
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "seg"))
        })
        .count();
    assert_eq!(files, 1);
    assert_eq!(q.get(0), None);
}

#[test]
fn an_unreadable_ack_file_resends_rather_than_loses() {
    let dir = tempfile::tempdir().unwrap();
    let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    for i in 0..10 {
        q.push(rec(i));
    }
    q.ack_through(6);
    q.close().unwrap();
    fs::write(dir.path().join("ack"), "garbage").unwrap();
    let (q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
    assert_eq!(r.pending, 10);
    assert_eq!(q.acked(), 0);
}
