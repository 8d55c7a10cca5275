//! `foisctl sim bench`: ray evaluations per second for rime, glazed and
//! water, thesis-ch5, on one thread and on all.

use std::time::Instant;

use anyhow::{Result, bail};
use clap::Args;
use fois_sim::{Geometry, IceKind, SensorKind, SensorModel, SimConfig};

use super::runs::{bar, pool};
use crate::cmd::args::{IceArg, threads};

/// `foisctl sim bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Accretions per measurement (>= 1).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Worker threads for the parallel measurement (>= 1; default: all cores).
    #[arg(long, value_parser = threads)]
    pub threads: Option<usize>,
    /// Only this medium (default: rime, glazed and water).
    #[arg(long, value_enum)]
    pub ice: Option<IceArg>,
}

/// The media `foisctl sim bench` measures by default: those of the response table.
const MEDIA: [IceKind; 3] = [IceKind::Rime, IceKind::Glazed, IceKind::Water];

/// Run `foisctl sim bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let BenchArgs { runs, threads, ice } = args;
    let media: Vec<IceKind> = match ice {
        Some(i) => vec![i.into()],
        None => MEDIA.to_vec(),
    };
    let one = pool(Some(1))?;
    let all = pool(threads)?;
    let n = all.current_num_threads();
    println!(
        "vector kernels: {} (of avx512, avx2, baseline: the best this CPU runs unless FOIS_SIM_ISA caps it)",
        fois_sim::isa().name()
    );
    for ice in media {
        let cfg = SimConfig::new(ice, SensorKind::B, Geometry::ThesisCh5);
        let model = SensorModel::new(&cfg);
        let evals = model.ray_evaluations() as f64;
        println!(
            "{} ice, thesis-ch5: {} rays × {} thicknesses = {} ray evaluations per accretion",
            ice.name(),
            model.n_rays(),
            cfg.thicknesses_mm().len(),
            evals
        );
        // One thread, then all of them.
        let (t1, sink) = time_accretions(&model, runs, &one, "1 thread")?;
        let single = evals * runs as f64 / t1;
        println!(
            "  1 thread:  {:.3e} ray evaluations/s ({:.2} ms per accretion)",
            single,
            1e3 * t1 / runs as f64
        );
        let (tp, par) = time_accretions(&model, runs, &all, "all threads")?;
        let total = evals * runs as f64 / tp;
        println!(
            "  {n} threads: {:.3e} ray evaluations/s total, {:.3e} per thread",
            total,
            total / n as f64
        );
        println!(
            "  estimated thesis Monte Carlo (1000 accretions): {:.2} s",
            1000.0 * evals / total
        );
        if !(sink.is_finite() && par.is_finite()) {
            bail!("non-finite currents");
        }
    }
    Ok(())
}

/// Trace accretions `0..runs` of seed 7 on `pool` behind a progress bar:
/// (wall seconds, the sum of the last I1 of each, so nothing is optimised away).
fn time_accretions(
    model: &SensorModel,
    runs: u64,
    pool: &rayon::ThreadPool,
    what: &str,
) -> Result<(f64, f64)> {
    let pb = bar(runs, what);
    let t0 = Instant::now();
    let sum: f64 = pool.install(|| {
        use rayon::prelude::*;
        (0..runs)
            .into_par_iter()
            .map(|r| {
                let v = model.accretion(7, r).points.last().map_or(0.0, |p| p.i1_ua);
                pb.inc(1);
                v
            })
            .sum()
    });
    let secs = t0.elapsed().as_secs_f64();
    pb.finish_and_clear();
    Ok((secs, sum))
}
