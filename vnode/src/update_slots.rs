//! The virtual node's update partitions: the board's boot-state sector,
//! active slot and DFU slot (`fois_firmware::platform::flash_layout`: 64,
//! 128 and 2 × 128 KiB) in RAM, each erase stalling the virtual clock by
//! its sector's time ([`StallingFlash`]). The node's updater is the
//! firmware's own [`FlashUpdater`] over the DFU slot and the boot state;
//! at every reset embassy-boot's bootloader (`BootLoader::prepare_boot`,
//! what `boot/` runs on the board) swaps a committed image in, or a failed
//! trial's image out, on these RAM flashes.
//!
//! The virtual node cannot execute the image it receives: it adopts its
//! version, read from the trailer at the end of the active slot's image
//! ([`running_version`]). Before any update the active slot holds no
//! trailer and the version is the crate's. The partitions live in memory
//! only: a restart of the process is a new board, freshly flashed.

use std::sync::{Arc, Mutex};

use embassy_boot::{BootLoader, BootLoaderConfig, State};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::platform::flash_layout::{ACTIVE, BOOT_STATE, DFU};
use fois_firmware::storage::ram_flash::RamFlashError;
use fois_firmware::update::session::Geometry;
use fois_firmware::update::transfer::UpdaterConfig;
use fois_firmware::update::{FIRMWARE_VERSION, FlashUpdater, UpdateKey};
use fois_protocol::FirmwareVersion;
use fois_protocol::update::{ImageTrailer, TRAILER_LEN};

use crate::VirtualClock;
use crate::flash::StallingFlash;

/// The boot state's sector, bytes (sector 4).
pub const STATE_SECTOR: usize = BOOT_STATE.largest_sector_bytes() as usize;
/// The slots' sector, bytes (sectors 5–7).
pub const SLOT_SECTOR: usize = ACTIVE.largest_sector_bytes() as usize;
/// Sectors of the DFU slot.
pub const DFU_SECTORS: usize = DFU.sectors as usize;

const _: () = assert!(BOOT_STATE.sectors == 1 && ACTIVE.sectors == 1);
const _: () = assert!(DFU.largest_sector_bytes() as usize == SLOT_SECTOR);

/// The swap's copy buffer: the board bootloader's (`boot/src/main.rs`).
const COPY_CHUNK: usize = 2048;

/// One partition in RAM, shared between the updater the node holds and
/// the bootloader the runner starts at a reset.
#[derive(Debug, Clone)]
pub struct SharedPartition<const PAGE: usize, const PAGES: usize>(
    Arc<Mutex<StallingFlash<PAGE, PAGES>>>,
);

impl<const PAGE: usize, const PAGES: usize> SharedPartition<PAGE, PAGES> {
    fn erased() -> Self {
        SharedPartition(Arc::new(Mutex::new(StallingFlash::new(
            vec![0xFF; PAGE * PAGES],
            None,
        ))))
    }

    /// Run `f` on the partition's flash (its bytes, its counters).
    pub fn with<T>(&self, f: impl FnOnce(&mut StallingFlash<PAGE, PAGES>) -> T) -> T {
        let mut guard = match self.0.lock() {
            Ok(g) => g,
            Err(poisoned) => poisoned.into_inner(),
        };
        f(&mut guard)
    }
}

impl<const PAGE: usize, const PAGES: usize> ErrorType for SharedPartition<PAGE, PAGES> {
    type Error = RamFlashError;
}

impl<const PAGE: usize, const PAGES: usize> ReadNorFlash for SharedPartition<PAGE, PAGES> {
    const READ_SIZE: usize = StallingFlash::<PAGE, PAGES>::READ_SIZE;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamFlashError> {
        self.with(|f| f.read(offset, bytes))
    }
    fn capacity(&self) -> usize {
        PAGE * PAGES
    }
}

impl<const PAGE: usize, const PAGES: usize> NorFlash for SharedPartition<PAGE, PAGES> {
    const WRITE_SIZE: usize = StallingFlash::<PAGE, PAGES>::WRITE_SIZE;
    const ERASE_SIZE: usize = StallingFlash::<PAGE, PAGES>::ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), RamFlashError> {
        self.with(|f| f.erase(from, to))
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamFlashError> {
        self.with(|f| f.write(offset, bytes))
    }
}

/// The boot-state partition.
pub type StatePartition = SharedPartition<STATE_SECTOR, 1>;
/// The active slot.
pub type ActivePartition = SharedPartition<SLOT_SECTOR, 1>;
/// The DFU slot.
pub type DfuPartition = SharedPartition<SLOT_SECTOR, DFU_SECTORS>;

/// The virtual node's updater: the firmware's, over the RAM partitions.
pub type VirtualUpdater = FlashUpdater<DfuPartition, StatePartition>;

/// The three partitions of one virtual board.
#[derive(Debug, Clone)]
pub struct UpdatePartitions {
    /// embassy-boot's state.
    pub state: StatePartition,
    /// The running image.
    pub active: ActivePartition,
    /// The downloaded image (and the swap's page).
    pub dfu: DfuPartition,
}

