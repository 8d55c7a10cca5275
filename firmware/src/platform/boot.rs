//! What survives a reset, and what the node does with it at boot: the
//! board keeps a few words in the STM32's backup registers (RTC_BKPxR,
//! RM0390 §22: kept across every reset but a power loss or a backup domain
//! reset), each record with a CRC so that garbage reads as nothing.
//!
//! - **Panic resets** ([`PanicRecord`]): the panic handler records the
//!   source line, counts the panic resets in a row and resets at once
//!   ([`record_panic`]). At the next boot [`plan_boot`] reports it once
//!   (`EventKind::PanicReset`) and, after [`PANIC_RESETS_BEFORE_SKIP`] in a
//!   row, boots without the flash store (`STORE_SKIPPED`: a panic that
//!   stored data causes would otherwise repeat at every boot). A run of
//!   [`HEALTHY_AFTER_MS`] without a panic ends the row ([`healthy`]); so
//!   does any reset that was not a panic.
//! - **The ice rule's state** ([`RuleSnapshot`]): after a watchdog, software,
//!   pin or panic reset the node comes back in the state it had — an alarm
//!   holds from the first instant instead of waiting `onset_frames` for the
//!   ice to be seen again, and its acknowledgement is kept. After a power-on
//!   it starts dry (the backup registers are powered from V_BAT, which the
//!   NUCLEO ties to V_DD: a power loss clears them anyway).
//!
//! The words are plain `u32`s: the board reads and writes the registers,
//! the host tests an array.

use fois_protocol::DetectorState;
use fois_protocol::framing::CRC;

use crate::storage::{Storage, StorageError};

/// Panic resets in a row after which the node boots without its flash
/// store.
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
}

impl PanicRecord {
    /// The record as backup-register words (magic, count, pending; line; CRC).
    pub fn encode(&self) -> [u32; PANIC_WORDS] {
        let w0 = PANIC_MAGIC | (u32::from(self.pending) << 8) | u32::from(self.resets_in_row);
        let w1 = self.line;
        [w0, w1, crc(&[w0, w1])]
    }

    /// The record in `words`, or `None` for anything else (erased, garbage,
    /// a damaged word).
    pub fn decode(words: [u32; PANIC_WORDS]) -> Option<Self> {
        let [w0, w1, c] = words;
        if w0 & MAGIC_MASK != PANIC_MAGIC || w0 & 0xFE00 != 0 || crc(&[w0, w1]) != c {
            return None;
        }
        Some(PanicRecord {
            resets_in_row: (w0 & 0xFF) as u8,
            line: w1,
            pending: w0 & 0x100 != 0,
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
    }
    .encode()
}

/// What a boot does about the panics before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BootPlan {
    /// The panic reset this boot follows, to report once: (line, resets in
    /// a row).
    pub panic_reset: Option<(u32, u8)>,
    /// Boot without the flash store (defaults, nothing saved).
    pub skip_store: bool,
    /// The words to write back (the report is marked done).
    pub words: [u32; PANIC_WORDS],
}

/// Decide the boot from the backup words and whether this was a power-on
/// reset.
pub fn plan_boot(words: [u32; PANIC_WORDS], power_on: bool) -> BootPlan {
    let record = PanicRecord::decode(words).filter(|_| !power_on);
    match record {
        Some(r) if r.pending => BootPlan {
            panic_reset: Some((r.line, r.resets_in_row)),
            skip_store: r.resets_in_row >= PANIC_RESETS_BEFORE_SKIP,
            words: PanicRecord {
                pending: false,
                ..r
            }
            .encode(),
        },
        // Power-on, nothing recorded, or a reset that was not a panic: the
        // row (if any) is over.
        _ => BootPlan {
            panic_reset: None,
            skip_store: false,
            words: PanicRecord::default().encode(),
        },
    }
}

/// The words once the node has run [`HEALTHY_AFTER_MS`] without a panic:
/// the row is over (the last line is kept for a debugger).
pub fn healthy(words: [u32; PANIC_WORDS]) -> [u32; PANIC_WORDS] {
    let line = PanicRecord::decode(words).map_or(0, |r| r.line);
    PanicRecord {
        resets_in_row: 0,
        line,
        pending: false,
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

    /// The state to resume after a reset: the stored one, unless this was a
    /// power-on or the words hold no snapshot.
    pub fn resume(words: [u32; RULE_WORDS], power_on: bool) -> RuleSnapshot {
        if power_on {
            return RuleSnapshot::DRY;
        }
        Self::decode(words).unwrap_or(RuleSnapshot::DRY)
    }
}

/// The node's storage, or none: after [`PANIC_RESETS_BEFORE_SKIP`] panic
/// resets in a row the board boots with `SkippableStorage(None)`, which
/// reads as empty (the defaults) and discards every write, so nothing the
/// store holds is read and nothing is saved until a reset.
#[derive(Debug)]
pub struct SkippableStorage<S>(pub Option<S>);

impl<S: Storage> Storage for SkippableStorage<S> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        match &mut self.0 {
            Some(s) => s.read(buf),
            None => Ok(0),
        }
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        match &mut self.0 {
            Some(s) => s.write(data),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panic_records_round_trip_and_refuse_damage() {
        let r = PanicRecord {
            resets_in_row: 2,
            line: 417,
            pending: true,
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
        let plan = plan_boot(w, true);
        assert_eq!((plan.panic_reset, plan.skip_store), (None, false));
        w = plan.words;
        for n in 1..=4u8 {
            w = record_panic(w, 100 + u32::from(n));
            let plan = plan_boot(w, false);
            assert_eq!(plan.panic_reset, Some((100 + u32::from(n), n)));
            assert_eq!(plan.skip_store, n >= PANIC_RESETS_BEFORE_SKIP, "{n}");
            w = plan.words;
            // Reported once: a second boot without a new panic is clean.
            assert_eq!(plan_boot(w, false).panic_reset, None);
        }
        // A healthy minute ends the row: the next panic is the first again.
        w = healthy(w);
        assert_eq!(PanicRecord::decode(w).map(|r| r.line), Some(104));
        w = record_panic(w, 7);
        assert_eq!(plan_boot(w, false).panic_reset, Some((7, 1)));
        // A power-on forgets everything.
        w = record_panic(record_panic(record_panic(w, 7), 7), 7);
        assert_eq!(plan_boot(w, true).panic_reset, None);
        // So does a reset that was not a panic (watchdog, command, pin).
        let w = record_panic([0; 3], 9);
        let after_report = plan_boot(w, false).words;
        let w = record_panic(after_report, 9);
        assert_eq!(plan_boot(w, false).panic_reset, Some((9, 2)));
        let clean = plan_boot(plan_boot(w, false).words, false).words;
        assert_eq!(
            plan_boot(record_panic(clean, 9), false).panic_reset,
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
        assert!(plan_boot(w, false).skip_store);
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
