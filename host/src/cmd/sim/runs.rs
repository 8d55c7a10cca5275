//! The long runs of the simulator commands, on a worker pool of the asked
//! size and behind a progress bar: many accretions, and the Monte Carlo.

use anyhow::{Context, Result};
use fois_sim::montecarlo::FitQuality;
use fois_sim::{Curve, MonteCarlo, SensorModel, SimConfig, monte_carlo};
use indicatif::{ProgressBar, ProgressStyle};

/// A worker pool of `threads` threads (all cores when `None`).
pub fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        b = b.num_threads(n);
    }
    b.build().context("cannot start worker threads")
}

/// A progress bar of `n` steps labelled `what` (on stderr).
pub fn bar(n: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(n);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(what.to_owned());
    pb
}

/// Trace accretions `0..runs` of `seed`, in parallel, in run order.
pub fn trace_runs(
    cfg: &SimConfig,
    runs: u64,
    seed: u64,
    threads: Option<usize>,
) -> Result<Vec<Curve>> {
    let model = SensorModel::new(cfg);
    let pb = bar(runs, "tracing");
    let pool = pool(threads)?;
    let curves = pool.install(|| {
        use rayon::prelude::*;
        (0..runs)
            .into_par_iter()
            .map(|r| {
                let c = model.accretion(seed, r);
                pb.inc(1);
                c
            })
            .collect()
    });
    pb.finish_and_clear();
    Ok(curves)
}

/// Run a Monte Carlo with a progress bar.
pub fn run_mc(cfg: &SimConfig, runs: u64, seed: u64, threads: Option<usize>) -> Result<MonteCarlo> {
    let pb = bar(runs, "monte carlo");
    let pool = pool(threads)?;
    eprintln!(
        "monte carlo: {runs} accretions on {} threads",
        pool.current_num_threads()
    );
    let inc = || pb.inc(1);
    let mc = pool.install(|| monte_carlo(cfg, runs, seed, &inc));
    pb.finish_and_clear();
    Ok(mc)
}

/// Print how well the local fits follow the Monte Carlo means.
pub fn report_fit(q: &FitQuality, secs: f64, runs: u64) {
    eprintln!(
        "monte carlo + crlb: {runs} accretions in {secs:.2} s; fit of μ(d): RMS residual \
         I1 {:.3} µA, I2 {:.3} µA (standard error of the means {:.3}, {:.3} µA)",
        q.rms_residual_ua[0], q.rms_residual_ua[1], q.rms_std_error_ua[0], q.rms_std_error_ua[1]
    );
}
