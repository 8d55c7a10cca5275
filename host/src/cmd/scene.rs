//! The simulated scene that `foisctl virtual-node` and `foisctl demo` share:
//! its flags (or a scenario file), their defaults per command, and the
//! [`fois_vnode::VirtualNode`] built from them.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use fois_sim::SensorKind;
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

use super::args::{CoverArg, SensorArg, f64_in, non_negative, ua_pair};

/// The simulated conditions and the node's pace.
#[derive(Debug, Clone, Args)]
pub struct SceneArgs {
    /// A scenario file (TOML timeline of segments: cover, rate, temperature,
    /// light, LED drift, noise; format in host/README.md). Replaces the
    /// scene flags below; --sensor and --seed override the file's.
    #[arg(long, value_name = "FILE.toml", conflicts_with_all = ["ice", "rate_mm_per_h", "temp_c", "dry_s", "ambient", "flicker", "led_factor", "noise_lsb", "target"])]
    pub scenario: Option<PathBuf>,
    /// Put a reference target on the face after the dry start (instead of
    /// a film), to practise `foisctl calibrate-gain`: its net currents at
    /// gain 1, µA, `I1,I2` (the target's data sheet values). The face then
    /// reads them times the node's optical gain (--led-factor) over its dark
    /// baseline. The node's rule sees the target as a cover (wet or ice).
    #[arg(long, value_name = "I1,I2", value_parser = ua_pair, conflicts_with_all = ["ice", "rate_mm_per_h"])]
    pub target: Option<[f64; 2]>,
    /// What forms on the face after the dry start: dry, flat, glazed, rime,
    /// water [default: rime].
    #[arg(long, value_name = "KIND", value_enum)]
    pub ice: Option<CoverArg>,
    /// Accretion rate, mm/h of film thickness, within ±1000 (negative:
    /// melting), clamped at 15 mm [default: 2 for virtual-node, 3 for demo].
    #[arg(long, value_name = "MM_PER_H", allow_negative_numbers = true,
          value_parser = f64_in(-1000.0, 1000.0))]
    pub rate_mm_per_h: Option<f64>,
    /// Air temperature, °C (-60..=80), as the NTC sees it; above the node's
    /// freeze limit a film counts as water, not ice [default: -5].
    #[arg(long, value_name = "CELSIUS", allow_negative_numbers = true,
          value_parser = f64_in(-60.0, 80.0))]
    pub temp_c: Option<f64>,
    /// Virtual seconds of dry face before the film starts to form (the node
    /// dark-calibrates at 1 s) [default: 30 for virtual-node, 60 for demo].
    #[arg(long, allow_negative_numbers = true, value_name = "SECONDS", value_parser = non_negative)]
    pub dry_s: Option<f64>,
    /// Ambient (sun) DC photocurrent, µA: one value for both channels or
    /// `A1,A2` [default: 0].
    #[arg(long, value_name = "UA[,UA]", value_parser = ua_pair)]
    pub ambient: Option<[f64; 2]>,
    /// Amplitude of the 100 Hz mains flicker of the ambient light, µA, both
    /// channels [default: 0].
    #[arg(long, allow_negative_numbers = true, value_name = "UA", value_parser = non_negative)]
    pub flicker: Option<f64>,
    /// LED output relative to nominal (0..=10), 0.7 = 30 % weaker [default: 1].
    #[arg(long, value_name = "FACTOR", value_parser = f64_in(0.0, 10.0))]
    pub led_factor: Option<f64>,
    /// ADC noise, rms LSB per conversion (0..=500) [default: 1].
    #[arg(long, value_name = "LSB", value_parser = f64_in(0.0, 500.0))]
    pub noise_lsb: Option<f64>,
    /// Sensor construction: a (transparent separation, dry offset) or b
    /// (opaque) [default: b].
    #[arg(long, value_enum)]
    pub sensor: Option<SensorArg>,
    /// Seed of the ray-traced accretion and of the ADC noise [default: 1].
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Virtual seconds per real second (> 0, at most 10000), 10 = ten times
    /// faster than a board [default: 1 for virtual-node, 20 for demo].
    #[arg(long, value_name = "X", value_parser = speed)]
    pub speed: Option<f64>,
    /// Stop after this many real seconds [default: never for virtual-node
    /// (Ctrl-C), 40 for demo].
    #[arg(long, allow_negative_numbers = true, value_name = "SECONDS", value_parser = non_negative)]
    pub duration: Option<f64>,
}

