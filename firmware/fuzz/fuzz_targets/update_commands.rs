//! Fuzz the firmware update's command path: arbitrary sequences of begin,
//! chunk, status, verify, commit, abort, resets (embassy-boot's bootloader
//! run on the flash) and power cuts, on the updater over a RAM flash cut
//! into boot state, active and DFU partitions. Some of the steps send the
//! pieces of a correctly signed image (test key), so the fuzzer reaches
//! verify, commit, the swap and the trial too.
//!
//! One input in 256 (first byte 0) runs with the real key, and at most two signature checks
//! (a verify and a commit of a complete transfer: salty's portable field
//! arithmetic takes milliseconds on the host); the others with no key
//! (every verify refused at once), so the transfer's paths get the runs.
//!
//! It must never panic; the status stays inside the image and the slot;
//! the active slot always holds one of the two images (old or new).
#![no_main]

use std::cell::RefCell;
use std::rc::Rc;

use embassy_boot::{AlignedBuffer, BootLoader, BootLoaderConfig};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::storage::ram_flash::{PowerCut, RamFlash, RamFlashError};
use fois_firmware::update::transfer::UpdaterConfig;
use fois_firmware::update::{FlashUpdater, UpdateKey, UpdateSlots};
use fois_protocol::update::ImageTrailer;
use fois_protocol::{ChunkData, Hello, ImageSignature, ImageState, UpdateBegin, UpdateChunk};
use libfuzzer_sys::fuzz_target;

const PAGE: usize = 1024;
const STATE: (u32, u32) = (0, 1024);
const ACTIVE: (u32, u32) = (1024, 4096);
const DFU: (u32, u32) = (5120, 5120);
type Flash = RamFlash<Vec<u8>, PAGE, 10>;
type Shared = Rc<RefCell<Flash>>;

struct Part(Shared, u32, u32);
impl ErrorType for Part {
    type Error = RamFlashError;
}
impl ReadNorFlash for Part {
    const READ_SIZE: usize = 1;
    fn read(&mut self, o: u32, b: &mut [u8]) -> Result<(), RamFlashError> {
        if o as usize + b.len() > self.2 as usize {
            return Err(RamFlashError::OutOfBounds);
        }
        self.0.borrow_mut().read(self.1 + o, b)
    }
    fn capacity(&self) -> usize {
        self.2 as usize
    }
}
impl NorFlash for Part {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = PAGE;
    fn erase(&mut self, f: u32, t: u32) -> Result<(), RamFlashError> {
        if t > self.2 || f > t {
            return Err(RamFlashError::OutOfBounds);
        }
        self.0.borrow_mut().erase(self.1 + f, self.1 + t)
    }
    fn write(&mut self, o: u32, b: &[u8]) -> Result<(), RamFlashError> {
        if o as usize + b.len() > self.2 as usize {
            return Err(RamFlashError::OutOfBounds);
        }
        self.0.borrow_mut().write(self.1 + o, b)
    }
}

fn part(f: &Shared, (at, len): (u32, u32)) -> Part {
    Part(f.clone(), at, len)
}

struct Img {
    bytes: Vec<u8>,
    begin: UpdateBegin,
    sig: ImageSignature,
}

fn img(body: usize, version: [u8; 3], key: &salty::Keypair) -> Img {
    let mut bytes: Vec<u8> = (0..body).map(|i| (i * 7 + body) as u8).collect();
    bytes.extend_from_slice(
        &ImageTrailer {
            body_len: body as u32,
            version,
            flags: 0,
            board: Hello::board_from_str("fuzz"),
        }
        .to_bytes(),
    );
    let sha = salty::Sha512::new().updated(&bytes).finalize();
    let mut digest = [0u8; 32];
    digest.copy_from_slice(&sha[..32]);
    Img {
        begin: UpdateBegin {
            image_len: bytes.len() as u32,
            version,
            image_digest: digest,
        },
        sig: ImageSignature::from_bytes(&key.sign(&sha).to_bytes()),
        bytes,
    }
}

fn chunk(data: &[u8], offset: u32, crc_ok: bool) -> UpdateChunk {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(data);
    UpdateChunk {
        offset,
        crc32: if crc_ok { crc } else { crc ^ 1 },
        data: ChunkData::new(data).unwrap_or_else(|| ChunkData::new(&[]).unwrap()),
    }
}

fn boot(flash: &Shared, old: &Img, new: &Img) -> [u8; 3] {
    for _ in 0..100 {
        flash.borrow_mut().power_on();
        let mut bl = BootLoader::new(BootLoaderConfig {
            active: part(flash, ACTIVE),
            dfu: part(flash, DFU),
            state: part(flash, STATE),
        });
        let mut buf = AlignedBuffer([0u8; 256]);
        if bl.prepare_boot(&mut buf.0).is_ok() {
            break;
        }
    }
    let f = flash.borrow();
    let active = &f.bytes()[ACTIVE.0 as usize..];
    if active[..old.bytes.len()] == old.bytes[..] {
        old.begin.version
    } else if active[..new.bytes.len()] == new.bytes[..] {
        new.begin.version
    } else {
        panic!("the active slot holds neither image");
    }
}

