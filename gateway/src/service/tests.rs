// A test module: unwrap and expect are assertions here.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use super::*;
use crate::config::file::{FileConfig, Overrides};

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap()
}

/// A read of the 24 registers of unit 1 and its answer, timed.
fn timed_read(s: &mut TcpStream, tid: u16) -> Duration {
    let t0 = Instant::now();
    let [t0b, t1b] = tid.to_be_bytes();
    s.write_all(&[t0b, t1b, 0, 0, 0, 6, 1, 0x04, 0, 0, 0, 24])
        .unwrap();
    let mut answer = [0u8; 7 + 2 + 48];
    s.read_exact(&mut answer).unwrap();
    assert_eq!((answer[..2].to_vec(), answer[7]), (vec![t0b, t1b], 0x04));
    t0.elapsed()
}

#[test]
fn a_stalled_disk_does_not_delay_a_modbus_answer() {
    let dir = tempfile::tempdir().unwrap();
    let queue = dir.path().join("q");
    let port = free_port();
    // Nothing listens on the broker's port; the node's port does not exist:
    // the gateway ticks its queue every 100 ms, and each tick blocks 400 ms.
    let text = format!(
        "name = \"gw\"\n[broker]\nhost = \"127.0.0.1\"\nport = {}\n[queue]\ndir = \"{}\"\n\
         [modbus]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\n\
         [[node]]\nport = \"/dev/does-not-exist\"\nname = \"n1\"\n",
        free_port(),
        queue.display()
    );
    let cfg = FileConfig::parse(&text)
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    crate::queue::stall::set(&queue, Duration::from_millis(400));
    let stop: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
    let run = std::thread::spawn(move || {
        Service::new(cfg).run(RunLimits {
            stop,
            duration: None,
            status_every: Duration::from_secs(3600),
        })
    });
    let t0 = Instant::now();
    let mut s = loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => break s,
            Err(e) => assert!(t0.elapsed() < Duration::from_secs(10), "connect: {e}"),
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    // 100 reads, 20 ms apart: 2 s, five stalls of the queue.
    let mut worst = Duration::ZERO;
    for k in 0..100 {
        worst = worst.max(timed_read(&mut s, k));
        std::thread::sleep(Duration::from_millis(20));
    }
    println!("slowest of 100 Modbus reads while every queue tick blocks 400 ms: {worst:?}");
    assert!(worst < Duration::from_millis(50), "{worst:?}");
    stop.store(true, Ordering::Relaxed);
    run.join().unwrap().unwrap();
}
