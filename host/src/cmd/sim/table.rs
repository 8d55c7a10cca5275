//! `foisctl sim table`: the node estimator's response table (`fois_sim::table`)
//! as the Rust source the firmware embeds.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use fois_sim::table::{REGENERATE, TableSpec, build_table, to_rust_source};

use super::runs::{bar, pool};
use crate::cmd::args::threads;

/// `foisctl sim table`.
#[derive(Debug, Args)]
pub struct TableArgs {
    /// Where to write the table: the firmware's `src/estimator/table.rs`
    /// (the default path is relative to the repository root). The file is
    /// replaced only when the table is complete.
    #[arg(
        long,
        value_name = "FILE.rs",
        default_value = "firmware/src/estimator/table.rs"
    )]
    pub out: PathBuf,
    /// Worker threads (>= 1; default: all cores). The table does not depend on it.
    #[arg(long, value_parser = threads)]
    pub threads: Option<usize>,
}

/// Run `foisctl sim table`.
pub fn run(args: TableArgs) -> Result<()> {
    let dir = match args.out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    anyhow::ensure!(
        dir.is_dir(),
        "{} does not exist: run from the repository root or give --out",
        dir.display()
    );
    let spec = TableSpec::default();
    let pb = bar(spec.total_runs(), "response table");
    let done = AtomicU64::new(0);
    let t0 = Instant::now();
    let table = pool(args.threads)?.install(|| {
        build_table(&spec, &|| {
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            pb.set_position(n);
        })
    })?;
    pb.finish_and_clear();
    let src = to_rust_source(&table, REGENERATE)?;
    let mut tmp = args.out.clone().into_os_string();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, &src).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, &args.out)
        .with_context(|| format!("cannot move {} to {}", tmp.display(), args.out.display()))?;
    println!(
        "response table version {}: {} media × {} rows, seed {}, {} accretions in {:.1} s; \
         written to {}",
        spec.version,
        table.media.len(),
        table.media.first().map_or(0, |m| m.rows.len()),
        spec.seed,
        spec.total_runs(),
        t0.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}
