//! A simulated day at 10 Hz (864 000 frames) through the host pipeline in
//! virtual time: the monitor's memory must stay flat.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_host::bench::long_run;

fn check(frames: u64) {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("day.csv");
    let r = long_run(frames, &log).unwrap();
    eprintln!(
        "{} frames in {:.1} s; RSS samples (frames, bytes): {:?}; growth {} bytes; summary {:?}",
        r.frames,
        r.seconds,
        r.rss,
        r.rss_growth(),
        r.summary
    );
    assert_eq!(r.summary.lost, 0);
    assert_eq!(r.summary.rejected, 0);
    assert_eq!(r.summary.disconnects, 0, "the pty stays open to the end");
    assert!(r.summary.measurements >= frames - 10, "{:?}", r.summary);
    assert!(
        r.summary.ice_onsets >= 1,
        "the rime half of the day trips the alarm"
    );
    assert_eq!(r.rss.len(), 10);
    // Flat: at most 4 MiB more than after the first tenth (allocator noise).
    assert!(
        r.rss_growth() < 4 << 20,
        "RSS grew by {} bytes",
        r.rss_growth()
    );
}

/// The full day, 864 000 frames: about 4 s in the test profile (fois-host
/// and the firmware logic are optimised there, see the root Cargo.toml).
/// A leak of 5 bytes per frame would already break the 4 MiB bound.
#[test]
fn memory_stays_flat_over_a_simulated_day() {
    check(864_000);
}
