//! `[firmware]`: the directory of signed images a roll-out may name
//! ([`crate::rollout`]), and how long a node's new image has to confirm
//! itself. Roll-outs are commands: the section needs `[commands] enabled`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use super::located::KeyError;

/// The new image's time to boot and confirm itself, by default, s.
pub const DEFAULT_CONFIRM_TIMEOUT_S: u64 = 120;
/// The longest accepted, s (an hour).
pub const MAX_CONFIRM_TIMEOUT_S: u64 = 3_600;

/// `[firmware]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FirmwareFile {
    /// Directory of the signed images (`foisctl sign`) a roll-out command
    /// may name [default: none, no roll-outs].
    pub dir: Option<PathBuf>,
    /// Time a node's new image has to boot and confirm itself, s
    /// [default: 120].
    pub confirm_timeout_s: Option<u64>,
}

/// `[firmware]`, resolved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FirmwareConfig {
    /// Directory of the signed images.
    pub dir: PathBuf,
    /// Time a node's new image has to boot and confirm itself.
    pub confirm_timeout: Duration,
}

/// `[firmware]` checked: `None` without a `dir`; a `dir` needs commands.
pub fn resolve_firmware(
    f: FirmwareFile,
    commands_enabled: bool,
) -> anyhow::Result<Option<FirmwareConfig>> {
    let Some(dir) = f.dir else {
        if f.confirm_timeout_s.is_some() {
            return Err(KeyError::at(
                "firmware.confirm_timeout_s",
                "[firmware] confirm_timeout_s is set but dir is not: give the directory of the \
                 signed images",
            ));
        }
        return Ok(None);
    };
    if dir.as_os_str().is_empty() {
        return Err(KeyError::at("firmware.dir", "[firmware] dir is empty"));
    }
    if !commands_enabled {
        return Err(KeyError::at(
            "firmware.dir",
            "[firmware] dir is set but commands are not enabled: a roll-out is a command, add \
             `enabled = true` to [commands] (or remove [firmware])",
        ));
    }
    let confirm_timeout_s = f.confirm_timeout_s.unwrap_or(DEFAULT_CONFIRM_TIMEOUT_S);
    if !(1..=MAX_CONFIRM_TIMEOUT_S).contains(&confirm_timeout_s) {
        return Err(KeyError::at(
            "firmware.confirm_timeout_s",
            format!(
                "[firmware] confirm_timeout_s = {confirm_timeout_s}: give 1 to \
                 {MAX_CONFIRM_TIMEOUT_S} s"
            ),
        ));
    }
    Ok(Some(FirmwareConfig {
        dir,
        confirm_timeout: Duration::from_secs(confirm_timeout_s),
    }))
}

/// The path of the image a command names: a plain file name in `dir`
/// (no path separator, no `..`, not hidden, not empty).
pub fn image_path(dir: &Path, name: &str) -> Result<PathBuf, String> {
    let bad = name.is_empty()
        || name.contains(['/', '\\', '\0'])
        || name.starts_with('.')
        || name.contains("..")
        || name.chars().any(char::is_control);
    if bad {
        return Err(format!(
            "`{}` is not an image name: give a file name of the firmware directory, without \
             a path (no `/`, `\\` or `..`)",
            name.escape_debug()
        ));
    }
    Ok(dir.join(name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_section_is_checked() {
        let r = |dir: Option<&str>, t, commands| {
            resolve_firmware(
                FirmwareFile {
                    dir: dir.map(PathBuf::from),
                    confirm_timeout_s: t,
                },
                commands,
            )
        };
        assert_eq!(r(None, None, true).unwrap(), None);
        assert_eq!(r(None, None, false).unwrap(), None);
        assert_eq!(
            r(Some("/var/lib/fois-gateway/firmware"), None, true).unwrap(),
            Some(FirmwareConfig {
                dir: "/var/lib/fois-gateway/firmware".into(),
                confirm_timeout: Duration::from_secs(120),
            })
        );
        for (dir, t, commands, msg) in [
            (Some("d"), None, false, "commands are not enabled"),
            (Some(""), None, true, "dir is empty"),
            (None, Some(30), true, "dir is not"),
            (Some("d"), Some(0), true, "1 to 3600"),
            (Some("d"), Some(3601), true, "1 to 3600"),
        ] {
            let e = r(dir, t, commands).unwrap_err().to_string();
            assert!(e.contains(msg), "{e}");
        }
    }

    #[test]
    fn an_image_name_is_a_plain_file_name_of_the_directory() {
        let dir = Path::new("/srv/fw");
        assert_eq!(
            image_path(dir, "fois-0.7.0.fois").unwrap(),
            PathBuf::from("/srv/fw/fois-0.7.0.fois")
        );
        for bad in [
            "",
            "../etc/passwd",
            "..",
            "a/b.fois",
            "/etc/passwd",
            "a\\b.fois",
            ".hidden",
            "x..y",
            "a\nb",
        ] {
            let e = image_path(dir, bad).unwrap_err();
            assert!(e.contains("not an image name"), "{bad:?}: {e}");
        }
    }
}
