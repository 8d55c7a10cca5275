//! Decoder throughput (frames/s): `cargo bench -p fois-host --bench decode`.
//! The same measurement as `foisctl bench-decode`, under criterion.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fois_host::bench::sample_frame;
use fois_protocol::{DeviceFrame, FrameDecoder, MAX_FRAME, encode_to_vec};

fn decode(c: &mut Criterion) {
    const N: u32 = 10_000;
    let mut stream = Vec::new();
    for seq in 0..N {
        stream.extend(encode_to_vec(&sample_frame(seq)));
    }
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(u64::from(N)));
    g.bench_function("10k measurement frames", |b| {
        b.iter(|| {
            let mut dec = FrameDecoder::<MAX_FRAME>::new();
            let mut n = 0u32;
            for chunk in stream.chunks(4096) {
                dec.feed::<DeviceFrame>(chunk, |r| n += u32::from(r.is_ok()));
            }
            assert_eq!(n, N);
            n
        })
    });
    g.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
