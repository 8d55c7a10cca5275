//! The firmware updater on the emulated Cortex-M4F: a 90 KiB image (the
//! issue's goal) sent in 256-byte chunks into a RAM flash, verified (SHA-512
//! of the slot and the ed25519 check) and committed (embassy-boot's
//! `verify_and_mark_updated`: the same again, then the boot-state mark).
//! Prints the instructions of the worst chunk, of the verify, of the
//! signature check alone and of the commit (`cargo xtask qemu` reads them
//! into firmware/README.md's table).

use cortex_m_semihosting::hprintln;
use fois_firmware::storage::ram_flash::RamFlash;
use fois_firmware::update::transfer::UpdaterConfig;
use fois_firmware::update::{FlashUpdater, UpdateKey};
use fois_protocol::update::{ImageTrailer, TRAILER_LEN};
use fois_protocol::{ChunkData, Hello, ImageSignature, UpdateBegin, UpdateChunk};

use super::ticks;

const BODY: usize = 90 * 1024;
const LEN: usize = BODY + TRAILER_LEN;
const PAGE: usize = 16 * 1024;
const ACTIVE: usize = 6 * PAGE;

type Dfu = RamFlash<&'static mut [u8], PAGE, 7>;
type State = RamFlash<&'static mut [u8], 4096, 1>;

/// The image's byte `i`.
fn byte(i: usize) -> u8 {
    if i < BODY {
        (i as u32).wrapping_mul(2_654_435_761).rotate_left(7) as u8
    } else {
        trailer().to_bytes()[i - BODY]
    }
}

fn trailer() -> ImageTrailer {
    ImageTrailer {
        body_len: BODY as u32,
        version: [0, 9, 0],
        flags: 0,
        board: Hello::board_from_str("qemu"),
    }
}

fn seed() -> [u8; 32] {
    let hex = include_str!("../../tests/keys/test-update-ed25519.seed").trim();
    let mut seed = [0u8; 32];
    for (i, b) in seed.iter_mut().enumerate() {
        *b = hex
            .get(2 * i..2 * i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0);
    }
    seed
}

/// Run the bench; `insn_per_tick` from the SysTick calibration. Returns
/// false when a step failed.
pub fn run(insn_per_tick: f32) -> bool {
    let (Some(dfu_mem), Some(state_mem)) = (
        cortex_m::singleton!(: [u8; 7 * PAGE] = [0; 7 * PAGE]),
        cortex_m::singleton!(: [u8; 4096] = [0; 4096]),
    ) else {
        return false;
    };
    dfu_mem.fill(0xFF);
    state_mem.fill(0xFF);
    let insn = |t: u64| (t as f32 * insn_per_tick + 0.5) as u64;

    // The host's side (not measured): digest and signature.
    let mut sha = salty::Sha512::new();
    let mut block = [0u8; 256];
    for start in (0..LEN).step_by(256) {
        let n = (LEN - start).min(256);
        for (i, b) in block[..n].iter_mut().enumerate() {
            *b = byte(start + i);
        }
        sha.update(&block[..n]);
    }
    let sha512 = sha.finalize();
    let keypair = salty::Keypair::from(&seed());
    let signature = ImageSignature::from_bytes(&keypair.sign(&sha512).to_bytes());
    let mut digest = [0u8; 32];
    digest.copy_from_slice(&sha512[..32]);

    let mut u = FlashUpdater::new(
        Dfu::new(&mut dfu_mem[..]),
        State::new(&mut state_mem[..]),
        UpdaterConfig {
            active_len: ACTIVE as u32,
            running: [0, 1, 0],
            key: UpdateKey::from_bytes(keypair.public.to_bytes()),
        },
    );
    let begin = UpdateBegin {
        image_len: LEN as u32,
        version: [0, 9, 0],
        image_digest: digest,
    };
    if u.begin_transfer(&begin).is_err() {
        return false;
    }
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut worst_chunk = 0u64;
    for start in (0..LEN).step_by(256) {
        let n = (LEN - start).min(256);
        for (i, b) in block[..n].iter_mut().enumerate() {
            *b = byte(start + i);
        }
        let Some(data) = ChunkData::new(&block[..n]) else {
            return false;
        };
        let chunk = UpdateChunk {
            offset: start as u32,
            crc32: crc.checksum(&block[..n]),
            data,
        };
        let t0 = ticks();
        if u.write_chunk(&chunk).is_err() {
            return false;
        }
        // A chunk that enters a page erases it first: the RAM flash's
        // byte loop, where the board's flash erases by itself.
        if start % PAGE != 0 {
            worst_chunk = worst_chunk.max(ticks() - t0);
        }
    }
    let board = Hello::board_from_str("qemu");
    let t0 = ticks();
    let verified = u.verify_image(&signature, &board);
    let verify = ticks() - t0;
    let key = UpdateKey::from_bytes(keypair.public.to_bytes());
    let t0 = ticks();
    let alone = key.verifies(&sha512, &signature);
    let signature_only = ticks() - t0;
    let t0 = ticks();
    let committed = u.commit_image();
    let commit = ticks() - t0;
    hprintln!("update image: {} B in 256 B chunks", LEN);
    hprintln!("update chunk worst (no page erase): {}", insn(worst_chunk));
    hprintln!("update verify (SHA-512 and signature): {}", insn(verify));
    hprintln!("update signature check alone: {}", insn(signature_only));
    hprintln!(
        "update commit (verify_and_mark_updated, state mark): {}",
        insn(commit)
    );
    verified.is_ok() && alone && committed == Ok([0, 9, 0])
}
