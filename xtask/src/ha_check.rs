//! `cargo xtask ha-check`: the gateway's Home Assistant discovery checked
//! by real Home Assistant releases (`gateway/tests/home_assistant.rs`).
//!
//! Each release in [`RELEASES`] is installed once into its own virtualenv
//! in a cache directory (`$FOIS_HA_CACHE`, else
//! `$XDG_CACHE_HOME/fois/home-assistant`, else
//! `~/.cache/fois/home-assistant`): the wheel from PyPI, installed against
//! the `package_constraints.txt` inside it (pip then resolves no versions
//! of its own: ~30 s instead of a long backtrack), then the requirements of
//! the integrations the check loads (read from the release's own
//! manifests). Then the check runs once per release, and on a pass the
//! results are recorded in [`RECORD`] with a hash of the files the check
//! depends on ([`INPUTS`]).
//!
//! `cargo xtask ci` runs the check only when that hash differs from the
//! recorded one (the discovery code, the payloads or the check changed):
//! the check takes minutes and downloads Home Assistant.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};

/// The releases checked: the oldest the discovery supports and the newest
/// that installs on Python 3.11 (later ones need 3.12).
pub const RELEASES: [&str; 2] = ["2024.1.6", "2024.3.3"];

/// Integrations whose requirements go into the virtualenv beside the ones
/// every release sets up: MQTT, the recorder (its database is where the
/// check counts rows), `stream` (MQTT's camera platform imports it).
const INTEGRATIONS: [&str; 3] = ["mqtt", "recorder", "stream"];

/// The recorded pass: the inputs' hash, then what the check printed.
pub const RECORD: &str = "gateway/tests/home_assistant/last-pass.txt";

/// The files the check's verdict depends on (directories: every file
/// below, but not the record itself).
pub const INPUTS: [&str; 10] = [
    "gateway/src/discovery",
    "gateway/src/payload.rs",
    "gateway/src/state_filter.rs",
    "gateway/src/topics.rs",
    "gateway/src/machine/homeassistant.rs",
    "gateway/tests/home_assistant.rs",
    "gateway/tests/home_assistant",
    "gateway/tests/support/home_assistant.rs",
    "gateway/tests/support/ha_snapshot.rs",
    "xtask/src/ha_check.rs",
];

fn cache_dir() -> Result<PathBuf> {
    if let Some(d) = std::env::var_os("FOIS_HA_CACHE") {
        return Ok(PathBuf::from(d));
    }
    let base = match std::env::var_os("XDG_CACHE_HOME") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(std::env::var_os("HOME").context("HOME is not set")?).join(".cache"),
    };
    Ok(base.join("fois/home-assistant"))
}

/// A Python 3.11 or 3.12 with `venv`: what these releases run on.
fn system_python() -> Result<String> {
    for candidate in ["python3.11", "python3.12", "python3"] {
        let ok = Command::new(candidate)
            .args([
                "-c",
                "import sys, venv; sys.exit(0 if sys.version_info[:2] in ((3, 11), (3, 12)) else 1)",
            ])
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
        if ok {
            return Ok(candidate.to_string());
        }
    }
    bail!(
        "Home Assistant {} needs Python 3.11 or 3.12 with its venv module; none was found \
         (Debian 12: apt-get install python3 python3-venv)",
        RELEASES.join(", ")
    )
}

fn run_logged(program: &Path, args: &[&str], cwd: Option<&Path>) -> Result<()> {
    eprintln!("$ {} {}", program.display(), args.join(" "));
    let mut c = Command::new(program);
    c.args(args);
    if let Some(d) = cwd {
        c.current_dir(d);
    }
    let st = c
        .status()
        .with_context(|| format!("could not start {}", program.display()))?;
    if !st.success() {
        bail!("`{} {}` failed ({st})", program.display(), args.join(" "));
    }
    Ok(())
}

