//! A test's slow disk: every [`super::Queue::tick`] of a queue in a
//! directory set here blocks for the time set (as a `fdatasync` on a
//! saturated or failing disk does).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

static STALLS: Mutex<Vec<(PathBuf, Duration)>> = Mutex::new(Vec::new());

/// Every tick of the queue in `dir` blocks for `each`.
pub fn set(dir: &Path, each: Duration) {
    if let Ok(mut s) = STALLS.lock() {
        s.push((dir.to_path_buf(), each));
    }
}

/// Block as set for `dir` (not at all when nothing is).
pub fn wait(dir: &Path) {
    let each = STALLS
        .lock()
        .ok()
        .and_then(|s| s.iter().find(|(d, _)| d == dir).map(|(_, t)| *t));
    if let Some(t) = each {
        std::thread::sleep(t);
    }
}
