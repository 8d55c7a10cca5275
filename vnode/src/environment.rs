//! What the sensor face sees over (virtual) time: a timeline of segments,
//! each with its cover (dry face, or a medium accreting at a rate), air
//! temperature, ambient light (DC + 100 Hz flicker), LED output factor, the
//! optics' temperature coefficient and self-heating, the face's transmission
//! (fouling) and ADC noise. The photocurrents come from the simulator's
//! curve of the segment's medium at the current thickness, times the
//! optical gain ([`crate::optics`]).
//!
//! Thickness is continuous across segments (a water film that freezes keeps
//! its thickness), is 0 on a `Dry` segment, may be set at a segment's start
//! ([`Segment::thickness`]) and is clamped to 0..=15 mm (the sim's range).
//! After the last segment its conditions hold forever.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use fois_sim::{Curve, Geometry, IceKind, SensorKind, SimConfig, accretion_curve};

use crate::optics::{OpticalGain, temperature_factor};

/// Largest thickness the curves cover, mm.
pub const MAX_THICKNESS_MM: f64 = 15.0;

/// What covers the sensor face during a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Cover {
    /// Clean, dry face.
    Dry,
    /// Ideal clear ice.
    Flat,
    /// Glazed ice.
    Glazed,
    /// Rime ice.
    Rime,
    /// A clear water film.
    Water,
}

impl Cover {
    /// The simulator's medium (`None` for a dry face).
    pub fn ice_kind(self) -> Option<IceKind> {
        match self {
            Cover::Dry => None,
            Cover::Flat => Some(IceKind::Flat),
            Cover::Glazed => Some(IceKind::Glazed),
            Cover::Rime => Some(IceKind::Rime),
            Cover::Water => Some(IceKind::Water),
        }
    }

    /// Parse `dry|flat|glazed|rime|water`.
    pub fn parse(s: &str) -> Option<Cover> {
        Some(match s.trim().to_ascii_lowercase().as_str() {
            "dry" => Cover::Dry,
            "flat" => Cover::Flat,
            "glazed" => Cover::Glazed,
            "rime" => Cover::Rime,
            "water" => Cover::Water,
            _ => return None,
        })
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Cover::Dry => "dry",
            Cover::Flat => "flat",
            Cover::Glazed => "glazed",
            Cover::Rime => "rime",
            Cover::Water => "water",
        }
    }
}

/// How the NTC (air temperature, PA4) is wired during a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NtcWiring {
    /// Connected: the divider reads the air temperature.
    #[default]
    Connected,
    /// Unplugged (or a broken lead): PA4 sits at 3V3 through the fixed
    /// resistor, code 4095.
    Open,
    /// Shorted to GND: code 0.
    Short,
}

impl NtcWiring {
    /// Parse `connected|open|short`.
    pub fn parse(s: &str) -> Option<NtcWiring> {
        Some(match s.trim().to_ascii_lowercase().as_str() {
            "connected" => NtcWiring::Connected,
            "open" => NtcWiring::Open,
            "short" => NtcWiring::Short,
            _ => return None,
        })
    }
}

