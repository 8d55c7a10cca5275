//! `foisctl demo`: a virtual node and the monitor in one process.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use super::scene::{DEMO_DEFAULTS, SceneArgs, build_node, describe};
use crate::monitor::{self, MonitorOptions};
use fois_vnode::pty::{self as serve, Pty, ServeOptions};

/// `foisctl demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// The simulated scene.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Also log to this CSV file.
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Print a plain status line each second instead of a redrawn one.
    #[arg(long)]
    pub plain: bool,
}

/// `foisctl demo`: a virtual node and the monitor in one process.
pub fn run(args: DemoArgs, stop: &AtomicBool) -> anyhow::Result<monitor::MonitorSummary> {
    let DemoArgs { scene, log, plain } = args;
    let scene = scene.resolve(DEMO_DEFAULTS)?;
    println!("FOIS demo: {}", describe(&scene));
    println!("ray-tracing the sensor's response ...");
    let t = Instant::now();
    let mut node = build_node(&scene);
    let mut pty = Pty::open()?;
    let path = pty.path().display().to_string();
    println!(
        "virtual node ready in {:.1} s on {path}; monitoring it as a board (Ctrl-C to stop{})",
        t.elapsed().as_secs_f64(),
        scene
            .duration
            .map(|d| format!(", ends after {:.0} s", d.as_secs_f64()))
            .unwrap_or_default()
    );
    let node_stop = Arc::new(AtomicBool::new(false));
    let serve_opts = ServeOptions {
        speed: scene.speed,
        duration: None,
    };
    let ns = node_stop.clone();
    let server = std::thread::spawn(move || {
        let r = serve::serve(&mut node, &mut pty, &serve_opts, &ns);
        (node, r)
    });
    let mut opts = MonitorOptions::new(path);
    opts.log = log;
    opts.plain = plain;
    opts.duration = scene.duration;
    let result = monitor::run(&opts, stop);
    node_stop.store(true, Ordering::Relaxed);
    let (node, served) = server
        .join()
        .map_err(|_| anyhow::anyhow!("the virtual node thread panicked"))?;
    served.context("virtual node")?;
    let sum = result?;
    let t = node.truth();
    println!(
        "virtual time {:.0} s: {} {:.2} mm at {:.1} °C; alarm output {}; {} measurement(s), {} lost, {} rejected, {} ice onset(s){}",
        node.clock().now_s(),
        t.cover.name(),
        t.thickness_mm,
        t.air_temp_c,
        if node.alarm_on() { "ON" } else { "off" },
        sum.measurements,
        sum.lost,
        sum.rejected,
        sum.ice_onsets,
        opts.log
            .as_ref()
            .map(|p| format!("; {} rows in {}", sum.log_rows, p.display()))
            .unwrap_or_default()
    );
    Ok(sum)
}
