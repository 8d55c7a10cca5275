//! The virtual node's config store: the board's [`FlashStore`]
//! (sequential-storage) over a [`VirtualFlash`] (two 16 KiB sectors, the
//! board's `CONFIG_STORE`), shared between the runner and every `Node` it
//! builds, optionally mirrored to a state file. A state file of the layout
//! before the bootloader (the store then two 128 KiB sectors) is migrated
//! with the firmware's own `storage::migrate` ([`SharedStorage::open_file`]).

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use fois_firmware::platform::flash_layout::OLD_CONFIG_STORE;
use fois_firmware::storage::flash_store::FlashStore;
use fois_firmware::storage::migrate::{Migration, migrate};
use fois_firmware::storage::ram_flash::RamFlash;
use fois_firmware::{MemStorage, Storage, StorageError};

use crate::VirtualClock;
use crate::flash::{FLASH_BYTES, VirtualFlash};

/// Bytes of a state file written before the store moved (the old store's
/// two 128 KiB sectors).
pub const OLD_FLASH_BYTES: usize = OLD_CONFIG_STORE.bytes() as usize;
const OLD_SECTOR_BYTES: usize = OLD_CONFIG_STORE.largest_sector_bytes() as usize;
const OLD_SECTORS: usize = OLD_CONFIG_STORE.sectors as usize;
const _: () = assert!(OLD_SECTOR_BYTES * OLD_SECTORS == OLD_FLASH_BYTES);

/// The node's flash store: the board's [`FlashStore`] over a
/// [`VirtualFlash`], shared with the runner (so it survives a `Reset` and
/// can be inspected), optionally mirrored to a file (the raw flash image,
/// so it survives the process, like flash survives a power cycle).
#[derive(Clone)]
pub struct SharedStorage {
    store: Arc<Mutex<FlashStore<VirtualFlash>>>,
    file: Option<PathBuf>,
}

impl std::fmt::Debug for SharedStorage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SharedStorage")
            .field("file", &self.file)
            .finish_non_exhaustive()
    }
}

fn flash_store(image: Vec<u8>) -> std::io::Result<FlashStore<VirtualFlash>> {
    FlashStore::new(VirtualFlash::new(image, None), 0..FLASH_BYTES as u32)
        .map_err(|e| std::io::Error::other(format!("flash store: {e:?}")))
}

impl SharedStorage {
    /// Erased flash (a first boot), then `initial`'s record written to it
    /// if it holds one.
    pub fn new(initial: MemStorage) -> Self {
        Self::try_new(initial).unwrap_or_else(|_| SharedStorage::erased())
    }

    fn erased() -> Self {
        // The geometry is the firmware's own; FlashStore::new cannot refuse it.
        #[allow(clippy::expect_used)]
        let store = flash_store(vec![0xFF; FLASH_BYTES]).expect("two whole pages");
        SharedStorage {
            store: Arc::new(Mutex::new(store)),
            file: None,
        }
    }

    fn try_new(mut initial: MemStorage) -> Result<Self, StorageError> {
        let this = Self::erased();
        let mut buf = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let n = initial.read(&mut buf)?;
        if n > 0 {
            let record = buf.get(..n).ok_or(StorageError::Read)?;
            this.store
                .lock()
                .map_err(|_| StorageError::Write)?
                .write(record)?;
        }
        Ok(this)
    }

    /// Backed by `path`: starts with its flash image (erased flash if the
    /// file does not exist) and rewrites it after every save. A file of
    /// the old layout is migrated ([`Self::open_file`]); any other size is
    /// an error (the node would otherwise boot on defaults without a word).
    pub fn with_file(path: &Path) -> std::io::Result<Self> {
        Self::open_file(path).map(|(s, _)| s)
    }

