//! Scenario files: a timeline (and optionally sensor and seed) as TOML, so
//! conditions like "water at +5 °C, then the same water freezing as the air
//! drops below zero" are data. Unknown keys are refused (typos do not pass
//! silently).
//!
//! ```toml
//! sensor = "b"          # a | b (optional, default b)
//! seed = 7              # optional, default 1
//! gain_calibration = [1.0, 0.02]  # a factory calibration of the optical gain (optional)
//!
//! [[segment]]
//! duration_s = 600      # virtual seconds ("inf" allowed for the last)
//! cover = "water"       # dry | flat | glazed | rime | water
//! rate_mm_per_h = 2.0   # accretion rate (default 0)
//! air_temp_c = 5.0      # (default -5)
//!
//! [[segment]]
//! duration_s = 1800
//! cover = "glazed"      # the same film, now ice: thickness carries on
//! rate_mm_per_h = 1.0
//! air_temp_c = 5.0
//! air_temp_end_c = -5.0 # linear ramp over the segment
//! ambient_ua = [20.0, 10.0]   # sun, per channel
//! flicker_ua = [3.0, 3.0]     # 100 Hz amplitude
//! flicker_hz = 100.0
//! led_factor = 1.0
//! led_factor_end = 0.7        # LED output -30 % over the segment
//! gain_tempco_ppm_per_k = -6000.0  # optical gain × exp(κ·(T_optics − 25 °C))
//! optics_above_air_k = 2.0    # enclosure self-heating (default 0)
//! face_transmission = 1.0     # fouling: signal × t², ambient × t (default 1)
//! face_transmission_end = 0.8
//! adc_noise_lsb = 1.0
//! thickness_mm = 2.0          # set the thickness at the start (optional)
//! ntc = "open"                # connected | open | short (default connected)
//! target_ua = [25.2, 9.56]    # a reference target on the face, µA at gain 1
//!                             # (gain calibration practice; default none)
//!
//! [config]                    # the node's config in its flash at first boot
//! frame_period_ms = 1000      # (names of `foisctl config set`)
//!
//! [[overlay]]                 # a temporary change over the segments
//! start_s = 300
//! duration_s = 60
//! ambient_ua = [40.0, 40.0]
//! ```
//!
//! A growth rate that varies: `rate_ln_sd = 0.5`, `rate_ln_corr_s = 3600`
//! (and optionally `rate_ln_step_s = 60`, `rate_ln_seed = 7`) in a segment
//! with a rate make ln r a seeded random process around it (the rate its
//! mean), held per step ([`crate::rate_walk`]); the segment becomes one
//! sub-segment per step.
//!
//! The hardware-in-loop suite reads the same files (`hil/scenarios/*.toml`)
//! and adds keys only its checker uses: `name`, `description`, `class`,
//! `end_s`, `accuracy`, `[[command]]`, `[sweep]`, `[link]`, `[expect]`. They
//! are accepted here and ignored ([`Scenario::ignored`] names the ones a
//! file has); their meaning and checks are in `hil/README.md`.

use serde::Deserialize;

use std::collections::BTreeMap;

use super::environment::{Cover, NtcWiring, Segment, Timeline};
use super::overlay::{self, OverlaySpec};
use fois_protocol::Config;
use fois_sim::SensorKind;

/// A parsed scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The timeline.
    pub timeline: Timeline,
    /// Sensor construction (default B).
    pub sensor: SensorKind,
    /// Seed (default 1).
    pub seed: u64,
    /// A factory calibration of the optical gain written to the node's
    /// flash before it boots: (gain, relative sd); `None`: a new node, its
    /// gain unknown ([`crate::NodeOptions::gain_calibration`]).
    pub gain_calibration: Option<(f64, f64)>,
    /// The node's config at first boot (the file's `[config]`); `None`:
    /// the defaults.
    pub config: Option<Config>,
    /// The keys of the file that only the hardware-in-loop checker uses
    /// (accepted, not acted on here), in file order of [`HIL_ONLY_KEYS`].
    pub ignored: Vec<&'static str>,
}

