//! The scenario file format (TOML, one file per case) and its translation
//! into a [`Timeline`] of the virtual hardware.
//!
//! The keys that shape the run (`sensor`, `seed`, `gain_calibration`,
//! `[[segment]]`, `[[overlay]]`, `[config]`) are the virtual node's
//! scenario format (`fois_vnode::scenario`, also read by
//! `foisctl virtual-node --scenario`, which accepts and ignores the keys
//! below): the segment and overlay tables are the vnode crate's own
//! `SegmentSpec` / `OverlaySpec`, checked there; this module adds the name,
//! class, commands, sweep, lossy link and expectations.
//!
//! Every table is `deny_unknown_fields`: a misspelt key is an error naming
//! the file and the key. The format is documented key by key in
//! `hil/README.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, ensure};
use fois_vnode::overlay::{self, OverlaySpec};
use fois_vnode::scenario::{self, SegmentSpec};
use fois_vnode::{Cover, Timeline};

use fois_protocol::Config;
use serde::Deserialize;

/// What kind of case a scenario is: decides which goal the report applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Class {
    /// A dry face: zero false alarms.
    Dry,
    /// Water on the face above freezing: `wet`, zero false alarms.
    Wet,
    /// Ambient-light disturbances on a dry face: zero false alarms.
    Ambient,
    /// Glazed ice: first alarm at ≤ 0.5 mm.
    Glazed,
    /// Rime ice: first alarm at ≤ 0.2 mm.
    Rime,
    /// Anything else: no goal, only the file's expectations.
    Other,
}

impl Class {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Class::Dry => "dry",
            Class::Wet => "wet",
            Class::Ambient => "ambient",
            Class::Glazed => "glazed",
            Class::Rime => "rime",
            Class::Other => "other",
        }
    }

    /// Largest thickness at the first alarm the project's goals allow, mm.
    pub fn alarm_goal_mm(self) -> Option<f64> {
        match self {
            Class::Glazed => Some(GLAZED_GOAL_MM),
            Class::Rime => Some(RIME_GOAL_MM),
            _ => None,
        }
    }

    /// True for the classes whose goal is zero false alarms (no ice at all).
    pub fn no_ice(self) -> bool {
        matches!(self, Class::Dry | Class::Wet | Class::Ambient)
    }
}

/// Goal: first alarm at or below this much rime, mm.
pub const RIME_GOAL_MM: f64 = 0.2;
/// Goal: first alarm at or below this much glazed ice, mm (the Rosemount
/// 0871 trips at 0.5 mm).
pub const GLAZED_GOAL_MM: f64 = 0.5;

/// One scenario file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Display name (default: the file's stem).
    pub name: Option<String>,
    /// One line on what the case shows.
    #[serde(default)]
    pub description: String,
    /// Which goal applies.
    pub class: Class,
    /// Sensor `"a"` or `"b"` (host format; default b).
    pub sensor: Option<String>,
    /// Seed of the accretion curves and the ADC noise (default 1).
    pub seed: Option<u64>,
    /// Run until this virtual time, s (default: the end of the last segment).
    pub end_s: Option<f64>,
    /// Config fields (names of `foisctl config set`) sent in a `SetConfig`
    /// right after boot; the others keep their defaults.
    #[serde(default)]
    pub config: BTreeMap<String, toml::Value>,
    /// The run feeds the ice estimator's accuracy table (its estimate is
    /// recorded beside the truth every frame; see [`crate::accuracy`]).
    #[serde(default)]
    pub accuracy: bool,
    /// A factory calibration of the optical gain, `[gain, relative sd]`
    /// (e.g. `[1.0, 0.02]`), in the node's flash before it boots
    /// (`fois_vnode::NodeOptions::gain_calibration`); without it the node
    /// is new and its gain unknown.
    pub gain_calibration: Option<[f64; 2]>,
    /// The timeline: `fois_vnode::scenario`'s `[[segment]]` tables, checked
    /// there.
    #[serde(default, rename = "segment")]
    pub segments: Vec<SegmentSpec>,
    /// Temporary changes laid over the segments (sun steps, noise bursts).
    #[serde(default, rename = "overlay")]
    pub overlays: Vec<OverlaySpec>,
    /// Commands and button presses at given times.
    #[serde(default, rename = "command")]
    pub commands: Vec<CommandSpec>,
    /// Run the scenario once per value (noise sweep).
    pub sweep: Option<SweepSpec>,
    /// A lossy UART between node and decoder.
    pub link: Option<LinkSpec>,
    /// What must hold.
    #[serde(default)]
    pub expect: Expect,
    /// The file's text (for error messages).
    #[serde(skip)]
    pub source: String,
}

