//! What survives a reset, and what the node does with it at boot: the
//! board keeps a few words in the STM32's backup registers (RTC_BKPxR,
//! RM0390 §22: kept across every reset but a power loss or a backup domain
//! reset), each record with a CRC so that garbage reads as nothing.
//!
//! - **Unhealthy resets** ([`PanicRecord`]): the panic handler records the
//!   source line, counts the panic resets in a row and resets at once
//!   ([`record_panic`]). Every boot also sets a *booting* marker that a run
//!   of [`HEALTHY_AFTER_MS`] clears ([`healthy`]) and a commanded reset
//!   clears ([`commanded_reset`]): a boot that finds the marker still set
//!   after a watchdog, window-watchdog, low-power, software or unknown
//!   reset counts that reset like a panic (a hang or a lockup ends in the
//!   watchdog with no panic). [`plan_boot`] reports a panic once
//!   (`EventKind::PanicReset`) and, after [`PANIC_RESETS_BEFORE_SKIP`]
//!   unhealthy resets in a row, boots without reading the flash store
//!   (`STORE_SKIPPED`: a fault that stored data causes would otherwise
//!   repeat at every boot). A pin reset, a brown-out and a power-on end
//!   the row.
//! - **The ice rule's state** ([`RuleSnapshot`]): after any reset that kept
//!   the backup domain powered — watchdog, software, pin, panic and a
//!   brown-out alone (BORRSTF without PORRSTF: V_DD sagged below the BOR
//!   level but not below the power-on reset's) — the node comes back in the
//!   state it had: an alarm holds from the first instant instead of waiting
//!   `onset_frames` for the ice to be seen again, and its acknowledgement
//!   is kept. After a power-on (PORRSTF) it starts dry (the backup
//!   registers are powered from V_BAT, which the NUCLEO ties to V_DD: a
//!   power loss clears them anyway). [`ResetCause::from_flags`] reads the
//!   RCC's reset flags.
//! - **Skipping the store** ([`SkippableStorage`]): a skipped store reads as
//!   empty (the defaults), and its first save starts the store afresh
//!   (erases it and writes the record, never parsing what was there), so a
//!   host can overwrite a bad record remotely.
//!
//! The words are plain `u32`s: the board reads and writes the registers,
//! the host tests an array.

use fois_protocol::framing::CRC;
use fois_protocol::{DetectorState, ResetReason};

use crate::ice_rule::Rule;
use crate::storage::{Storage, StorageError};

/// Unhealthy resets (panics, or watchdog and other resets before a boot
/// became healthy) in a row after which the node boots without reading
/// its flash store.
pub const PANIC_RESETS_BEFORE_SKIP: u8 = 3;
/// Uptime after which a boot counts as healthy (the row of panic resets
/// ends), ms.
pub const HEALTHY_AFTER_MS: u64 = 60_000;
/// Words of a [`PanicRecord`].
pub const PANIC_WORDS: usize = 3;
/// Words of a [`RuleSnapshot`].
pub const RULE_WORDS: usize = 2;

/// Marks the records' first word (and their layout version).
const PANIC_MAGIC: u32 = 0xF0_15_00_00;
const RULE_MAGIC: u32 = 0x1C_E5_00_00;
const MAGIC_MASK: u32 = 0xFFFF_0000;

fn crc(words: &[u32]) -> u32 {
    let mut digest = CRC.digest();
    for w in words {
        digest.update(&w.to_le_bytes());
    }
    digest.finalize()
}

/// The panic bookkeeping in the backup registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PanicRecord {
    /// Panic resets in a row, the last one included.
    pub resets_in_row: u8,
    /// Source line of the last panic (0: unknown, e.g. a HardFault).
    pub line: u32,
    /// Set by the panic handler, cleared by the boot that reported it.
    pub pending: bool,
    /// Set by every boot, cleared once it ran [`HEALTHY_AFTER_MS`] or
    /// before a commanded reset.
    pub booting: bool,
}

impl PanicRecord {
    /// The record as backup-register words (magic, count, pending,
    /// booting; line; CRC).
    pub fn encode(&self) -> [u32; PANIC_WORDS] {
        let w0 = PANIC_MAGIC
            | (u32::from(self.booting) << 9)
            | (u32::from(self.pending) << 8)
            | u32::from(self.resets_in_row);
        let w1 = self.line;
        [w0, w1, crc(&[w0, w1])]
    }