impl UpdatePartitions {
    /// Erased partitions (a board flashed by a probe with the crate's
    /// image, which the virtual node does not hold: no trailer).
    pub fn erased() -> Self {
        UpdatePartitions {
            state: SharedPartition::erased(),
            active: SharedPartition::erased(),
            dfu: SharedPartition::erased(),
        }
    }

    /// From now on every erase and program stalls `clock`.
    pub fn stall_on(&self, clock: &VirtualClock) {
        self.state.with(|f| f.set_clock(Some(clock.clone())));
        self.active.with(|f| f.set_clock(Some(clock.clone())));
        self.dfu.with(|f| f.set_clock(Some(clock.clone())));
    }

    /// The board's boot stage at a reset: embassy-boot's `prepare_boot`
    /// (swap a committed image in, or revert a trial that was not
    /// confirmed). A flash error would reset the board and resume: the RAM
    /// flash has none, so one run; its error is given back.
    pub fn run_bootloader(&self) -> Result<State, embassy_boot::BootError> {
        let mut loader = BootLoader::new(BootLoaderConfig {
            active: self.active.clone(),
            dfu: self.dfu.clone(),
            state: self.state.clone(),
        });
        let mut buf = [0u8; COPY_CHUNK];
        loader.prepare_boot(&mut buf)
    }

    /// The running image's version: its trailer's, else the crate's. The
    /// image is looked for below the transfer's record (which the swap
    /// copies along: `update::session`).
    pub fn running_version(&self) -> FirmwareVersion {
        let image_bytes = Geometry::new::<DfuPartition>(ACTIVE.bytes(), DFU.bytes() as usize)
            .map_or(0, |g| g.slot_bytes() as usize);
        self.active
            .with(|f| trailer_version(f.bytes().get(..image_bytes).unwrap_or(&[])))
            .unwrap_or(FIRMWARE_VERSION)
    }

    /// The updater the booted image builds (its version read from the
    /// active slot), checking images with `key`.
    pub fn updater(&self, key: UpdateKey) -> VirtualUpdater {
        FlashUpdater::new(
            self.dfu.clone(),
            self.state.clone(),
            UpdaterConfig {
                active_len: ACTIVE.bytes(),
                running: self.running_version(),
                key,
            },
        )
    }
}

/// The version in the trailer of the image at the start of `slot` (the
/// part of the active slot an image may fill): the image ends at its last
/// byte that is not erased (a trailer ends
/// in zeros), its last [`TRAILER_LEN`] bytes are a trailer whose body
/// length agrees. `None`: no image with a trailer.
pub fn trailer_version(slot: &[u8]) -> Option<FirmwareVersion> {
    let end = slot.iter().rposition(|&b| b != 0xFF)? + 1;
    let bytes: &[u8; TRAILER_LEN] = slot
        .get(end.checked_sub(TRAILER_LEN)?..end)?
        .try_into()
        .ok()?;
    let trailer = ImageTrailer::parse(bytes).ok()?;
    (trailer.body_len as usize + TRAILER_LEN == end).then_some(trailer.version)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn trailer(body_len: u32, version: FirmwareVersion) -> [u8; TRAILER_LEN] {
        ImageTrailer {
            body_len,
            version,
            flags: 0,
            board: fois_protocol::Hello::board_from_str("virtual-f446"),
        }
        .to_bytes()
    }

    #[test]
    fn the_version_is_the_trailers_at_the_images_end() {
        let mut slot = vec![0xFF; 4096];
        assert_eq!(trailer_version(&slot), None);
        slot[..1000].fill(0xFF);
        slot[..999]
            .iter_mut()
            .enumerate()
            .for_each(|(i, b)| *b = i as u8);
        slot[999] = 0x42;
        slot[1000..1064].copy_from_slice(&trailer(1000, [1, 2, 3]));
        assert_eq!(trailer_version(&slot), Some([1, 2, 3]));
        // A body length that disagrees: no image.
        slot[1000..1064].copy_from_slice(&trailer(999, [1, 2, 3]));
        assert_eq!(trailer_version(&slot), None);
        // Bytes after the trailer: not an image ending in a trailer.
        slot[1000..1064].copy_from_slice(&trailer(1000, [1, 2, 3]));
        slot[2000] = 0;
        assert_eq!(trailer_version(&slot), None);
    }

    #[test]
    fn erased_partitions_boot_the_crates_version_confirmed() {
        let p = UpdatePartitions::erased();
        assert_eq!(p.run_bootloader().unwrap(), State::Boot);
        assert_eq!(p.running_version(), FIRMWARE_VERSION);
        let u = p.updater(UpdateKey::NONE);
        use fois_firmware::update::UpdateSlots;
        assert_eq!(u.image_state(), fois_protocol::ImageState::Confirmed);
        assert!(u.slot_bytes() > 120 * 1024 && u.slot_bytes() <= ACTIVE.bytes());
    }
}
