//! `cargo xtask`: the project's task runner.
//!
//! - `cargo xtask ci`   — every check the README promises, in order: the
//!   system tools the tests need (installed if missing, before anything is
//!   compiled: [`tools`]; with the gateway Modbus tests' pymodbus
//!   virtualenv), format, the crate rules of ARCHITECTURE.md
//!   ([`crates`]), the module rule: no import circles between a crate's
//!   files ([`modules`]), clippy (host crates, and the firmware on its thumb
//!   target), the whole test suite, the firmware's release cross-build with
//!   its size budget, the firmware logic on an emulated Cortex-M4F (both
//!   with firmware/README.md's tables of their figures checked), the
//!   fuzz crates' build, the gateway's Debian package ([`package`]), and
//!   the Home Assistant check when its inputs changed since its recorded
//!   pass ([`ha_check`]).
//! - `cargo xtask tools` — only the system tools (and the pymodbus
//!   virtualenv `target/pymodbus-venv`).
//! - `cargo xtask crates` — only the crate rules.
//! - `cargo xtask modules [--graph]` — only the module rule: every crate's
//!   files form no import circle (a list of known ones is tolerated for
//!   now); `--graph`: print each file and the files it imports first.
//! - `cargo xtask deb` — build the gateway's Debian package and check it.
//! - `cargo xtask ha-check [--if-changed]` — the gateway's Home Assistant
//!   discovery checked by real Home Assistant releases (installed into
//!   cached virtualenvs); `--if-changed`: only when its inputs changed since
//!   the recorded pass (what `ci` runs).
//! - `cargo xtask size [--write]` — cross-build the firmware's two link
//!   variants (the ST-LINK's virtual COM port; `field-link`: RS-485 on
//!   USART6) and the bootloader (`fois-boot`), lint the field one on thumb,
//!   check each against its size budget (application 128 KiB, bootloader
//!   24 KiB) and firmware/README.md's size table against them (stale:
//!   fails; `--write`: rewrites it; [`generated_docs`]).
//! - `cargo xtask image [--features field-link]` — cross-build the
//!   application and write its raw binary `fois-node.bin` next to the ELF
//!   (llvm-objcopy): the input of `foisctl sign`.
//! - `cargo xtask qemu [--write]` — run the firmware logic under
//!   qemu-system-arm, and check (or with `--write` rewrite)
//!   firmware/README.md's table of its instruction counts.
//! - `cargo xtask fuzz [--runs N] [--target NAME]` — every cargo-fuzz target
//!   (or one) for N executions (default 10⁷), installing the nightly
//!   toolchain and cargo-fuzz if missing.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};

mod crates;
mod generated_docs;
mod ha_check;
mod measured;
mod modules;
mod package;
mod shell;
mod tools;

use generated_docs::Mode;
use shell::{have, run, run_in};

/// Flash budget of the firmware image (the project's goal for a small MCU).
const FLASH_BUDGET_BYTES: u64 = 128 * 1024;
/// Static RAM budget (.data + .bss; the stack comes on top, flip-link places it below).
const RAM_BUDGET_BYTES: u64 = 32 * 1024;
/// Both, for the size table.
const BUDGET: measured::Budget = measured::Budget {
    flash_bytes: FLASH_BUDGET_BYTES,
    ram_bytes: RAM_BUDGET_BYTES,
};
/// Flash budget of the bootloader (`fois-boot`, sectors 0–1: 32 KiB, a
/// quarter kept free); the same number as firmware/src/platform/
/// flash_layout.rs's `BOOTLOADER_BUDGET_BYTES` (checked by a test here).
const BOOT_FLASH_BUDGET_BYTES: u64 = 24 * 1024;
/// The bootloader's budgets, for the size table (RAM: the same 32 KiB).
const BOOT_BUDGET: measured::Budget = measured::Budget {
    flash_bytes: BOOT_FLASH_BUDGET_BYTES,
    ram_bytes: RAM_BUDGET_BYTES,
};
const THUMB: &str = "thumbv7em-none-eabihf";
/// The cargo-fuzz crates (each its own workspace) and their targets.
const FUZZ_TARGETS: [(&str, &str); 4] = [
    ("protocol/fuzz", "decode"),
    ("firmware/fuzz", "node_commands"),
    ("firmware/fuzz", "modbus_rtu"),
    ("host/fuzz", "link_reader"),
];
/// Executions per fuzz target by default.
const FUZZ_RUNS: u64 = 10_000_000;
/// Longest input, bytes: a frame is at most 63 bytes, so 512 hold several
/// commands, chunk boundaries and garbage, and keep each run short (with
/// ASan the node target did ~2 800 runs/s at this length, 1 200 at
/// libFuzzer's 4 096).
const FUZZ_MAX_LEN: &str = "-max_len=512";

