//! The firmware's two deterministic figures, as firmware/README.md shows
//! them: the image sizes (`cargo xtask size`) and the instruction counts on
//! the emulated Cortex-M4F (`cargo xtask qemu`). Both follow from the
//! pinned toolchain and `Cargo.lock` (QEMU runs with `-icount shift=0`), so
//! the README's tables are checked against each run ([`crate::generated_docs`]).

use std::path::Path;

use anyhow::{Context, Result, bail};

use crate::generated_docs::{Mode, sync, thousands};

/// The file that holds both tables.
pub const FIRMWARE_README: &str = "firmware/README.md";

/// Flash and static-RAM budgets, bytes (the task's own, passed in).
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    pub flash_bytes: u64,
    pub ram_bytes: u64,
}

/// One measured image: its name, flash bytes, static RAM bytes and budget.
pub type SizeRow<'a> = (&'a str, u64, u64, Budget);

/// The size table: one row per image (the application's link variants,
/// the bootloader), in the order measured, each against its own budget.
pub fn size_table(sizes: &[SizeRow]) -> String {
    let kib = |b: u64| format!("{:.1} KiB", b as f64 / 1024.0);
    let mut out = String::from(
        "| variant | flash | static RAM |\n\
         | --- | ---: | ---: |\n",
    );
    for (variant, flash, ram, budget) in sizes {
        let name = match *variant {
            "bench link" => "bench link (default)".to_string(),
            "bootloader" => "bootloader (`fois-boot`)".to_string(),
            other => format!("`{other}`"),
        };
        out.push_str(&format!(
            "| {name} | {} B ({} of {} KiB) | {} B ({} of {} KiB) |\n",
            thousands(*flash),
            kib(*flash),
            budget.flash_bytes / 1024,
            thousands(*ram),
            kib(*ram),
            budget.ram_bytes / 1024,
        ));
    }
    out
}

/// How far the flash figure may differ from the README's before the table
/// counts as stale, bytes. The image holds the dependencies' source paths
/// (panic locations) under the Cargo home, so a Cargo home at another path
/// than the one the table was written with (`/root/.cargo` here, a user's
/// `~/.cargo` elsewhere) moves the flash figure by a few hundred bytes
/// while nothing of the firmware changed. Static RAM holds no paths and is
/// checked exactly.
pub const FLASH_PATH_TOLERANCE_BYTES: u64 = 1024;

/// Check (or rewrite) the README's size table against `sizes`. In check
/// mode a table whose static RAM figures are exact and whose flash figures
/// are each within [`FLASH_PATH_TOLERANCE_BYTES`] passes, with a note.
pub fn sync_sizes(sizes: &[SizeRow], mode: Mode) -> Result<()> {
    let path = Path::new(FIRMWARE_README);
    if mode == Mode::Check {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let written = block(&text, "size").map(|b| table_sizes(&b));
        if let Some(written) = written
            && written.len() == sizes.len()
            && written
                .iter()
                .zip(sizes)
                .all(|(w, m)| w.1 == m.2 && w.0.abs_diff(m.1) <= FLASH_PATH_TOLERANCE_BYTES)
            && written.iter().zip(sizes).any(|(w, m)| w.0 != m.1)
        {
            eprintln!(
                "{}: the size table's flash figures differ from this build by at most {} B \
                 (the Cargo home's path in the image's panic locations; within {} B): up to date",
                path.display(),
                written
                    .iter()
                    .zip(sizes)
                    .map(|(w, m)| w.0.abs_diff(m.1))
                    .max()
                    .unwrap_or(0),
                FLASH_PATH_TOLERANCE_BYTES
            );
            return Ok(());
        }
    }
    sync(path, "size", "size table", &size_table(sizes), mode)
}

/// The lines between the markers of `task`'s block, if the file has one.
fn block(text: &str, task: &str) -> Option<String> {
    let (begin, end) = crate::generated_docs::markers(task);
    let b = text.find(&begin)? + begin.len();
    let e = text.find(&end)?;
    text.get(b..e).map(str::to_string)
}

