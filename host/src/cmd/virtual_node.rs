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
    /// Speak Modbus RTU on the pty (the node's link settings set so at
    /// start, as `foisctl modbus enable` does on a board), serving the
    /// register map of `fois_protocol::registers` with the firmware's own
    /// RTU code.
    #[arg(long)]
    pub modbus_rtu: bool,
    /// The Modbus address with --modbus-rtu (1–247).
    #[arg(long, value_name = "N", default_value_t = 1, requires = "modbus_rtu",
          value_parser = clap::value_parser!(u8).range(1..=247))]
    pub modbus_address: u8,
    /// Parity and stop bits with --modbus-rtu: 8E1, 8N2 or 8N1 (a pty
    /// carries no parity; it sets the character time of the silences).
    #[arg(long, value_name = "P", default_value = "8E1", requires = "modbus_rtu",
          value_parser = super::modbus::parse_parity)]
    pub parity: fois_protocol::Parity,
    /// The emulated link rate of the Modbus silences, Bd.
    #[arg(
        long,
        value_name = "BD",
        default_value_t = 19_200,
        requires = "modbus_rtu"
    )]
    pub baud: u32,
    /// Append the node's own frames (as it would stream them framed) to
    /// this file while it speaks Modbus: the log to check registers against.
    #[arg(long, value_name = "FILE", requires = "modbus_rtu")]
    pub frame_log: Option<PathBuf>,
}

/// `foisctl virtual-node`.
pub fn run(args: VirtualNodeArgs, stop: &AtomicBool) -> anyhow::Result<()> {
    let VirtualNodeArgs {
        scene,
        link,
        state,
        modbus_rtu,
        modbus_address,
        parity,
        baud,
        frame_log,
    } = args;
    let scene = scene.resolve(VIRTUAL_NODE_DEFAULTS)?;
    if let Some(p) = &state {
        fois_vnode::SharedStorage::with_file(p)
            .with_context(|| format!("cannot read the node state {}", p.display()))?;
    }
    let mut node = build_node_with_state(&scene, state);
    if modbus_rtu {
        let settings = fois_protocol::LinkSettings {
            protocol: fois_protocol::LinkProtocol::ModbusRtu,
            modbus_address,
            parity,
        };
        node.command(
            fois_protocol::Command::SetLinkSettings(settings),
            &mut |_| {},
        )
        .map_err(|e| anyhow::anyhow!("the node refused the link settings: {e:?}"))?;
    }
    let mut pty = Pty::open()?;
    let _guard = match &link {
        Some(l) => Some(serve::make_link(l, pty.path())?),
        None => None,
    };
    println!("{}", pty.path().display());
    let connect = if modbus_rtu {
        format!(
            "Modbus RTU, address {modbus_address}, {} at an emulated {baud} Bd; read with: mbpoll -m rtu -b {baud} -P {} -a {modbus_address} -t 3 -r 1 -c 27 -1 {}",
            parity.name(),
            match parity {
                fois_protocol::Parity::Even8E1 => "even",
                _ => "none",
            },
            pty.path().display()
        )
    } else {
        format!(
            "connect with: foisctl monitor --port {}",
            pty.path().display()
        )
    };
    eprintln!(
        "virtual node on {}{}: {}\n{connect}   (Ctrl-C stops the node)",
        pty.path().display(),
        link.as_ref()
            .map(|l| format!(" (also {})", l.display()))
            .unwrap_or_default(),
        describe(&scene),
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let opts = ServeOptions {
        speed: scene.speed,
        duration: scene.duration,
    };
    let modbus = serve::ModbusOptions { baud, frame_log };
    let stats = serve::serve_with(&mut node, &mut pty, &opts, &modbus, stop)?;
    eprintln!(
        "virtual node stopped at virtual t = {:.1} s: {} frames run, {} sent, {} dropped (no reader)",
        node.clock().now_s(),
        node.frames(),
        stats.frames_sent,
        stats.frames_dropped
    );
    Ok(())
}
