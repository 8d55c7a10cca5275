//! `cargo run --release -p fois-hil --bin hil-report [-- FILE_OR_DIR...]`:
//! run scenarios and print the results table, the goals and notes.
//! Exit code 1 if an asserted expectation fails.

use std::path::PathBuf;
use std::time::Instant;

use fois_hil::{report, run, scenario};

fn main() {
    if let Err(e) = report() {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}

fn report() -> anyhow::Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let paths = if args.is_empty() {
        vec![scenario::default_dir()]
    } else {
        args
    };
    let mut scenarios = Vec::new();
    for p in &paths {
        if p.is_dir() {
            scenarios.extend(scenario::load_dir(p)?);
        } else {
            scenarios.extend(scenario::load(p)?);
        }
    }
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
