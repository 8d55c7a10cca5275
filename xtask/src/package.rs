//! The gateway's Debian package: `cargo deb -p fois-gateway --strip`
//! builds it (cargo-deb, installed when missing), then it is read back and
//! checked: the files it installs, the conffile, the packaged example
//! config passing the packaged binary's `--check-config`, and the packaged
//! unit passing `systemd-analyze verify` (with no warning) and scoring at
//! most [`MAX_EXPOSURE`] in `systemd-analyze security`.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// What the package must install (`dpkg-deb -c` paths).
pub const FILES: [&str; 5] = [
    "./usr/bin/fois-gateway",
    "./usr/lib/systemd/system/fois-gateway.service",
    "./etc/fois/gateway.toml",
    "./usr/share/doc/fois-gateway/README.md",
    "./usr/share/doc/fois-gateway/copyright",
];

/// The worst `systemd-analyze security` exposure accepted (0 = locked
/// down, 10 = nothing restricted; systemd calls below 2 "OK").
pub const MAX_EXPOSURE: f64 = 2.0;

const UNIT: &str = "usr/lib/systemd/system/fois-gateway.service";

fn output(program: &str, args: &[&str]) -> Result<(bool, String)> {
    let out = Command::new(program)
        .args(args)
        .output()
        .with_context(|| format!("could not run {program}"))?;
    let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stderr));
    Ok((out.status.success(), text))
}

/// Build the package; its path.
pub fn build() -> Result<PathBuf> {
    if !crate::tools::found("cargo-deb", &[]) {
        crate::shell::run("cargo", &["install", "cargo-deb", "--locked"])?;
    }
    eprintln!("\n$ cargo deb -p fois-gateway --strip");
    let out = Command::new("cargo")
        .args(["deb", "-p", "fois-gateway", "--strip"])
        .output()
        .context("could not run cargo deb")?;
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!("cargo deb failed:\n{stdout}");
    }
    let deb = stdout
        .lines()
        .rev()
        .find(|l| l.trim_end().ends_with(".deb"))
        .map(|l| PathBuf::from(l.trim()))
        .context("cargo deb printed no package path")?;
    Ok(deb)
}

/// The paths of a `dpkg-deb -c` listing (last column).
pub fn listed_paths(listing: &str) -> Vec<String> {
    listing
        .lines()
        .filter_map(|l| l.split_whitespace().last())
        .map(str::to_string)
        .collect()
}

/// The overall exposure of a `systemd-analyze security` report.
pub fn exposure(report: &str) -> Option<f64> {
    let line = report
        .lines()
        .find(|l| l.contains("Overall exposure level"))?;
    line.split(':')
        .nth(1)?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Read the package back and check it; prints its file list.
pub fn check(deb: &Path) -> Result<()> {
    let deb_s = deb.display().to_string();
    let (ok, listing) = output("dpkg-deb", &["-c", &deb_s])?;
    if !ok {
        bail!("dpkg-deb -c {deb_s}: {listing}");
    }
    eprintln!("package {deb_s}:\n{listing}");
    let paths = listed_paths(&listing);
    let missing: Vec<&str> = FILES
        .iter()
        .copied()
        .filter(|f| !paths.iter().any(|p| p == f))
        .collect();
    if !missing.is_empty() {
        bail!("the package lacks {}", missing.join(", "));
    }
    if !listing
        .lines()
        .any(|l| l.starts_with("-rwxr-xr-x") && l.ends_with("./usr/bin/fois-gateway"))
    {
        bail!("./usr/bin/fois-gateway is not installed executable (0755)");
    }

    let root = PathBuf::from("target/xtask-deb");
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root)?;
    let root_s = root.display().to_string();
    let control = root.join("DEBIAN");
    for (flag, dir) in [
        ("-x", root_s.clone()),
        ("-e", control.display().to_string()),
    ] {
        let (ok, text) = output("dpkg-deb", &[flag, &deb_s, &dir])?;
        if !ok {
            bail!("dpkg-deb {flag} {deb_s}: {text}");
        }
    }
    let conffiles = std::fs::read_to_string(control.join("conffiles")).unwrap_or_default();
    if !conffiles
        .lines()
        .any(|l| l.trim() == "/etc/fois/gateway.toml")
    {
        bail!(
            "/etc/fois/gateway.toml is not a conffile (an upgrade would overwrite the site's config)"
        );
    }

    // The packaged example config passes the packaged binary's check.
    let bin = root.join("usr/bin/fois-gateway").display().to_string();
    let cfg = root.join("etc/fois/gateway.toml").display().to_string();
    let (ok, text) = output(&bin, &["--config", &cfg, "--check-config"])?;
    if !ok || !text.contains("config OK") {
        bail!("the packaged example config fails --check-config:\n{text}");
    }
    eprint!("packaged config: {text}");

    // The unit, verified against the package's own files (its ExecStart
    // binary among them) and the system's targets.
    let units = root.join("usr/lib/systemd/system");
    for dir in ["/usr/lib/systemd/system", "/lib/systemd/system"] {
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                let to = units.join(e.file_name());
                if !to.exists() && e.path().is_file() {
                    let _ = std::fs::copy(e.path(), &to);
                }
            }
        }
    }
    let root_arg = format!("--root={root_s}");
    let (ok, text) = output("systemd-analyze", &["verify", &root_arg, UNIT])?;
    if !ok || !text.trim().is_empty() {
        bail!("systemd-analyze verify {UNIT}:\n{text}");
    }
    eprintln!("systemd-analyze verify {UNIT}: no finding");
    let (_, report) = output(
        "systemd-analyze",
        &["security", "--offline=yes", &root_arg, UNIT],
    )?;
    let level = exposure(&report).context("systemd-analyze security printed no exposure level")?;
    if level > MAX_EXPOSURE {
        bail!("the unit's exposure is {level} (at most {MAX_EXPOSURE}):\n{report}");
    }
    eprintln!("systemd-analyze security: exposure {level} (at most {MAX_EXPOSURE})");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listing_and_exposure_are_read() {
        let listing = "drwxr-xr-x 0/0 0 2026-11-24 00:00 ./usr/\n\
                       -rwxr-xr-x 0/0 38715520 2026-11-24 00:00 ./usr/bin/fois-gateway\n";
        assert_eq!(
            listed_paths(listing),
            vec!["./usr/", "./usr/bin/fois-gateway"]
        );
        let report =
            "✓ UMask= ...\n\n→ Overall exposure level for fois-gateway.service: 1.6 OK 🙂\n";
        assert_eq!(exposure(report), Some(1.6));
        assert_eq!(exposure("nothing"), None);
    }
}
