//! The system tools the checks need, looked for before anything is
//! compiled: a missing one is installed (Debian or Ubuntu, as root or
//! through `sudo -n`: `apt-get install`), or CI stops at once with the one
//! command that installs them all.
//!
//! | tool | package | used by |
//! | --- | --- | --- |
//! | `mosquitto`, `mosquitto_passwd` | `mosquitto` | the gateway's tests: a real broker (plain, password, mutual TLS) |
//! | `qemu-system-arm` | `qemu-system-arm` | the firmware logic on an emulated Cortex-M4F |
//! | `systemd-analyze` | `systemd` | `systemd-analyze verify` of the gateway's unit file |
//! | `dpkg-deb` | `dpkg` | reading the gateway's Debian package back |
//! | `python3` (3.11 or 3.12, with `venv`) | `python3-venv` | the Home Assistant check's virtualenvs ([`crate::ha_check`]); the gateway's Modbus tests' client |
//! | `mbpoll` | `mbpoll` | the virtual node's Modbus RTU tests (`host/tests/modbus_rtu.rs`): a second, independent RTU master |
//!
//! Then the virtualenv of the gateway's Modbus tests ([`ensure_pymodbus`]):
//! `target/pymodbus-venv` with the pymodbus of
//! `gateway/tests/modbus/requirements.txt` (the test fails without it).
//!
//! Cargo tools (`flip-link`, `cargo-deb`) are installed with `cargo install`
//! by the steps that need them.

use std::path::Path;
use std::process::Command;

use anyhow::{Result, bail};

/// A system tool: where it may be, and the Debian package that has it.
#[derive(Debug, Clone, Copy)]
pub struct Tool {
    /// The program's name.
    pub name: &'static str,
    /// The Debian/Ubuntu package that installs it.
    pub package: &'static str,
    /// Directories it is found in (beside `PATH`: `/usr/sbin` is not on
    /// every user's `PATH`).
    pub dirs: &'static [&'static str],
}

const SBIN: &[&str] = &["/usr/sbin", "/usr/local/sbin", "/sbin"];

/// Every system tool `cargo xtask ci` needs.
pub const TOOLS: [Tool; 7] = [
    Tool {
        name: "mosquitto",
        package: "mosquitto",
        dirs: SBIN,
    },
    Tool {
        name: "mosquitto_passwd",
        package: "mosquitto",
        dirs: &[],
    },
    Tool {
        name: "qemu-system-arm",
        package: "qemu-system-arm",
        dirs: &[],
    },
    Tool {
        name: "systemd-analyze",
        package: "systemd",
        dirs: &[],
    },
    Tool {
        name: "dpkg-deb",
        package: "dpkg",
        dirs: &[],
    },
    Tool {
        name: "python3",
        package: "python3-venv",
        dirs: &[],
    },
    Tool {
        name: "mbpoll",
        package: "mbpoll",
        dirs: &[],
    },
];

/// True when `program` is on `PATH` or in one of `dirs`.
pub fn found(program: &str, dirs: &[&str]) -> bool {
    let on_path = Command::new("sh")
        .args(["-c", &format!("command -v {program} >/dev/null 2>&1")])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    on_path || dirs.iter().any(|d| Path::new(d).join(program).exists())
}

/// The packages of the tools in `tools` that are missing, each once.
pub fn missing_packages(tools: &[Tool], found: impl Fn(&Tool) -> bool) -> Vec<&'static str> {
    let mut out: Vec<&'static str> = Vec::new();
    for t in tools {
        if !found(t) && !out.contains(&t.package) {
            out.push(t.package);
        }
    }
    out
}

/// How packages can be installed here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Installer {
    /// apt-get as root.
    AptRoot,
    /// apt-get through `sudo -n` (no password asked).
    AptSudo,
    /// Neither: the user must run the command.
    None,
}

fn installer() -> Installer {
    if !found("apt-get", &[]) {
        return Installer::None;
    }
    let root = Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false);
    if root {
        return Installer::AptRoot;
    }
    let sudo = Command::new("sudo")
        .args(["-n", "true"])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if sudo {
        Installer::AptSudo
    } else {
        Installer::None
    }
}

/// The one command that installs `packages`.
pub fn install_command(packages: &[&str]) -> String {
    format!(
        "sudo apt-get update && sudo apt-get install -y --no-install-recommends {}",
        packages.join(" ")
    )
}