/// Top-level keys of a scenario file that only the hardware-in-loop suite
/// acts on (its checker's class and expectations, its commands, sweeps and
/// lossy link); the virtual node accepts and ignores them.
pub const HIL_ONLY_KEYS: [&str; 9] = [
    "name",
    "description",
    "class",
    "end_s",
    "accuracy",
    "command",
    "sweep",
    "link",
    "expect",
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    sensor: Option<String>,
    seed: Option<u64>,
    gain_calibration: Option<[f64; 2]>,
    segment: Vec<SegmentSpec>,
    #[serde(default)]
    config: BTreeMap<String, toml::Value>,
    #[serde(default)]
    overlay: Vec<OverlaySpec>,
    // The hardware-in-loop suite's keys (HIL_ONLY_KEYS): checked there.
    name: Option<toml::Value>,
    description: Option<toml::Value>,
    class: Option<toml::Value>,
    end_s: Option<toml::Value>,
    accuracy: Option<toml::Value>,
    command: Option<toml::Value>,
    sweep: Option<toml::Value>,
    link: Option<toml::Value>,
    expect: Option<toml::Value>,
}

/// A `[config]` table (keys as `foisctl config set` names them, integer or
/// boolean values) as a node config, checked by the node's own rule;
/// `None` for an empty table.
pub fn config(table: &BTreeMap<String, toml::Value>) -> Result<Option<Config>, String> {
    if table.is_empty() {
        return Ok(None);
    }
    let mut cfg = Config::default();
    for (key, value) in table {
        let text = match value {
            toml::Value::Integer(i) => i.to_string(),
            toml::Value::Boolean(b) => b.to_string(),
            other => {
                return Err(format!(
                    "[config] {key} = {other}: expected an integer or a boolean"
                ));
            }
        };
        cfg.set_from_str(key, &text)
            .map_err(|e| format!("[config] {key} = {text}: {e}"))?;
    }
    cfg.validate()
        .map_err(|e| format!("[config] is refused by the node's rule: {e}"))?;
    Ok(Some(cfg))
}

/// A `gain_calibration = [gain, relative sd]` as a file gives it, checked:
/// the gain within what the node's calibration accepts
/// (`fois_firmware::calibration::gain::GAIN_RANGE`), the sd in (0, 1).
pub fn gain_calibration(spec: [f64; 2]) -> Result<(f64, f64), String> {
    let [gain, rel_sd] = spec;
    let (lo, hi) = fois_firmware::calibration::gain::GAIN_RANGE;
    if !(gain >= f64::from(lo) && gain <= f64::from(hi)) {
        return Err(format!(
            "gain_calibration: gain {gain} outside the node's range {lo}..={hi}"
        ));
    }
    if !(rel_sd > 0.0 && rel_sd < 1.0) {
        return Err(format!(
            "gain_calibration: relative sd {rel_sd} must be in (0, 1)"
        ));
    }
    Ok((gain, rel_sd))
}

