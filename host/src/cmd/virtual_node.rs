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
    /// cycle on a board [default: RAM only]. A file of the layout before
    /// the bootloader (256 KiB) is migrated once, with a note.
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
    /// The public key (the 64-hex-digit `.pub` file `foisctl keygen`
    /// writes) the node checks update images with, as a board checks them
    /// with the key built into its firmware. The node runs the firmware's
    /// updater on its own boot-state, active and DFU slots (in RAM: a
    /// restart is a freshly flashed board) and, after a committed update,
    /// embassy-boot's swap; it then reports the image's version (it cannot
    /// run the image's code). Images for it are signed with
    /// `foisctl sign --board virtual-f446` (its Hello's board name).
    /// Without this option it refuses every image.
    #[arg(long, value_name = "FILE.pub")]
    pub update_key: Option<PathBuf>,
    /// Carry the framed link at this rate, Bd: each byte takes 10 bit
    /// times on one half-duplex line, and an answer leaves only after the
    /// node's flash work for it (`fois_vnode::line`) [default: no byte
    /// time, as fast as the pty moves bytes].
    #[arg(long, value_name = "BD", conflicts_with = "modbus_rtu",
          value_parser = clap::value_parser!(u32).range(300..=4_000_000))]
    pub line_baud: Option<u32>,
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
        update_key,
        line_baud,
    } = args;
    let scene = scene.resolve(VIRTUAL_NODE_DEFAULTS)?;
    if let Some(p) = &state {
        let (_, migration) = fois_vnode::SharedStorage::open_file(p)
            .with_context(|| format!("cannot read the node state {}", p.display()))?;
        if let Some(m) = migration {
            eprintln!("{}", migration_note(p, m));
        }
    }
    let key = match &update_key {
        Some(p) => {
            let key = crate::signing::read_public_key(p)
                .with_context(|| format!("cannot read the update key {}", p.display()))?;
            fois_firmware::update::UpdateKey::from_bytes(key.to_bytes())
        }
        None => fois_firmware::update::UpdateKey::NONE,
    };
    let mut node = build_node_with_state(&scene, state, key);
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
    let stats = serve::serve_on_line(&mut node, &mut pty, &opts, &modbus, line_baud, stop)?;
    eprintln!(
        "virtual node stopped at virtual t = {:.1} s: {} frames run, {} sent, {} dropped (no reader)",
        node.clock().now_s(),
        node.frames(),
        stats.frames_sent,
        stats.frames_dropped
    );
    Ok(())
}

/// What the user is told, once, when a state file of the layout before the
/// bootloader was converted.
fn migration_note(path: &std::path::Path, m: fois_firmware::storage::migrate::Migration) -> String {
    use fois_firmware::storage::migrate::Migration;
    let what = match m {
        Migration::Moved { layout, .. } => {
            format!("its record (layout {layout}) moved into the new 2 × 16 KiB store")
        }
        Migration::NothingToMove | Migration::NotNeeded => {
            "it held no record; it now holds the new 2 × 16 KiB store, empty".to_string()
        }
    };
    format!(
        "note: the node state {} was of the layout before the bootloader (2 × 128 KiB): {what}, as a board's first boot after the move does; the file is rewritten in the new layout",
        path.display()
    )
}