/// The gateway Modbus tests' virtualenv, under the workspace root.
pub const PYMODBUS_VENV: &str = "target/pymodbus-venv";
/// Its pinned requirements (read by the tests too).
pub const PYMODBUS_REQUIREMENTS: &str = "gateway/tests/modbus/requirements.txt";
/// What the virtualenv was made from (a copy of the requirements).
const PYMODBUS_MARKER: &str = "fois-requirements.txt";

/// Look for every tool; install what is missing where this machine allows,
/// otherwise fail at once with the command to run. Then the Modbus tests'
/// virtualenv.
pub fn ensure(root: &Path) -> Result<()> {
    ensure_packages()?;
    ensure_pymodbus(root)
}

/// The virtualenv `target/pymodbus-venv` with the pinned pymodbus, made
/// (again) unless it was made from the same requirements.
pub fn ensure_pymodbus(root: &Path) -> Result<()> {
    let req_path = root.join(PYMODBUS_REQUIREMENTS);
    let req = std::fs::read_to_string(&req_path)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", req_path.display()))?;
    let venv = root.join(PYMODBUS_VENV);
    let python = venv.join("bin/python");
    let marker = venv.join(PYMODBUS_MARKER);
    if python.exists() && std::fs::read_to_string(&marker).is_ok_and(|m| m == req) {
        eprintln!("pymodbus virtualenv: {} ({})", venv.display(), req.trim());
        return Ok(());
    }
    if venv.exists() {
        std::fs::remove_dir_all(&venv)?;
    }
    let v = venv.to_string_lossy().to_string();
    let r = req_path.to_string_lossy().to_string();
    crate::shell::run("python3", &["-m", "venv", &v])?;
    let pip = venv.join("bin/pip").to_string_lossy().to_string();
    crate::shell::run(
        &pip,
        &[
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "-r",
            &r,
        ],
    )?;
    std::fs::write(&marker, &req)?;
    Ok(())
}

fn ensure_packages() -> Result<()> {
    let missing = missing_packages(&TOOLS, |t| found(t.name, t.dirs));
    if missing.is_empty() {
        eprintln!("system tools: all present");
        return Ok(());
    }
    let how = installer();
    eprintln!("system tools: missing packages {}", missing.join(" "));
    let (program, prefix): (&str, &[&str]) = match how {
        Installer::AptRoot => ("apt-get", &[]),
        Installer::AptSudo => ("sudo", &["-n", "apt-get"]),
        Installer::None => bail!(
            "the checks need these packages, and this user cannot install them: {}\n\
             run (Debian/Ubuntu; on another system install the same tools):\n\n    {}\n",
            missing.join(" "),
            install_command(&missing)
        ),
    };
    let apt = |args: &[&str]| -> Result<()> {
        let mut all: Vec<&str> = prefix.to_vec();
        all.extend_from_slice(args);
        eprintln!("\n$ {program} {}", all.join(" "));
        let st = Command::new(program)
            .args(&all)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()?;
        if !st.success() {
            bail!(
                "`{program} {}` failed ({st}); install by hand:\n\n    {}\n",
                all.join(" "),
                install_command(&missing)
            );
        }
        Ok(())
    };
    apt(&["update", "-qq"])?;
    let mut install = vec!["install", "-y", "-qq", "--no-install-recommends"];
    install.extend(missing.iter().copied());
    apt(&install)?;
    let still = missing_packages(&TOOLS, |t| found(t.name, t.dirs));
    if !still.is_empty() {
        bail!(
            "after installing, still missing: {} (install by hand: {})",
            still.join(" "),
            install_command(&still)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_missing_package_is_named_once_in_one_command() {
        // mosquitto and mosquitto_passwd are one package.
        let missing = missing_packages(&TOOLS, |t| t.name == "dpkg-deb");
        assert_eq!(
            missing,
            vec![
                "mosquitto",
                "qemu-system-arm",
                "systemd",
                "python3-venv",
                "mbpoll"
            ]
        );
        assert_eq!(
            install_command(&missing),
            "sudo apt-get update && sudo apt-get install -y --no-install-recommends \
             mosquitto qemu-system-arm systemd python3-venv mbpoll"
        );
        assert!(missing_packages(&TOOLS, |_| true).is_empty());
    }
}