/// Virtual seconds per real second: > 0, at most 10 000.
fn speed(s: &str) -> Result<f64, String> {
    super::args::positive(s).and_then(|x| {
        if x <= 10_000.0 {
            Ok(x)
        } else {
            Err(format!("must be at most 10000, got {x}"))
        }
    })
}

/// Defaults of one command (virtual-node and demo differ in pace).
#[derive(Debug, Clone, Copy)]
pub struct SceneDefaults {
    /// Film kind.
    pub ice: Cover,
    /// mm/h.
    pub rate_mm_per_h: f64,
    /// °C.
    pub temp_c: f64,
    /// s.
    pub dry_s: f64,
    /// Virtual s per real s.
    pub speed: f64,
    /// Real s (None: forever).
    pub duration: Option<f64>,
}

/// `virtual-node` defaults.
pub const VIRTUAL_NODE_DEFAULTS: SceneDefaults = SceneDefaults {
    ice: Cover::Rime,
    rate_mm_per_h: 2.0,
    temp_c: -5.0,
    dry_s: 30.0,
    speed: 1.0,
    duration: None,
};

/// `demo` defaults: the alarm trips after about 15 s of real time.
pub const DEMO_DEFAULTS: SceneDefaults = SceneDefaults {
    ice: Cover::Rime,
    rate_mm_per_h: 3.0,
    temp_c: -5.0,
    dry_s: 60.0,
    speed: 20.0,
    duration: Some(40.0),
};

/// A resolved scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The environment's timeline.
    pub timeline: Timeline,
    /// Sensor.
    pub sensor: SensorKind,
    /// Seed.
    pub seed: u64,
    /// Speed.
    pub speed: f64,
    /// Real duration.
    pub duration: Option<Duration>,
    /// The node's factory gain calibration (gain, relative sd), from a
    /// scenario file; `None`: its gain unknown.
    pub gain_calibration: Option<(f64, f64)>,
    /// The node's config at first boot, from a scenario's `[config]`.
    pub config: Option<fois_protocol::Config>,
    /// Keys of the scenario file only the hardware-in-loop checker uses
    /// (ignored here; said so when the node starts).
    pub ignored: Vec<&'static str>,
}

impl SceneArgs {
    /// Resolve against defaults (the values were range-checked by clap).
    pub fn resolve(&self, d: SceneDefaults) -> anyhow::Result<Scene> {
        let speed = self.speed.unwrap_or(d.speed);
        let duration = self.duration.or(d.duration).map(Duration::from_secs_f64);
        let sensor = self.sensor.map(SensorKind::from);
        if let Some(path) = &self.scenario {
            let sc = fois_vnode::scenario::load(path)?;
            return Ok(Scene {
                timeline: sc.timeline,
                sensor: sensor.unwrap_or(sc.sensor),
                seed: self.seed.unwrap_or(sc.seed),
                speed,
                duration,
                gain_calibration: sc.gain_calibration,
                config: sc.config,
                ignored: sc.ignored,
            });
        }
        let ice = self.ice.map_or(d.ice, Cover::from);
        let rate = self.rate_mm_per_h.unwrap_or(d.rate_mm_per_h);
        let temp = self.temp_c.unwrap_or(d.temp_c);
        let dry_s = self.dry_s.unwrap_or(d.dry_s);
        let led = self.led_factor.unwrap_or(1.0);
        let noise = self.noise_lsb.unwrap_or(1.0);
        let flicker = self.flicker.unwrap_or(0.0);
        let style = |s: Segment| {
            s.temp(temp)
                .ambient(self.ambient.unwrap_or([0.0; 2]))
                .flicker([flicker; 2])
                .led(led)
                .noise(noise)
        };
        let mut segs = Vec::new();
        if dry_s > 0.0 {
            segs.push(style(Segment::new(dry_s, Cover::Dry)));
        }
        segs.push(match self.target {
            Some(t) => style(Segment::new(f64::INFINITY, Cover::Dry).target(t)),
            None => style(Segment::new(f64::INFINITY, ice).rate(rate)),
        });
        Ok(Scene {
            timeline: Timeline::new(segs),
            sensor: sensor.unwrap_or(SensorKind::B),
            seed: self.seed.unwrap_or(1),
            speed,
            duration,
            gain_calibration: None,
            config: None,
            ignored: Vec::new(),
        })
    }
}