/// The (flash, static RAM) bytes of each row of a size table, in order:
/// the two numbers before ` B (` in each row.
fn table_sizes(block: &str) -> Vec<(u64, u64)> {
    block
        .lines()
        .filter_map(|line| {
            let numbers: Vec<u64> = line
                .split(" B (")
                .filter_map(|part| {
                    let cell = part.rsplit('|').next()?;
                    cell.trim().replace(' ', "").parse().ok()
                })
                .collect();
            match numbers[..] {
                [flash, ram] => Some((flash, ram)),
                _ => None,
            }
        })
        .collect()
}

/// What the QEMU image prints about its cost.
#[derive(Debug, Clone, PartialEq)]
pub struct QemuFigures {
    pub tests_passed: u64,
    pub calibration_instructions: u64,
    pub calibration_ticks: u64,
    pub per_frame: u64,
    pub estimator_per_frame: u64,
    pub estimator_per_s: u64,
    pub estimator_budget_per_s: u64,
    pub estimator_worst_per_s: u64,
    /// "226 of 226 states alive in the likeliest of 7 gain hypotheses".
    pub worst_case_states: String,
    /// The bootloader's swap of a 128 KiB image (embassy-boot on RAM flash).
    pub boot_swap: u64,
    /// Its rollback.
    pub boot_rollback: u64,
    /// The firmware update's bench: the image's bytes, the worst chunk
    /// (no page erase), the verify, the signature check alone, the commit.
    pub update_image_bytes: u64,
    pub update_chunk: u64,
    pub update_verify: u64,
    pub update_signature: u64,
    pub update_commit: u64,
}

/// The whole number that follows `marker` in `text` (spaces skipped).
fn number_after(text: &str, marker: &str) -> Result<u64> {
    let at = text
        .find(marker)
        .with_context(|| format!("the QEMU run printed no `{marker}`"))?;
    let digits: String = text[at + marker.len()..]
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits
        .parse()
        .with_context(|| format!("no number after `{marker}` in the QEMU run's output"))
}

/// Read the figures from the QEMU run's standard output.
pub fn parse_qemu(out: &str) -> Result<QemuFigures> {
    let worst_line = out
        .lines()
        .find(|l| l.starts_with("estimator worst case:"))
        .context("the QEMU run printed no `estimator worst case:` line")?;
    let worst_case_states = worst_line
        .split_once('(')
        .and_then(|(_, rest)| rest.split(';').next())
        .map(str::to_string)
        .context("the worst-case line names no states")?;
    let failed = number_after(out, "passed;")?;
    if failed != 0 {
        bail!("{failed} tests failed on the emulated M4F");
    }
    Ok(QemuFigures {
        tests_passed: number_after(out, "test result: ok.")?,
        calibration_instructions: number_after(out, "SysTick calibration:")?,
        calibration_ticks: number_after(out, "instructions in")?,
        per_frame: number_after(out, "instructions per frame:")?,
        estimator_per_frame: number_after(out, "estimator instructions per step:")?,
        estimator_per_s: number_after(out, "one update a second:")?,
        estimator_budget_per_s: number_after(out, "per second of operation, budget")?,
        estimator_worst_per_s: number_after(out, "estimator worst case:")?,
        worst_case_states,
        boot_swap: number_after(out, "bootloader swap of a 128 KiB image:")?,
        boot_rollback: number_after(out, "instructions; rollback:")?,
        update_image_bytes: number_after(out, "update image:")?,
        update_chunk: number_after(out, "update chunk worst (no page erase):")?,
        update_verify: number_after(out, "update verify (SHA-512 and signature):")?,
        update_signature: number_after(out, "update signature check alone:")?,
        update_commit: number_after(out, "update commit (verify_and_mark_updated, state mark):")?,
    })
}

/// Milliseconds of `instructions` at the board's 180 MHz, one instruction
/// a cycle (flash wait states hidden by the ART accelerator), rounded.
fn ms_at_180_mhz(instructions: u64) -> u64 {
    (instructions + 90_000) / 180_000
}