/// One stretch of constant conditions (temperature may ramp).
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Length, s of virtual time.
    pub duration_s: f64,
    /// What covers the face.
    pub cover: Cover,
    /// Accretion rate, mm/h (negative: melting/sublimation).
    pub rate_mm_per_h: f64,
    /// Thickness at the segment's start, mm (`None`: continue).
    pub start_thickness_mm: Option<f64>,
    /// Air temperature at the start, °C.
    pub air_temp_c: f64,
    /// Air temperature at the end, °C (`None`: constant); linear ramp.
    pub air_temp_end_c: Option<f64>,
    /// Ambient (sun) DC photocurrent per channel, µA.
    pub ambient_ua: [f64; 2],
    /// Amplitude of the 100 Hz mains flicker per channel, µA.
    pub flicker_ua: [f64; 2],
    /// Flicker frequency, Hz (100 Hz: 50 Hz mains, full-wave).
    pub flicker_hz: f64,
    /// LED output relative to nominal (0.7 = −30 %) at the start.
    pub led_factor: f64,
    /// LED output factor at the end (`None`: constant); linear ramp.
    pub led_factor_end: Option<f64>,
    /// Net temperature coefficient κ of the optical gain, 1/K (LED output ×
    /// phototransistor responsivity): the signal scales with
    /// exp(κ·(T_optics − 25 °C)) ([`crate::optics`]). 0: none.
    pub gain_tempco_per_k: f64,
    /// The optoelectronics' (and the MCU die's) temperature above the air,
    /// K: the enclosure's self-heating. T_optics = air + this.
    pub optics_above_air_k: f64,
    /// Transmission of the face at the start (1 = clean; fouling < 1): the
    /// LED-induced signal scales with its square, ambient light with it.
    pub face_transmission: f64,
    /// Transmission at the end (`None`: constant); linear ramp.
    pub face_transmission_end: Option<f64>,
    /// ADC noise, rms LSB (Gaussian, per conversion).
    pub adc_noise_lsb: f64,
    /// The NTC's wiring (fault injection: unplugged or shorted).
    pub ntc: NtcWiring,
    /// A reference target on the face for a gain calibration: its net
    /// currents per channel at gain 1, µA (`None`: no target). While it is
    /// on, the face reads the dry face's currents plus these, both times
    /// the optical gain, whatever the cover: its rise over the dark
    /// baseline is the target's currents times the gain.
    pub target_ua: Option<[f64; 2]>,
}

impl Segment {
    /// A segment of `duration_s` with `cover`, no accretion, −5 °C, no
    /// ambient light, nominal LED, 1 LSB noise.
    pub fn new(duration_s: f64, cover: Cover) -> Self {
        Segment {
            duration_s,
            cover,
            rate_mm_per_h: 0.0,
            start_thickness_mm: None,
            air_temp_c: -5.0,
            air_temp_end_c: None,
            ambient_ua: [0.0; 2],
            flicker_ua: [0.0; 2],
            flicker_hz: 100.0,
            led_factor: 1.0,
            led_factor_end: None,
            gain_tempco_per_k: 0.0,
            optics_above_air_k: 0.0,
            face_transmission: 1.0,
            face_transmission_end: None,
            adc_noise_lsb: 1.0,
            ntc: NtcWiring::Connected,
            target_ua: None,
        }
    }
    /// A reference target on the face, µA at gain 1 per channel.
    pub fn target(mut self, ua: [f64; 2]) -> Self {
        self.target_ua = Some(ua);
        self
    }
    /// The NTC unplugged, shorted or connected.
    pub fn ntc(mut self, wiring: NtcWiring) -> Self {
        self.ntc = wiring;
        self
    }
    /// Accretion rate, mm/h.
    pub fn rate(mut self, mm_per_h: f64) -> Self {
        self.rate_mm_per_h = mm_per_h;
        self
    }
    /// Thickness at the start, mm.
    pub fn thickness(mut self, mm: f64) -> Self {
        self.start_thickness_mm = Some(mm);
        self
    }
    /// Constant air temperature, °C.
    pub fn temp(mut self, c: f64) -> Self {
        self.air_temp_c = c;
        self.air_temp_end_c = None;
        self
    }
    /// Air temperature ramping from `start` to `end` °C.
    pub fn temp_ramp(mut self, start: f64, end: f64) -> Self {
        self.air_temp_c = start;
        self.air_temp_end_c = Some(end);
        self
    }
    /// Ambient DC per channel, µA.
    pub fn ambient(mut self, ua: [f64; 2]) -> Self {
        self.ambient_ua = ua;
        self
    }
    /// 100 Hz flicker amplitude per channel, µA.
    pub fn flicker(mut self, ua: [f64; 2]) -> Self {
        self.flicker_ua = ua;
        self
    }
    /// Constant LED output factor.
    pub fn led(mut self, factor: f64) -> Self {
        self.led_factor = factor;
        self.led_factor_end = None;
        self
    }
    /// LED output factor ramping from `start` to `end` (drift).
    pub fn led_ramp(mut self, start: f64, end: f64) -> Self {
        self.led_factor = start;
        self.led_factor_end = Some(end);
        self
    }
    /// The optical gain's net temperature coefficient κ, 1/K.
    pub fn gain_tempco(mut self, per_k: f64) -> Self {
        self.gain_tempco_per_k = per_k;
        self
    }
    /// The optics' self-heating above the air, K.
    pub fn optics_above_air(mut self, k: f64) -> Self {
        self.optics_above_air_k = k;
        self
    }
    /// Face transmission ramping from `start` to `end` (fouling).
    pub fn transmission_ramp(mut self, start: f64, end: f64) -> Self {
        self.face_transmission = start;
        self.face_transmission_end = Some(end);
        self
    }
    /// ADC noise, rms LSB.
    pub fn noise(mut self, lsb: f64) -> Self {
        self.adc_noise_lsb = lsb;
        self
    }
}

