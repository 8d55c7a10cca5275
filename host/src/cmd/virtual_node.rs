//! `foisctl virtual-node`: the firmware's own logic on simulated hardware,
//! served on a pseudo-terminal.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::Context;
use clap::Args;

use super::scene::{SceneArgs, VIRTUAL_NODE_DEFAULTS, build_node_with_state, describe};
use fois_vnode::pty::{self as serve, Pty, ServeOptions};

/// `foisctl virtual-node`.
#[derive(Debug, Args)]
pub struct VirtualNodeArgs {
    /// The simulated scene.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Also create this symlink to the pty: a stable name across restarts
    /// (e.g. /tmp/fois-node), so a monitor reconnects after a restart.
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Keep the node's flash record (config, dark baseline) in this file,
    /// so it survives a restart of the virtual node as it survives a power
    /// cycle on a board [default: RAM only].
    #[arg(long, value_name = "FILE")]
    pub state: Option<PathBuf>,
}

/// `foisctl virtual-node`.
pub fn run(args: VirtualNodeArgs, stop: &AtomicBool) -> anyhow::Result<()> {
    let VirtualNodeArgs { scene, link, state } = args;
    let scene = scene.resolve(VIRTUAL_NODE_DEFAULTS)?;
    if let Some(p) = &state {
        fois_vnode::SharedStorage::with_file(p)
            .with_context(|| format!("cannot read the node state {}", p.display()))?;
    }
    let mut node = build_node_with_state(&scene, state);
    let mut pty = Pty::open()?;
    let _guard = match &link {
        Some(l) => Some(serve::make_link(l, pty.path())?),
        None => None,
    };
    println!("{}", pty.path().display());
    eprintln!(
        "virtual node on {}{}: {}\nconnect with: foisctl monitor --port {}   (Ctrl-C stops the node)",
        pty.path().display(),
        link.as_ref()
            .map(|l| format!(" (also {})", l.display()))
            .unwrap_or_default(),
        describe(&scene),
        pty.path().display()
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let opts = ServeOptions {
        speed: scene.speed,
        duration: scene.duration,
    };
    let stats = serve::serve(&mut node, &mut pty, &opts, stop)?;
    eprintln!(
        "virtual node stopped at virtual t = {:.1} s: {} frames run, {} sent, {} dropped (no reader)",
        node.clock().now_s(),
        node.frames(),
        stats.frames_sent,
        stats.frames_dropped
    );
    Ok(())
}