    /// The record in `words`, or `None` for anything else (erased, garbage,
    /// a damaged word).
    pub fn decode(words: [u32; PANIC_WORDS]) -> Option<Self> {
        let [w0, w1, c] = words;
        if w0 & MAGIC_MASK != PANIC_MAGIC || w0 & 0xFC00 != 0 || crc(&[w0, w1]) != c {
            return None;
        }
        Some(PanicRecord {
            resets_in_row: (w0 & 0xFF) as u8,
            line: w1,
            pending: w0 & 0x100 != 0,
            booting: w0 & 0x200 != 0,
        })
    }
}

/// What the panic handler writes: one more panic reset in a row, at `line`.
pub fn record_panic(words: [u32; PANIC_WORDS], line: u32) -> [u32; PANIC_WORDS] {
    let before = PanicRecord::decode(words).unwrap_or_default();
    PanicRecord {
        resets_in_row: before.resets_in_row.saturating_add(1),
        line,
        pending: true,
        booting: before.booting,
    }
    .encode()
}

/// The RCC's reset flags (RCC_CSR, RM0390 §6.3.21), as read at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResetFlags {
    /// LPWRRSTF: low-power reset.
    pub low_power: bool,
    /// WWDGRSTF: window watchdog.
    pub window_watchdog: bool,
    /// IWDGRSTF: independent watchdog.
    pub independent_watchdog: bool,
    /// SFTRSTF: software reset (a commanded reset, a panic).
    pub software: bool,
    /// PORRSTF: power-on / power-down reset (V_DD below ≈ 1.7 V).
    pub power_on: bool,
    /// PINRST: the NRST pin (also pulsed by every internal reset).
    pub pin: bool,
    /// BORRSTF: brown-out reset (set by a power-on reset too).
    pub brown_out: bool,
}

/// Why the chip reset, and whether the backup registers lived through it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResetCause {
    /// The reason reported in `Hello` (a brown-out alone is reported as
    /// `PowerOn`: the protocol has no reason of its own for it).
    pub reason: ResetReason,
    /// The supply fell below the power-on reset's level: the backup
    /// registers hold nothing of the run before.
    pub power_lost: bool,
}

impl ResetCause {
    /// The cause from the flags. The most specific flag wins (a watchdog
    /// or software reset also pulses NRST, so PINRST is set with them).
    pub fn from_flags(f: ResetFlags) -> ResetCause {
        let reason = if f.independent_watchdog {
            ResetReason::IndependentWatchdog
        } else if f.window_watchdog {
            ResetReason::WindowWatchdog
        } else if f.low_power {
            ResetReason::LowPower
        } else if f.software {
            ResetReason::Software
        } else if f.power_on || f.brown_out {
            ResetReason::PowerOn
        } else if f.pin {
            ResetReason::Pin
        } else {
            ResetReason::Unknown
        };
        ResetCause {
            reason,
            power_lost: f.power_on,
        }
    }

    /// A reset that, before the boot became healthy, counts toward the
    /// boot-loop guard: one the node did not ask for and no person or
    /// supply explains.
    pub fn unhealthy(&self) -> bool {
        !self.power_lost
            && matches!(
                self.reason,
                ResetReason::IndependentWatchdog
                    | ResetReason::WindowWatchdog
                    | ResetReason::LowPower
                    | ResetReason::Software
                    | ResetReason::Unknown
            )
    }
}

/// What a boot does about the resets before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BootPlan {
    /// The panic reset this boot follows, to report once: (line, resets in
    /// a row).
    pub panic_reset: Option<(u32, u8)>,
    /// This boot follows a watchdog (or other unhealthy) reset of a boot
    /// that never became healthy: counted in the row.
    pub unhealthy_reset: bool,
    /// Boot without reading the flash store (defaults; the first save
    /// starts the store afresh).
    pub skip_store: bool,
    /// The words to write back (the report marked done, the booting
    /// marker set).
    pub words: [u32; PANIC_WORDS],
}