/// One `[[segment]]` table as written in a file (every key but
/// `duration_s` and `cover` optional). Public so that other file formats
/// (the hardware-in-loop scenarios) embed the same table and get the same
/// checks; turn a list of them into a [`Timeline`] with [`timeline`].
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentSpec {
    /// Virtual seconds; `"inf"` only for the last segment.
    pub duration_s: DurationSpec,
    /// dry | flat | glazed | rime | water.
    pub cover: String,
    /// Accretion rate, mm/h (default 0).
    pub rate_mm_per_h: Option<f64>,
    /// Air temperature, °C (default −5).
    pub air_temp_c: Option<f64>,
    /// Air temperature at the segment's end (linear ramp), °C.
    pub air_temp_end_c: Option<f64>,
    /// Ambient DC per channel, µA (default 0).
    pub ambient_ua: Option<[f64; 2]>,
    /// Flicker amplitude per channel, µA (default 0).
    pub flicker_ua: Option<[f64; 2]>,
    /// Flicker frequency, Hz (default 100).
    pub flicker_hz: Option<f64>,
    /// LED output factor (default 1).
    pub led_factor: Option<f64>,
    /// LED output factor at the segment's end (linear ramp).
    pub led_factor_end: Option<f64>,
    /// Net temperature coefficient of the optical gain, ppm/K (the node
    /// config's unit; default 0): `fois_vnode::optics`.
    pub gain_tempco_ppm_per_k: Option<f64>,
    /// The optics' temperature above the air (self-heating), K (default 0).
    pub optics_above_air_k: Option<f64>,
    /// Face transmission, 0..=1 (default 1: clean).
    pub face_transmission: Option<f64>,
    /// Face transmission at the segment's end (linear ramp).
    pub face_transmission_end: Option<f64>,
    /// ADC noise, rms LSB (default 1).
    pub adc_noise_lsb: Option<f64>,
    /// Thickness at the segment's start, mm (default: carried over).
    pub thickness_mm: Option<f64>,
    /// The NTC's wiring: connected | open | short (default connected).
    pub ntc: Option<String>,
    /// A reference target on the face (gain calibration practice), µA at
    /// gain 1 per channel.
    pub target_ua: Option<[f64; 2]>,
    /// A varying rate: the standard deviation of ln r, an
    /// Ornstein–Uhlenbeck process around the segment's rate (its mean)
    /// ([`crate::rate_walk`]; default none: a constant rate).
    pub rate_ln_sd: Option<f64>,
    /// The walk's correlation time, s (required with `rate_ln_sd`).
    pub rate_ln_corr_s: Option<f64>,
    /// The walk's constant-rate steps, s (default 60).
    pub rate_ln_step_s: Option<f64>,
    /// The walk's seed (default 1).
    pub rate_ln_seed: Option<u64>,
}

/// A segment's length: seconds, or `"inf"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum DurationSpec {
    /// Virtual seconds.
    Seconds(f64),
    /// `"inf"` (only for the last segment).
    Text(String),
}

/// `"a"` / `"b"` (any case; `None` = B) as a sensor construction.
pub fn sensor_named(name: Option<&str>) -> Result<SensorKind, String> {
    match name.map(str::to_ascii_lowercase).as_deref() {
        None | Some("b") => Ok(SensorKind::B),
        Some("a") => Ok(SensorKind::A),
        Some(other) => Err(format!("sensor = \"{other}\": expected \"a\" or \"b\"")),
    }
}

