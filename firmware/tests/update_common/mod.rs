//! The update tests' flash: one NOR flash in RAM (`RamFlash`, power cuts
//! and all) cut into the board's partitions — config store, boot state,
//! active slot, DFU slot — at a small scale (4 KiB pages), embassy-boot's
//! bootloader run on it, signed test images, and the test key pair (its
//! seed in `tests/keys/`: a test key, never a release's).
#![allow(dead_code)]

use std::cell::RefCell;
use std::rc::Rc;

use embassy_boot::{AlignedBuffer, BootLoader, BootLoaderConfig, State};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::storage::ram_flash::{RamFlash, RamFlashError};
use fois_firmware::update::transfer::UpdaterConfig;
use fois_firmware::update::{FlashUpdater, UpdateKey};
use fois_protocol::update::{ImageTrailer, TRAILER_LEN, image_flags};
use fois_protocol::{ChunkData, FirmwareVersion, ImageSignature, UpdateBegin, UpdateChunk};

/// Erase unit of the test flash.
pub const PAGE: usize = 4096;
/// Config store, boot state, active slot, DFU slot (one page larger).
pub const CONFIG_AT: u32 = 0;
pub const CONFIG_LEN: u32 = 2 * PAGE as u32;
pub const STATE_AT: u32 = CONFIG_AT + CONFIG_LEN;
pub const STATE_LEN: u32 = PAGE as u32;
pub const ACTIVE_AT: u32 = STATE_AT + STATE_LEN;
pub const ACTIVE_LEN: u32 = 4 * PAGE as u32;
pub const DFU_AT: u32 = ACTIVE_AT + ACTIVE_LEN;
pub const DFU_LEN: u32 = ACTIVE_LEN + PAGE as u32;
pub const PAGES: usize = ((DFU_AT + DFU_LEN) as usize) / PAGE;

/// The board's name in the test images' trailers.
pub const BOARD: &str = "sim";

pub type Flash = RamFlash<Vec<u8>, PAGE, PAGES>;
pub type Shared = Rc<RefCell<Flash>>;

/// A partition of the shared flash.
pub struct Part {
    pub flash: Shared,
    pub at: u32,
    pub len: u32,
}

impl ErrorType for Part {
    type Error = RamFlashError;
}

impl ReadNorFlash for Part {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamFlashError> {
        if offset as usize + bytes.len() > self.len as usize {
            return Err(RamFlashError::OutOfBounds);
        }
        self.flash.borrow_mut().read(self.at + offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.len as usize
    }
}

impl NorFlash for Part {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = PAGE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), RamFlashError> {
        if to > self.len || from > to {
            return Err(RamFlashError::OutOfBounds);
        }
        self.flash.borrow_mut().erase(self.at + from, self.at + to)
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamFlashError> {
        if offset as usize + bytes.len() > self.len as usize {
            return Err(RamFlashError::OutOfBounds);
        }
        self.flash.borrow_mut().write(self.at + offset, bytes)
    }
}

pub fn part(flash: &Shared, at: u32, len: u32) -> Part {
    Part {
        flash: flash.clone(),
        at,
        len,
    }
}

pub type Updater = FlashUpdater<Part, Part>;

/// The test key pair.
pub fn keypair() -> salty::Keypair {
    let hex = include_str!("../keys/test-update-ed25519.seed").trim();
    let mut seed = [0u8; 32];
    for (i, b) in seed.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap();
    }
    salty::Keypair::from(&seed)
}

pub fn test_key() -> UpdateKey {
    UpdateKey::from_bytes(keypair().public.to_bytes())
}

/// A signed image: `body | trailer`, its digest and signature.
#[derive(Clone)]
pub struct Image {
    pub bytes: Vec<u8>,
    pub version: FirmwareVersion,
    pub sha512: [u8; 64],
    pub signature: ImageSignature,
}

impl Image {
    pub fn begin(&self) -> UpdateBegin {
        let mut digest = [0u8; 32];
        digest.copy_from_slice(&self.sha512[..32]);
        UpdateBegin {
            image_len: self.bytes.len() as u32,
            version: self.version,
            image_digest: digest,
        }
    }
}

/// A body of `body_len` seeded bytes for `board`, version, flags; signed
/// with `key` (the SHA-512 of `body | trailer`, as embassy-boot checks).
pub fn image_for(
    body_len: usize,
    seed: u8,
    version: FirmwareVersion,
    flags: u8,
    board: &str,
    key: &salty::Keypair,
) -> Image {
    let mut bytes: Vec<u8> = (0..body_len)
        .map(|i| {
            (i as u32)
                .wrapping_mul(2_654_435_761)
                .rotate_left(u32::from(seed)) as u8
                ^ seed
        })
        .collect();
    let trailer = ImageTrailer {
        body_len: body_len as u32,
        version,
        flags,
        board: fois_protocol::Hello::board_from_str(board),
    };
    bytes.extend_from_slice(&trailer.to_bytes());
    sign(bytes, version, key)
}