fn one() -> u64 {
    1
}

/// What a [`CommandSpec`] sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Send {
    /// The user button B1 (dark calibration when not iced, else alarm ack).
    Button,
    /// `CalibrateDark` (the version-1 command an older host sends: guarded
    /// like the version-4 one, refused with the codes it knows).
    CalibrateDark,
    /// `CalibrateDarkV4 { force: false }`: the guarded calibration.
    CalibrateDarkV4,
    /// `CalibrateDarkV4 { force: true }`: the forced calibration.
    CalibrateDarkForced,
    /// `AckAlarm`.
    AckAlarm,
    /// `AckAlarmV4` (answered `NoAlarm` when no alarm is on).
    AckAlarmV4,
    /// `GetInfo`.
    GetInfo,
    /// `GetConfig`.
    GetConfig,
    /// `StartStream` (with `frame_period_ms` if given).
    StartStream,
    /// `StopStream`.
    StopStream,
    /// `Reset`.
    Reset,
}

/// The answer a command must get.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Reply {
    /// An `Ack`.
    #[default]
    Ack,
    /// An `Error`.
    Error,
}

/// A command at a given virtual time.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandSpec {
    /// When, s.
    pub at_s: f64,
    /// What.
    pub send: Send,
    /// For `start_stream`: the frame period, ms.
    pub frame_period_ms: Option<u32>,
    /// The answer expected (default ack).
    #[serde(default)]
    pub expect: Reply,
    /// With `expect = "error"`: the reason the error must give (a dark
    /// calibration's refusal).
    pub refusal: Option<Refusal>,
}

/// Why a dark calibration is refused, as a scenario names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Refusal {
    /// The face is iced or wet, or the baseline would move too far, as an
    /// older host hears it (`ErrorCode::NotDry`).
    NotDry,
    /// Version 4: the face is iced or wet (`ErrorCode::FaceNotDry`).
    FaceNotDry,
    /// Version 4: the baseline would move further than the noise allows
    /// (`ErrorCode::BaselineShift`).
    BaselineShift,
    /// A step in the currents (`CalibrationRefusal::Step`).
    Step,
    /// A trend (`CalibrationRefusal::Trend`).
    Trend,
    /// Too noisy for the time (`CalibrationRefusal::Noisy`).
    Noisy,
    /// A channel saturated (`CalibrationRefusal::Saturated`).
    Saturated,
}

impl Refusal {
    /// True when the node's error `code` is this refusal (whatever numbers
    /// a version-4 refusal carries).
    pub fn matches(self, code: &fois_protocol::ErrorCode) -> bool {
        use fois_protocol::{CalibrationRefusal as R, ErrorCode as E};
        matches!(
            (self, code),
            (Refusal::NotDry, E::NotDry)
                | (Refusal::FaceNotDry, E::FaceNotDry(_))
                | (Refusal::BaselineShift, E::BaselineShift(_))
                | (Refusal::Step, E::CalibrationRefused(R::Step))
                | (Refusal::Trend, E::CalibrationRefused(R::Trend))
                | (Refusal::Noisy, E::CalibrationRefused(R::Noisy))
                | (Refusal::Saturated, E::CalibrationRefused(R::Saturated))
        )
    }
}

/// Run the scenario once per noise level and/or seed (every combination).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    /// Noise levels, rms LSB: replace every segment's and overlay's noise.
    #[serde(default)]
    pub adc_noise_lsb: Vec<f64>,
    /// Seeds: replace the file's seed (another ray-traced ice body, other
    /// noise draws).
    #[serde(default)]
    pub seed: Vec<u64>,
    /// The file's expectations are asserted for levels up to this; above
    /// it the runs are only reported (default: all levels).
    pub expect_up_to_lsb: Option<f64>,
}

/// A lossy UART between node and decoder (seeded).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    /// Probability that a frame gets one byte corrupted.
    #[serde(default)]
    pub corrupt_probability: f64,
    /// Probability that a frame is dropped whole (UART buffer full).
    #[serde(default)]
    pub drop_probability: f64,
    /// Seed of the link's draws (default 1).
    #[serde(default = "one")]
    pub seed: u64,
}