    /// [`Self::with_file`], saying whether the file was of the layout
    /// before the store moved ([`OLD_FLASH_BYTES`]: two 128 KiB sectors):
    /// its newest record is then moved into the new store by the
    /// firmware's `storage::migrate`, as a board's first boot after the
    /// move does, and the file is rewritten in the new layout (so this
    /// happens once). `Some(NothingToMove)`: an old file without a record.
    pub fn open_file(path: &Path) -> std::io::Result<(Self, Option<Migration>)> {
        let image = match std::fs::read(path) {
            Ok(bytes) if bytes.len() == FLASH_BYTES => bytes,
            Ok(bytes) if bytes.len() == OLD_FLASH_BYTES => {
                let this = SharedStorage {
                    file: Some(path.to_path_buf()),
                    ..SharedStorage::erased()
                };
                let mut old = RamFlash::<Vec<u8>, OLD_SECTOR_BYTES, OLD_SECTORS>::new(bytes);
                let migration = migrate(&mut this.clone(), &mut old, 0..OLD_FLASH_BYTES as u32)
                    .map_err(|e| std::io::Error::other(format!("migrating the store: {e:?}")))?;
                this.save_file()?;
                return Ok((this, Some(migration)));
            }
            Ok(bytes) => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!(
                        "{} bytes, not a flash image of {FLASH_BYTES} bytes (nor of {OLD_FLASH_BYTES}, the layout before the bootloader)",
                        bytes.len()
                    ),
                ));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => vec![0xFF; FLASH_BYTES],
            Err(e) => return Err(e),
        };
        Ok((
            SharedStorage {
                store: Arc::new(Mutex::new(flash_store(image)?)),
                file: Some(path.to_path_buf()),
            },
            None,
        ))
    }

    /// Erased flash mirrored to `path` (a state file that could not be
    /// read: saves try to rewrite it).
    pub(crate) fn erased_with_file(path: &Path) -> Self {
        SharedStorage {
            file: Some(path.to_path_buf()),
            ..SharedStorage::erased()
        }
    }

    /// Write the flash image to the state file, if there is one.
    fn save_file(&self) -> std::io::Result<()> {
        let Some(path) = &self.file else {
            return Ok(());
        };
        let mut store = self
            .store
            .lock()
            .map_err(|_| std::io::Error::other("store lock poisoned"))?;
        std::fs::write(path, store.flash_mut().bytes())
    }

    /// The newest record now (empty storage if there is none or the flash
    /// holds no readable record).
    pub fn snapshot(&self) -> MemStorage {
        let mut buf = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let n = self
            .store
            .lock()
            .ok()
            .and_then(|mut s| s.read(&mut buf).ok())
            .unwrap_or(0);
        MemStorage::with_bytes(buf.get(..n).unwrap_or(&[]))
    }

    /// Write `record` if the flash holds none (erased, or nothing readable
    /// as a record); a stored record is left as it is. Returns whether it
    /// wrote.
    pub fn write_if_empty(&self, record: &fois_firmware::storage::record::Record) -> bool {
        let mut probe = self.clone();
        let mut buf = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let empty = match probe.read(&mut buf) {
            Ok(n) => matches!(
                fois_firmware::storage::record::decode(buf.get(..n).unwrap_or(&[])),
                Err(fois_firmware::storage::record::LoadError::Empty)
            ),
            Err(_) => false,
        };
        if !empty {
            return false;
        }
        let mut out = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let n = fois_firmware::storage::record::encode(record, &mut out);
        n > 0 && probe.write(out.get(..n).unwrap_or(&[])).is_ok()
    }

    /// From now on every erase and write stalls `clock` as the board's
    /// flash stalls its CPU.
    pub fn stall_on(&self, clock: &VirtualClock) {
        self.with_flash(|f| f.set_clock(Some(clock.clone())));
    }

    /// Run `f` on the flash (to read its counters or damage it in a test).
    pub fn with_flash<T>(&self, f: impl FnOnce(&mut VirtualFlash) -> T) -> Option<T> {
        self.store.lock().ok().map(|mut s| f(s.flash_mut()))
    }
}

impl Storage for SharedStorage {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        self.store.lock().map_err(|_| StorageError::Read)?.read(buf)
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        let mut store = self.store.lock().map_err(|_| StorageError::Write)?;
        store.write(data)?;
        if let Some(path) = &self.file {
            std::fs::write(path, store.flash_mut().bytes()).map_err(|_| StorageError::Write)?;
        }
        Ok(())
    }

    fn overwrite(&mut self, data: &[u8]) -> Result<(), StorageError> {
        let mut store = self.store.lock().map_err(|_| StorageError::Write)?;
        store.overwrite(data)?;
        if let Some(path) = &self.file {
            std::fs::write(path, store.flash_mut().bytes()).map_err(|_| StorageError::Write)?;
        }
        Ok(())
    }
}

/// The record a factory-calibrated node has in its flash before its first
/// boot: the default config, no dark baseline, the gain calibration
/// `(gain, relative sd)` and, as the learned gain, the same (the node's
/// prior is then the calibration itself, not widened).
pub fn factory_record(gain: f64, rel_sd: f64) -> fois_firmware::storage::record::Record {
    let estimate = fois_firmware::calibration::gain::to_estimate(gain as f32, rel_sd as f32);
    fois_firmware::storage::record::Record {
        config: fois_protocol::Config::default(),
        baseline: None,
        gain: Some(estimate),
        gain_calibration: Some(estimate),
        link: fois_protocol::LinkSettings::default(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use fois_firmware::storage::record;

    #[test]
    fn a_state_file_of_the_old_layout_is_migrated_once() {
        let dir = std::env::temp_dir().join(format!("fois-vnode-migrate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("state.bin");
        // An old file: the store on two 128 KiB sectors, holding a record.
        let rec = factory_record(0.9, 0.02);
        let mut bytes = [0u8; record::MAX_RECORD];
        let n = record::encode(&rec, &mut bytes);
        let old =
            RamFlash::<Vec<u8>, OLD_SECTOR_BYTES, OLD_SECTORS>::new(vec![0xFF; OLD_FLASH_BYTES]);
        let mut store = FlashStore::new(old, 0..OLD_FLASH_BYTES as u32).unwrap();
        store.write(&bytes[..n]).unwrap();
        std::fs::write(&path, store.flash_mut().bytes()).unwrap();

        let (migrated, how) = SharedStorage::open_file(&path).unwrap();
        assert!(matches!(how, Some(Migration::Moved { .. })), "{how:?}");
        let mut buf = [0u8; record::MAX_RECORD];
        let m = migrated.snapshot().read(&mut buf).unwrap();
        assert_eq!(record::decode(&buf[..m]).unwrap(), rec);
        // Rewritten in the new layout: the next start reads it as it is.
        assert_eq!(std::fs::metadata(&path).unwrap().len(), FLASH_BYTES as u64);
        let (again, how) = SharedStorage::open_file(&path).unwrap();
        assert_eq!(how, None);
        let m = again.snapshot().read(&mut buf).unwrap();
        assert_eq!(record::decode(&buf[..m]).unwrap(), rec);
        // An old file without a record: nothing to move, the new layout.
        std::fs::write(&path, vec![0xFF; OLD_FLASH_BYTES]).unwrap();
        let (_, how) = SharedStorage::open_file(&path).unwrap();
        assert_eq!(how, Some(Migration::NothingToMove));
        assert_eq!(std::fs::metadata(&path).unwrap().len(), FLASH_BYTES as u64);
        // Any other size is refused.
        std::fs::write(&path, vec![0xFF; 1000]).unwrap();
        assert!(SharedStorage::open_file(&path).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
