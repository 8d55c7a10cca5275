//! A NOR flash in RAM, for tests and the virtual node: it behaves like the
//! STM32F4's flash as the node uses it (erase sets whole pages to 0xFF;
//! programming 4-byte words only clears bits, and a word may be programmed
//! again, giving old AND new, as RM0390 allows on the F4, which has no
//! flash ECC) and it can lose power in the middle of an operation.
//!
//! Power cuts ([`PowerCut`]): after N operations (the (N+1)-th erase or
//! write does not start) or after N bytes (a write stops after its N-th
//! programmed byte, an erase after its N-th erased byte: the page is left
//! partly erased). From the cut on, every operation fails with
//! [`RamFlashError::PowerLost`] until [`RamFlash::power_on`] (the reboot).
//!
//! It counts operations, programmed bytes and erases per page (the wear
//! figure in `firmware/README.md`).

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Programming unit, bytes (the F4 at 32-bit parallelism).
pub const RAM_FLASH_WORD: usize = 4;

/// When the power goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerCut {
    /// After this many erase/write operations (the next one never starts).
    AfterOps(u32),
    /// After this many bytes programmed or erased (mid-operation).
    AfterBytes(u32),
}

/// Why an operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RamFlashError {
    /// Outside the flash.
    OutOfBounds,
    /// Not on a word (write) or page (erase) boundary.
    NotAligned,
    /// The power is off (see [`PowerCut`]).
    PowerLost,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            RamFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            RamFlashError::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

/// What a [`RamFlash`] has done so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FlashCounters {
    /// Erase and write operations started.
    pub ops: u32,
    /// Bytes programmed plus bytes erased.
    pub bytes: u32,
    /// Write operations started.
    pub writes: u32,
    /// Pages erased (all pages).
    pub erases: u32,
}

/// A NOR flash of `PAGES` pages of `PAGE` bytes in `mem` (a `Vec<u8>` on the
/// host, an array or a `&mut [u8]` without a heap). Only the first
/// `PAGE × PAGES` bytes of `mem` are used; a shorter `mem` gives fewer pages.
#[derive(Debug, Clone)]
pub struct RamFlash<B, const PAGE: usize, const PAGES: usize> {
    mem: B,
    cut: Option<PowerCut>,
    powered: bool,
    counters: FlashCounters,
    page_erases: [u32; PAGES],
}

impl<B, const PAGE: usize, const PAGES: usize> RamFlash<B, PAGE, PAGES>
where
    B: AsRef<[u8]> + AsMut<[u8]>,
{
    /// A flash over `mem`, as it is (fill it with 0xFF for an erased part).
    pub fn new(mem: B) -> Self {
        RamFlash {
            mem,
            cut: None,
            powered: true,
            counters: FlashCounters::default(),
            page_erases: [0; PAGES],
        }
    }

    /// Size in bytes (whole pages).
    pub fn size(&self) -> usize {
        (self.mem.as_ref().len() / PAGE).min(PAGES) * PAGE
    }

    /// The contents.
    pub fn bytes(&self) -> &[u8] {
        let n = self.size();
        self.mem.as_ref().get(..n).unwrap_or(&[])
    }

    /// The contents, writable (to corrupt them in a test).
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        let n = self.size();
        self.mem.as_mut().get_mut(..n).unwrap_or(&mut [])
    }

    /// Give the memory back.
    pub fn into_inner(self) -> B {
        self.mem
    }

    /// Cut the power at this point from now on (counted from this call).
    pub fn cut_power(&mut self, cut: PowerCut) {
        self.cut = Some(cut);
    }

    /// Power back on (a reboot): operations work again, no cut is pending.
    pub fn power_on(&mut self) {
        self.powered = true;
        self.cut = None;
    }

    /// False after a cut, until [`Self::power_on`].
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// Operations, bytes and erases so far.
    pub fn counters(&self) -> FlashCounters {
        self.counters
    }

    /// How often each page was erased.
    pub fn page_erases(&self) -> [u32; PAGES] {
        self.page_erases
    }

    /// Start an operation: false if the power is (now) off.
    fn start_op(&mut self) -> bool {
        if !self.powered {
            return false;
        }
        if let Some(PowerCut::AfterOps(n)) = self.cut.as_mut() {
            if *n == 0 {
                self.powered = false;
                return false;
            }
            *n -= 1;
        }
        self.counters.ops = self.counters.ops.saturating_add(1);
        true
    }

    /// One byte of work: false if the power goes before it.
    fn step_byte(&mut self) -> bool {
        if let Some(PowerCut::AfterBytes(n)) = self.cut.as_mut() {
            if *n == 0 {
                self.powered = false;
                return false;
            }
            *n -= 1;
        }
        self.counters.bytes = self.counters.bytes.saturating_add(1);
        true
    }
}

impl<B, const PAGE: usize, const PAGES: usize> ErrorType for RamFlash<B, PAGE, PAGES> {
    type Error = RamFlashError;
}

impl<B, const PAGE: usize, const PAGES: usize> ReadNorFlash for RamFlash<B, PAGE, PAGES>
where
    B: AsRef<[u8]> + AsMut<[u8]>,
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        if !self.powered {
            return Err(RamFlashError::PowerLost);
        }
        let start = offset as usize;
        let end = start
            .checked_add(bytes.len())
            .ok_or(RamFlashError::OutOfBounds)?;
        let src = self
            .bytes()
            .get(start..end)
            .ok_or(RamFlashError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.size()
    }
}