/// Decide the boot from the backup words and the reset's cause.
pub fn plan_boot(words: [u32; PANIC_WORDS], cause: ResetCause) -> BootPlan {
    let record = PanicRecord::decode(words).filter(|_| !cause.power_lost);
    let plan = |resets_in_row: u8, line: u32| BootPlan {
        panic_reset: None,
        unhealthy_reset: false,
        skip_store: resets_in_row >= PANIC_RESETS_BEFORE_SKIP,
        words: PanicRecord {
            resets_in_row,
            line,
            pending: false,
            booting: true,
        }
        .encode(),
    };
    match record {
        Some(r) if r.pending => BootPlan {
            panic_reset: Some((r.line, r.resets_in_row)),
            ..plan(r.resets_in_row, r.line)
        },
        Some(r) if r.booting && cause.unhealthy() => BootPlan {
            unhealthy_reset: true,
            ..plan(r.resets_in_row.saturating_add(1), r.line)
        },
        // Power-on, nothing recorded, or a reset that was not a panic after
        // a healthy boot (or a pin reset, a brown-out): the row is over.
        Some(r) => plan(0, r.line),
        None => plan(0, 0),
    }
}

/// The words once the node has run [`HEALTHY_AFTER_MS`]: the row is over,
/// the booting marker cleared (the last line is kept for a debugger).
pub fn healthy(words: [u32; PANIC_WORDS]) -> [u32; PANIC_WORDS] {
    let line = PanicRecord::decode(words).map_or(0, |r| r.line);
    PanicRecord {
        resets_in_row: 0,
        line,
        pending: false,
        booting: false,
    }
    .encode()
}

/// The words right before a commanded reset: the booting marker cleared,
/// so the reset does not count as unhealthy (and the next boot reads the
/// store again).
pub fn commanded_reset(words: [u32; PANIC_WORDS]) -> [u32; PANIC_WORDS] {
    let r = PanicRecord::decode(words).unwrap_or_default();
    PanicRecord {
        booting: false,
        pending: false,
        ..r
    }
    .encode()
}

/// The ice rule's state kept across a reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RuleSnapshot {
    /// Dry, wet or ice.
    pub state: DetectorState,
    /// The alarm was acknowledged (only while iced).
    pub acked: bool,
}

impl RuleSnapshot {
    /// A dry face, nothing acknowledged (what a power-on starts from).
    pub const DRY: RuleSnapshot = RuleSnapshot {
        state: DetectorState::Dry,
        acked: false,
    };

    /// The snapshot as backup-register words (magic, state, ack; CRC).
    pub fn encode(&self) -> [u32; RULE_WORDS] {
        let state = match self.state {
            DetectorState::Dry => 0,
            DetectorState::Wet => 1,
            DetectorState::Ice => 2,
        };
        let w0 = RULE_MAGIC | (u32::from(self.acked) << 8) | state;
        [w0, crc(&[w0])]
    }

    /// The snapshot in `words`, or `None` (erased, garbage, damaged).
    pub fn decode(words: [u32; RULE_WORDS]) -> Option<Self> {
        let [w0, c] = words;
        if w0 & MAGIC_MASK != RULE_MAGIC || w0 & 0xFE00 != 0 || crc(&[w0]) != c {
            return None;
        }
        let state = match w0 & 0xFF {
            0 => DetectorState::Dry,
            1 => DetectorState::Wet,
            2 => DetectorState::Ice,
            _ => return None,
        };
        Some(RuleSnapshot {
            state,
            // An acknowledgement only means something while iced.
            acked: w0 & 0x100 != 0 && state == DetectorState::Ice,
        })
    }

    /// The state to resume after a reset: the stored one, unless the power
    /// was lost (`ResetCause::power_lost`) or the words hold no snapshot.
    pub fn resume(words: [u32; RULE_WORDS], power_lost: bool) -> RuleSnapshot {
        if power_lost {
            return RuleSnapshot::DRY;
        }
        Self::decode(words).unwrap_or(RuleSnapshot::DRY)
    }

    /// The alarm output in this state (what the board drives the pin to
    /// before anything else at boot).
    pub fn alarm_on(&self) -> bool {
        Rule::resumed(self.state, self.acked).alarm()
    }
}

/// How the boot treats the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreRead {
    /// Read it (a healthy boot).
    Read,
    /// After [`PANIC_RESETS_BEFORE_SKIP`] unhealthy resets in a row: not
    /// read; the first write starts it afresh ([`Storage::overwrite`]), so
    /// a `SetConfig` or a calibration replaces a bad record remotely.
    Skip,
    /// The supply was too low to read it at boot (a read may repair by
    /// erasing): not read, and nothing written either — the record stays
    /// as it is (writes fail: `STORAGE_FAILED`, retried with the save
    /// back-off) until the board, once the supply has been healthy for
    /// [`DEFERRED_READ_RESET_MS`], resets to read it.
    Defer,
}

