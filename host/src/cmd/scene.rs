//! `foisctl virtual-node` and `foisctl demo`: command-line front ends of
//! [`fois_vnode::VirtualNode`] ([`crate::serve`] puts it on a pseudo-terminal).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use fois_sim::SensorKind;

use crate::monitor::{self, MonitorOptions};
use crate::serve::{self, Pty, ServeOptions};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

/// The simulated conditions and the node's pace.
#[derive(Debug, Clone, Args)]
pub struct SceneArgs {
    /// A scenario file (TOML timeline of segments: cover, rate, temperature,
    /// light, LED drift, noise; format in host/README.md). Replaces the
    /// scene flags below; --sensor and --seed override the file's.
    #[arg(long, value_name = "FILE.toml", conflicts_with_all = ["ice", "rate_mm_per_h", "temp_c", "dry_s", "ambient", "flicker", "led_factor", "noise_lsb"])]
    pub scenario: Option<PathBuf>,
    /// What forms on the face after the dry start: dry, flat, glazed, rime,
    /// water [default: rime].
    #[arg(long, value_name = "KIND", value_parser = parse_cover)]
    pub ice: Option<Cover>,
    /// Accretion rate, mm/h of film thickness, clamped at 15 mm [default:
    /// 2 for virtual-node, 3 for demo].
    #[arg(long, value_name = "MM_PER_H")]
    pub rate_mm_per_h: Option<f64>,
    /// Air temperature, °C, as the NTC sees it; above the node's freeze
    /// limit a film counts as water, not ice [default: -5].
    #[arg(long, value_name = "CELSIUS", allow_negative_numbers = true)]
    pub temp_c: Option<f64>,
    /// Virtual seconds of dry face before the film starts to form (the node
    /// dark-calibrates at 1 s) [default: 30 for virtual-node, 60 for demo].
    #[arg(long, value_name = "SECONDS")]
    pub dry_s: Option<f64>,
    /// Ambient (sun) DC photocurrent, µA: one value for both channels or
    /// `A1,A2` [default: 0].
    #[arg(long, value_name = "UA[,UA]", value_parser = parse_pair)]
    pub ambient: Option<[f64; 2]>,
    /// Amplitude of the 100 Hz mains flicker of the ambient light, µA, both
    /// channels [default: 0].
    #[arg(long, value_name = "UA")]
    pub flicker: Option<f64>,
    /// LED output relative to nominal, 0.7 = 30 % weaker [default: 1].
    #[arg(long, value_name = "FACTOR")]
    pub led_factor: Option<f64>,
    /// ADC noise, rms LSB per conversion [default: 1].
    #[arg(long, value_name = "LSB")]
    pub noise_lsb: Option<f64>,
    /// Sensor construction: a (transparent separation, dry offset) or b
    /// (opaque) [default: b].
    #[arg(long, value_name = "a|b", value_parser = parse_sensor)]
    pub sensor: Option<SensorKind>,
    /// Seed of the ray-traced accretion and of the ADC noise [default: 1].
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Virtual seconds per real second, 10 = ten times faster than a board
    /// [default: 1 for virtual-node, 20 for demo].
    #[arg(long, value_name = "X")]
    pub speed: Option<f64>,
    /// Stop after this many real seconds [default: never for virtual-node
    /// (Ctrl-C), 40 for demo].
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
}

fn parse_cover(s: &str) -> Result<Cover, String> {
    Cover::parse(s).ok_or_else(|| format!("`{s}` is not one of dry, flat, glazed, rime, water"))
}

fn parse_sensor(s: &str) -> Result<SensorKind, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "a" => Ok(SensorKind::A),
        "b" => Ok(SensorKind::B),
        _ => Err(format!("`{s}` is not a or b")),
    }
}

fn parse_pair(s: &str) -> Result<[f64; 2], String> {
    let nums: Result<Vec<f64>, _> = s.split(',').map(|x| x.trim().parse::<f64>()).collect();
    match nums.as_deref() {
        Ok([a]) if *a >= 0.0 => Ok([*a, *a]),
        Ok([a, b]) if *a >= 0.0 && *b >= 0.0 => Ok([*a, *b]),
        _ => Err(format!("`{s}` is not UA or UA1,UA2 (non-negative µA)")),
    }
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
}

