//! When a node's retained state (`<node>/state`) is published, and with
//! which values.
//!
//! Home Assistant's entities read the state topic, and every change of an
//! entity's value is a row in its database: the state must not follow the
//! noise of every frame (the measurements did: about two entity changes per
//! second per node, for ever). So:
//!
//! - a discrete change (detector state, alarm, acknowledgement, validity,
//!   faults, dark baseline, medium, an estimate or a gain appearing) is
//!   published at once;
//! - a continuous value is *held*: the state carries the value last
//!   published until the new one moved by at least its deadband
//!   ([`DEADBANDS`]); such a change is published at most every
//!   `state_interval_ms` (default 5 s) — values that did not move past their
//!   band stay held even then, so a quiet node changes nothing in Home
//!   Assistant;
//! - the frame counter (`frames_received`) is refreshed [`COUNTERS_FIRST`]
//!   after a node's state is first published (or republished after a
//!   reconnection: it would show 1 for minutes), then at most every
//!   [`COUNTERS_EVERY`]; `frames_lost` is a continuous value of band 1.
//!
//! The measurement topic keeps every value exact, at its own rate.

use std::time::{Duration, Instant};

use crate::payload::StateJson;

/// `frames_received` is refreshed at most this often.
pub const COUNTERS_EVERY: Duration = Duration::from_secs(300);
/// ... and this long after the state was first published.
pub const COUNTERS_FIRST: Duration = Duration::from_secs(30);

/// A continuous value of the state and its deadband: the value is
/// re-published when it moved by at least `max(absolute, relative × |last|)`.
#[derive(Debug, Clone, Copy)]
pub struct Deadband {
    /// The key in the state payload.
    pub key: &'static str,
    /// The band in the key's unit.
    pub absolute: f64,
    /// The band relative to the value last published (0: none).
    pub relative: f64,
    get: fn(&StateJson) -> Option<f64>,
    set: fn(&mut StateJson, f64),
}

impl Deadband {
    fn moved(&self, last: &StateJson, now: &StateJson) -> bool {
        match ((self.get)(last), (self.get)(now)) {
            (Some(a), Some(b)) => (b - a).abs() >= self.absolute.max(self.relative * a.abs()),
            (None, Some(_)) | (Some(_), None) => true,
            (None, None) => false,
        }
    }
}

macro_rules! band {
    ($key:literal, $abs:expr, $rel:expr, |$s:ident| $get:expr, |$t:ident, $v:ident| $set:expr) => {
        Deadband {
            key: $key,
            absolute: $abs,
            relative: $rel,
            get: |$s: &StateJson| $get,
            set: |$t: &mut StateJson, $v: f64| $set,
        }
    };
}

/// Every continuous value of the state with its band (documented in the
/// gateway README, "Home Assistant"). Currents: the virtual node's noise is
/// 0.02–0.04 µA rms, a rime onset more than 25 µA; thickness: a tenth of the
/// estimator's usual σ.
pub const DEADBANDS: [Deadband; 12] = [
    band!("i1_ua", 0.2, 0.02, |s| Some(s.i1_ua), |s, v| s.i1_ua = v),
    band!("i2_ua", 0.2, 0.02, |s| Some(s.i2_ua), |s, v| s.i2_ua = v),
    band!(
        "temperature_c",
        0.2,
        0.0,
        |s| Some(s.temperature_c),
        |s, v| s.temperature_c = v
    ),
    band!(
        "thickness_mm",
        0.05,
        0.0,
        |s| s.estimate.map(|e| e.thickness_mm),
        |s, v| {
            if let Some(e) = &mut s.estimate {
                e.thickness_mm = v;
            }
        }
    ),
    band!(
        "ice_thickness_mm",
        0.05,
        0.0,
        |s| s.ice_thickness_mm,
        |s, v| s.ice_thickness_mm = Some(v)
    ),
    band!("water_film_mm", 0.05, 0.0, |s| s.water_film_mm, |s, v| s
        .water_film_mm =
        Some(v)),
    band!(
        "thickness_sigma_mm",
        0.05,
        0.1,
        |s| s.estimate.map(|e| e.thickness_sigma_mm),
        |s, v| {
            if let Some(e) = &mut s.estimate {
                e.thickness_sigma_mm = v;
            }
        }
    ),
    band!(
        "medium_probability",
        0.05,
        0.0,
        |s| s.estimate.map(|e| e.medium_probability),
        |s, v| {
            if let Some(e) = &mut s.estimate {
                e.medium_probability = v;
            }
        }
    ),
    band!("gain", 0.01, 0.0, |s| s.gain.map(|g| g.gain), |s, v| {
        if let Some(g) = &mut s.gain {
            g.gain = v;
        }
    }),
    // The icing rate: a tenth of a mm/h or 10 %; the probability of
    // accreting as the medium's.
    band!(
        "rate_mm_per_h",
        0.1,
        0.1,
        |s| s.icing.map(|i| i.rate_mm_per_h),
        |s, v| {
            if let Some(i) = &mut s.icing {
                i.rate_mm_per_h = v;
            }
        }
    ),
    band!(
        "accreting_probability",
        0.05,
        0.0,
        |s| s.icing.map(|i| i.accreting_probability),
        |s, v| {
            if let Some(i) = &mut s.icing {
                i.accreting_probability = v;
            }
        }
    ),
    band!(
        "frames_lost",
        1.0,
        0.0,
        |s| Some(s.frames_lost as f64),
        |s, v| s.frames_lost = v as u64
    ),
];