/// Segments in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    segments: Vec<Segment>,
    /// Start time of each segment, s.
    starts_s: Vec<f64>,
    /// Thickness at each segment's start, mm.
    start_mm: Vec<f64>,
}

fn clamp_mm(d: f64) -> f64 {
    if d.is_finite() {
        d.clamp(0.0, MAX_THICKNESS_MM)
    } else {
        0.0
    }
}

impl Timeline {
    /// A timeline; an empty list means one endless dry segment. Negative or
    /// NaN durations count as 0; `f64::INFINITY` is allowed.
    pub fn new(mut segments: Vec<Segment>) -> Self {
        if segments.is_empty() {
            segments.push(Segment::new(0.0, Cover::Dry));
        }
        let mut starts_s = Vec::with_capacity(segments.len());
        let mut start_mm = Vec::with_capacity(segments.len());
        let (mut t, mut d) = (0.0, 0.0);
        for s in &mut segments {
            if s.duration_s.is_nan() || s.duration_s < 0.0 {
                s.duration_s = 0.0;
            }
            let d0 = match (s.cover, s.start_thickness_mm) {
                (Cover::Dry, _) => 0.0,
                (_, Some(x)) => clamp_mm(x),
                (_, None) => d,
            };
            starts_s.push(t);
            start_mm.push(d0);
            t += s.duration_s;
            d = if s.cover == Cover::Dry {
                0.0
            } else {
                clamp_mm(d0 + s.rate_mm_per_h * s.duration_s / 3600.0)
            };
        }
        Timeline {
            segments,
            starts_s,
            start_mm,
        }
    }

    /// One endless segment.
    pub fn constant(segment: Segment) -> Self {
        Self::new(vec![segment])
    }

    /// The segments.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Total length of the segments, s.
    pub fn duration_s(&self) -> f64 {
        self.starts_s.last().copied().unwrap_or(0.0)
            + self.segments.last().map_or(0.0, |s| s.duration_s)
    }

    /// Index of the segment in force at `t_s` (the last one after the end).
    pub fn index_at(&self, t_s: f64) -> usize {
        self.starts_s
            .partition_point(|&s| s <= t_s)
            .saturating_sub(1)
    }
}

/// The true conditions at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Time, s.
    pub t_s: f64,
    /// Segment index.
    pub segment: usize,
    /// Face cover.
    pub cover: Cover,
    /// Film thickness, mm.
    pub thickness_mm: f64,
    /// Air temperature, °C.
    pub air_temp_c: f64,
    /// The optoelectronics' temperature (air + self-heating): what the
    /// MCU's internal sensor reads, °C.
    pub optics_temp_c: f64,
    /// LED-induced photocurrent per channel (sim curve × optical gain), µA.
    pub led_signal_ua: [f64; 2],
    /// Ambient photocurrent per channel at this instant ((DC + flicker ≥ 0)
    /// × face transmission), µA.
    pub ambient_ua: [f64; 2],
    /// LED output factor.
    pub led_factor: f64,
    /// The optical gain's factors (LED, temperature, face transmission);
    /// `gain.signal_gain()` is the true relative gain g the node estimates.
    pub gain: OpticalGain,
    /// ADC noise, rms LSB.
    pub adc_noise_lsb: f64,
    /// The NTC's wiring.
    pub ntc: NtcWiring,
}

/// Timeline + the simulator's curves for each medium in it.
#[derive(Debug, Clone)]
pub struct Environment {
    timeline: Timeline,
    curves: BTreeMap<Cover, Curve>,
    dry_ua: [f64; 2],
}

fn lerp(a: f64, b: Option<f64>, w: f64) -> f64 {
    match b {
        Some(b) => a + (b - a) * w,
        None => a,
    }
}