fn main() -> Result<()> {
    let task = std::env::args().nth(1).unwrap_or_else(|| "help".into());
    let root = project_root();
    std::env::set_current_dir(&root)?;
    match task.as_str() {
        "ci" => ci(),
        "tools" => tools::ensure(&root),
        "crates" => crates::check(&root),
        "modules" => match std::env::args().nth(2).as_deref() {
            None => modules::check(&root, false),
            Some("--graph") => modules::check(&root, true),
            Some(other) => bail!("usage: cargo xtask modules [--graph] (not `{other}`)"),
        },
        "deb" => package::build().and_then(|deb| package::check(&deb)),
        "ha-check" => match std::env::args().nth(2).as_deref() {
            None => ha_check::run(&root),
            Some("--if-changed") => ha_check::if_changed(&root),
            Some(other) => bail!("usage: cargo xtask ha-check [--if-changed] (not `{other}`)"),
        },
        "size" => {
            let mode = Mode::from_args("size", &std::env::args().skip(2).collect::<Vec<_>>())?;
            let sizes = firmware_variants()?;
            measured::sync_sizes(&sizes, mode)
        }
        "image" => image(&std::env::args().skip(2).collect::<Vec<_>>()),
        "qemu" => qemu(
            true,
            Mode::from_args("qemu", &std::env::args().skip(2).collect::<Vec<_>>())?,
        ),
        "fuzz" => fuzz(&std::env::args().skip(2).collect::<Vec<_>>()),
        _ => {
            eprintln!(
                "usage: cargo xtask <task>\n\n\
                 tasks:\n  \
                 ci     system tools, format, crate rules, module rule, clippy (host + thumb), tests, firmware size\n         \
                 budget and QEMU run (each with its firmware/README.md table checked), fuzz crates build,\n         \
                 the gateway's Debian package, the Home Assistant check when its inputs changed since its\n         \
                 recorded pass\n  \
                 tools  install the system tools the tests need (mosquitto, qemu-system-arm, systemd, python3)\n         and the gateway Modbus tests' pymodbus virtualenv (target/pymodbus-venv)\n  \
                 crates check the crate rules of ARCHITECTURE.md on the dependency graph\n  \
                 modules [--graph]  check that no two files of a crate import each other (directly or around\n         \
                 a loop); --graph: print each file and the files it imports first\n  \
                 deb    build the gateway's Debian package and check its files, config and unit\n  \
                 ha-check [--if-changed]  the gateway's Home Assistant discovery checked by Home Assistant\n         \
                 2024.1.6 and 2024.3.3 (installed into virtualenvs under ~/.cache/fois/home-assistant);\n         \
                 records a pass; --if-changed: only when its inputs changed since the recorded pass\n  \
                 size [--write]  cross-build both firmware link variants and the bootloader (release), check\n         \
                 flash <= 128 KiB (bootloader 24 KiB), RAM <= 32 KiB and firmware/README.md's size table;\n         \
                 --write: rewrite the table\n  \
                 image [--features field-link]  cross-build the application and write its raw binary\n         \
                 target/thumbv7em-none-eabihf/firmware/fois-node.bin (the input of `foisctl sign`)\n  \
                 qemu [--write]  run the firmware logic tests on qemu-system-arm (mps2-an386), check\n         \
                 firmware/README.md's instruction-count table; --write: rewrite the table\n  \
                 fuzz   [--runs N] [--target NAME] run every fuzz target (or one) N times (default 10^7; installs nightly + cargo-fuzz)"
            );
            if task == "help" || task == "--help" {
                Ok(())
            } else {
                bail!("unknown task `{task}`")
            }
        }
    }
}

fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn ci() -> Result<()> {
    let started = Instant::now();
    let mut steps: Vec<(String, f64)> = Vec::new();
    let mut step = |name: &str, f: &mut dyn FnMut() -> Result<()>| -> Result<()> {
        let t = Instant::now();
        eprintln!("\n=== {name} ===");
        f().with_context(|| format!("CI step `{name}` failed"))?;
        steps.push((name.to_string(), t.elapsed().as_secs_f64()));
        Ok(())
    };

    // Before anything is compiled: a missing broker must not cost minutes
    // of building first.
    step("system tools", &mut || tools::ensure(&project_root()))?;
    step("cargo tools", &mut || {
        // The firmware links through flip-link (stack overflow protection).
        if !have("flip-link") {
            run("cargo", &["install", "flip-link", "--locked"])?;
        }
        Ok(())
    })?;
    step("format", &mut || {
        run("cargo", &["fmt", "--all", "--", "--check"])
    })?;
    let root = project_root();
    step("crate rules", &mut || crates::check(&root))?;
    step("module rule (no import circles)", &mut || {
        modules::check(&root, false)
    })?;
    step("clippy (host)", &mut || {
        run(
            "cargo",
            &[
                "clippy",
                "--workspace",
                "--all-targets",
                "--",
                "-D",
                "warnings",
            ],
        )
    })?;
    step("clippy (firmware and bootloader, thumb)", &mut || {
        run("cargo", &["fw-clippy", "--", "-D", "warnings"])?;
        run("cargo", &["boot-clippy", "--", "-D", "warnings"])
    })?;
    step("tests", &mut || run("cargo", &["test", "--workspace"]))?;
    let mut sizes = Vec::new();
    step(
        "firmware size (both link variants, bootloader)",
        &mut || {
            sizes = firmware_variants()?;
            measured::sync_sizes(&sizes, Mode::Check)
        },
    )?;
    step("firmware on emulated Cortex-M4F", &mut || {
        qemu(true, Mode::Check)
    })?;
    step("fuzz targets build", &mut || {
        // The fuzz crates are their own workspaces (cargo-fuzz runs them on
        // nightly); libfuzzer-sys builds on the pinned toolchain, so CI
        // checks that they still compile against today's APIs.
        let mut checked: Vec<&str> = Vec::new();
        for (dir, _) in FUZZ_TARGETS {
            if checked.contains(&dir) {
                continue; // a crate with two targets is checked once
            }
            checked.push(dir);
            let manifest = format!("{dir}/Cargo.toml");
            run("cargo", &["check", "--manifest-path", &manifest, "--bins"])?;
        }
        Ok(())
    })?;
    step("gateway Debian package", &mut || {
        let deb = package::build()?;
        package::check(&deb)
    })?;
    // Minutes and a download of Home Assistant: only when the discovery
    // code, the payloads or the check changed since the recorded pass.
    step("Home Assistant check (if changed)", &mut || {
        ha_check::if_changed(&root)
    })?;

    eprintln!("\n=== summary ===");
    for (name, secs) in &steps {
        eprintln!("  {name:<34} {secs:>7.1} s");
    }
    for (variant, flash, ram, budget) in &sizes {
        let (flash, ram) = (*flash, *ram);
        eprintln!(
            "  firmware image ({variant}): flash {flash} B ({:.1} KiB of {} KiB), static RAM {ram} B ({:.1} KiB of {} KiB)",
            flash as f64 / 1024.0,
            budget.flash_bytes / 1024,
            ram as f64 / 1024.0,
            budget.ram_bytes / 1024
        );
    }
    eprintln!(
        "  total {:.1} s: all checks passed",
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The board image's link variants: name and extra cargo arguments. The
/// bench image (the default features) comes last, so the image left in
/// `target/` is the default one.
const FIRMWARE_VARIANTS: [(&str, &[&str]); 2] = [
    ("field-link", &["--features", "field-link"]),
    ("bench link", &[]),
];

/// Both link variants of the board image and the bootloader: the field
/// link linted on its thumb target (the bench image and the bootloader are
/// linted by `cargo fw-clippy` and `cargo boot-clippy` in CI's clippy step),
/// each cross-built and checked against its size budget. Returns (image,
/// flash bytes, static RAM bytes, budget) per image.
fn firmware_variants() -> Result<Vec<measured::SizeRow<'static>>> {
    let mut sizes = Vec::new();
    for (variant, args) in FIRMWARE_VARIANTS {
        if !args.is_empty() {
            let mut clippy = vec!["fw-clippy"];
            clippy.extend_from_slice(args);
            clippy.extend_from_slice(&["--", "-D", "warnings"]);
            run("cargo", &clippy)?;
        }
        let mut fw = vec!["fw"];
        fw.extend_from_slice(args);
        let (flash, ram) = image_size(&fw, "fois-node", BUDGET)
            .with_context(|| format!("firmware image ({variant})"))?;
        sizes.push((variant, flash, ram, BUDGET));
    }
    let (flash, ram) =
        image_size(&["boot"], "fois-boot", BOOT_BUDGET).context("bootloader image")?;
    sizes.push(("bootloader", flash, ram, BOOT_BUDGET));
    Ok(sizes)
}

/// A tool of the llvm-tools component (`llvm-size`, `llvm-objcopy`).
fn llvm_tool(name: &str) -> Result<PathBuf> {
    let sysroot = String::from_utf8(
        Command::new("rustc")
            .args(["--print", "sysroot"])
            .output()?
            .stdout,
    )?;
    let host = host_triple()?;
    Ok(PathBuf::from(sysroot.trim())
        .join("lib/rustlib")
        .join(host)
        .join("bin")
        .join(name))
}

/// The ELF `cargo fw` / `cargo boot` leave for `bin`.
fn elf_of(bin: &str) -> PathBuf {
    PathBuf::from(format!("target/{THUMB}/firmware/{bin}"))
}

/// Cross-build an image (`cargo` with `cargo_args`, e.g. `fw --features
/// field-link`) and check its ELF (`bin`) against `budget`. Returns (flash
/// bytes, static RAM bytes).
fn image_size(cargo_args: &[&str], bin: &str, budget: measured::Budget) -> Result<(u64, u64)> {
    run("cargo", cargo_args)?;
    let elf = elf_of(bin);
    let size_tool = llvm_tool("llvm-size")?;
    let out = Command::new(&size_tool)
        .args(["-A", "-d"])
        .arg(&elf)
        .output()
        .with_context(|| {
            format!(
                "could not run {} (rustup component llvm-tools)",
                size_tool.display()
            )
        })?;
    if !out.status.success() {
        bail!("llvm-size failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let (flash, ram) = parse_sizes(&String::from_utf8(out.stdout)?);
    println!(
        "image {}: flash {flash} B ({:.1} KiB, budget {} KiB), static RAM {ram} B ({:.1} KiB, budget {} KiB)",
        elf.display(),
        flash as f64 / 1024.0,
        budget.flash_bytes / 1024,
        ram as f64 / 1024.0,
        budget.ram_bytes / 1024
    );
    if flash > budget.flash_bytes {
        bail!(
            "flash {flash} B is over the budget of {} B",
            budget.flash_bytes
        );
    }
    if ram > budget.ram_bytes {
        bail!(
            "static RAM {ram} B is over the budget of {} B",
            budget.ram_bytes
        );
    }
    Ok((flash, ram))
}

/// `cargo xtask image [--features field-link]`: cross-build the application
/// and write its raw binary (what the active slot holds from 0x0802_0000,
/// `llvm-objcopy -O binary`) next to the ELF as `fois-node.bin`: the input
/// of `foisctl sign`.
fn image(args: &[String]) -> Result<()> {
    let mut fw = vec!["fw"];
    match args {
        [] => {}
        [flag, features] if flag == "--features" => {
            fw.extend_from_slice(&["--features", features.as_str()]);
        }
        _ => bail!("usage: cargo xtask image [--features field-link]"),
    }
    let (flash, _) = image_size(&fw, "fois-node", BUDGET)?;
    let elf = elf_of("fois-node");
    let bin = elf.with_extension("bin");
    let objcopy = llvm_tool("llvm-objcopy")?;
    let status = Command::new(&objcopy)
        .args(["-O", "binary"])
        .arg(&elf)
        .arg(&bin)
        .status()
        .with_context(|| {
            format!(
                "could not run {} (rustup component llvm-tools)",
                objcopy.display()
            )
        })?;
    if !status.success() {
        bail!("llvm-objcopy failed ({status})");
    }
    let written = std::fs::metadata(&bin)?.len();
    // The raw binary spans the programmed sections from the vector table on.
    if written < flash || written > BUDGET.flash_bytes {
        bail!(
            "{} is {written} B: expected between the image's {flash} B and the slot's {} B",
            bin.display(),
            BUDGET.flash_bytes
        );
    }
    println!("{}: {written} B (for `foisctl sign`)", bin.display());
    Ok(())
}

/// Flash = what is programmed (vector table, code, read-only data, the
/// initial values of .data); RAM = .data + .bss + .uninit.
fn parse_sizes(llvm_size_a: &str) -> (u64, u64) {
    let mut flash = 0;
    let mut ram = 0;
    for line in llvm_size_a.lines() {
        let mut cols = line.split_whitespace();
        let (Some(name), Some(size)) = (cols.next(), cols.next()) else {
            continue;
        };
        let Ok(size) = size.parse::<u64>() else {
            continue;
        };
        match name {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => {
                flash += size;
                ram += size;
            }
            ".bss" | ".uninit" => ram += size,
            _ => {}
        }
    }
    (flash, ram)
}

fn host_triple() -> Result<String> {
    let out = Command::new("rustc").arg("-vV").output()?;
    let text = String::from_utf8(out.stdout)?;
    text.lines()
        .find_map(|l| l.strip_prefix("host: "))
        .map(str::to_string)
        .context("rustc -vV printed no host triple")
}

/// `cargo xtask fuzz [--runs N] [--target NAME]`: each target (or the one
/// named) for N executions (libFuzzer's `-runs`), one after the other; any
/// crash fails (its input is left in the crate's `artifacts/`).
fn fuzz(args: &[String]) -> Result<()> {
    const USAGE: &str = "usage: cargo xtask fuzz [--runs N] [--target NAME]";
    let mut runs = FUZZ_RUNS;
    let mut only: Option<&str> = None;
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let Some(value) = it.next() else {
            bail!("{USAGE}");
        };
        match flag.as_str() {
            "--runs" => {
                runs = value
                    .parse::<u64>()
                    .with_context(|| format!("--runs takes a whole number, not `{value}`"))?;
            }
            "--target" => {
                if !FUZZ_TARGETS.iter().any(|(_, t)| t == value) {
                    let names: Vec<&str> = FUZZ_TARGETS.iter().map(|(_, t)| *t).collect();
                    bail!("no fuzz target `{value}` (there are: {})", names.join(", "));
                }
                only = Some(value.as_str());
            }
            _ => bail!("{USAGE}"),
        }
    }
    let nightly = Command::new("rustup")
        .args(["run", "nightly", "rustc", "--version"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !nightly {
        run(
            "rustup",
            &["toolchain", "install", "nightly", "--profile", "minimal"],
        )?;
    }
    if !have("cargo-fuzz") {
        run("cargo", &["install", "cargo-fuzz", "--locked"])?;
    }
    let runs_arg = format!("-runs={runs}");
    for (dir, target) in FUZZ_TARGETS {
        if only.is_some_and(|o| o != target) {
            continue;
        }
        let t = Instant::now();
        run_in(
            dir,
            "cargo",
            &[
                "+nightly",
                "fuzz",
                "run",
                // No AddressSanitizer: the targets are safe Rust, what they
                // hunt is panics and broken assertions, and ASan costs a
                // factor 7 (node target: 1 200 vs 9 000–16 000 runs/s here).
                "--sanitizer",
                "none",
                target,
                "--",
                &runs_arg,
                FUZZ_MAX_LEN,
                "-print_final_stats=1",
            ],
        )?;
        eprintln!(
            "fuzz {dir} {target}: {runs} executions, no crash ({:.0} s)",
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// Run the firmware's hardware-free logic on qemu-system-arm (mps2-an386),
/// then check (or rewrite) firmware/README.md's instruction counts with
/// what it printed. `cargo xtask ci` installs QEMU first ([`tools`]);
/// without it this fails.
fn qemu(required: bool, mode: Mode) -> Result<()> {
    let script = Path::new("firmware/qemu-test/run.sh");
    if !script.exists() {
        eprintln!("skipped: {} does not exist yet", script.display());
        return Ok(());
    }
    if !have("qemu-system-arm") {
        if required {
            bail!("qemu-system-arm is not installed (apt-get install qemu-system-arm)");
        }
        eprintln!("skipped: qemu-system-arm is not installed (apt-get install qemu-system-arm)");
        return Ok(());
    }
    let output = run_echoed("bash", &[&script.to_string_lossy()])?;
    measured::sync_qemu(&output, mode)
}

/// Run a command, its standard output shown as it comes and returned;
/// failing on a non-zero exit.
fn run_echoed(program: &str, args: &[&str]) -> Result<String> {
    use std::io::{BufRead, BufReader, Write};
    eprintln!("\n$ {program} {}", args.join(" "));
    let mut child = Command::new(program)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .with_context(|| format!("could not start `{program}`"))?;
    let mut text = String::new();
    if let Some(out) = child.stdout.take() {
        let mut stdout = std::io::stdout();
        for line in BufReader::new(out).lines() {
            let line = line?;
            writeln!(stdout, "{line}")?;
            text.push_str(&line);
            text.push('\n');
        }
    }
    let status = child.wait()?;
    if !status.success() {
        bail!("`{program} {}` failed ({status})", args.join(" "));
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::{BOOT_FLASH_BUDGET_BYTES, parse_sizes, project_root};

    /// xtask depends on no FOIS crate: the bootloader's budget is checked
    /// against the firmware's flash layout by its text.
    #[test]
    fn the_bootloader_budget_is_the_flash_layouts() {
        let layout =
            std::fs::read_to_string(project_root().join("firmware/src/platform/flash_layout.rs"))
                .unwrap();
        assert_eq!(BOOT_FLASH_BUDGET_BYTES, 24 * 1024);
        assert!(
            layout.contains("pub const BOOTLOADER_BUDGET_BYTES: u32 = 24 * 1024;"),
            "flash_layout.rs changed the bootloader's budget: change xtask's too"
        );
    }

    #[test]
    fn sizes_from_llvm_size_output() {
        let text = "fois-node  :\nsection              size        addr\n\
                    .vector_table         408   134217728\n.text               20000   134218136\n\
                    .rodata               3000   134238136\n.data                  56   536870912\n\
                    .gnu.sgstubs             0   134241200\n.bss                  1200   536870968\n\
                    .uninit               1024   536872168\n.defmt                  12           0\n\
                    .debug_info         90000           0\nTotal              115700\n";
        assert_eq!(
            parse_sizes(text),
            (408 + 20_000 + 3_000 + 56, 56 + 1_200 + 1_024)
        );
    }
}