impl SceneArgs {
    /// Resolve against defaults; refuses nonsense values.
    pub fn resolve(&self, d: SceneDefaults) -> anyhow::Result<Scene> {
        if let Some(path) = &self.scenario {
            let sc = fois_vnode::scenario::load(path)?;
            let speed = self.speed.unwrap_or(d.speed);
            if !(speed.is_finite() && speed > 0.0 && speed <= 10_000.0) {
                anyhow::bail!("--speed must be in (0, 10000]");
            }
            return Ok(Scene {
                timeline: sc.timeline,
                sensor: self.sensor.unwrap_or(sc.sensor),
                seed: self.seed.unwrap_or(sc.seed),
                speed,
                duration: self.duration.or(d.duration).map(Duration::from_secs_f64),
            });
        }
        let ice = self.ice.unwrap_or(d.ice);
        let rate = self.rate_mm_per_h.unwrap_or(d.rate_mm_per_h);
        let temp = self.temp_c.unwrap_or(d.temp_c);
        let dry_s = self.dry_s.unwrap_or(d.dry_s);
        let speed = self.speed.unwrap_or(d.speed);
        let check = |ok: bool, what: &str| -> anyhow::Result<()> {
            if ok {
                Ok(())
            } else {
                Err(crate::exit::Exit::new(crate::exit::USAGE, what.to_string()).into())
            }
        };
        check(
            rate.is_finite() && rate.abs() <= 1000.0,
            "--rate-mm-per-h must be within ±1000",
        )?;
        check(
            temp.is_finite() && (-60.0..=80.0).contains(&temp),
            "--temp-c must be within -60..=80 °C",
        )?;
        check(dry_s.is_finite() && dry_s >= 0.0, "--dry-s must be >= 0")?;
        check(
            speed.is_finite() && speed > 0.0 && speed <= 10_000.0,
            "--speed must be in (0, 10000]",
        )?;
        let led = self.led_factor.unwrap_or(1.0);
        check(
            led.is_finite() && (0.0..=10.0).contains(&led),
            "--led-factor must be within 0..=10",
        )?;
        let noise = self.noise_lsb.unwrap_or(1.0);
        check(
            noise.is_finite() && (0.0..=500.0).contains(&noise),
            "--noise-lsb must be within 0..=500",
        )?;
        let flicker = self.flicker.unwrap_or(0.0);
        check(
            flicker.is_finite() && flicker >= 0.0,
            "--flicker must be >= 0",
        )?;
        let duration = self.duration.or(d.duration);
        if let Some(x) = duration {
            check(x.is_finite() && x >= 0.0, "--duration must be >= 0")?;
        }
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
        segs.push(style(Segment::new(f64::INFINITY, ice).rate(rate)));
        Ok(Scene {
            timeline: Timeline::new(segs),
            sensor: self.sensor.unwrap_or(SensorKind::B),
            seed: self.seed.unwrap_or(1),
            speed,
            duration: duration.map(Duration::from_secs_f64),
        })
    }
}

fn describe(scene: &Scene) -> String {
    let segs = scene.timeline.segments();
    if segs.len() > 2 || (segs.len() == 2 && segs[0].cover != Cover::Dry) {
        let parts: Vec<String> = segs
            .iter()
            .map(|s| format!("{} {:.0} s", s.cover.name(), s.duration_s))
            .collect();
        return format!(
            "scenario: {}; sensor {:?}, speed ×{}",
            parts.join(" → "),
            scene.sensor,
            scene.speed
        );
    }
    let last = segs.last().expect("a timeline has a segment");
    let dry = if segs.len() > 1 {
        format!("dry face for {:.0} s, then ", segs[0].duration_s)
    } else {
        String::new()
    };
    format!(
        "{dry}{} at {} mm/h, air {} °C, sensor {:?}, speed ×{}",
        last.cover.name(),
        last.rate_mm_per_h,
        last.air_temp_c,
        scene.sensor,
        scene.speed
    )
}

