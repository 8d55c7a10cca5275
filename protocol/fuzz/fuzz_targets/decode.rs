//! Fuzz the streaming decoder: arbitrary bytes, in both directions' types.
//! It must never panic, and whatever it accepts must re-encode to a frame
//! that decodes to the same message.
#![no_main]

use fois_protocol::{DeviceFrame, FrameDecoder, HostFrame, MAX_FRAME, encode_to_vec};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut host_side = FrameDecoder::<MAX_FRAME>::new();
    host_side.feed::<DeviceFrame>(data, |r| {
        if let Ok(frame) = r {
            let again = encode_to_vec(&frame);
            let mut check = FrameDecoder::<MAX_FRAME>::new();
            let mut back = None;
            check.feed::<DeviceFrame>(&again, |r| back = Some(r));
            assert_eq!(back, Some(Ok(frame)));
        }
    });
    let mut node_side = FrameDecoder::<MAX_FRAME>::new();
    node_side.feed::<HostFrame>(data, |_| {});
    let s = node_side.stats();
    assert!(s.frames + s.rejected() <= data.iter().filter(|&&b| b == 0).count() as u32);
});