/// The instruction-count table.
pub fn qemu_table(f: &QemuFigures) -> String {
    let budget = thousands(f.estimator_budget_per_s);
    format!(
        "| figure | instructions |\n\
         | --- | ---: |\n\
         | one output frame (default config: K = 8, streaming, the `MeasurementV5` frame encoded, the ice estimator included) | {} |\n\
         | the ice estimator, per 10 Hz frame on average (nine frames gathered, one update of the gain hypotheses a second; rime at 5 mm) | {} |\n\
         | the ice estimator, per second of 10 Hz operation (budget {budget}) | {} |\n\
         | the ice estimator, worst second of 48 ({}; the growth history's parts one a second; budget {budget}) | {} |\n\
         | the bootloader's swap of a 128 KiB image (embassy-boot's `prepare_boot` on RAM flashes of the board's geometry, 2 KiB copy buffer; on the board the flash's erase and programming times dominate) | {} |\n\
         | the bootloader's rollback of that image | {} |\n\
         | SysTick calibration: a loop of known length, instructions in ticks | {} in {} |\n\
         | firmware update, {} B image: the worst 256 B chunk (no page erase) | {} |\n\
         | firmware update: the verify (SHA-512 of the image, the trailer, the ed25519 check; ≈ {} ms at 180 MHz) | {} |\n\
         | firmware update: the ed25519 check alone (salty; ≈ {} ms at 180 MHz) | {} |\n\
         | firmware update: the commit (embassy-boot's `verify_and_mark_updated`, the boot-state mark on a 4 KiB RAM page; ≈ {} ms at 180 MHz) | {} |\n\
         \n\
         The run's tests: {} passed on the emulated M4F.\n",
        thousands(f.per_frame),
        thousands(f.estimator_per_frame),
        thousands(f.estimator_per_s),
        f.worst_case_states,
        thousands(f.estimator_worst_per_s),
        thousands(f.boot_swap),
        thousands(f.boot_rollback),
        thousands(f.calibration_instructions),
        thousands(f.calibration_ticks),
        thousands(f.update_image_bytes),
        thousands(f.update_chunk),
        ms_at_180_mhz(f.update_verify),
        thousands(f.update_verify),
        ms_at_180_mhz(f.update_signature),
        thousands(f.update_signature),
        ms_at_180_mhz(f.update_commit),
        thousands(f.update_commit),
        f.tests_passed,
    )
}

