//! Helpers of the test crates that run `foisctl` processes (end-to-end and
//! gateway tests, the gateway load benchmark): the binary and a virtual node
//! served on a pseudo-terminal.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

/// `foisctl`.
pub const BIN: &str = env!("CARGO_BIN_EXE_foisctl");

/// Run `foisctl` with `args` to its end: (exit code, -1 if killed by a
/// signal; stdout; stderr).
pub fn foisctl(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(BIN).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A `foisctl virtual-node`, killed on drop.
pub struct NodeProc {
    child: Child,
    /// Its pty.
    pub path: String,
}

impl NodeProc {
    /// Start with these flags; waits for the pty path.
    pub fn start(extra: &[&str]) -> NodeProc {
        let mut child = Command::new(BIN)
            .arg("virtual-node")
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn virtual-node");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let path = line.trim().to_string();
        assert!(path.starts_with("/dev/pts/"), "first line: {line:?}");
        NodeProc { child, path }
    }

    /// SIGKILL: the pty goes away as when a USB cable is pulled.
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for NodeProc {
    fn drop(&mut self) {
        self.kill9();
    }
}
