//! Persistence: the node keeps one record (config, dark baseline, optical
//! gain) across resets and power losses.
//!
//! - [`Storage`]: the seam the node writes its record through (a flash
//!   store on the board, [`MemStorage`] or a [`ram_flash::RamFlash`] in
//!   tests and the virtual node);
//! - [`record`]: the record's bytes (versioned, CRC);
//! - [`flash_store`]: the [`Storage`] on NOR flash (power-fail safe,
//!   wear-levelled over two sectors);
//! - [`ram_flash`]: a NOR flash in RAM that can lose power mid-operation;
//! - [`supply`]: flash writes wait for a healthy supply;
//! - [`migrate`]: the store's one move from the layout before the
//!   bootloader (sectors 6–7) to sectors 2–3, reading the old one with
//!   [`old_store`].
//!
//! When the node saves (coalescing, rate limit) is `crate::node::saving`;
//! booting without the store after panic resets is `crate::platform::boot`.

pub mod flash_store;
pub mod migrate;
pub mod old_store;
pub mod ram_flash;
pub mod record;
pub mod supply;

/// Why a [`Storage`] operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StorageError {
    /// The medium could not be read.
    Read,
    /// Erasing or programming failed.
    Write,
    /// The record does not fit the medium (or the caller's buffer).
    TooLarge,
    /// The flash range does not suit the store (see [`flash_store::FlashStore::new`]).
    Layout,
}

/// One persisted record (config + baseline): a flash sector on the board, RAM
/// in tests. The record is self-delimiting (see [`record`]), so `read` may
/// return more bytes than were written (erased flash reads 0xFF).
pub trait Storage {
    /// Copy the stored bytes into `buf`; returns how many were copied (0:
    /// nothing was ever stored). An error means the medium holds something
    /// unreadable: the node then raises `CONFIG_DEFAULTED`.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError>;
    /// Replace the stored record with `data`.
    fn write(&mut self, data: &[u8]) -> Result<(), StorageError>;
    /// Replace whatever the medium holds with `data`, without reading or
    /// parsing what is there first (after a skipped read at boot: the
    /// stored data may be what made the node fail). A flash store erases
    /// and writes afresh; the default is [`Self::write`].
    fn overwrite(&mut self, data: &[u8]) -> Result<(), StorageError> {
        self.write(data)
    }
}

impl<T: Storage + ?Sized> Storage for &mut T {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        (**self).read(buf)
    }
    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        (**self).write(data)
    }
    fn overwrite(&mut self, data: &[u8]) -> Result<(), StorageError> {
        (**self).overwrite(data)
    }
}

/// Capacity of [`MemStorage`], bytes (larger than any record).
pub const MEM_STORAGE_LEN: usize = 256;

/// A RAM [`Storage`] for tests and the virtual node. Starts empty (like
/// erased flash); `fail_writes` makes every write fail.
#[derive(Debug, Clone)]
pub struct MemStorage {
    data: [u8; MEM_STORAGE_LEN],
    len: usize,
    /// When true, `write` returns [`StorageError::Write`] and keeps the old record.
    pub fail_writes: bool,
    /// Number of successful writes (flash wear, for tests).
    pub writes: u32,
}

impl Default for MemStorage {
    fn default() -> Self {
        Self::new()
    }
}

impl MemStorage {
    /// An empty store (as erased flash: nothing recorded).
    pub const fn new() -> Self {
        MemStorage {
            data: [0xFF; MEM_STORAGE_LEN],
            len: 0,
            fail_writes: false,
            writes: 0,
        }
    }

    /// A store that already holds these bytes (e.g. a corrupt record).
    pub fn with_bytes(bytes: &[u8]) -> Self {
        let mut s = Self::new();
        let n = bytes.len().min(MEM_STORAGE_LEN);
        if let (Some(dst), Some(src)) = (s.data.get_mut(..n), bytes.get(..n)) {
            dst.copy_from_slice(src);
        }
        s.len = n;
        s
    }

    /// The bytes stored.
    pub fn bytes(&self) -> &[u8] {
        self.data.get(..self.len).unwrap_or(&[])
    }
}

impl Storage for MemStorage {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        let n = self.len.min(buf.len());
        match (buf.get_mut(..n), self.data.get(..n)) {
            (Some(dst), Some(src)) => {
                dst.copy_from_slice(src);
                Ok(n)
            }
            _ => Err(StorageError::Read),
        }
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        if self.fail_writes {
            return Err(StorageError::Write);
        }
        let dst = self
            .data
            .get_mut(..data.len())
            .ok_or(StorageError::TooLarge)?;
        dst.copy_from_slice(data);
        self.len = data.len();
        self.writes = self.writes.wrapping_add(1);
        Ok(())
    }
}