/// Sign `bytes` as they are (a tampered image keeps its old signature by
/// taking the signature of another call).
pub fn sign(bytes: Vec<u8>, version: FirmwareVersion, key: &salty::Keypair) -> Image {
    let sha512 = salty::Sha512::new().updated(&bytes).finalize();
    let signature = ImageSignature::from_bytes(&key.sign(&sha512).to_bytes());
    Image {
        bytes,
        version,
        sha512,
        signature,
    }
}

/// A newer image for the board.
pub fn image(body_len: usize, seed: u8, version: FirmwareVersion) -> Image {
    image_for(body_len, seed, version, 0, BOARD, &keypair())
}

/// A deliberate, signed downgrade.
pub fn downgrade(body_len: usize, seed: u8, version: FirmwareVersion) -> Image {
    image_for(
        body_len,
        seed,
        version,
        image_flags::DOWNGRADE,
        BOARD,
        &keypair(),
    )
}

pub const TRAILER: usize = TRAILER_LEN;

/// The chunk at `offset` of at most `max` bytes.
pub fn chunk(img: &Image, offset: usize, max: usize) -> UpdateChunk {
    let end = (offset + max).min(img.bytes.len());
    let data = &img.bytes[offset..end];
    UpdateChunk {
        offset: offset as u32,
        crc32: crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(data),
        data: ChunkData::new(data).unwrap(),
    }
}

/// A fresh board flash: erased, the config store filled with a pattern,
/// `running` programmed into the active slot (as a probe flashes it).
pub fn board_flash(running: &Image) -> Shared {
    let mut mem = vec![0xFFu8; PAGES * PAGE];
    for (i, b) in mem[CONFIG_AT as usize..(CONFIG_AT + CONFIG_LEN) as usize]
        .iter_mut()
        .enumerate()
    {
        *b = (i % 251) as u8;
    }
    mem[ACTIVE_AT as usize..ACTIVE_AT as usize + running.bytes.len()]
        .copy_from_slice(&running.bytes);
    Rc::new(RefCell::new(Flash::new(mem)))
}

/// The config store's bytes are the pattern `board_flash` wrote.
pub fn config_untouched(flash: &Shared) -> bool {
    let f = flash.borrow();
    f.bytes()[CONFIG_AT as usize..(CONFIG_AT + CONFIG_LEN) as usize]
        .iter()
        .enumerate()
        .all(|(i, &b)| b == (i % 251) as u8)
}

/// Run embassy-boot's bootloader (`prepare_boot`) as the board's boot
/// stage does at each reset; a cut in it is followed by another reset
/// (power back on) and another run. Returns the boot state it left.
pub fn run_bootloader(flash: &Shared) -> State {
    for _ in 0..1_000 {
        // A reset: power back on if it was cut (an armed cut stays armed).
        if !flash.borrow().is_powered() {
            flash.borrow_mut().power_on();
        }
        let mut bl = BootLoader::new(BootLoaderConfig {
            active: part(flash, ACTIVE_AT, ACTIVE_LEN),
            dfu: part(flash, DFU_AT, DFU_LEN),
            state: part(flash, STATE_AT, STATE_LEN),
        });
        let mut buf = AlignedBuffer([0u8; 1024]);
        if let Ok(state) = bl.prepare_boot(&mut buf.0) {
            return state;
        }
    }
    panic!("the bootloader never finished");
}

/// Which of `images` the active slot holds (`None`: neither — a node that
/// cannot boot).
pub fn active_image(flash: &Shared, images: &[&Image]) -> Option<FirmwareVersion> {
    let f = flash.borrow();
    let active = &f.bytes()[ACTIVE_AT as usize..(ACTIVE_AT + ACTIVE_LEN) as usize];
    images
        .iter()
        .find(|img| active[..img.bytes.len()] == img.bytes[..])
        .map(|img| img.version)
}

/// The updater as the booted image builds it.
pub fn updater(flash: &Shared, running: FirmwareVersion) -> Updater {
    FlashUpdater::new(
        part(flash, DFU_AT, DFU_LEN),
        part(flash, STATE_AT, STATE_LEN),
        UpdaterConfig {
            active_len: ACTIVE_LEN,
            running,
            key: test_key(),
        },
    )
}
