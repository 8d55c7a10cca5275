//! `foisctl bench-decode`: the host decoder's throughput.

use clap::Args;

/// `foisctl bench-decode`.
#[derive(Debug, Args)]
pub struct BenchDecodeArgs {
    /// Frames in the stream (>= 1).
    #[arg(long, default_value_t = 1_000_000, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
}

/// Run `foisctl bench-decode`.
pub fn run(args: BenchDecodeArgs) -> anyhow::Result<()> {
    let r = crate::bench::decode_throughput(args.frames);
    println!(
        "decoded {} frames ({} bytes) in {:.3} s: {:.0} frames/s, {:.1} MB/s",
        r.frames,
        r.bytes,
        r.seconds,
        r.frames_per_s(),
        r.bytes as f64 / r.seconds / 1e6
    );
    Ok(())
}
