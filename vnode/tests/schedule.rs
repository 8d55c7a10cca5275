//! The virtual node runs the board's schedule (`fois_firmware::platform::schedule`,
//! the code the board binary's main loop polls): `Hello` and the first
//! frame at boot, frames on a fixed grid, a new stream period applied at
//! once from the last frame, `Hello` every second while not streaming.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;

use fois_protocol::{Command, DeviceFrame, DeviceMsg, FrameDecoder, HostFrame, encode_to_vec};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

/// What the node sent: `Hello`s at the virtual time they went out, frames
/// at their own uptime, ms.
#[derive(Default, Debug)]
struct Seen {
    hellos_ms: Vec<u64>,
    frames_ms: Vec<u64>,
}

fn node() -> VirtualNode {
    let tl = Timeline::constant(Segment::new(f64::INFINITY, Cover::Dry).noise(0.0));
    let env = Arc::new(Environment::with_curves(tl, [], [0.0, 0.0]));
    let opts = NodeOptions {
        calibrate_at_s: None,
        ..NodeOptions::default()
    };
    VirtualNode::new(env, opts)
}

/// A `tx` that decodes into `seen`, stamping `Hello`s with the clock.
fn sink(node: &VirtualNode, seen: &Rc<RefCell<Seen>>) -> impl FnMut(&[u8]) + use<> {
    let clock = node.clock().clone();
    let seen = seen.clone();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    move |bytes: &[u8]| {
        dec.feed::<DeviceFrame>(bytes, |r| {
            let f = r.expect("a good frame");
            let mut s = seen.borrow_mut();
            match &f.msg {
                DeviceMsg::Hello(_) => s.hellos_ms.push(clock.now_ms()),
                m => {
                    if let Some((m, _)) = m.measurement() {
                        s.frames_ms.push(m.uptime_ms);
                    }
                }
            }
        });
    }
}

fn send(node: &mut VirtualNode, tx: &mut impl FnMut(&[u8]), id: u16, cmd: Command) {
    node.handle_rx(&encode_to_vec(&HostFrame { id, cmd }), tx);
}

const MS: u64 = 1_000_000;

#[test]
fn first_frame_grid_and_new_periods_as_on_the_board() {
    let mut n = node();
    let seen = Rc::new(RefCell::new(Seen::default()));
    let mut tx = sink(&n, &seen);

    // Boot: Hello and the first frame at once (the board's first poll).
    n.advance_to(0, &mut tx);
    assert_eq!(seen.borrow().hellos_ms, [0]);
    assert_eq!(seen.borrow().frames_ms, [0]);

    // The 100 ms grid (the config's default period); streaming from boot,
    // so no further Hello.
    n.advance_to(1_234 * MS, &mut tx);
    let grid: Vec<u64> = (0..=12).map(|k| k * 100).collect();
    assert_eq!(seen.borrow().frames_ms, grid);
    assert_eq!(seen.borrow().hellos_ms, [0]);

    // A shorter period at 1 234 ms applies at once, counted from the last
    // frame (1 200 ms): 1 250, 1 300, …
    send(
        &mut n,
        &mut tx,
        1,
        Command::StartStream {
            frame_period_ms: Some(50),
        },
    );
    n.advance_to(1_400 * MS, &mut tx);
    assert_eq!(seen.borrow().frames_ms[13..], [1_250, 1_300, 1_350, 1_400]);

    // A longer one at 1 420 ms: the next frame one new period after the
    // last (1 400 + 500), not one period after the command.
    n.advance_to(1_420 * MS, &mut tx);
    send(
        &mut n,
        &mut tx,
        2,
        Command::StartStream {
            frame_period_ms: Some(500),
        },
    );
    n.advance_to(2_450 * MS, &mut tx);
    assert_eq!(seen.borrow().frames_ms[17..], [1_900, 2_400]);

    // Stop streaming at 2 450 ms: Hello at once, then every second; no
    // frames go out (they still run).
    send(&mut n, &mut tx, 3, Command::StopStream);
    let frames_before = n.frames();
    n.advance_to(4_500 * MS, &mut tx);
    assert_eq!(seen.borrow().hellos_ms, [0, 2_450, 3_450, 4_450]);
    assert_eq!(seen.borrow().frames_ms.len(), 19);
    // StopStream drops the stream's period: the frames run on at the
    // config's 100 ms, counted from the last one (2 400 ms): 2 500 … 4 500.
    assert_eq!(n.frames() - frames_before, 21);
    assert_eq!(n.schedule().skipped_frames(), 0);
}

#[test]
fn a_reset_boots_a_fresh_schedule() {
    let mut n = node();
    let seen = Rc::new(RefCell::new(Seen::default()));
    let mut tx = sink(&n, &seen);
    n.advance_to(1_050 * MS, &mut tx);
    assert_eq!(seen.borrow().frames_ms.last(), Some(&1_000));
    send(&mut n, &mut tx, 1, Command::Reset);
    // The new node says Hello and runs its first frame at once (1 050 ms
    // of virtual time, uptime of the same clock), then its own grid.
    assert_eq!(seen.borrow().hellos_ms, [0, 1_050]);
    n.advance_to(1_250 * MS, &mut tx);
    assert_eq!(seen.borrow().frames_ms[11..], [1_050, 1_150, 1_250]);
    assert_eq!(n.resets(), 1);
}