/// Check every segment table and build the timeline.
pub fn timeline(specs: Vec<SegmentSpec>) -> Result<Timeline, String> {
    if specs.is_empty() {
        return Err("a scenario needs at least one [[segment]]".into());
    }
    let n = specs.len();
    let mut segs = Vec::with_capacity(n);
    for (i, s) in specs.into_iter().enumerate() {
        let at = |what: &str| format!("segment {}: {what}", i + 1);
        let duration_s = match s.duration_s {
            DurationSpec::Seconds(x) if x.is_finite() && x >= 0.0 => x,
            DurationSpec::Text(t) if t == "inf" && i + 1 == n => f64::INFINITY,
            _ => {
                return Err(at(
                    "duration_s must be >= 0 seconds (\"inf\" only for the last segment)",
                ));
            }
        };
        let cover = Cover::parse(&s.cover).ok_or_else(|| {
            at(&format!(
                "cover = \"{}\": expected dry, flat, glazed, rime or water",
                s.cover
            ))
        })?;
        let finite =
            |v: Option<f64>, name: &str, lo: f64, hi: f64| -> Result<Option<f64>, String> {
                match v {
                    Some(x) if !(x.is_finite() && (lo..=hi).contains(&x)) => {
                        Err(at(&format!("{name} = {x} is outside {lo}..={hi}")))
                    }
                    other => Ok(other),
                }
            };
        let pair = |v: Option<[f64; 2]>, name: &str| -> Result<Option<[f64; 2]>, String> {
            match v {
                Some([a, b]) if !(a.is_finite() && b.is_finite() && a >= 0.0 && b >= 0.0) => {
                    Err(at(&format!("{name} must be two non-negative µA values")))
                }
                other => Ok(other),
            }
        };
        let mut seg = Segment::new(duration_s, cover);
        seg.rate_mm_per_h =
            finite(s.rate_mm_per_h, "rate_mm_per_h", -1000.0, 1000.0)?.unwrap_or(0.0);
        seg.air_temp_c = finite(s.air_temp_c, "air_temp_c", -60.0, 80.0)?.unwrap_or(seg.air_temp_c);
        seg.air_temp_end_c = finite(s.air_temp_end_c, "air_temp_end_c", -60.0, 80.0)?;
        seg.ambient_ua = pair(s.ambient_ua, "ambient_ua")?.unwrap_or([0.0; 2]);
        seg.flicker_ua = pair(s.flicker_ua, "flicker_ua")?.unwrap_or([0.0; 2]);
        seg.flicker_hz = finite(s.flicker_hz, "flicker_hz", 0.0, 10_000.0)?.unwrap_or(100.0);
        seg.led_factor = finite(s.led_factor, "led_factor", 0.0, 10.0)?.unwrap_or(1.0);
        seg.led_factor_end = finite(s.led_factor_end, "led_factor_end", 0.0, 10.0)?;
        seg.gain_tempco_per_k = crate::optics::tempco_per_k_from_ppm(
            finite(
                s.gain_tempco_ppm_per_k,
                "gain_tempco_ppm_per_k",
                -50_000.0,
                50_000.0,
            )?
            .unwrap_or(0.0),
        );
        seg.optics_above_air_k =
            finite(s.optics_above_air_k, "optics_above_air_k", -20.0, 60.0)?.unwrap_or(0.0);
        seg.face_transmission =
            finite(s.face_transmission, "face_transmission", 0.0, 1.0)?.unwrap_or(1.0);
        seg.face_transmission_end =
            finite(s.face_transmission_end, "face_transmission_end", 0.0, 1.0)?;
        seg.adc_noise_lsb = finite(s.adc_noise_lsb, "adc_noise_lsb", 0.0, 500.0)?.unwrap_or(1.0);
        seg.start_thickness_mm = finite(s.thickness_mm, "thickness_mm", 0.0, 15.0)?;
        seg.target_ua = pair(s.target_ua, "target_ua")?;
        if let Some(w) = &s.ntc {
            seg.ntc = NtcWiring::parse(w)
                .ok_or_else(|| at(&format!("ntc = \"{w}\": expected connected, open or short")))?;
        }
        match walk(
            (
                s.rate_ln_sd,
                s.rate_ln_corr_s,
                s.rate_ln_step_s,
                s.rate_ln_seed,
            ),
            &seg,
        )
        .map_err(|e| at(&e))?
        {
            Some(w) => segs.extend(crate::rate_walk::expand(&seg, w)),
            None => segs.push(seg),
        }
    }
    Ok(Timeline::new(segs))
}

/// A segment's rate walk, checked (`None`: a constant rate).
/// The keys: `rate_ln_sd`, `rate_ln_corr_s`, `rate_ln_step_s`, `rate_ln_seed`.
type WalkKeys = (Option<f64>, Option<f64>, Option<f64>, Option<u64>);

fn walk(keys: WalkKeys, seg: &Segment) -> Result<Option<crate::rate_walk::RateWalk>, String> {
    let (sd_ln, corr_s, step_s, seed) = keys;
    let Some(sd_ln) = sd_ln else {
        return match (corr_s, step_s, seed) {
            (None, None, None) => Ok(None),
            _ => Err("rate_ln_corr_s, rate_ln_step_s and rate_ln_seed need rate_ln_sd".into()),
        };
    };
    if !(sd_ln.is_finite() && (0.0..=3.0).contains(&sd_ln)) {
        return Err(format!("rate_ln_sd = {sd_ln} is outside 0..=3"));
    }
    if !(seg.duration_s.is_finite() && seg.rate_mm_per_h > 0.0) {
        return Err("rate_ln_sd needs a finite duration_s and rate_mm_per_h > 0".into());
    }
    let corr_s = corr_s.ok_or("rate_ln_sd needs rate_ln_corr_s (the correlation time, s)")?;
    let step_s = step_s.unwrap_or(crate::rate_walk::DEFAULT_STEP_S);
    for (name, v) in [("rate_ln_corr_s", corr_s), ("rate_ln_step_s", step_s)] {
        if !(v.is_finite() && v >= 1.0) {
            return Err(format!("{name} = {v} must be >= 1 s"));
        }
    }
    Ok(Some(crate::rate_walk::RateWalk {
        sd_ln,
        corr_s,
        step_s,
        seed: seed.unwrap_or(1),
    }))
}