/// What must hold. Every key is optional; absent keys are not checked,
/// except `max_false_alarms`, `max_frames_lost` and `max_errors` (default 0).
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Expect {
    /// An ice alarm (`IceOnset`) happens (true) or never happens (false).
    pub alarm: Option<bool>,
    /// The first alarm comes at or below this true thickness, mm.
    pub alarm_by_mm: Option<f64>,
    /// The first alarm comes at or before this virtual time, s.
    pub alarm_by_s: Option<f64>,
    /// No alarm before this virtual time, s.
    pub no_alarm_before_s: Option<f64>,
    /// Latest time of a `WetOnset`, s (and one must happen).
    pub wet_by_s: Option<f64>,
    /// The rule's and the faults' events, in order: ice_onset, ice_cleared,
    /// wet_onset, wet_cleared, fault_raised, fault_cleared.
    pub events: Option<Vec<String>>,
    /// The states the measurements go through, repeats merged: dry|wet|ice.
    pub states: Option<Vec<String>>,
    /// The state of the last measurement.
    pub final_state: Option<String>,
    /// Most false alarms allowed (default 0).
    #[serde(default)]
    pub max_false_alarms: u32,
    /// Most frames lost (sequence gaps + undecodable frames) allowed (default 0).
    #[serde(default)]
    pub max_frames_lost: u64,
    /// At least this many frames lost (a lossy-link scenario proves the count).
    pub min_frames_lost: Option<u64>,
    /// Most `Error` replies not asked for by a command (default 0).
    #[serde(default)]
    pub max_errors: u32,
    /// At least this many measurements flagged saturated.
    pub min_saturated_frames: Option<u64>,
    /// At least this many measurements decoded.
    pub min_measurements: Option<u64>,
    /// No frame with at least this much ice (mm) is *confidently thin*: its
    /// estimate + 2σ below half the true thickness (needs `accuracy =
    /// true`, whose runs record the estimates).
    pub not_confidently_thin_from_mm: Option<f64>,
}

/// A scenario ready to run: one file, or one level of a sweep.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Display name (with `@σ=…` for a sweep level).
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// The parsed file (sweep levels already applied to the segments).
    pub file: ScenarioFile,
    /// Sensor construction.
    pub sensor: fois_sim::SensorKind,
    /// Seed of the curves and the ADC noise.
    pub seed: u64,
    /// The config sent after boot (`None`: defaults, nothing sent).
    pub config: Option<Config>,
    /// The timeline, overlays applied.
    pub timeline: Timeline,
    /// Virtual time to run to, s.
    pub end_s: f64,
    /// False for sweep levels above `expect_up_to_lsb`: reported only.
    pub checked: bool,
    /// The sweep level, rms LSB.
    pub sweep_lsb: Option<f64>,
}

/// The first seed [`for_accuracy`] uses by default.
pub const ACCURACY_FIRST_SEED: u64 = 101;

/// The accuracy scenarios (`accuracy = true`) on `seeds` seeds
/// `first_seed`, `first_seed` + 1, … instead of their files' (one run per
/// seed, named `NAME@seedK`) and at `frame_ms` frames; every other scenario
/// unchanged. `None`: as the files say.
pub fn for_accuracy(
    scenarios: Vec<Scenario>,
    seeds: Option<u64>,
    first_seed: u64,
    frame_ms: Option<u32>,
) -> Vec<Scenario> {
    let mut out: Vec<Scenario> = Vec::new();
    for mut sc in scenarios {
        if !sc.file.accuracy {
            out.push(sc);
            continue;
        }
        if let Some(ms) = frame_ms {
            let mut cfg = sc.config.clone().unwrap_or_default();
            cfg.frame_period_ms = ms;
            sc.config = Some(cfg);
        }
        let Some(n) = seeds else {
            out.push(sc);
            continue;
        };
        let base = sc
            .name
            .split("@seed")
            .next()
            .unwrap_or(&sc.name)
            .to_string();
        if out
            .iter()
            .any(|o| o.file.accuracy && o.name.starts_with(&format!("{base}@seed")))
        {
            continue; // this file's seeds are already expanded
        }
        for k in first_seed..first_seed.saturating_add(n) {
            let mut s = sc.clone();
            s.seed = k;
            s.name = format!("{base}@seed{k}");
            out.push(s);
        }
    }
    out
}

/// Parse and validate one file (all its sweep levels).
pub fn load(path: &Path) -> anyhow::Result<Vec<Scenario>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse(path, &text)
}