impl<B, const PAGE: usize, const PAGES: usize> NorFlash for RamFlash<B, PAGE, PAGES>
where
    B: AsRef<[u8]> + AsMut<[u8]>,
{
    const WRITE_SIZE: usize = RAM_FLASH_WORD;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let (from, to) = (from as usize, to as usize);
        if from > to || to > self.size() {
            return Err(RamFlashError::OutOfBounds);
        }
        if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) {
            return Err(RamFlashError::NotAligned);
        }
        let mut page = from / PAGE;
        while page * PAGE < to {
            if !self.start_op() {
                return Err(RamFlashError::PowerLost);
            }
            if let Some(count) = self.page_erases.get_mut(page) {
                *count = count.saturating_add(1);
            }
            self.counters.erases = self.counters.erases.saturating_add(1);
            for i in page * PAGE..(page + 1) * PAGE {
                if !self.step_byte() {
                    // Partly erased: the bytes before the cut are 0xFF.
                    return Err(RamFlashError::PowerLost);
                }
                if let Some(b) = self.mem.as_mut().get_mut(i) {
                    *b = 0xFF;
                }
            }
            page += 1;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let start = offset as usize;
        if !start.is_multiple_of(RAM_FLASH_WORD) || !bytes.len().is_multiple_of(RAM_FLASH_WORD) {
            return Err(RamFlashError::NotAligned);
        }
        let end = start
            .checked_add(bytes.len())
            .ok_or(RamFlashError::OutOfBounds)?;
        if end > self.size() {
            return Err(RamFlashError::OutOfBounds);
        }
        if !self.start_op() {
            return Err(RamFlashError::PowerLost);
        }
        self.counters.writes = self.counters.writes.saturating_add(1);
        for (i, &b) in bytes.iter().enumerate() {
            if !self.step_byte() {
                // Programmed up to the cut, the rest still erased.
                return Err(RamFlashError::PowerLost);
            }
            if let Some(cell) = self.mem.as_mut().get_mut(start + i) {
                *cell &= b;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    type Small = RamFlash<Vec<u8>, 64, 2>;

    fn flash() -> Small {
        RamFlash::new(vec![0xFF; 128])
    }

    #[test]
    fn nor_rules() {
        let mut f = flash();
        assert_eq!(f.capacity(), 128);
        f.write(4, &[1, 2, 3, 4]).unwrap();
        let mut b = [0u8; 6];
        f.read(2, &mut b).unwrap();
        assert_eq!(b, [0xFF, 0xFF, 1, 2, 3, 4]);
        // Programming again only clears bits: old AND new.
        f.write(4, &[0xFE, 0xFF, 0x02, 0xF0]).unwrap();
        f.read(4, &mut b[..4]).unwrap();
        assert_eq!(b[..4], [0, 2, 2, 0]);
        assert_eq!(f.write(2, &[0; 4]), Err(RamFlashError::NotAligned));
        assert_eq!(f.write(8, &[0; 3]), Err(RamFlashError::NotAligned));
        assert_eq!(f.write(128, &[0; 4]), Err(RamFlashError::OutOfBounds));
        assert_eq!(f.erase(0, 32), Err(RamFlashError::NotAligned));
        f.erase(0, 64).unwrap();
        assert!(f.bytes()[..64].iter().all(|&b| b == 0xFF));
        assert_eq!(f.page_erases(), [1, 0]);
        assert_eq!(f.counters().erases, 1);
        // The misaligned and out-of-range writes never start.
        assert_eq!(f.counters().ops, 3, "two writes, one erase");
        assert_eq!(f.counters().writes, 2);
        assert_eq!(f.counters().bytes, 4 + 4 + 64);
    }

    #[test]
    fn cut_after_bytes_stops_mid_write_and_mid_erase() {
        let mut f = flash();
        f.cut_power(PowerCut::AfterBytes(6));
        assert_eq!(
            f.write(0, &[0, 0, 0, 0, 0, 0, 0, 0]),
            Err(RamFlashError::PowerLost)
        );
        assert_eq!(&f.bytes()[..8], &[0, 0, 0, 0, 0, 0, 0xFF, 0xFF]);
        assert!(!f.is_powered());
        let mut b = [0u8; 1];
        assert_eq!(f.read(0, &mut b), Err(RamFlashError::PowerLost));
        f.power_on();
        f.cut_power(PowerCut::AfterBytes(3));
        assert_eq!(f.erase(0, 64), Err(RamFlashError::PowerLost));
        assert_eq!(&f.bytes()[..8], &[0xFF, 0xFF, 0xFF, 0, 0, 0, 0xFF, 0xFF]);
    }

    #[test]
    fn cut_after_ops_stops_before_an_operation() {
        let mut f = flash();
        f.cut_power(PowerCut::AfterOps(1));
        f.write(0, &[0; 4]).unwrap();
        assert_eq!(f.write(4, &[0; 4]), Err(RamFlashError::PowerLost));
        assert_eq!(&f.bytes()[4..8], &[0xFF; 4]);
        f.power_on();
        f.write(4, &[0; 4]).unwrap();
    }
}
