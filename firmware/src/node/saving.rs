//! When the node writes its record: a change is saved once no further
//! change came for [`SAVE_QUIET_MS`], at most [`SAVE_MAX_DELAY_MS`] after the
//! first, saves at least [`SAVE_MIN_INTERVAL_MS`] apart, only while the
//! supply is healthy; a failed save is retried after an interval that
//! doubles with each failure in a row, from [`SAVE_MIN_INTERVAL_MS`] up to
//! [`SAVE_RETRY_MAX_MS`] ([`save_interval_ms`]): a stuck flash cell costs
//! an erase an hour, not one a minute (each stalls the CPU for up to
//! 2.6 s). The record's bytes are [`crate::storage::record`].

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;

use super::{Node, PendingSave};
use crate::hal::PhotoAdc;
use crate::measure::vref;
use crate::storage::record::{self, MAX_RECORD, Record};
use crate::storage::{Storage, supply};
use crate::update::UpdateSlots;

/// A change is saved once no further change came for this long, ms: a burst
/// of config changes and calibrations is one flash write.
pub const SAVE_QUIET_MS: u64 = 1_000;
/// ... but at most this long after the first unsaved change, ms.
pub const SAVE_MAX_DELAY_MS: u64 = 10_000;
/// Saves (and retries after a failed one) are at least this far apart, ms:
/// at most 1 440 a day, whatever a host sends: a host forcing a change
/// every second for ten years wears each 16 KiB store sector about 9 400
/// times, within the F446's 10 000 cycles (`firmware/README.md`, wear).
pub const SAVE_MIN_INTERVAL_MS: u64 = 60_000;
/// The longest wait before retrying after failed saves, ms (1 h).
pub const SAVE_RETRY_MAX_MS: u64 = 3_600_000;

/// How long after a save attempt the next may start, ms, after `failures`
/// failed saves in a row: [`SAVE_MIN_INTERVAL_MS`] (none or one failed),
/// then doubled per further failure, capped at [`SAVE_RETRY_MAX_MS`]
/// (60, 60, 120, 240 s, ..., 1 920 s, then 1 h).
pub const fn save_interval_ms(failures: u32) -> u64 {
    let doublings = failures.saturating_sub(1);
    if doublings >= 20 {
        return SAVE_RETRY_MAX_MS;
    }
    let interval = SAVE_MIN_INTERVAL_MS << doublings;
    if interval > SAVE_RETRY_MAX_MS {
        SAVE_RETRY_MAX_MS
    } else {
        interval
    }
}

impl<A, L, AL, IND, D, S, U> Node<A, L, AL, IND, D, S, U>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
{
    /// When the pending change will be saved (`None`: nothing to save), ms
    /// on the `now_ms` clock. The driver calls [`Self::poll_storage`] then
    /// (`run_frame` also does, after its frame).
    pub fn save_due_ms(&self) -> Option<u64> {
        let p = self.pending_save?;
        let coalesced = p
            .last_ms
            .saturating_add(SAVE_QUIET_MS)
            .min(p.first_ms.saturating_add(SAVE_MAX_DELAY_MS));
        let earliest = self.last_save_ms.map_or(0, |t| {
            t.saturating_add(save_interval_ms(self.save_failures))
        });
        Some(coalesced.max(earliest))
    }

    /// Save the pending change if it is due. A failed save sets
    /// `STORAGE_FAILED` (reported as a fault event with the next frame) and
    /// is retried [`save_interval_ms`] later.
    pub fn poll_storage(&mut self, now_ms: u64) {
        if self.save_due_ms().is_some_and(|due| now_ms >= due) {
            self.save(now_ms);
        }
    }

    /// True while a change waits to be saved.
    pub fn save_pending(&self) -> bool {
        self.pending_save.is_some()
    }

    /// The record the node would store now.
    fn record(&self) -> Record {
        Record {
            config: self.config.clone(),
            baseline: self.baseline,
            gain: self.gain_kept,
            gain_calibration: self.gain_calibration,
            link: self.link,
        }
    }

    /// Config or baseline changed: schedule a save, unless the storage
    /// already holds exactly this (then a pending save is dropped).
    pub(super) fn changed(&mut self, now_ms: u64) {
        if self.stored.as_ref() == Some(&self.record()) && !self.storage_failed {
            self.pending_save = None;
            return;
        }
        self.pending_save = Some(match self.pending_save {
            Some(p) => PendingSave {
                last_ms: now_ms,
                ..p
            },
            None => PendingSave {
                first_ms: now_ms,
                last_ms: now_ms,
            },
        });
    }

    /// Write the record now, if the supply allows (else it stays pending).
    pub(super) fn save(&mut self, now_ms: u64) {
        // V_DDA now, not the last frame's: a save can come before the first
        // frame (a `Reset` right after a `SetConfig`) or long after one.
        let vdda_mv = vref::vdda_mv(&self.info.cal, self.adc.read_vrefint());
        if !supply::flash_write_allowed(vdda_mv, self.supply_low) {
            return;
        }
        let record = self.record();
        let mut buf = [0u8; MAX_RECORD];
        let n = record::encode(&record, &mut buf);
        let written = match buf.get(..n) {
            Some(bytes) if n > 0 => self.storage.write(bytes).is_ok(),
            _ => false,
        };
        self.last_save_ms = Some(now_ms);
        self.storage_failed = !written;
        self.save_failures = if written {
            0
        } else {
            self.save_failures.saturating_add(1)
        };
        if written {
            self.stored = Some(record);
            self.pending_save = None;
        } else {
            // Retry once the (backed-off) interval has passed.
            self.pending_save = Some(PendingSave {
                first_ms: now_ms,
                last_ms: now_ms,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retries_back_off_from_a_minute_to_an_hour() {
        let intervals: [u64; 8] = core::array::from_fn(|n| save_interval_ms(n as u32) / 1_000);
        assert_eq!(intervals, [60, 60, 120, 240, 480, 960, 1_920, 3_600]);
        assert_eq!(save_interval_ms(10), 3_600_000);
        assert_eq!(save_interval_ms(u32::MAX), 3_600_000);
        // A day of a stuck cell: 29 attempts instead of 1 440.
        let (mut t, mut attempts, mut failures) = (0u64, 0, 0u32);
        while t < 86_400_000 {
            attempts += 1;
            failures += 1;
            t += save_interval_ms(failures);
        }
        assert_eq!(attempts, 29);
    }
}