/// How long the supply must stay healthy before a node that deferred its
/// store's read resets to read it, ms.
pub const DEFERRED_READ_RESET_MS: u64 = 10_000;

/// The board's watch over a deferred read: `healthy` is the supply gate's
/// answer now (`storage::supply::flash_write_allowed`); true once it has
/// held for [`DEFERRED_READ_RESET_MS`] (the board then resets to read the
/// store). `since` keeps when it began to hold.
pub fn deferred_read_due(since: &mut Option<u64>, healthy: bool, now_ms: u64) -> bool {
    if !healthy {
        *since = None;
        return false;
    }
    let start = *since.get_or_insert(now_ms);
    now_ms.saturating_sub(start) >= DEFERRED_READ_RESET_MS
}

/// The node's storage, read at boot or not ([`StoreRead`]). Unread, `read`
/// gives nothing (the defaults).
#[derive(Debug)]
pub struct SkippableStorage<S> {
    store: S,
    mode: StoreRead,
}

impl<S> SkippableStorage<S> {
    /// `store`, treated as `mode` says.
    pub fn new(store: S, mode: StoreRead) -> Self {
        SkippableStorage { store, mode }
    }

    /// How the store is treated now (a skipped store is `Read` after its
    /// first write).
    pub fn mode(&self) -> StoreRead {
        self.mode
    }

    /// The store back.
    pub fn into_inner(self) -> S {
        self.store
    }
}