/// The state a node last published, and when; what the next one holds.
#[derive(Debug, Clone, Default)]
pub struct StateFilter {
    published: Option<(StateJson, Instant)>,
    /// When `frames_received` may be refreshed next.
    counters_due: Option<Instant>,
}

impl StateFilter {
    /// The state to publish after a frame whose exact state is `next`, or
    /// `None` (nothing a reader would see changed enough). `interval`: the
    /// least spacing of continuous changes (`state_interval_ms`).
    pub fn offer(
        &mut self,
        mut next: StateJson,
        now: Instant,
        interval: Duration,
    ) -> Option<StateJson> {
        let Some((last, at)) = &self.published else {
            return Some(self.force(next, now));
        };
        let moved = DEADBANDS.iter().any(|b| b.moved(last, &next));
        let counters_due = next.frames_received != last.frames_received
            && self.counters_due.is_none_or(|t| now >= t);
        let spaced = now.saturating_duration_since(*at) >= interval;
        if !(last.differs_discretely(&next) || ((moved || counters_due) && spaced)) {
            return None;
        }
        for b in &DEADBANDS {
            if !b.moved(last, &next)
                && let Some(v) = (b.get)(last)
            {
                (b.set)(&mut next, v);
            }
        }
        // The gain's σ goes with the gain (an attribute of one entity).
        if let (Some(g), Some(old)) = (&mut next.gain, last.gain)
            && g.gain == old.gain
        {
            g.gain_sigma = old.gain_sigma;
        }
        // The icing rate's σ goes with the rate (an attribute).
        if let (Some(i), Some(old)) = (&mut next.icing, last.icing)
            && i.rate_mm_per_h == old.rate_mm_per_h
        {
            i.rate_sigma_mm_per_h = old.rate_sigma_mm_per_h;
        }
        if counters_due {
            self.counters_due = Some(now + COUNTERS_EVERY);
        } else {
            next.frames_received = last.frames_received;
        }
        self.published = Some((next.clone(), now));
        Some(next)
    }

    /// Publish `next` as it is (a reconnection, a new node): it becomes the
    /// baseline the next frames are held against.
    pub fn force(&mut self, next: StateJson, now: Instant) -> StateJson {
        self.counters_due = Some(now + COUNTERS_FIRST);
        self.published = Some((next.clone(), now));
        next
    }

