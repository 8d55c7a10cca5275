//! The icing report's rows/s on one synthetic day at 1 Hz (86 400 rows,
//! an icing day): `cargo bench -p fois-host --bench icing_report`. The
//! year (31.5 M rows) is `foisctl icing-report --bench`, too long for
//! criterion's repetitions.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fois_host::icing::events::Thresholds;
use fois_host::icing::input::LogSamples;
use fois_host::icing::report::analyse_sources;
use fois_host::icing::synthetic::synthetic_bytes;

fn icing_report(c: &mut Criterion) {
    let day = synthetic_bytes(1, 1, 1, true);
    let mut g = c.benchmark_group("icing_report");
    g.throughput(Throughput::Elements(86_400));
    g.bench_function("one day at 1 Hz", |b| {
        b.iter(|| {
            let src = LogSamples::from_reader(
                "day",
                Box::new(std::io::Cursor::new(day.clone())),
                Path::new("day"),
            );
            let r = analyse_sources([src], Thresholds::default()).map(|r| r.events.len());
            assert_eq!(r.ok(), Some(1));
        })
    });
    g.finish();
}

criterion_group!(benches, icing_report);
criterion_main!(benches);