impl<S: Storage> Storage for SkippableStorage<S> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        match self.mode {
            StoreRead::Read => self.store.read(buf),
            StoreRead::Skip | StoreRead::Defer => Ok(0),
        }
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        match self.mode {
            StoreRead::Read => self.store.write(data),
            StoreRead::Skip => self.overwrite(data),
            StoreRead::Defer => Err(StorageError::Write),
        }
    }

    fn overwrite(&mut self, data: &[u8]) -> Result<(), StorageError> {
        if self.mode == StoreRead::Defer {
            return Err(StorageError::Write);
        }
        self.store.overwrite(data)?;
        self.mode = StoreRead::Read;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const POWER_ON: ResetFlags = ResetFlags {
        power_on: true,
        brown_out: true,
        pin: true,
        ..NONE
    };
    const BROWN_OUT: ResetFlags = ResetFlags {
        brown_out: true,
        pin: true,
        ..NONE
    };
    const NONE: ResetFlags = ResetFlags {
        low_power: false,
        window_watchdog: false,
        independent_watchdog: false,
        software: false,
        power_on: false,
        pin: false,
        brown_out: false,
    };
    /// A panic's (or a command's) `SCB::sys_reset`.
    fn software() -> ResetCause {
        ResetCause::from_flags(ResetFlags {
            software: true,
            pin: true,
            ..NONE
        })
    }
    fn watchdog() -> ResetCause {
        ResetCause::from_flags(ResetFlags {
            independent_watchdog: true,
            pin: true,
            ..NONE
        })
    }
    fn pin() -> ResetCause {
        ResetCause::from_flags(ResetFlags { pin: true, ..NONE })
    }
    fn power_on() -> ResetCause {
        ResetCause::from_flags(POWER_ON)
    }

    #[test]
    fn panic_records_round_trip_and_refuse_damage() {
        let r = PanicRecord {
            resets_in_row: 2,
            line: 417,
            pending: true,
            booting: true,
        };
        let w = r.encode();
        assert_eq!(PanicRecord::decode(w), Some(r));
        // Every single bit flip is refused.
        for i in 0..PANIC_WORDS {
            for bit in 0..32 {
                let mut bad = w;
                bad[i] ^= 1 << bit;
                assert_eq!(PanicRecord::decode(bad), None, "word {i} bit {bit}");
            }
        }
        // Reset values and garbage are nothing.
        assert_eq!(PanicRecord::decode([0; 3]), None);
        assert_eq!(PanicRecord::decode([u32::MAX; 3]), None);
    }

    #[test]
    fn three_panics_in_a_row_skip_the_store_and_a_healthy_run_ends_the_row() {
        let mut w = [0u32; 3]; // backup registers after a power-on
        let plan = plan_boot(w, power_on());
        assert_eq!((plan.panic_reset, plan.skip_store), (None, false));
        w = plan.words;
        for n in 1..=4u8 {
            w = record_panic(w, 100 + u32::from(n));
            let plan = plan_boot(w, software());
            assert_eq!(plan.panic_reset, Some((100 + u32::from(n), n)));
            assert_eq!(plan.skip_store, n >= PANIC_RESETS_BEFORE_SKIP, "{n}");
            w = plan.words;
            // Reported once: a second boot without a new panic is clean.
            assert_eq!(plan_boot(w, pin()).panic_reset, None);
        }
        // A healthy minute ends the row: the next panic is the first again.
        w = healthy(w);
        assert_eq!(PanicRecord::decode(w).map(|r| r.line), Some(104));
        w = record_panic(w, 7);
        assert_eq!(plan_boot(w, software()).panic_reset, Some((7, 1)));
        // A power-on forgets everything.
        w = record_panic(record_panic(record_panic(w, 7), 7), 7);
        assert_eq!(plan_boot(w, power_on()).panic_reset, None);
        // So does a pin reset.
        let w = record_panic([0; 3], 9);
        let after_report = plan_boot(w, software()).words;
        let w = record_panic(after_report, 9);
        assert_eq!(plan_boot(w, software()).panic_reset, Some((9, 2)));
        let clean = plan_boot(plan_boot(w, software()).words, pin()).words;
        assert_eq!(
            plan_boot(record_panic(clean, 9), software()).panic_reset,
            Some((9, 1))
        );
    }

    #[test]
    fn the_count_saturates() {
        let mut w = [0u32; 3];
        for _ in 0..300 {
            w = record_panic(w, 1);
        }
        assert_eq!(PanicRecord::decode(w).map(|r| r.resets_in_row), Some(255));
        assert!(plan_boot(w, software()).skip_store);
    }

    #[test]
    fn the_reset_flags_tell_a_brown_out_from_a_power_loss() {
        let c = ResetCause::from_flags(POWER_ON);
        assert_eq!((c.reason, c.power_lost), (ResetReason::PowerOn, true));
        let c = ResetCause::from_flags(BROWN_OUT);
        assert_eq!((c.reason, c.power_lost), (ResetReason::PowerOn, false));
        assert!(!c.unhealthy());
        assert_eq!(watchdog().reason, ResetReason::IndependentWatchdog);
        assert_eq!(software().reason, ResetReason::Software);
        assert_eq!(pin().reason, ResetReason::Pin);
        assert_eq!(ResetCause::from_flags(NONE).reason, ResetReason::Unknown);
        assert!(watchdog().unhealthy() && software().unhealthy());
        assert!(!pin().unhealthy() && !power_on().unhealthy());
    }

    #[test]
    fn watchdog_resets_before_a_healthy_boot_count_toward_the_skip() {
        // Every boot sets the marker; a hang then ends in the watchdog.
        let mut w = plan_boot([0; 3], power_on()).words;
        assert_eq!(PanicRecord::decode(w).map(|r| r.booting), Some(true));
        for n in 1..=3u8 {
            let plan = plan_boot(w, watchdog());
            assert!(plan.unhealthy_reset, "{n}");
            assert_eq!(plan.panic_reset, None, "no panic to report");
            assert_eq!(plan.skip_store, n >= PANIC_RESETS_BEFORE_SKIP, "{n}");
            w = plan.words;
        }
        // A panic on top is the fourth in the row.
        let plan = plan_boot(record_panic(w, 55), software());
        assert_eq!(plan.panic_reset, Some((55, 4)));
        assert!(plan.skip_store);
        // A boot that became healthy: the next watchdog reset starts nothing.
        let plan = plan_boot(healthy(plan.words), watchdog());
        assert!(!plan.unhealthy_reset && !plan.skip_store);
        // A commanded reset is not unhealthy, even in the first minute, and
        // the boot after it reads the store again.
        let mut w = plan.words;
        for _ in 0..3 {
            w = plan_boot(w, watchdog()).words;
        }
        assert!(plan_boot(w, watchdog()).skip_store);
        let plan = plan_boot(commanded_reset(w), software());
        assert!(!plan.unhealthy_reset && !plan.skip_store);
        // Nor is a brown-out.
        let plan = plan_boot(w, ResetCause::from_flags(BROWN_OUT));
        assert!(!plan.unhealthy_reset && !plan.skip_store);
    }

    #[test]
    fn a_brown_out_alone_resumes_the_rule_and_its_acknowledgement() {
        let s = RuleSnapshot {
            state: DetectorState::Ice,
            acked: true,
        };
        let w = s.encode();
        let brown_out = ResetCause::from_flags(BROWN_OUT);
        assert_eq!(RuleSnapshot::resume(w, brown_out.power_lost), s);
        assert!(RuleSnapshot::resume(w, brown_out.power_lost).alarm_on());
        assert_eq!(
            RuleSnapshot::resume(w, power_on().power_lost),
            RuleSnapshot::DRY
        );
        assert!(!RuleSnapshot::DRY.alarm_on());
    }

    #[test]
    fn a_deferred_read_resets_after_10_s_of_healthy_supply() {
        let mut since = None;
        assert!(!deferred_read_due(&mut since, false, 0));
        assert!(!deferred_read_due(&mut since, true, 1_000));
        assert!(!deferred_read_due(&mut since, true, 10_999));
        // A dip starts the count again.
        assert!(!deferred_read_due(&mut since, false, 11_000));
        assert!(!deferred_read_due(&mut since, true, 12_000));
        assert!(!deferred_read_due(&mut since, true, 21_999));
        assert!(deferred_read_due(&mut since, true, 22_000));
    }

    #[test]
    #[allow(clippy::expect_used)]
    fn a_skipped_store_is_overwritten_by_the_first_save() {
        use crate::storage::flash_store::FlashStore;
        use crate::storage::ram_flash::RamFlash;
        // Another program's bytes in the store's pages.
        let mut flash = RamFlash::<_, 1024, 2>::new([0u8; 2 * 1024]);
        for (i, b) in flash.bytes_mut().iter_mut().enumerate() {
            *b = (i * 7 + 3) as u8;
        }
        let store = FlashStore::new(flash, 0..2 * 1024).expect("two pages");
        let mut s = SkippableStorage::new(store, StoreRead::Skip);
        let mut buf = [0u8; 64];
        assert_eq!(s.read(&mut buf), Ok(0), "the read is skipped");
        s.write(b"a new record").expect("overwritten");
        assert_eq!(s.mode(), StoreRead::Read);
        s.write(b"and another").expect("written");
        // Another boot on the same flash reads the last record.
        let mut again = FlashStore::new(s.into_inner().into_flash(), 0..2 * 1024).expect("pages");
        let n = again.read(&mut buf).expect("readable");
        assert_eq!(buf.get(..n), Some(&b"and another"[..]));

        // Deferred (a low supply at boot): nothing read, nothing written,
        // the record kept for the boot that reads it.
        let mut d = SkippableStorage::new(again, StoreRead::Defer);
        assert_eq!(d.read(&mut buf), Ok(0));
        assert_eq!(d.write(b"defaults"), Err(StorageError::Write));
        assert_eq!(d.overwrite(b"defaults"), Err(StorageError::Write));
        let mut later = d.into_inner();
        let n = later.read(&mut buf).expect("readable");
        assert_eq!(buf.get(..n), Some(&b"and another"[..]));
    }

    #[test]
    fn the_rule_state_resumes_after_resets_but_not_after_power_on() {
        for (state, acked) in [
            (DetectorState::Dry, false),
            (DetectorState::Wet, false),
            (DetectorState::Ice, false),
            (DetectorState::Ice, true),
        ] {
            let s = RuleSnapshot { state, acked };
            let w = s.encode();
            assert_eq!(RuleSnapshot::resume(w, false), s);
            assert_eq!(RuleSnapshot::resume(w, true), RuleSnapshot::DRY);
            for i in 0..RULE_WORDS {
                for bit in 0..32 {
                    let mut bad = w;
                    bad[i] ^= 1 << bit;
                    assert_eq!(RuleSnapshot::decode(bad), None, "word {i} bit {bit}");
                    assert_eq!(RuleSnapshot::resume(bad, false), RuleSnapshot::DRY);
                }
            }
        }
        // An ack stored with a dry state means nothing.
        let odd = RULE_MAGIC | 0x100;
        assert_eq!(
            RuleSnapshot::decode([odd, crc(&[odd])]),
            Some(RuleSnapshot::DRY)
        );
        // A state number out of range is refused.
        let bad = RULE_MAGIC | 3;
        assert_eq!(RuleSnapshot::decode([bad, crc(&[bad])]), None);
        assert_eq!(RuleSnapshot::resume([0, 0], false), RuleSnapshot::DRY);
    }
}