/// Check (or rewrite) the README's instruction-count table against the
/// QEMU run's output.
pub fn sync_qemu(output: &str, mode: Mode) -> Result<()> {
    let figures = parse_qemu(output)?;
    sync(
        Path::new(FIRMWARE_README),
        "qemu",
        "instruction-count table",
        &qemu_table(&figures),
        mode,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The QEMU image's output, as `bash firmware/qemu-test/run.sh` prints it.
    const RUN: &str = "running 8 tests on the emulated Cortex-M4F\n\
        test ntc_and_vref ... ok\n\
        test result: ok. 8 passed; 0 failed\n\
        SysTick calibration: 4000000 instructions in 99999 ticks = 40.0004 instructions per tick\n\
        bootloader swap of a 128 KiB image: 7762680 instructions; rollback: 8549640 instructions (RAM flash, 2 KiB copy buffer)\n\
        measurement loop: K = 8 cycles/frame, 200 and 400 frames, 26131 bytes sent\n\
        instructions per frame: 37770\n\
        \x20 (about 2360 us of CPU per frame at 16 MHz)\n\
        estimator instructions per step: 46911 (mean over 10 Hz frames, one update a second: 469110 per second of operation, budget 600000)\n\
        estimator worst case: 560805 instructions per second of 10 Hz frames (226 of 226 states alive in the likeliest of 7 gain hypotheses; ±1 tick = ±40)\n\
        update image: 92224 B in 256 B chunks\n\
        update chunk worst (no page erase): 6120\n\
        update verify (SHA-512 and signature): 14091742\n\
        update signature check alone: 3790398\n\
        update commit (verify_and_mark_updated, state mark): 18198142\n";

    #[test]
    fn the_size_table_reads_back_its_own_figures() {
        let budget = Budget {
            flash_bytes: 128 * 1024,
            ram_bytes: 32 * 1024,
        };
        let boot = Budget {
            flash_bytes: 24 * 1024,
            ram_bytes: 32 * 1024,
        };
        let sizes = [
            ("field-link", 91_264, 18_384, budget),
            ("bench link", 91_244, 18_388, budget),
            ("bootloader", 4_120, 0, boot),
        ];
        let table = size_table(&sizes);
        assert_eq!(
            table_sizes(&table),
            vec![(91_264, 18_384), (91_244, 18_388), (4_120, 0)]
        );
        let text = format!(
            "before\n<!-- generated by cargo xtask size: begin -->\n{table}\
             <!-- generated by cargo xtask size: end -->\nafter\n"
        );
        assert_eq!(
            block(&text, "size").map(|b| table_sizes(&b)).unwrap().len(),
            3
        );
        assert_eq!(block("no markers", "size"), None);
    }

    #[test]
    fn the_qemu_figures_are_read_from_its_output() {
        let f = parse_qemu(RUN).unwrap();
        assert_eq!(
            f,
            QemuFigures {
                tests_passed: 8,
                calibration_instructions: 4_000_000,
                calibration_ticks: 99_999,
                per_frame: 37_770,
                estimator_per_frame: 46_911,
                estimator_per_s: 469_110,
                estimator_budget_per_s: 600_000,
                estimator_worst_per_s: 560_805,
                worst_case_states: "226 of 226 states alive in the likeliest of 7 gain hypotheses"
                    .into(),
                boot_swap: 7_762_680,
                boot_rollback: 8_549_640,
                update_image_bytes: 92_224,
                update_chunk: 6_120,
                update_verify: 14_091_742,
                update_signature: 3_790_398,
                update_commit: 18_198_142,
            }
        );
        let table = qemu_table(&f);
        assert!(table.contains("| 37 770 |"), "{table}");
        assert!(table.contains("budget 600 000) | 560 805 |"), "{table}");
        assert!(table.contains("| 4 000 000 in 99 999 |"), "{table}");
        assert!(table.contains("2 KiB copy buffer; on the board the flash's erase and programming times dominate) | 7 762 680 |"), "{table}");
        assert!(
            table.contains("rollback of that image | 8 549 640 |"),
            "{table}"
        );
        assert!(
            table.contains("≈ 78 ms at 180 MHz) | 14 091 742 |"),
            "{table}"
        );
    }

    #[test]
    fn a_run_without_a_figure_or_with_a_failed_test_is_refused() {
        let no_frame = RUN.replace("instructions per frame: 37770", "");
        assert!(
            parse_qemu(&no_frame)
                .unwrap_err()
                .to_string()
                .contains("instructions per frame:")
        );
        let failed = RUN.replace("ok. 8 passed; 0 failed", "FAILED. 7 passed; 1 failed");
        assert!(parse_qemu(&failed).is_err());
    }

    #[test]
    fn the_size_table_has_one_row_per_variant() {
        let budget = Budget {
            flash_bytes: 128 * 1024,
            ram_bytes: 32 * 1024,
        };
        let boot = Budget {
            flash_bytes: 24 * 1024,
            ram_bytes: 32 * 1024,
        };
        let table = size_table(&[
            ("field-link", 91_264, 18_384, budget),
            ("bench link", 91_244, 18_388, budget),
            ("bootloader", 4_120, 0, boot),
        ]);
        assert_eq!(
            table,
            "| variant | flash | static RAM |\n\
             | --- | ---: | ---: |\n\
             | `field-link` | 91 264 B (89.1 KiB of 128 KiB) | 18 384 B (18.0 KiB of 32 KiB) |\n\
             | bench link (default) | 91 244 B (89.1 KiB of 128 KiB) | 18 388 B (18.0 KiB of 32 KiB) |\n\
             | bootloader (`fois-boot`) | 4 120 B (4.0 KiB of 24 KiB) | 0 B (0.0 KiB of 32 KiB) |\n"
        );
    }
}