/// One line saying what the scene is.
pub fn describe(scene: &Scene) -> String {
    let ignored = if scene.ignored.is_empty() {
        String::new()
    } else {
        format!(
            " (the hardware-in-loop checker's keys {} are not used here)",
            scene.ignored.join(", ")
        )
    };
    let segs = scene.timeline.segments();
    if segs.len() > 2 || (segs.len() == 2 && segs[0].cover != Cover::Dry) {
        let parts: Vec<String> = segs
            .iter()
            .map(|s| format!("{} {:.0} s", s.cover.name(), s.duration_s))
            .collect();
        return format!(
            "scenario: {}; sensor {:?}, speed ×{}{ignored}",
            parts.join(" → "),
            scene.sensor,
            scene.speed
        );
    }
    // A timeline always has a segment (an empty one is an endless dry face).
    let Some(last) = segs.last() else {
        return "dry face".into();
    };
    let dry = if segs.len() > 1 {
        format!("dry face for {:.0} s, then ", segs[0].duration_s)
    } else {
        String::new()
    };
    if let Some(t) = last.target_ua {
        return format!(
            "{dry}a reference target of I1 {} µA, I2 {} µA at gain 1 on the face (LED ×{}), \
             air {} °C, sensor {:?}, speed ×{}: practise `foisctl calibrate-gain --i1-ua {} \
             --i2-ua {}`",
            t[0], t[1], last.led_factor, last.air_temp_c, scene.sensor, scene.speed, t[0], t[1]
        );
    }
    format!(
        "{dry}{} at {} mm/h, air {} °C, sensor {:?}, speed ×{}{ignored}",
        last.cover.name(),
        last.rate_mm_per_h,
        last.air_temp_c,
        scene.sensor,
        scene.speed
    )
}

/// Build the node of a scene (ray-traces the curves: about a second).
pub fn build_node(scene: &Scene) -> VirtualNode {
    build_node_with_state(scene, None, fois_firmware::update::UpdateKey::NONE)
}

/// Build the node of a scene, its flash record kept in `state` (a file).
pub fn build_node_with_state(
    scene: &Scene,
    state: Option<PathBuf>,
    update_key: fois_firmware::update::UpdateKey,
) -> VirtualNode {
    let env = Arc::new(Environment::new(
        scene.timeline.clone(),
        scene.sensor,
        scene.seed,
    ));
    VirtualNode::new(
        env,
        NodeOptions {
            seed: scene.seed,
            state_file: state,
            gain_calibration: scene.gain_calibration,
            config: scene.config.clone(),
            update_key,
            ..NodeOptions::default()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        scene: SceneArgs,
    }

    fn resolve(args: &[&str]) -> anyhow::Result<Scene> {
        let cli = Cli::try_parse_from(std::iter::once("foisctl").chain(args.iter().copied()))?;
        cli.scene.resolve(VIRTUAL_NODE_DEFAULTS)
    }

    /// `--scenario` loads every file of the hardware-in-loop suite (the
    /// suite's own keys ignored, its overlays and config kept).
    #[test]
    fn every_hil_scenario_loads_through_the_scenario_flag() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hil/scenarios");
        let mut files: Vec<_> = std::fs::read_dir(&dir)
            .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
            .unwrap_or_default();
        files.retain(|p| p.extension().is_some_and(|e| e == "toml"));
        assert_eq!(files.len(), 52);
        let mut with_config = 0;
        for f in &files {
            let scene = resolve(&["--scenario", &f.display().to_string()])
                .unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
            assert!(scene.ignored.contains(&"class"), "{}", f.display());
            assert!(describe(&scene).contains("class"), "{}", f.display());
            with_config += usize::from(scene.config.is_some());
        }
        assert!(with_config >= 10, "{with_config} files carry a [config]");
        let sun = resolve(&[
            "--scenario",
            &dir.join("glazed-sun-step.toml").display().to_string(),
        ])
        .unwrap();
        assert!(
            sun.timeline.segments().len() > 2,
            "the sun step's overlay splits the timeline"
        );
        let own = resolve(&[
            "--scenario",
            concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/scenarios/water-then-freeze.toml"
            ),
        ])
        .unwrap();
        assert!(own.ignored.is_empty());
    }
}
