//! `cargo run --release -p fois-hil-report [-- FILE_OR_DIR...]`: run
//! hardware-in-loop scenarios and print the results table, the goals and
//! notes. Exit code 1 if an asserted expectation fails, 2 for a bad command
//! line or an invalid scenario file.

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use fois_hil::{accuracy, icing_accuracy, report, run, scenario};

/// Run hardware-in-loop scenarios (the firmware's own Node on the virtual
/// hardware, in virtual time) on all cores and print a Markdown table of the
/// results, the goals (met or missed, by how much) and one line of notes per
/// run.
#[derive(Debug, Parser)]
#[command(
    name = "hil-report",
    version,
    after_help = "Exit codes: 0 every expectation met; 1 an asserted expectation failed; \
                  2 bad command line or invalid scenario file."
)]
struct Args {
    /// Scenario files (.toml) and directories of them [default: the
    /// scenarios shipped in hil/scenarios].
    #[arg(value_name = "FILE_OR_DIR")]
    paths: Vec<PathBuf>,
    /// Run every accuracy scenario (`accuracy = true`) on this many seeds,
    /// 101, 102, … (`--accuracy-first-seed`) instead of its file's few: the
    /// report's full accuracy table (0: the files' own seeds, as CI runs
    /// them; 0..=100).
    #[arg(long, value_name = "N", default_value_t = 10,
          value_parser = clap::value_parser!(u64).range(0..=100))]
    accuracy_seeds: u64,
    /// The first of those seeds (the gain scenarios' table uses 231: seeds
    /// no firmware test and no other scenario uses).
    #[arg(long, value_name = "SEED", default_value_t = scenario::ACCURACY_FIRST_SEED)]
    accuracy_first_seed: u64,
    /// Frame period of the accuracy scenarios, ms: the node's default 100
    /// (their files use 1000 to keep CI short; 0: as the files say;
    /// 10..=60000).
    #[arg(long, value_name = "MS", default_value_t = 100,
          value_parser = clap::value_parser!(u32).range(0..=60_000))]
    accuracy_frame_ms: u32,
    /// Accretions of the Monte Carlo behind √CRLB in the accuracy table
    /// (seed 4242; 2..=10000).
    #[arg(long, value_name = "N", default_value_t = 256,
          value_parser = clap::value_parser!(u64).range(2..=10_000))]
    crlb_runs: u64,
}

fn main() {
    let args = Args::parse();
    if let Err(e) = report(args) {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn report(args: Args) -> anyhow::Result<()> {
    let paths = if args.paths.is_empty() {
        vec![scenario::default_dir()]
    } else {
        args.paths
    };
    let mut scenarios = Vec::new();
    for p in &paths {
        if p.is_dir() {
            scenarios.extend(scenario::load_dir(p)?);
        } else {
            scenarios.extend(scenario::load(p)?);
        }
    }
    let frame_ms = match args.accuracy_frame_ms {
        0 => None,
        ms if ms < 10 => anyhow::bail!("--accuracy-frame-ms {ms}: 0 or 10..=60000"),
        ms => Some(ms),
    };
    let seeds = (args.accuracy_seeds > 0).then_some(args.accuracy_seeds);
    let scenarios = scenario::for_accuracy(scenarios, seeds, args.accuracy_first_seed, frame_ms);
    let start = Instant::now();
    let threads = run::default_threads();
    let results = run::run_all(&scenarios, threads);
    let wall = start.elapsed();
    let mut outcomes = Vec::new();
    for (sc, r) in scenarios.iter().zip(results) {
        match r {
            Ok(o) => outcomes.push(o),
            Err(e) => eprintln!("{}: {e:#}", sc.name),
        }
    }
    println!("{}", report::table(&outcomes));
    println!("Goals:\n{}", report::goals_summary(&outcomes));
    println!("Notes:\n{}", report::notes(&outcomes));
    let rows = accuracy::rows(&outcomes);
    if !rows.is_empty() {
        let crlb = accuracy::crlb_rows(args.crlb_runs);
        println!(
            "Ice estimator accuracy (bias / RMS over seeds in mm, mean σ; √CRLB from {} accretions of seed {}):\n{}",
            args.crlb_runs,
            accuracy::CRLB_SEED,
            accuracy::table(&rows, &crlb)
        );
        let icing = icing_accuracy::rows(&outcomes);
        if !icing.is_empty() {
            println!(
                "Icing rate and period (the growth history; rate over the frames after {:.0} min of growth):\n{}",
                icing_accuracy::RATE_AFTER_S / 60.0,
                icing_accuracy::table(&icing)
            );
        }
    }
    let frames: u64 = outcomes.iter().map(|o| o.node_frames).sum();
    let virt: f64 = outcomes.iter().map(|o| o.virtual_s).sum();
    println!(
        "{} runs, {:.1} h virtual, {frames} frames, {:.1} s wall on {threads} threads",
        outcomes.len(),
        virt / 3600.0,
        wall.as_secs_f64()
    );
    let failed = outcomes.iter().filter(|o| !o.failures.is_empty()).count();
    if failed > 0 {
        eprintln!("{failed} scenario(s) failed their expectations");
        std::process::exit(1);
    }
    Ok(())
}
