//! A real Home Assistant core for the discovery check: started from the
//! virtualenv `cargo xtask ha-check` installs (`FOIS_HA_PYTHON` names its
//! python), headless, on a config directory the test writes, and read
//! through the `fois_probe` custom integration (tests/home_assistant/),
//! which dumps what a user sees to a JSON file.
//!
//! Set-up without onboarding or a login: Home Assistant 2024 configures
//! MQTT only as a config entry, so the directory gets
//! `.storage/core.config_entries` with one MQTT entry (storage version 1,
//! which every 2024 release reads) pointing at the test's broker;
//! `configuration.yaml` sets the location and units (no repair issues),
//! the HTTP server on a free loopback port (MQTT depends on it; onboarding
//! only gates the web UI, not the core), the recorder (its SQLite database
//! is what "a row per state change" is counted in) and the probe.
//! `--skip-pip`: the integrations' requirements are in the virtualenv; a
//! missing one fails the set-up at once instead of being fetched.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use super::free_port;
use super::ha_snapshot::Snapshot;

/// The probe integration's sources.
fn probe_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/home_assistant/fois_probe")
}

/// The virtualenv's python (`FOIS_HA_PYTHON`); panics with the command
/// that sets it up.
pub fn python() -> PathBuf {
    let p = std::env::var_os("FOIS_HA_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            panic!(
                "FOIS_HA_PYTHON is not set: this check runs a real Home Assistant; \
             `cargo xtask ha-check` installs it and runs the check"
            )
        });
    assert!(p.exists(), "FOIS_HA_PYTHON={} does not exist", p.display());
    p
}

/// A running Home Assistant.
pub struct HomeAssistant {
    child: Option<Child>,
    /// Its config directory.
    pub dir: PathBuf,
    requests: u32,
}

impl HomeAssistant {
    /// Write the config directory `dir` for a broker on `broker_port` and
    /// start Home Assistant.
    pub fn start(dir: &Path, broker_port: u16) -> HomeAssistant {
        std::fs::create_dir_all(dir.join(".storage")).unwrap();
        let probe = dir.join("custom_components/fois_probe");
        std::fs::create_dir_all(&probe).unwrap();
        for f in ["__init__.py", "manifest.json"] {
            std::fs::copy(probe_dir().join(f), probe.join(f)).unwrap();
        }
        let http_port = free_port();
        std::fs::write(
            dir.join("configuration.yaml"),
            format!(
                "homeassistant:\n  name: FOIS check\n  unit_system: metric\n  time_zone: UTC\n  \
                 latitude: 47.07\n  longitude: 15.44\n  elevation: 350\n  currency: EUR\n  \
                 country: AT\nhttp:\n  server_host: 127.0.0.1\n  server_port: {http_port}\n\
                 recorder:\n  commit_interval: 1\nlogger:\n  default: warning\nfois_probe:\n"
            ),
        )
        .unwrap();
        let entries = json!({
            "version": 1,
            "minor_version": 1,
            "key": "core.config_entries",
            "data": {"entries": [{
                "entry_id": "f01500000000000000000000000000aa",
                "version": 1,
                "minor_version": 1,
                "domain": "mqtt",
                "title": "FOIS test broker",
                "data": {
                    "broker": "127.0.0.1",
                    "port": broker_port,
                    "discovery": true,
                    "discovery_prefix": "homeassistant",
                },
                "options": {},
                "pref_disable_new_entities": false,
                "pref_disable_polling": false,
                "source": "user",
                "unique_id": null,
                "disabled_by": null,
            }]},
        });
        std::fs::write(
            dir.join(".storage/core.config_entries"),
            serde_json::to_vec_pretty(&entries).unwrap(),
        )
        .unwrap();
        let out = std::fs::File::create(dir.join("ha.out")).unwrap();
        let child = Command::new(python())
            .args(["-m", "homeassistant", "--config"])
            .arg(dir)
            .args(["--skip-pip", "--log-no-color"])
            .stdout(Stdio::from(out.try_clone().unwrap()))
            .stderr(Stdio::from(out))
            .spawn()
            .expect("start Home Assistant");
        HomeAssistant {
            child: Some(child),
            dir: dir.to_path_buf(),
            requests: 0,
        }
    }

    /// The probe's latest snapshot (None before the first).
    pub fn snapshot(&self) -> Option<Snapshot> {
        let text = std::fs::read_to_string(self.dir.join("fois_probe.json")).ok()?;
        serde_json::from_str(&text).ok().map(Snapshot)
    }

    /// Wait until `pred` holds for a snapshot; panics with `what`, the
    /// last snapshot's states and Home Assistant's log after `timeout`.
    pub fn wait(
        &mut self,
        what: &str,
        timeout: Duration,
        pred: impl Fn(&Snapshot) -> bool,
    ) -> Snapshot {
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.snapshot()
                && pred(&s)
            {
                return s;
            }
            if let Some(c) = &mut self.child
                && let Ok(Some(status)) = c.try_wait()
            {
                panic!(
                    "Home Assistant exited ({status}) while waiting for {what}:\n{}",
                    self.log_tail()
                );
            }
            if t0.elapsed() > timeout {
                let states = self
                    .snapshot()
                    .map(|s| s.states_text())
                    .unwrap_or_else(|| "(no snapshot)".into());
                panic!(
                    "Home Assistant: no {what} within {timeout:?}\nstates:\n{states}\nlog:\n{}",
                    self.log_tail()
                );
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }

    /// Call a service as a user would (the probe carries it out): e.g.
    /// `button.press` on an entity. Returns once it was called.
    pub fn call(&mut self, domain: &str, service: &str, data: Value) {
        self.requests += 1;
        let name = format!("r{}", self.requests);
        let dir = self.dir.join("fois_probe_requests");
        let tmp = dir.join(format!("{name}.tmp"));
        std::fs::write(
            &tmp,
            json!({"domain": domain, "service": service, "data": data}).to_string(),
        )
        .unwrap();
        std::fs::rename(&tmp, dir.join(format!("{name}.json"))).unwrap();
        let s = self.wait(
            &format!("the call {domain}.{service}"),
            Duration::from_secs(20),
            |s| {
                s.0["requests"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|r| r["request"] == name)
            },
        );
        let r = s.0["requests"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["request"] == name)
            .unwrap();
        assert_eq!(r["ok"], true, "{domain}.{service} failed: {r}");
    }

    /// The end of Home Assistant's log file.
    pub fn log_tail(&self) -> String {
        let log = std::fs::read_to_string(self.dir.join("home-assistant.log"))
            .or_else(|_| std::fs::read_to_string(self.dir.join("ha.out")))
            .unwrap_or_default();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(40)..].join("\n")
    }

    /// Stop it (SIGTERM: the recorder writes what it holds); its exit status.
    pub fn stop(&mut self) -> Option<std::process::ExitStatus> {
        let mut c = self.child.take()?;
        // SAFETY: signalling our own child process.
        unsafe {
            libc::kill(c.id() as i32, libc::SIGTERM);
        }
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(60) {
            if let Ok(Some(st)) = c.try_wait() {
                return Some(st);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = c.kill();
        c.wait().ok()
    }
}

impl Drop for HomeAssistant {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