/// Build the node of a scene (ray-traces the curves: about a second).
pub fn build_node(scene: &Scene) -> VirtualNode {
    build_node_with_state(scene, None)
}

/// Build the node of a scene, its flash record kept in `state` (a file).
pub fn build_node_with_state(scene: &Scene, state: Option<PathBuf>) -> VirtualNode {
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
            ..NodeOptions::default()
        },
    )
}

/// `foisctl virtual-node`.
pub fn run_virtual_node(
    args: &SceneArgs,
    link: Option<PathBuf>,
    state: Option<PathBuf>,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let scene = args.resolve(VIRTUAL_NODE_DEFAULTS)?;
    if let Some(p) = &state {
        fois_vnode::SharedStorage::with_file(p)
            .with_context(|| format!("cannot read the node state {}", p.display()))?;
    }
    let mut node = build_node_with_state(&scene, state);
    let mut pty = Pty::open()?;
    let _guard = match &link {
        Some(l) => Some(serve::make_link(l, pty.path())?),
        None => None,
    };
    println!("{}", pty.path().display());
    eprintln!(
        "virtual node on {}{}: {}\nconnect with: foisctl monitor --port {}   (Ctrl-C stops the node)",
        pty.path().display(),
        link.as_ref()
            .map(|l| format!(" (also {})", l.display()))
            .unwrap_or_default(),
        describe(&scene),
        pty.path().display()
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let opts = ServeOptions {
        speed: scene.speed,
        duration: scene.duration,
    };
    let stats = serve::serve(&mut node, &mut pty, &opts, stop)?;
    eprintln!(
        "virtual node stopped at virtual t = {:.1} s: {} frames run, {} sent, {} dropped (no reader)",
        node.clock().now_s(),
        node.frames(),
        stats.frames_sent,
        stats.frames_dropped
    );
    Ok(())
}

/// `foisctl demo`: a virtual node and the monitor in one process.
pub fn run_demo(
    args: &SceneArgs,
    log: Option<PathBuf>,
    plain: bool,
    stop: &'static AtomicBool,
) -> anyhow::Result<monitor::MonitorSummary> {
    let scene = args.resolve(DEMO_DEFAULTS)?;
    println!("FOIS demo: {}", describe(&scene));
    println!("ray-tracing the sensor's response ...");
    let t = Instant::now();
    let mut node = build_node(&scene);
    let mut pty = Pty::open()?;
    let path = pty.path().display().to_string();
    println!(
        "virtual node ready in {:.1} s on {path}; monitoring it as a board (Ctrl-C to stop{})",
        t.elapsed().as_secs_f64(),
        scene
            .duration
            .map(|d| format!(", ends after {:.0} s", d.as_secs_f64()))
            .unwrap_or_default()
    );
    let node_stop = Arc::new(AtomicBool::new(false));
    let serve_opts = ServeOptions {
        speed: scene.speed,
        duration: None,
    };
    let ns = node_stop.clone();
    let server = std::thread::spawn(move || {
        let r = serve::serve(&mut node, &mut pty, &serve_opts, &ns);
        (node, r)
    });
    let mut opts = MonitorOptions::new(path);
    opts.log = log;
    opts.plain = plain;
    opts.duration = scene.duration;
    let result = monitor::run(&opts, stop);
    node_stop.store(true, Ordering::Relaxed);
    let (node, served) = server
        .join()
        .map_err(|_| anyhow::anyhow!("the virtual node thread panicked"))?;
    served.context("virtual node")?;
    let sum = result?;
    let t = node.truth();
    println!(
        "virtual time {:.0} s: {} {:.2} mm at {:.1} °C; alarm output {}; {} measurement(s), {} lost, {} rejected, {} ice onset(s){}",
        node.clock().now_s(),
        t.cover.name(),
        t.thickness_mm,
        t.air_temp_c,
        if node.alarm_on() { "ON" } else { "off" },
        sum.measurements,
        sum.lost,
        sum.rejected,
        sum.ice_onsets,
        opts.log
            .as_ref()
            .map(|p| format!("; {} rows in {}", sum.log_rows, p.display()))
            .unwrap_or_default()
    );
    Ok(sum)
}