    /// The state last published.
    pub fn published(&self) -> Option<&StateJson> {
        self.published.as_ref().map(|(s, _)| s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_link::Reading;
    use fois_protocol::{DetectorState, IceEstimate, Measurement, Medium};

    fn state(i1_na: i32, temp_centi: i16, thickness_um: Option<u16>, received: u64) -> StateJson {
        let m = Measurement {
            uptime_ms: 1_000,
            i1_na,
            i2_na: 300,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: temp_centi,
            vdda_mv: 3300,
            flags: 0,
            state: DetectorState::Dry,
        };
        let est = thickness_um.map(|t| IceEstimate {
            thickness_um: t,
            sigma_um: 100,
            medium: Medium::Rime,
            probability_permille: 900,
        });
        StateJson::new(
            "n",
            1,
            &Reading::new(&m, est.as_ref(), None),
            (received, 0),
            0,
        )
    }

    const FIVE_S: Duration = Duration::from_secs(5);

    #[test]
    fn noise_changes_nothing_a_reader_sees() {
        let t0 = Instant::now();
        let mut f = StateFilter::default();
        let first = f.offer(state(30_000, -500, Some(1_000), 10), t0, FIVE_S);
        assert_eq!(first.unwrap().i1_ua, 30.0, "the first state goes out");
        // 100 frames of noise (±0.1 µA at 30 µA, ±0.05 °C, ±0.02 mm) over
        // 10 minutes: nothing is published.
        for k in 1..=100u64 {
            let wiggle = if k % 2 == 0 { 1 } else { -1 };
            let s = state(
                30_000 + wiggle * 100,
                -500 + wiggle as i16 * 5,
                Some((1_000 + wiggle * 20) as u16),
                10,
            );
            let now = t0 + Duration::from_secs(6 * k);
            assert_eq!(f.offer(s, now, FIVE_S), None, "frame {k}");
        }
    }

    #[test]
    fn a_value_past_its_band_goes_out_after_the_interval_the_rest_held() {
        let t0 = Instant::now();
        let mut f = StateFilter::default();
        f.offer(state(30_000, -500, Some(1_000), 10), t0, FIVE_S);
        // The thickness moved 0.06 mm (band 0.05), I1 by 0.3 µA (band:
        // 2 % of 30 = 0.6 µA): too early at 2 s, out at 5 s with I1 held.
        let moved = state(30_300, -500, Some(1_060), 10);
        assert_eq!(
            f.offer(moved.clone(), t0 + Duration::from_secs(2), FIVE_S),
            None
        );
        let out = f.offer(moved, t0 + FIVE_S, FIVE_S).unwrap();
        assert_eq!(out.estimate.unwrap().thickness_mm, 1.06);
        assert_eq!(out.ice_thickness_mm, Some(1.06));
        assert_eq!(out.i1_ua, 30.0, "held: moved less than its band");
        // Drift under the band accumulates: 30.0 -> 30.7 µA is past 0.6.
        let drift = state(30_700, -500, Some(1_060), 10);
        let out = f
            .offer(drift, t0 + Duration::from_secs(11), FIVE_S)
            .unwrap();
        assert_eq!(out.i1_ua, 30.7);
        assert_eq!(out.estimate.unwrap().thickness_mm, 1.06);
    }

    #[test]
    fn discrete_changes_go_out_at_once_counters_after_30_s_then_every_five_minutes() {
        let t0 = Instant::now();
        let mut f = StateFilter::default();
        f.offer(state(0, -500, None, 10), t0, FIVE_S);
        let mut iced = state(28_000, -500, None, 11);
        iced.state = "ice";
        iced.ice = true;
        let out = f
            .offer(iced.clone(), t0 + Duration::from_millis(100), FIVE_S)
            .unwrap();
        assert!(out.ice);
        assert_eq!(out.i1_ua, 28.0, "a jump past its band goes with it");
        assert_eq!(out.frames_received, 10, "the counter is held");
        // Only the counter moved: 30 s after the first state, then not
        // before 5 minutes more.
        let at = |s: u64| t0 + Duration::from_secs(s);
        iced.frames_received = 300;
        assert_eq!(f.offer(iced.clone(), at(29), FIVE_S), None);
        assert_eq!(
            f.offer(iced.clone(), at(30), FIVE_S)
                .unwrap()
                .frames_received,
            300
        );
        iced.frames_received = 2_000;
        assert_eq!(f.offer(iced.clone(), at(329), FIVE_S), None);
        iced.frames_received = 3_000;
        let out = f.offer(iced, at(330), FIVE_S).unwrap();
        assert_eq!(out.frames_received, 3_000);
        // A lost frame is shown (band 1), spaced like any value.
        let mut lost = out.clone();
        lost.frames_lost = 1;
        assert_eq!(f.offer(lost.clone(), at(332), FIVE_S), None);
        assert_eq!(f.offer(lost, at(335), FIVE_S).unwrap().frames_lost, 1);
    }

    #[test]
    fn water_is_not_ice_thickness() {
        let m = Measurement {
            uptime_ms: 1,
            i1_na: 5_000,
            i2_na: 0,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: 500,
            vdda_mv: 3300,
            flags: 0,
            state: DetectorState::Wet,
        };
        let water = IceEstimate {
            thickness_um: 400,
            sigma_um: 50,
            medium: Medium::Water,
            probability_permille: 950,
        };
        let s = StateJson::new("n", 1, &Reading::new(&m, Some(&water), None), (1, 0), 0);
        assert_eq!(s.ice_thickness_mm, Some(0.0));
        assert_eq!(s.water_film_mm, Some(0.4));
        let none = StateJson::new("n", 1, &Reading::new(&m, None, None), (1, 0), 0);
        let v = serde_json::to_value(&none).unwrap();
        assert!(v.get("ice_thickness_mm").is_none() && v.get("water_film_mm").is_none());
    }
}