/// The key's public half and the two signed images (made once).
fn fixtures() -> &'static ([u8; 32], Img, Img) {
    static F: std::sync::OnceLock<([u8; 32], Img, Img)> = std::sync::OnceLock::new();
    F.get_or_init(|| {
        let key = salty::Keypair::from(&[7u8; 32]);
        (
            key.public.to_bytes(),
            img(1_500, [0, 1, 0], &key),
            img(2_000, [0, 2, 0], &key),
        )
    })
}

fuzz_target!(|data: &[u8]| {
    let (public, old, new) = fixtures();
    let Some((&keyed, data)) = data.split_first() else {
        return;
    };
    let mut signature_checks = 2u8;
    let key = if keyed == 0 {
        UpdateKey::from_bytes(*public)
    } else {
        UpdateKey::NONE
    };
    let mut mem = vec![0xFFu8; 10 * PAGE];
    mem[ACTIVE.0 as usize..ACTIVE.0 as usize + old.bytes.len()].copy_from_slice(&old.bytes);
    let flash: Shared = Rc::new(RefCell::new(Flash::new(mem)));
    let build = |running: [u8; 3]| {
        FlashUpdater::new(
            part(&flash, DFU),
            part(&flash, STATE),
            UpdaterConfig {
                active_len: ACTIVE.1,
                running,
                key,
            },
        )
    };
    let mut u = build(boot(&flash, old, new));
    let board = Hello::board_from_str("fuzz");
    let mut rest = data;
    while let Some((&op, tail)) = rest.split_first() {
        let arg = |i: usize| tail.get(i).copied().unwrap_or(0);
        let arg16 = |i: usize| u16::from_le_bytes([arg(i), arg(i + 1)]);
        let mut used = 0;
        let complete = u
            .status()
            .is_ok_and(|s| s.image_len > 0 && s.next_offset == s.image_len);
        if matches!(op % 12, 5..=7) && complete && key != UpdateKey::NONE {
            if signature_checks == 0 {
                rest = tail;
                continue;
            }
            signature_checks -= 1;
        }
        match op % 12 {
            // A begin of the new image, or of arbitrary bytes.
            0 => {
                let _ = u.begin(&new.begin);
            }
            1 => {
                let mut b = new.begin;
                b.image_len = u32::from(arg16(0)) * 3;
                b.image_digest[0] = arg(2);
                b.version = [arg(3), arg(4), 0];
                used = 5;
                let _ = u.begin(&b);
            }
            // The new image's next chunk, with a length and an offset error.
            2 | 3 => {
                let st = u.status();
                let at = st.map_or(0, |s| s.next_offset) as usize;
                let len = usize::from(arg(0)) + 1;
                let end = (at + len).min(new.bytes.len());
                let part = new.bytes.get(at..end).unwrap_or(&[]);
                let offset = (at as u32)
                    .wrapping_add(u32::from(arg(1) & 0x3).wrapping_sub(1) * u32::from(op == 3));
                used = 2;
                let _ = u.chunk(&chunk(part, offset, true));
            }
            // Arbitrary chunk bytes at an arbitrary offset, CRC good or bad.
            4 => {
                let n = usize::from(arg(0)).min(tail.len().saturating_sub(3));
                let bytes = tail.get(3..3 + n).unwrap_or(&[]);
                let _ = u.chunk(&chunk(bytes, u32::from(arg16(1)), arg(0) & 1 == 0));
                used = 3 + n;
            }
            5 => {
                let _ = u.verify(&new.sig, &board);
            }
            6 => {
                let mut sig = new.sig;
                sig.s[usize::from(arg(0)) % 32] ^= arg(1) | 1;
                used = 2;
                let _ = u.verify(&sig, &board);
            }
            7 => {
                let _ = u.commit();
            }
            8 => {
                let _ = u.abort();
            }
            9 => {
                let _ = u.confirm();
            }
            // A reset: the bootloader, then the image that booted.
            10 => {
                drop(u);
                let running = boot(&flash, old, new);
                u = build(running);
                if u.image_state() == ImageState::Trial {
                    assert_eq!(running, new.begin.version);
                }
            }
            // A power cut, in a while.
            _ => {
                let n = u32::from(arg(1));
                flash.borrow_mut().cut_power(if arg(0) & 1 == 0 {
                    PowerCut::AfterOps(n % 8)
                } else {
                    PowerCut::AfterBytes(n * 13)
                });
                used = 2;
            }
        }
        if let Ok(st) = u.status() {
            assert!(st.next_offset <= st.image_len);
            assert!(st.image_len <= u.slot_bytes());
        }
        rest = tail.get(used..).unwrap_or(&[]);
    }
    drop(u);
    boot(&flash, old, new);
});