impl Environment {
    /// Ray-trace one accretion (run 0 of `seed`) of each medium the timeline
    /// uses, thesis chapter-5 geometry, sensor `sensor`.
    pub fn new(timeline: Timeline, sensor: SensorKind, seed: u64) -> Self {
        let mut kinds: Vec<Cover> = timeline
            .segments()
            .iter()
            .filter(|s| s.cover != Cover::Dry)
            .map(|s| s.cover)
            .collect();
        kinds.sort();
        kinds.dedup();
        // The dry face needs a curve too (its value at 0 mm).
        let dry_source = kinds.first().copied().unwrap_or(Cover::Flat);
        if kinds.is_empty() {
            kinds.push(dry_source);
        }
        let curves: Vec<(Cover, Curve)> = {
            use rayon::prelude::*;
            kinds
                .par_iter()
                .map(|&c| {
                    let kind = c.ice_kind().unwrap_or(IceKind::Flat);
                    let cfg = SimConfig::new(kind, sensor, Geometry::default());
                    (c, accretion_curve(&cfg, seed, 0))
                })
                .collect()
        };
        let dry = curves
            .iter()
            .find(|(c, _)| *c == dry_source)
            .map(|(_, curve)| curve.currents_at(0.0))
            .unwrap_or((0.0, 0.0));
        Self::with_curves(timeline, curves, [dry.0, dry.1])
    }

    /// With given curves (tests: no ray tracing). `dry_ua`: the dry face's
    /// currents. A medium without a curve reads as dry.
    pub fn with_curves(
        timeline: Timeline,
        curves: impl IntoIterator<Item = (Cover, Curve)>,
        dry_ua: [f64; 2],
    ) -> Self {
        Environment {
            timeline,
            curves: curves.into_iter().collect(),
            dry_ua,
        }
    }

    /// The timeline.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The curve used for a medium.
    pub fn curve(&self, cover: Cover) -> Option<&Curve> {
        self.curves.get(&cover)
    }

    /// Conditions at virtual time `t_ns`.
    pub fn truth(&self, t_ns: u64) -> Truth {
        let t_s = t_ns as f64 * 1e-9;
        let tl = &self.timeline;
        let i = tl.index_at(t_s);
        let seg = &tl.segments[i];
        let into = (t_s - tl.starts_s[i]).max(0.0);
        let w = if seg.duration_s > 0.0 {
            (into / seg.duration_s).min(1.0)
        } else {
            1.0
        };
        let thickness_mm = match seg.cover {
            Cover::Dry => 0.0,
            _ => clamp_mm(tl.start_mm[i] + seg.rate_mm_per_h * into / 3600.0),
        };
        let optical = match (seg.target_ua, seg.cover, self.curves.get(&seg.cover)) {
            (Some(t), _, _) => [self.dry_ua[0] + t[0], self.dry_ua[1] + t[1]],
            (None, Cover::Dry, _) | (None, _, None) => self.dry_ua,
            (None, _, Some(c)) => {
                let (a, b) = c.currents_at(thickness_mm);
                [a, b]
            }
        };
        let led_factor = lerp(seg.led_factor, seg.led_factor_end, w).max(0.0);
        let air_temp_c = lerp(seg.air_temp_c, seg.air_temp_end_c, w);
        let optics_temp_c = air_temp_c + seg.optics_above_air_k;
        let gain = OpticalGain {
            led_factor,
            temperature_factor: temperature_factor(seg.gain_tempco_per_k, optics_temp_c),
            face_transmission: lerp(seg.face_transmission, seg.face_transmission_end, w)
                .clamp(0.0, 1.0),
        };
        let phase = (2.0 * PI * seg.flicker_hz * t_s).sin();
        let ambient_ua = [0, 1].map(|k| {
            (seg.ambient_ua[k] + seg.flicker_ua[k] * phase).max(0.0) * gain.ambient_gain()
        });
        let signal_gain = gain.signal_gain();
        Truth {
            t_s,
            segment: i,
            cover: seg.cover,
            thickness_mm,
            air_temp_c,
            optics_temp_c,
            led_signal_ua: optical.map(|x| x * signal_gain),
            ambient_ua,
            led_factor,
            gain,
            adc_noise_lsb: seg.adc_noise_lsb.max(0.0),
            ntc: seg.ntc,
        }
    }
}

#[cfg(test)]
mod tests;
