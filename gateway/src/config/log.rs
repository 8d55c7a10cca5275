//! `[log]`: the season's data on the gateway's disk — each node's frames
//! as daily CSV files in `foisctl monitor`'s format
//! ([`crate::season_log`]).

use std::path::PathBuf;

use serde::Deserialize;

/// Days kept by default: a year and a day (a whole season and the same
/// days of the year before).
pub const DEFAULT_DAYS_KEPT: u32 = 366;
/// Days kept at most (ten years).
pub const MAX_DAYS_KEPT: u32 = 3653;

/// `[log]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogFile {
    /// Directory of the daily logs, one subdirectory per node [default:
    /// none, no logs].
    pub dir: Option<PathBuf>,
    /// Days of files kept (today's included); older files are deleted
    /// after midnight UTC [default: 366].
    pub days_kept: Option<u32>,
}

/// `[log]`, resolved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogConfig {
    /// Directory of the daily logs.
    pub dir: PathBuf,
    /// Days of files kept, today's included.
    pub days_kept: u32,
}

/// `[log]` checked: `None` without a `dir`.
pub fn resolve_log(f: LogFile) -> anyhow::Result<Option<LogConfig>> {
    let Some(dir) = f.dir else {
        if f.days_kept.is_some() {
            anyhow::bail!("[log] days_kept is set but dir is not: give the directory of the logs");
        }
        return Ok(None);
    };
    if dir.as_os_str().is_empty() {
        anyhow::bail!("[log] dir is empty");
    }
    let days_kept = f.days_kept.unwrap_or(DEFAULT_DAYS_KEPT);
    if !(1..=MAX_DAYS_KEPT).contains(&days_kept) {
        anyhow::bail!("[log] days_kept = {days_kept}: give 1 to {MAX_DAYS_KEPT} days");
    }
    Ok(Some(LogConfig { dir, days_kept }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_section_is_checked() {
        let r = |dir: Option<&str>, days| {
            resolve_log(LogFile {
                dir: dir.map(PathBuf::from),
                days_kept: days,
            })
        };
        assert_eq!(r(None, None).unwrap(), None);
        assert_eq!(
            r(Some("/var/lib/fois-gateway/logs"), None).unwrap(),
            Some(LogConfig {
                dir: "/var/lib/fois-gateway/logs".into(),
                days_kept: 366
            })
        );
        assert_eq!(r(Some("d"), Some(30)).unwrap().unwrap().days_kept, 30);
        for (dir, days, msg) in [
            (None, Some(3), "dir is not"),
            (Some(""), None, "dir is empty"),
            (Some("d"), Some(0), "1 to 3653"),
            (Some("d"), Some(4000), "1 to 3653"),
        ] {
            let e = r(dir, days).unwrap_err().to_string();
            assert!(e.contains(msg), "{e}");
        }
    }
}
