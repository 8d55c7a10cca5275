//! A long stream of random valid frames, damaged the ways a serial line
//! damages bytes: bit flips, dropped bytes, inserted garbage (zeros
//! included), and long runs that overflow the decoder. Every frame that
//! arrived intact must come out, in order; no damaged frame may ever be
//! accepted.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use fois_protocol::*;
use proptest::strategy::{Strategy, ValueTree};
use proptest::test_runner::{Config as PtConfig, RngAlgorithm, TestRng, TestRunner};
use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg64;

#[derive(Debug, Default)]
struct Tally {
    sent: usize,
    intact: usize,
    bit_flips: usize,
    dropped: usize,
    inserted: usize,
    oversize: usize,
    lost_to_neighbour: usize,
}

fn below(rng: &mut Pcg64, n: usize) -> usize {
    (rng.next_u64() % n as u64) as usize
}

/// Build the damaged stream; returns it, the seqs of the frames that
/// arrived intact, and the tally.
fn damaged_stream(seed: u64, frames: usize) -> (Vec<u8>, Vec<u32>, Tally) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut seed32 = [0u8; 32];
    seed32[..8].copy_from_slice(&seed.to_le_bytes());
    let mut runner = TestRunner::new_with_rng(
        PtConfig::default(),
        TestRng::from_seed(RngAlgorithm::ChaCha, &seed32),
    );
    let msg_strategy = common::device_msg();
    let mut stream = Vec::new();
    let mut intact = Vec::new();
    let mut tally = Tally::default();
    // Was the previous frame's delimiter delivered? If not, this frame is
    // glued to the previous one and lost with it.
    let mut in_sync = true;
    for i in 0..frames {
        let seq = i as u32;
        let msg = msg_strategy.new_tree(&mut runner).unwrap().current();
        let original = encode_to_vec(&DeviceFrame { seq, msg });
        let mut bytes = original.clone();
        let last = bytes.len() - 1;
        tally.sent += 1;
        match below(&mut rng, 100) {
            0..=64 => {}
            65..=79 => {
                for _ in 0..=below(&mut rng, 3) {
                    let at = below(&mut rng, bytes.len());
                    bytes[at] ^= 1 << below(&mut rng, 8);
                }
                tally.bit_flips += 1;
            }
            80..=89 => {
                bytes.remove(below(&mut rng, bytes.len()));
                tally.dropped += 1;
            }
            90..=96 => {
                let at = below(&mut rng, last);
                let garbage: Vec<u8> = (0..1 + below(&mut rng, 8))
                    .map(|_| (rng.next_u64() & 0xff) as u8)
                    .collect();
                // The garbage must change the frame: force one non-zero byte
                // into it so even all-zero garbage is a change.
                let mut garbage = garbage;
                garbage[0] |= 0x80;
                bytes.splice(at..at, garbage);
                tally.inserted += 1;
            }
            _ => {
                let at = below(&mut rng, last);
                let run = vec![0xA5u8; MAX_FRAME + 1 + below(&mut rng, 400)];
                bytes.splice(at..at, run);
                tally.oversize += 1;
            }
        }
        // Judge by the bytes, not by the kind of damage (two flips of one bit
        // cancel; garbage with a zero inserted before the frame is a garbled
        // frame of its own and leaves this one whole). The decoder sees the
        // bytes after the last zero before this frame's delimiter; they come
        // out as this frame if they are its bytes and the decoder is in sync
        // there (the previous delimiter arrived, or a zero in the damage).
        let arrived = match bytes.split_last() {
            Some((0, body)) => {
                let start = body.iter().rposition(|&b| b == 0).map_or(0, |p| p + 1);
                let whole = body[start..] == original[..original.len() - 1];
                whole.then_some(in_sync || start > 0)
            }
            _ => None,
        };
        match arrived {
            Some(true) => {
                intact.push(seq);
                tally.intact += 1;
            }
            Some(false) => tally.lost_to_neighbour += 1,
            None => {}
        }
        in_sync = bytes.last() == Some(&0);
        stream.extend_from_slice(&bytes);
    }
    (stream, intact, tally)
}

fn run(seed: u64, frames: usize) {
    let (stream, intact, tally) = damaged_stream(seed, frames);
    let mut dec = FrameDecoder::<MAX_FRAME>::new();
    let mut accepted = Vec::new();
    // Feed in uneven chunks, as a UART driver would deliver them.
    for chunk in stream.chunks(37) {
        dec.feed::<DeviceFrame>(chunk, |r| {
            if let Ok(f) = r {
                accepted.push(f.seq);
            }
        });
    }
    let s = dec.stats();
    println!(
        "seed {seed}: sent {} frames ({} B): intact {}, bit-flipped {}, byte dropped {}, \
         garbage inserted {}, oversize runs {}, lost with a damaged neighbour {}",
        tally.sent,
        stream.len(),
        tally.intact,
        tally.bit_flips,
        tally.dropped,
        tally.inserted,
        tally.oversize,
        tally.lost_to_neighbour
    );
    println!(
        "seed {seed}: decoder accepted {} | rejected: garbled {}, crc {}, oversized {}, malformed {}",
        s.frames, s.garbled, s.crc_failed, s.oversized, s.malformed
    );
    // Every intact frame recovered, in order, and nothing else accepted.
    assert_eq!(
        accepted, intact,
        "accepted frames differ from the intact ones"
    );
    assert_eq!(s.frames as usize, tally.intact);
    assert!(
        s.oversized as usize >= tally.oversize,
        "each oversize run is counted"
    );
    assert!(s.rejected() > 0);
}

#[test]
fn corrupted_stream_keeps_every_intact_frame_and_accepts_nothing_else() {
    for seed in [1, 2, 3] {
        run(seed, 20_000);
    }
}