/// Parse a scenario from TOML text.
pub fn parse(text: &str) -> Result<Scenario, String> {
    let f: File = toml::from_str(text).map_err(|e| e.to_string())?;
    let present = [
        f.name.is_some(),
        f.description.is_some(),
        f.class.is_some(),
        f.end_s.is_some(),
        f.accuracy.is_some(),
        f.command.is_some(),
        f.sweep.is_some(),
        f.link.is_some(),
        f.expect.is_some(),
    ];
    let ignored = HIL_ONLY_KEYS
        .iter()
        .zip(present)
        .filter_map(|(k, p)| p.then_some(*k))
        .collect();
    let segments = timeline(f.segment)?.segments().to_vec();
    Ok(Scenario {
        timeline: Timeline::new(overlay::apply(segments, &f.overlay)?),
        sensor: sensor_named(f.sensor.as_deref())?,
        seed: f.seed.unwrap_or(1),
        gain_calibration: f.gain_calibration.map(gain_calibration).transpose()?,
        config: config(&f.config)?,
        ignored,
    })
}

/// Read and parse a scenario file.
pub fn load(path: &std::path::Path) -> anyhow::Result<Scenario> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("cannot read scenario {}: {e}", path.display()))?;
    parse(&text).map_err(|e| anyhow::anyhow!("scenario {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_varying_rate_becomes_steps_and_its_keys_are_checked() {
        let seg = |extra: &str| {
            format!(
                "[[segment]]\nduration_s = 600\ncover = \"rime\"\nrate_mm_per_h = 2.0\n{extra}\n"
            )
        };
        let s = parse(&seg(
            "rate_ln_sd = 0.5\nrate_ln_corr_s = 3600\nrate_ln_step_s = 100",
        ))
        .unwrap();
        let segs = s.timeline.segments();
        assert_eq!(segs.len(), 6);
        assert!(
            segs.iter()
                .all(|s| s.duration_s == 100.0 && s.cover == Cover::Rime)
        );
        assert!(
            segs.windows(2)
                .all(|w| w[0].rate_mm_per_h != w[1].rate_mm_per_h)
        );
        let seeded = parse(&seg(
            "rate_ln_sd = 0.5\nrate_ln_corr_s = 3600\nrate_ln_seed = 2",
        ))
        .unwrap();
        assert_ne!(
            seeded.timeline.segments()[0].rate_mm_per_h,
            parse(&seg("rate_ln_sd = 0.5\nrate_ln_corr_s = 3600"))
                .unwrap()
                .timeline
                .segments()[0]
                .rate_mm_per_h
        );
        for (bad, says) in [
            ("rate_ln_corr_s = 3600", "need rate_ln_sd"),
            ("rate_ln_sd = 0.5", "needs rate_ln_corr_s"),
            ("rate_ln_sd = -1.0\nrate_ln_corr_s = 3600", "outside 0..=3"),
            ("rate_ln_sd = 0.5\nrate_ln_corr_s = 0.5", "must be >= 1 s"),
        ] {
            let e = parse(&seg(bad)).unwrap_err();
            assert!(e.contains(says) && e.contains("segment 1"), "{bad}: {e}");
        }
        let paused = "[[segment]]\nduration_s = 600\ncover = \"rime\"\nrate_ln_sd = 0.5\nrate_ln_corr_s = 60\n";
        assert!(parse(paused).unwrap_err().contains("rate_mm_per_h > 0"));
    }

    #[test]
    fn the_documented_example_parses() {
        let text = include_str!("scenario.rs")
            .lines()
            .filter_map(|l| l.strip_prefix("//! "))
            .skip_while(|l| !l.starts_with("sensor"))
            .take_while(|l| !l.starts_with("```"))
            .collect::<Vec<_>>()
            .join("\n");
        let s = parse(&text).unwrap();
        assert_eq!((s.sensor, s.seed), (SensorKind::B, 7));
        assert_eq!(s.gain_calibration, Some((1.0, 0.02)));
        for bad in ["[5.0, 0.02]", "[1.0, 0.0]", "[nan, 0.02]", "[1.0, 1.0]"] {
            let t = text.replace("[1.0, 0.02]", bad);
            assert!(parse(&t).unwrap_err().contains("gain_calibration"), "{bad}");
        }
        let segs = s.timeline.segments();
        // The overlay cuts the water segment at 300 s and 360 s.
        assert_eq!(segs.len(), 4);
        assert_eq!(
            segs.iter().map(|s| s.duration_s).collect::<Vec<_>>(),
            [300.0, 60.0, 240.0, 1800.0]
        );
        assert_eq!(segs[1].ambient_ua, [40.0, 40.0]);
        assert_eq!(segs[2].ambient_ua, [0.0, 0.0]);
        assert_eq!(s.config.map(|c| c.frame_period_ms), Some(1000));
        assert!(s.ignored.is_empty());
        let segs = [&segs[0], &segs[3]];
        assert_eq!(segs[0].cover, Cover::Water);
        assert_eq!(segs[1].air_temp_end_c, Some(-5.0));
        assert_eq!(segs[1].led_factor_end, Some(0.7));
        assert!((segs[1].gain_tempco_per_k + 0.006).abs() < 1e-15);
        assert_eq!(segs[1].optics_above_air_k, 2.0);
        assert_eq!(
            (segs[1].face_transmission, segs[1].face_transmission_end),
            (1.0, Some(0.8))
        );
        assert_eq!(
            (segs[0].gain_tempco_per_k, segs[0].face_transmission),
            (0.0, 1.0)
        );
        assert_eq!(segs[1].ambient_ua, [20.0, 10.0]);
        assert_eq!(segs[1].start_thickness_mm, Some(2.0));
        assert_eq!(segs[0].ntc, NtcWiring::Connected);
        assert_eq!(segs[1].ntc, NtcWiring::Open);
    }

    #[test]
    fn mistakes_are_refused_with_the_reason() {
        let e = parse("[[segment]]\nduration_s = 1\ncover = \"slush\"\n").unwrap_err();
        assert!(e.contains("segment 1") && e.contains("slush"), "{e}");
        let e = parse("[[segment]]\nduration_s = 1\ncover = \"dry\"\ntemp = 3\n").unwrap_err();
        assert!(e.contains("unknown field"), "{e}");
        let e = parse("[[segment]]\nduration_s = \"inf\"\ncover = \"dry\"\n[[segment]]\nduration_s = 1\ncover = \"dry\"\n").unwrap_err();
        assert!(e.contains("inf"), "{e}");
        let e =
            parse("[[segment]]\nduration_s = 1\ncover = \"rime\"\nair_temp_c = 300\n").unwrap_err();
        assert!(e.contains("air_temp_c"), "{e}");
        let e = parse("[[segment]]\nduration_s = 1\ncover = \"dry\"\nface_transmission = 1.2\n")
            .unwrap_err();
        assert!(e.contains("face_transmission"), "{e}");
        let e = parse("class = \"rime\"\nexpect = { alarm = true }\n[[segment]]\nduration_s = 1\ncover = \"dry\"\n[config]\nframe_period_ms = 1\n").unwrap_err();
        assert!(e.contains("frame_period_ms"), "{e}");
        let e =
            parse("[[segment]]\nduration_s = 1\ncover = \"dry\"\nntc = \"loose\"\n").unwrap_err();
        assert!(e.contains("segment 1") && e.contains("loose"), "{e}");
        for bad in ["[-1.0, 2.0]", "[20.0, nan]", "[20.0]", "\"20,8\""] {
            let e = parse(&format!(
                "[[segment]]\nduration_s = 1\ncover = \"dry\"\ntarget_ua = {bad}\n"
            ))
            .unwrap_err();
            assert!(e.contains("target_ua"), "{bad}: {e}");
        }
        let ok = parse("[[segment]]\nduration_s = \"inf\"\ncover = \"rime\"\nrate_mm_per_h = 3\n")
            .unwrap();
        assert_eq!(ok.timeline.segments()[0].duration_s, f64::INFINITY);
    }
}
