//! Criterion benchmarks of the ray tracer: one accretion per medium, and the sensor set-up.
//! `foisctl sim bench` reports the same work as ray evaluations per second.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fois_sim::{Geometry, IceKind, SensorKind, SensorModel, SimConfig};
use std::hint::black_box;

fn accretions(c: &mut Criterion) {
    let mut g = c.benchmark_group("accretion");
    for ice in [
        IceKind::Flat,
        IceKind::Water,
        IceKind::Glazed,
        IceKind::Rime,
    ] {
        let cfg = SimConfig::new(ice, SensorKind::B, Geometry::ThesisCh5);
        let model = SensorModel::new(&cfg);
        // Throughput in ray evaluations (rays × thicknesses).
        g.throughput(Throughput::Elements(model.ray_evaluations()));
        let mut run = 0u64;
        g.bench_function(ice.name(), |b| {
            b.iter(|| {
                run += 1;
                black_box(model.accretion(1, run))
            })
        });
    }
    g.finish();
    c.bench_function("sensor_setup", |b| {
        let cfg = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
        b.iter(|| black_box(SensorModel::new(&cfg)))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = accretions
}
criterion_main!(benches);
