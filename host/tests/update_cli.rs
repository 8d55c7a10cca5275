//! `foisctl update` as a user runs it, against the scripted update node
//! (`fois_link::update_fake`) served on a pseudo-terminal: a clean update
//! (exit 0, the versions printed), and each kind of refusal with its own
//! exit code and its reason in words. The end-to-end run against the
//! virtual node (which runs the node's own updater) is separate.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{Read, Write};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use fois_link::signed_image::SignedImage;
use fois_link::update_fake::{FakeNode, Script, TrialOutcome};
use fois_protocol::{Hello, ImageTrailer};
use serialport::SerialPort;

const BIN: &str = env!("CARGO_BIN_EXE_foisctl");
const SIGNATURE: [u8; 64] = [0x5A; 64];

/// Serve `node` on a pty until the guard drops; the pty's path.
struct Served {
    path: String,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
    }
}

fn serve(node: &FakeNode) -> Served {
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::ZERO).unwrap();
    let path = slave.name().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let node = node.clone();
    let thread = std::thread::spawn(move || {
        let _slave = slave;
        let mut port = node.port();
        let mut buf = [0u8; 4096];
        while !s2.load(Ordering::Relaxed) {
            let mut idle = true;
            if let Ok(n) = master.read(&mut buf)
                && n > 0
            {
                port.write_all(&buf[..n]).unwrap();
                idle = false;
            }
            if let Ok(n) = port.read(&mut buf)
                && n > 0
            {
                master.write_all(&buf[..n]).unwrap();
                idle = false;
            }
            if idle {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    });
    Served {
        path,
        stop,
        thread: Some(thread),
    }
}

fn image(dir: &std::path::Path, version: [u8; 3], board: &str) -> std::path::PathBuf {
    let body: Vec<u8> = (0..30_000u32).map(|i| (i * 7 + 3) as u8).collect();
    let trailer = ImageTrailer {
        body_len: body.len() as u32,
        version,
        flags: 0,
        board: Hello::board_from_str(board),
    };
    let img = SignedImage::assemble(&body, &trailer, &SIGNATURE).unwrap();
    let path = dir.join(format!(
        "{board}-{}.{}.{}.fois",
        version[0], version[1], version[2]
    ));
    std::fs::write(&path, img.as_bytes()).unwrap();
    path
}

fn node(script: Script, signatures_ok: bool) -> FakeNode {
    FakeNode::new(
        "NUCLEO-F446RE",
        [0, 6, 0],
        128 * 1024,
        script,
        Box::new(move |_, sig| signatures_ok && *sig == SIGNATURE),
    )
}

fn update(served: &Served, image: &std::path::Path) -> (i32, String, String) {
    let out = Command::new(BIN)
        .args([
            "update",
            "--port",
            &served.path,
            "--image",
            image.to_str().unwrap(),
            "--plain",
            "--confirm-timeout-s",
            "2",
            "--timeout-ms",
            "1000",
        ])
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn an_update_succeeds_and_each_refusal_has_its_exit_code() {
    let dir = tempfile::tempdir().unwrap();
    let good = image(dir.path(), [0, 7, 0], "NUCLEO-F446RE");

    let n = node(Script::default(), true);
    let served = serve(&n);
    let (code, out, err) = update(&served, &good);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("updated 0.6.0 -> 0.7.0: confirmed"), "{out}");
    assert!(
        out.contains("sending") && out.contains("committing"),
        "{out}"
    );
    assert_eq!(n.image_info().version, [0, 7, 0]);
    // Again: it runs it already, nothing is sent.
    let (code, out, _) = update(&served, &good);
    assert_eq!(code, 0);
    assert!(out.contains("runs 0.7.0 already"), "{out}");
    drop(served);

    let cases: Vec<(FakeNode, std::path::PathBuf, i32, &str)> = vec![
        (
            node(Script::default(), false),
            good.clone(),
            14,
            "signature does not verify",
        ),
        (
            node(Script::default(), true),
            image(dir.path(), [0, 7, 0], "OTHER-BOARD"),
            12,
            "another board",
        ),
        (
            node(Script::default(), true),
            image(dir.path(), [0, 5, 0], "NUCLEO-F446RE"),
            13,
            "--downgrade",
        ),
        (
            node(
                Script {
                    trial: TrialOutcome::RollBack,
                    ..Script::default()
                },
                true,
            ),
            good.clone(),
            19,
            "rolled back and runs 0.6.0",
        ),
        (
            node(
                Script {
                    trial: TrialOutcome::Silent,
                    ..Script::default()
                },
                true,
            ),
            good.clone(),
            20,
            "did not confirm 0.7.0",
        ),
    ];
    for (n, img, want, why) in cases {
        let served = serve(&n);
        let (code, out, err) = update(&served, &img);
        assert_eq!(code, want, "{out}{err}");
        assert!(err.contains(why), "{want}: {err}");
    }
    let old = node(Script::default(), true);
    old.set_protocol_version(5);
    let served = serve(&old);
    let (code, _, err) = update(&served, &good);
    assert_eq!(code, 10, "{err}");
    assert!(err.contains("version 6 or later"), "{err}");
    // Not an image: refused before the port is opened.
    let (code, _, err) = update(&served, &dir.path().join("missing.fois"));
    assert_eq!(code, 1, "{err}");
    let junk = dir.path().join("junk.fois");
    std::fs::write(&junk, vec![0u8; 4096]).unwrap();
    assert_eq!(update(&served, &junk).0, 11);
}