/// Parse and validate `text` as the file `path`.
pub fn parse(path: &Path, text: &str) -> anyhow::Result<Vec<Scenario>> {
    let mut file: ScenarioFile =
        toml::from_str(text).map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e))?;
    file.source = text.to_string();
    build(path, file).with_context(|| format!("{}", path.display()))
}

/// Every `*.toml` in `dir`, sorted by file name.
pub fn files_in(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let p = entry?.path();
        if p.extension().is_some_and(|e| e == "toml") {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// Load every scenario of `dir`.
pub fn load_dir(dir: &Path) -> anyhow::Result<Vec<Scenario>> {
    let mut out = Vec::new();
    for p in files_in(dir)? {
        out.extend(load(&p)?);
    }
    Ok(out)
}

/// The scenarios shipped with the suite: `hil/scenarios`.
pub fn default_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios")
}

fn build(path: &Path, file: ScenarioFile) -> anyhow::Result<Vec<Scenario>> {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = file.name.clone().unwrap_or(stem);
    ensure!(!file.segments.is_empty(), "no [[segment]]");
    let config = scenario::config(&file.config).map_err(anyhow::Error::msg)?;
    validate_commands(&file.commands)?;
    validate_expect(&file.expect)?;
    if let Some(spec) = file.gain_calibration {
        scenario::gain_calibration(spec).map_err(anyhow::Error::msg)?;
    }
    ensure!(
        file.accuracy || file.expect.not_confidently_thin_from_mm.is_none(),
        "[expect] not_confidently_thin_from_mm needs accuracy = true (the estimates are recorded only then)"
    );
    if let Some(l) = &file.link {
        for (k, p) in [
            ("corrupt_probability", l.corrupt_probability),
            ("drop_probability", l.drop_probability),
        ] {
            ensure!((0.0..=1.0).contains(&p), "[link] {k} = {p} is not in 0..=1");
        }
    }
    let host = host_scenario(&file)?;
    let (noises, seeds): (Vec<Option<f64>>, Vec<Option<u64>>) = match &file.sweep {
        None => (vec![None], vec![None]),
        Some(s) => {
            ensure!(
                !s.adc_noise_lsb.is_empty() || !s.seed.is_empty(),
                "[sweep] needs adc_noise_lsb or seed values"
            );
            let opt_all = |v: Vec<Option<f64>>| if v.is_empty() { vec![None] } else { v };
            let noises = opt_all(s.adc_noise_lsb.iter().map(|&x| Some(x)).collect());
            let seeds: Vec<Option<u64>> = if s.seed.is_empty() {
                vec![None]
            } else {
                s.seed.iter().map(|&x| Some(x)).collect()
            };
            (noises, seeds)
        }
    };
    let up_to = file.sweep.as_ref().and_then(|s| s.expect_up_to_lsb);
    let levels: Vec<(Option<f64>, Option<u64>, bool)> = noises
        .iter()
        .flat_map(|&x| {
            seeds.iter().map(move |&seed| {
                let checked = match (x, up_to) {
                    (Some(x), Some(m)) => x <= m,
                    _ => true,
                };
                (x, seed, checked)
            })
        })
        .collect();
    let mut out = Vec::new();
    for (level, seed, checked) in levels {
        let mut f = file.clone();
        let mut segments = host.timeline.segments().to_vec();
        if let Some(x) = level {
            ensure!(x >= 0.0 && x.is_finite(), "[sweep] noise {x} is not ≥ 0");
            for s in &mut segments {
                s.adc_noise_lsb = x;
            }
            for o in &mut f.overlays {
                o.adc_noise_lsb = o.adc_noise_lsb.map(|_| x);
            }
        }
        ensure!(
            segments.iter().all(|s| s.duration_s.is_finite()) || f.end_s.is_some(),
            "a segment lasts \"inf\": set end_s"
        );
        let segments = overlay::apply(segments, &f.overlays).map_err(anyhow::Error::msg)?;
        let timeline = Timeline::new(segments);
        let end_s = f.end_s.unwrap_or_else(|| timeline.duration_s());
        ensure!(end_s > 0.0 && end_s.is_finite(), "end_s must be > 0");
        for c in &f.commands {
            ensure!(
                c.at_s >= 0.0 && c.at_s <= end_s,
                "command at {} s is outside 0..={end_s} s",
                c.at_s
            );
        }
        let mut run_name = name.clone();
        if let Some(x) = level {
            run_name.push_str(&format!("@{x}lsb"));
        }
        if let Some(k) = seed {
            run_name.push_str(&format!("@seed{k}"));
        }
        out.push(Scenario {
            name: run_name,
            path: path.to_path_buf(),
            file: f,
            sensor: host.sensor,
            seed: seed.unwrap_or(host.seed),
            config: config.clone(),
            timeline,
            end_s,
            checked,
            sweep_lsb: level,
        });
    }
    Ok(out)
}

fn validate_commands(cmds: &[CommandSpec]) -> anyhow::Result<()> {
    for (i, c) in cmds.iter().enumerate() {
        ensure!(
            c.frame_period_ms.is_none() || c.send == Send::StartStream,
            "[[command]] #{}: frame_period_ms only goes with send = \"start_stream\"",
            i + 1
        );
        anyhow::ensure!(
            c.refusal.is_none() || c.expect == Reply::Error,
            "[[command]] #{}: refusal only goes with expect = \"error\"",
            i + 1
        );
    }
    let sorted = cmds.windows(2).all(|w| w[0].at_s <= w[1].at_s);
    ensure!(sorted, "[[command]] entries must be in time order");
    Ok(())
}

fn parse_state(s: &str) -> anyhow::Result<fois_protocol::DetectorState> {
    use fois_protocol::DetectorState as D;
    [D::Dry, D::Wet, D::Ice]
        .into_iter()
        .find(|d| d.name() == s)
        .with_context(|| format!("state `{s}` is not one of dry|wet|ice"))
}

/// The state named `s` (dry|wet|ice).
pub fn state_named(s: &str) -> Option<fois_protocol::DetectorState> {
    parse_state(s).ok()
}

/// Event names accepted in `expect.events`.
pub const EVENT_NAMES: [&str; 6] = [
    "ice_onset",
    "ice_cleared",
    "wet_onset",
    "wet_cleared",
    "fault_raised",
    "fault_cleared",
];

fn validate_expect(e: &Expect) -> anyhow::Result<()> {
    for name in e.events.iter().flatten() {
        ensure!(
            EVENT_NAMES.contains(&name.as_str()),
            "[expect] events: `{name}` is not one of {}",
            EVENT_NAMES.join("|")
        );
    }
    for s in e.states.iter().flatten().chain(e.final_state.iter()) {
        parse_state(s).context("[expect]")?;
    }
    if e.alarm == Some(false) {
        ensure!(
            e.alarm_by_mm.is_none() && e.alarm_by_s.is_none(),
            "[expect] alarm = false contradicts alarm_by_mm / alarm_by_s"
        );
    }
    Ok(())
}

/// The timeline part of the file, checked and built by the virtual node's
/// scenario code (`fois_vnode::scenario`).
fn host_scenario(f: &ScenarioFile) -> anyhow::Result<fois_vnode::Scenario> {
    Ok(fois_vnode::Scenario {
        timeline: scenario::timeline(f.segments.clone())
            .map_err(|e| anyhow::anyhow!("[[segment]] {e}"))?,
        sensor: scenario::sensor_named(f.sensor.as_deref()).map_err(anyhow::Error::msg)?,
        seed: f.seed.unwrap_or(1),
        gain_calibration: f
            .gain_calibration
            .map(scenario::gain_calibration)
            .transpose()
            .map_err(anyhow::Error::msg)?,
        config: None,
        ignored: Vec::new(),
    })
}

/// When ice is first on the face in `timeline` (a flat, glazed or rime
/// cover with a thickness > 0 or growing), s.
pub fn ice_start_s(timeline: &Timeline) -> Option<f64> {
    let mut t0 = 0.0;
    let mut d = 0.0;
    for seg in timeline.segments() {
        let start_d = match (seg.cover, seg.start_thickness_mm) {
            (Cover::Dry, _) => 0.0,
            (_, Some(x)) => x,
            (_, None) => d,
        };
        let end_d = if seg.cover == Cover::Dry {
            0.0
        } else {
            (start_d + seg.rate_mm_per_h * seg.duration_s / 3600.0).clamp(0.0, 15.0)
        };
        let is_ice = matches!(seg.cover, Cover::Flat | Cover::Glazed | Cover::Rime);
        if is_ice && (start_d > 0.0 || seg.rate_mm_per_h > 0.0) {
            return Some(t0);
        }
        t0 += seg.duration_s;
        d = end_d;
    }
    None
}
