//! Criterion benchmark of the thesis Monte Carlo on two threads, the work of
//! `foisctl sim crlb --ice MEDIUM --runs 1000` (without the CSV) for rime, glazed and water.
//!
//! `cargo bench -p fois-sim --bench montecarlo` (about 2 min). Each iteration builds the
//! sensor, traces 1000 accretions on a 2-thread rayon pool, sums μ/Σ and fits the CRLB; the
//! throughput is in ray evaluations (rays × thicknesses × runs).

// A bench that cannot build its thread pool is a failed bench, not a crash in the field.
#![allow(clippy::expect_used)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fois_sim::montecarlo::DEFAULT_FIT_HALF_WIDTH_MM;
use fois_sim::{Geometry, IceKind, SensorKind, SensorModel, SimConfig, crlb, monte_carlo};
use std::hint::black_box;
use std::time::Duration;

const RUNS: u64 = 1000;
const THREADS: usize = 2;

fn montecarlo(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .expect("rayon pool");
    let mut g = c.benchmark_group("montecarlo_2_threads");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(20));
    g.warm_up_time(Duration::from_secs(3));
    for (name, ice) in [
        ("rime_1000_crlb", IceKind::Rime),
        ("glazed_1000_crlb", IceKind::Glazed),
        ("water_1000_crlb", IceKind::Water),
    ] {
        let cfg = SimConfig::new(ice, SensorKind::B, Geometry::ThesisCh5);
        let evals = SensorModel::new(&cfg).ray_evaluations() * RUNS;
        g.throughput(Throughput::Elements(evals));
        g.bench_function(name, |b| {
            b.iter(|| {
                pool.install(|| {
                    let mc = monte_carlo(&cfg, RUNS, 1, &|| {});
                    black_box(crlb(&mc.points, DEFAULT_FIT_HALF_WIDTH_MM));
                    black_box(mc)
                })
            })
        });
    }
    g.finish();
}

criterion_group!(benches, montecarlo);
criterion_main!(benches);