/// The virtualenv of `release`, installed if it is not yet; its python.
fn venv(release: &str, root: &Path) -> Result<PathBuf> {
    let dir = cache_dir()?.join(release);
    let python = dir.join("venv/bin/python");
    let marker = dir.join("installed");
    if marker.exists() && python.exists() {
        return Ok(python);
    }
    let t = Instant::now();
    eprintln!("installing Home Assistant {release} into {}", dir.display());
    if dir.exists() {
        std::fs::remove_dir_all(&dir)?;
    }
    std::fs::create_dir_all(&dir)?;
    let sys = PathBuf::from(system_python()?);
    let d = dir.to_string_lossy().to_string();
    run_logged(&sys, &["-m", "venv", &format!("{d}/venv")], None)?;
    let pip = dir.join("venv/bin/pip");
    let spec = format!("homeassistant=={release}");
    run_logged(
        &pip,
        &[
            "download",
            "--quiet",
            "--no-deps",
            &spec,
            "-d",
            &format!("{d}/wheel"),
        ],
        None,
    )?;
    let wheel = std::fs::read_dir(dir.join("wheel"))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .context("pip downloaded no wheel")?;
    let wheel = wheel.to_string_lossy().to_string();
    let constraints = format!("{d}/constraints.txt");
    // The release's own pins, from inside its wheel.
    run_logged(
        &python,
        &[
            "-c",
            "import sys, zipfile; open(sys.argv[2], 'wb').write(zipfile.ZipFile(sys.argv[1]).read('homeassistant/package_constraints.txt'))",
            &wheel,
            &constraints,
        ],
        None,
    )?;
    run_logged(
        &pip,
        &["install", "--quiet", &wheel, "-c", &constraints],
        None,
    )?;
    let script = root.join("gateway/tests/home_assistant/requirements.py");
    let out = Command::new(&python)
        .arg(&script)
        .args(INTEGRATIONS)
        .output()
        .context("could not list the integrations' requirements")?;
    if !out.status.success() {
        bail!(
            "requirements.py failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let reqs = String::from_utf8(out.stdout)?;
    let mut args = vec!["install", "--quiet"];
    args.extend(reqs.lines().filter(|l| !l.trim().is_empty()));
    args.extend(["-c", &constraints]);
    run_logged(&pip, &args, None)?;
    std::fs::write(&marker, reqs)?;
    eprintln!(
        "Home Assistant {release} installed in {:.0} s",
        t.elapsed().as_secs_f64()
    );
    Ok(python)
}

fn files_of(root: &Path, rel: &str, out: &mut Vec<String>) -> Result<()> {
    let p = root.join(rel);
    if p.is_dir() {
        let mut entries: Vec<_> = std::fs::read_dir(&p)?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect();
        entries.sort();
        for name in entries {
            if name == "__pycache__" || format!("{rel}/{name}") == RECORD {
                continue;
            }
            files_of(root, &format!("{rel}/{name}"), out)?;
        }
    } else if p.is_file() {
        out.push(rel.to_string());
    } else {
        bail!("{rel} does not exist (xtask/src/ha_check.rs INPUTS)");
    }
    Ok(())
}

/// The hash of the inputs: git's blob id of every input file, then of
/// the list of `<blob id> <path>` lines.
pub fn inputs_hash(root: &Path) -> Result<String> {
    let mut files = Vec::new();
    for i in INPUTS {
        files_of(root, i, &mut files)?;
    }
    let out = Command::new("git")
        .arg("hash-object")
        .args(&files)
        .current_dir(root)
        .output()
        .context("could not run git hash-object")?;
    if !out.status.success() {
        bail!(
            "git hash-object failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let blobs = String::from_utf8(out.stdout)?;
    let list: String = blobs
        .lines()
        .zip(&files)
        .map(|(b, f)| format!("{b} {f}\n"))
        .collect();
    let mut child = Command::new("git")
        .args(["hash-object", "--stdin"])
        .current_dir(root)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()?;
    {
        use std::io::Write;
        child
            .stdin
            .take()
            .context("git's stdin")?
            .write_all(list.as_bytes())?;
    }
    let out = child.wait_with_output()?;
    Ok(String::from_utf8(out.stdout)?.trim().to_string())
}

/// The hash in the record (None: no record).
fn recorded_hash(root: &Path) -> Option<String> {
    let text = std::fs::read_to_string(root.join(RECORD)).ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix("inputs: "))
        .map(|h| h.trim().to_string())
}

/// Install what is missing, run the check on every release, record a pass.
pub fn run(root: &Path) -> Result<()> {
    let t_all = Instant::now();
    let mut pythons = Vec::new();
    for r in RELEASES {
        let t = Instant::now();
        pythons.push((r, venv(r, root)?, t.elapsed().as_secs_f64()));
    }
    // Build once (the run below then only starts the test binary).
    crate::shell::run(
        "cargo",
        &[
            "test",
            "-p",
            "fois-gateway",
            "--test",
            "home_assistant",
            "--no-run",
        ],
    )?;
    let reports = root.join("target/ha-check");
    std::fs::create_dir_all(&reports)?;
    let mut record = String::new();
    let mut summary = Vec::new();
    for (release, python, install_s) in &pythons {
        let report = reports.join(format!("{release}.txt"));
        let _ = std::fs::remove_file(&report);
        let t = Instant::now();
        eprintln!("\n=== Home Assistant {release} ===");
        let st = Command::new("cargo")
            .args([
                "test",
                "-p",
                "fois-gateway",
                "--test",
                "home_assistant",
                "--",
                "--ignored",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("FOIS_HA_PYTHON", python)
            .env("FOIS_HA_REPORT", &report)
            .status()
            .context("could not run cargo test")?;
        let run_s = t.elapsed().as_secs_f64();
        if !st.success() {
            bail!("the Home Assistant check failed on {release} ({st}); its output is above");
        }
        let text = std::fs::read_to_string(&report)
            .with_context(|| format!("the check wrote no report for {release}"))?;
        record.push_str(&text);
        record.push('\n');
        summary.push(format!(
            "  Home Assistant {release}: passed in {run_s:.0} s (virtualenv {})",
            if *install_s > 5.0 {
                format!("installed in {install_s:.0} s")
            } else {
                "cached".into()
            }
        ));
    }
    let hash = inputs_hash(root)?;
    let header = format!(
        "# The last pass of `cargo xtask ha-check` (written by it). `cargo xtask ci`\n\
         # runs the check again when the hash of its inputs (xtask/src/ha_check.rs,\n\
         # INPUTS) differs from this one.\n\
         inputs: {hash}\n\
         releases: {}\n\n",
        RELEASES.join(" ")
    );
    std::fs::write(root.join(RECORD), format!("{header}{record}"))?;
    eprintln!("\n=== Home Assistant check ===\n{record}");
    for s in &summary {
        eprintln!("{s}");
    }
    eprintln!(
        "  all releases passed in {:.0} s; recorded in {RECORD} (inputs {hash})",
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}

/// For `cargo xtask ci`: run the check only when its inputs changed since
/// the recorded pass.
pub fn if_changed(root: &Path) -> Result<()> {
    let now = inputs_hash(root)?;
    match recorded_hash(root) {
        Some(h) if h == now => {
            eprintln!(
                "Home Assistant check: its inputs are unchanged since the recorded pass \
                 ({RECORD}, inputs {now}); not run (`cargo xtask ha-check` runs it)"
            );
            Ok(())
        }
        recorded => {
            eprintln!(
                "Home Assistant check: inputs {now}, recorded {}: running it",
                recorded.as_deref().unwrap_or("none")
            );
            run(root)
        }
    }
}
