//! `foisctl demo`: a virtual node and the monitor in one process.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use super::scene::{DEMO_DEFAULTS, SceneArgs, build_node, describe};
use crate::monitor::{self, MonitorOptions, TruthFn};
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
    /// Also print the protocol's chatter: every answer (`ack ...`) and the
    /// node's full hello (its 24-hex-digit unique id, reset reason).
    #[arg(long)]
    pub verbose: bool,
    /// Do not print the legend of the status lines at the start.
    #[arg(long)]
    pub no_legend: bool,
}

/// `foisctl demo`: a virtual node and the monitor in one process.
pub fn run(args: DemoArgs, stop: &AtomicBool) -> anyhow::Result<monitor::MonitorSummary> {
    let DemoArgs {
        scene,
        log,
        plain,
        verbose,
        no_legend,
    } = args;
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
    let truth = {
        let env = node.env().clone();
        let clock = node.clock().clone();
        TruthFn(Arc::new(move || {
            let t = env.truth(clock.now_ns());
            truth_line(t.cover, t.thickness_mm, t.air_temp_c, t.t_s)
        }))
    };
    let ns = node_stop.clone();
    let server = std::thread::spawn(move || {
        let r = serve::serve(&mut node, &mut pty, &serve_opts, &ns);
        (node, r)
    });
    let mut opts = MonitorOptions::new(path);
    opts.log = log;
    opts.plain = plain;
    opts.verbose = verbose;
    opts.legend = !no_legend;
    opts.truth = Some(truth);
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

/// The demo's "truth" status line: what the simulator has on the face at
/// virtual time `t_s` (the value the node's estimate should approach).
pub fn truth_line(
    cover: fois_vnode::Cover,
    thickness_mm: f64,
    air_temp_c: f64,
    t_s: f64,
) -> String {
    format!(
        "truth {} {thickness_mm:.2} mm, air {air_temp_c:.1} °C  (virtual time {})",
        cover.name(),
        virtual_time(t_s)
    )
}

/// Virtual seconds as `h:mm:ss` (`0:01:05`).
pub fn virtual_time(t_s: f64) -> String {
    let s = t_s.max(0.0) as u64;
    format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_truth_line_names_cover_thickness_and_virtual_time() {
        assert_eq!(
            truth_line(fois_vnode::Cover::Rime, 1.234, -5.0, 3725.9),
            "truth rime 1.23 mm, air -5.0 °C  (virtual time 1:02:05)"
        );
    }
}
