//! The independent Modbus client of the gateway's Modbus tests: pymodbus
//! (pinned in `tests/modbus/requirements.txt`) in a virtualenv that
//! `cargo xtask tools` (CI's "system tools" step) makes in
//! `target/pymodbus-venv`, driven through `tests/modbus/client.py`, which
//! answers in JSON. A missing virtualenv or another pymodbus fails the
//! test with the command that makes it (these tests never skip).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

/// The workspace root.
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(PathBuf::from)
        .unwrap_or_default()
}

/// The pinned requirement, e.g. `pymodbus==3.16.1`.
pub fn requirement() -> String {
    let p = root().join("gateway/tests/modbus/requirements.txt");
    std::fs::read_to_string(&p)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()))
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("pymodbus=="))
        .unwrap_or_else(|| panic!("{} pins no pymodbus", p.display()))
        .to_string()
}

/// The virtualenv's python, checked to hold the pinned pymodbus; panics
/// with the command that makes it.
pub fn python() -> PathBuf {
    let python = std::env::var_os("FOIS_PYMODBUS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/pymodbus-venv/bin/python"));
    let req = requirement();
    let version = req.trim_start_matches("pymodbus==");
    let fix = "make it with `cargo xtask tools` (CI's \"system tools\" step), or by hand: \
               `python3 -m venv target/pymodbus-venv && target/pymodbus-venv/bin/pip install -r \
               gateway/tests/modbus/requirements.txt` (Debian: apt-get install python3-venv)";
    let out = Command::new(&python)
        .args(["-c", "import pymodbus; print(pymodbus.__version__)"])
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "the Modbus tests need {req} in a virtualenv; {} cannot run ({e}): {fix}",
                python.display()
            )
        });
    let found = String::from_utf8_lossy(&out.stdout).trim().to_string();
    assert!(
        out.status.success() && found == version,
        "the Modbus tests need {req} in {}; found {}: {fix}",
        python.display(),
        if out.status.success() {
            format!("pymodbus {found}")
        } else {
            String::from_utf8_lossy(&out.stderr).trim().to_string()
        }
    );
    python
}

/// A pymodbus client of the server at `127.0.0.1:port`.
#[derive(Debug, Clone)]
pub struct Client {
    python: PathBuf,
    port: u16,
}

impl Client {
    /// A client of `127.0.0.1:port` (checks the virtualenv first).
    pub fn new(port: u16) -> Client {
        Client {
            python: python(),
            port,
        }
    }

    /// Run `client.py CMD 127.0.0.1 PORT ARGS…`; its JSON answer.
    pub fn run(&self, cmd: &str, args: &[String]) -> serde_json::Value {
        let script = root().join("gateway/tests/modbus/client.py");
        let t = Instant::now();
        let out = Command::new(&self.python)
            .arg(&script)
            .arg(cmd)
            .arg("127.0.0.1")
            .arg(self.port.to_string())
            .args(args)
            .output()
            .expect("running the pymodbus client");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "client.py {cmd} {args:?} failed after {:.1} s: {text}{}",
            t.elapsed().as_secs_f64(),
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
    }

    /// Read `count` registers from `address` of `unit` with function
    /// `fc` (3 or 4): `Ok(registers)` or `Err(exception code)`.
    pub fn read(&self, unit: u8, fc: u8, address: u16, count: u16) -> Result<Vec<u16>, u8> {
        answer(&self.run(
            "read",
            &[
                unit.to_string(),
                fc.to_string(),
                address.to_string(),
                count.to_string(),
            ],
        ))
    }

    /// Write `value` to `address` of `unit` with function `fc` (6 or 16):
    /// `Ok(())` or `Err(exception code)`.
    pub fn write(&self, unit: u8, address: u16, value: u16, fc: u8) -> Result<(), u8> {
        let v = self.run(
            "write",
            &[
                unit.to_string(),
                address.to_string(),
                value.to_string(),
                fc.to_string(),
            ],
        );
        match v["exception"].as_u64() {
            Some(e) => Err(e as u8),
            None => Ok(()),
        }
    }
}

/// `{"registers": [...]}` or `{"exception": N}`.
pub fn answer(v: &serde_json::Value) -> Result<Vec<u16>, u8> {
    if let Some(e) = v["exception"].as_u64() {
        return Err(e as u8);
    }
    Ok(v["registers"]
        .as_array()
        .unwrap_or_else(|| panic!("no registers: {v}"))
        .iter()
        .map(|x| x.as_u64().unwrap_or(u64::MAX) as u16)
        .collect())
}
