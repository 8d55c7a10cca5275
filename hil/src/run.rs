//! The runner: a [`Scenario`] → the virtual hardware (`fois_vnode`) and the
//! firmware's own `Node` in virtual time → the bytes of its UART → the
//! protocol's [`FrameDecoder`] → an [`Outcome`] made only of decoded frames,
//! with the environment's [`Truth`] beside each event.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use fois_protocol::{
    AckResult, Command, DetectorState, DeviceFrame, DeviceMsg, ErrorCode, EventKind, FrameDecoder,
    HostFrame, MAX_FRAME, SeqEvent, SeqTracker, encode_to_vec, flags,
};
use fois_sim::streams::SplitMix64;
use fois_vnode::{Cover, Environment, NodeOptions, Truth, VirtualNode};

use crate::scenario::{Class, Scenario, Send, ice_start_s};

/// Water in air at or below this temperature counts as freezing, not as a
/// false alarm, °C: the NTC's ±0.5 K near 0 °C plus the rule's +0.5 °C
/// freeze limit (firmware/README.md) — inside this band the node cannot
/// tell water from ice, by design.
pub const WATER_FREEZING_BAND_C: f64 = 1.0;

/// An event frame as decoded, with the truth at its time.
#[derive(Debug, Clone)]
pub struct Seen {
    /// Sequence number of the frame.
    pub seq: u32,
    /// Event time (node uptime = virtual time), s.
    pub t_s: f64,
    /// What happened.
    pub kind: EventKind,
    /// I1 rise over the baseline the node reported, nA.
    pub rise1_na: i32,
    /// Temperature the node reported, °C.
    pub temperature_c: f64,
    /// The environment at that instant.
    pub truth: Truth,
}

/// One frame's ice estimate beside the truth (accuracy scenarios).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstSample {
    /// Node uptime, s.
    pub t_s: f64,
    /// What covers the face and how thick it is (truth).
    pub cover: Cover,
    /// True thickness, mm.
    pub true_mm: f64,
    /// Estimated thickness, mm.
    pub est_mm: f64,
    /// Its σ, mm.
    pub sigma_mm: f64,
    /// The most likely medium the node reported.
    pub medium: fois_protocol::Medium,
    /// The true relative optical gain g (LED × temperature factor × face
    /// transmission², `fois_vnode::optics`).
    pub true_gain: f64,
    /// The node's gain estimate and its σ (`MeasurementV3::gain`), if sent.
    pub gain: Option<(f64, f64)>,
}

impl EstSample {
    /// The estimate is confidently thin: est + 2σ < half the true
    /// thickness (the node would tell a de-icing system there is far less
    /// ice than there is, and be sure of it).
    pub fn confidently_thin(&self) -> bool {
        self.est_mm + 2.0 * self.sigma_mm < 0.5 * self.true_mm
    }
}

/// A reply to a command.
#[derive(Debug, Clone)]
pub struct ReplySeen {
    /// Command id.
    pub id: u16,
    /// Virtual time the reply arrived, s.
    pub t_s: f64,
    /// Ack result or error code.
    pub result: Result<AckResult, ErrorCode>,
}

/// Everything one run produced, from decoded frames only (plus the truth).
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Scenario name.
    pub name: String,
    /// Goal class.
    pub class: Class,
    /// Sensor kind name.
    pub sensor: &'static str,
    /// Expectations asserted (false: a sweep level reported only).
    pub checked: bool,
    /// Sweep level, rms LSB.
    pub sweep_lsb: Option<f64>,
    /// Virtual time run, s.
    pub virtual_s: f64,
    /// Frames the node ran (from the runner, for the frame rate).
    pub node_frames: u64,
    /// Frames decoded.
    pub decoded: u64,
    /// Measurements decoded.
    pub measurements: u64,
    /// Measurements flagged saturated (invalid).
    pub saturated: u64,
    /// Hello frames.
    pub hellos: u64,
    /// Rule and fault events, in order.
    pub events: Vec<Seen>,
    /// Replies to commands (and to the button), in order.
    pub replies: Vec<ReplySeen>,
    /// The commands sent: (id, virtual time s); the button's id is
    /// `BUTTON_ID`. The config's `SetConfig` (if any) comes first.
    pub sent: Vec<(u16, f64)>,
    /// `Error` frames with no command of ours behind them.
    pub stray_errors: u32,
    /// States of the measurements, repeats merged.
    pub states: Vec<DetectorState>,
    /// State of the last measurement.
    pub final_state: Option<DetectorState>,
    /// Frames missing from the sequence numbers.
    pub seq_missing: u64,
    /// Frames the decoder rejected (CRC, COBS, oversized, malformed).
    pub rejected: u64,
    /// Frames dropped or corrupted by the scenario's lossy link.
    pub link_dropped: u64,
    /// Frames corrupted by the lossy link.
    pub link_corrupted: u64,
    /// When ice first covers the face (truth), s.
    pub ice_start_s: Option<f64>,
    /// Inconsistencies between frames, or frames and the alarm pin.
    pub inconsistencies: Vec<String>,
    /// Smallest and largest I1 the measurements reported, nA.
    pub i1_range_na: Option<(i32, i32)>,
    /// The estimates of every measurement beside the truth (scenarios with
    /// `accuracy = true` only; empty otherwise).
    pub estimates: Vec<EstSample>,
    /// Measurements with water on the face above the freezing band.
    pub warm_water_frames: u64,
    /// … of which the node's estimate called ice (glazed or rime).
    pub warm_water_called_ice: u64,
    /// Wall time of the run.
    pub wall: Duration,
    /// Expectations that failed (filled by [`crate::check`]).
    pub failures: Vec<String>,
}

impl Outcome {
    /// The first `IceOnset`.
    pub fn first_alarm(&self) -> Option<&Seen> {
        self.events.iter().find(|e| e.kind == EventKind::IceOnset)
    }

    /// Alarms with no ice on the face: dry, or water above the freezing band.
    pub fn false_alarms(&self) -> u32 {
        self.events
            .iter()
            .filter(|e| e.kind == EventKind::IceOnset && is_false_alarm(&e.truth))
            .count() as u32
    }

    /// `IceCleared` while ice is still on the face in freezing air.
    pub fn dropped_alarms(&self) -> u32 {
        self.events
            .iter()
            .filter(|e| {
                e.kind == EventKind::IceCleared
                    && matches!(e.truth.cover, Cover::Flat | Cover::Glazed | Cover::Rime)
                    && e.truth.thickness_mm > 0.0
                    && e.truth.air_temp_c <= 0.0
            })
            .count() as u32
    }

    /// First alarm time minus the time ice first covered the face, s.
    pub fn latency_s(&self) -> Option<f64> {
        Some(self.first_alarm()?.t_s - self.ice_start_s?)
    }

    /// Frames lost between node and decoder (sequence gaps + rejected frames
    /// that left no gap are both counted once: the sequence gap counts them).
    pub fn frames_lost(&self) -> u64 {
        self.seq_missing
    }
}

/// True when an alarm at this truth is a false one.
pub fn is_false_alarm(t: &Truth) -> bool {
    match t.cover {
        Cover::Dry => true,
        Cover::Water => t.air_temp_c > WATER_FREEZING_BAND_C,
        _ => t.thickness_mm <= 0.0,
    }
}

struct Observer {
    env: Arc<Environment>,
    record_estimates: bool,
    decoder: FrameDecoder<MAX_FRAME>,
    link: Option<(f64, f64, SplitMix64)>,
    seq: SeqTracker,
    out: Outcome,
    expected_ids: Vec<u16>,
}

impl Observer {
    /// Bytes of one frame on the node's UART.
    fn wire(&mut self, bytes: &[u8]) {
        if let Some((p_corrupt, p_drop, rng)) = &mut self.link {
            if rng.uniform() < *p_drop {
                self.out.link_dropped += 1;
                return;
            }
            if rng.uniform() < *p_corrupt && bytes.len() > 1 {
                let mut b = bytes.to_vec();
                let i = (rng.next_u64() % (b.len() as u64 - 1)) as usize;
                b[i] ^= 1 << (rng.next_u64() % 8);
                self.out.link_corrupted += 1;
                self.feed(&b);
                return;
            }
        }
        self.feed(bytes);
    }

    fn feed(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.decoder.push::<DeviceFrame>(b) {
                None => {}
                Some(Ok(f)) => self.frame(f),
                Some(Err(_)) => self.out.rejected += 1,
            }
        }
    }

    fn frame(&mut self, f: DeviceFrame) {
        let now_s = self.out.virtual_s;
        let o = &mut self.out;
        o.decoded += 1;
        // The protocol's sequence-gap rule; a restart is expected only as a
        // `Hello` with seq 0 (a reboot), anything else going back is wrong.
        let prev = self.seq.last();
        match self.seq.observe(f.seq) {
            SeqEvent::Gap(n) => o.seq_missing += n,
            SeqEvent::Restart if matches!(f.msg, DeviceMsg::Hello(_)) && f.seq == 0 => {}
            SeqEvent::Restart | SeqEvent::Duplicate => o.inconsistencies.push(format!(
                "sequence went back from {} to {}",
                prev.unwrap_or(0),
                f.seq
            )),
            SeqEvent::First | SeqEvent::InOrder => {}
        }
        let gain = f.msg.gain().map(|g| (g.gain(), g.sigma()));
        if let Some((m, estimate)) = f.msg.measurement() {
            let truth = self.env.truth(m.uptime_ms.saturating_mul(1_000_000));
            if truth.cover == Cover::Water && truth.air_temp_c > WATER_FREEZING_BAND_C {
                o.warm_water_frames += 1;
                if estimate.is_some_and(|e| {
                    matches!(
                        e.medium,
                        fois_protocol::Medium::Glazed | fois_protocol::Medium::Rime
                    )
                }) {
                    o.warm_water_called_ice += 1;
                }
            }
            if let (true, Some(e)) = (self.record_estimates, estimate) {
                o.estimates.push(EstSample {
                    t_s: m.uptime_ms as f64 / 1000.0,
                    cover: truth.cover,
                    true_mm: truth.thickness_mm,
                    est_mm: f64::from(e.thickness_um) / 1000.0,
                    sigma_mm: f64::from(e.sigma_um) / 1000.0,
                    medium: e.medium,
                    true_gain: truth.gain.signal_gain(),
                    gain,
                });
            }
        }
        match f.msg {
            DeviceMsg::Hello(_) => o.hellos += 1,
            DeviceMsg::Measurement(m)
            | DeviceMsg::MeasurementV2(fois_protocol::MeasurementV2 { measurement: m, .. })
            | DeviceMsg::MeasurementV3(fois_protocol::MeasurementV3 { measurement: m, .. }) => {
                o.measurements += 1;
                if !m.is_valid() {
                    o.saturated += 1;
                }
                if o.states.last() != Some(&m.state) {
                    o.states.push(m.state);
                }
                o.final_state = Some(m.state);
                let alarm_flag = m.flags & flags::ALARM != 0;
                if alarm_flag != (m.state == DetectorState::Ice) && o.inconsistencies.len() < 10 {
                    o.inconsistencies.push(format!(
                        "measurement seq {} at {} ms: ALARM flag {alarm_flag} but state {:?}",
                        f.seq, m.uptime_ms, m.state
                    ));
                }
                o.i1_range_na = Some(match o.i1_range_na {
                    None => (m.i1_na, m.i1_na),
                    Some((a, b)) => (a.min(m.i1_na), b.max(m.i1_na)),
                });
            }
            DeviceMsg::Event(e) => {
                let t_ns = e.uptime_ms.saturating_mul(1_000_000);
                o.events.push(Seen {
                    seq: f.seq,
                    t_s: e.uptime_ms as f64 / 1000.0,
                    kind: e.kind,
                    rise1_na: e.rise1_na,
                    temperature_c: f64::from(e.temperature_centi_c) / 100.0,
                    truth: self.env.truth(t_ns),
                });
            }
            DeviceMsg::Ack(a) => o.replies.push(ReplySeen {
                id: a.id,
                t_s: now_s,
                result: Ok(a.result),
            }),
            DeviceMsg::Error(e) => match e.id {
                Some(id) if self.expected_ids.contains(&id) => o.replies.push(ReplySeen {
                    id,
                    t_s: now_s,
                    result: Err(e.code),
                }),
                _ => o.stray_errors += 1,
            },
        }
    }
}

fn ns(t_s: f64) -> u64 {
    (t_s * 1e9).round().max(0.0) as u64
}

/// Run one scenario (does not check its expectations: see [`crate::check`]).
pub fn run(sc: &Scenario) -> anyhow::Result<Outcome> {
    let start = Instant::now();
    let f = &sc.file;
    let env = Arc::new(Environment::new(sc.timeline.clone(), sc.sensor, sc.seed));
    let opts = NodeOptions {
        seed: sc.seed,
        calibrate_at_s: None,
        gain_calibration: f.gain_calibration.map(|[gain, rel_sd]| (gain, rel_sd)),
        ..NodeOptions::default()
    };
    let mut node = VirtualNode::new(env.clone(), opts);
    // The ids our commands will carry, 1.. (so their Errors are not stray).
    let n_ids = f.commands.len() + usize::from(sc.config.is_some());
    let mut ids: Vec<u16> = (1u16..).take(n_ids).collect();
    ids.push(fois_firmware::node::dispatch::BUTTON_ID);
    let mut obs = Observer {
        env: env.clone(),
        record_estimates: f.accuracy,
        decoder: FrameDecoder::new(),
        link: f.link.as_ref().map(|l| {
            (
                l.corrupt_probability,
                l.drop_probability,
                SplitMix64::new(l.seed),
            )
        }),
        seq: SeqTracker::new(),
        out: Outcome {
            sensor: match sc.sensor {
                fois_sim::SensorKind::A => "A",
                fois_sim::SensorKind::B => "B",
            },
            checked: sc.checked,
            sweep_lsb: sc.sweep_lsb,
            ice_start_s: ice_start_s(&sc.timeline),
            ..Outcome::empty(&sc.name, f.class)
        },
        expected_ids: ids,
    };
    // Boot (Hello), then the scenario's config as a host would send it.
    node.advance_to(0, &mut |b: &[u8]| obs.wire(b));
    let mut id = 1u16;
    if let Some(cfg) = &sc.config {
        let bytes = encode_to_vec(&HostFrame {
            id,
            cmd: Command::SetConfigV3(cfg.clone()),
        });
        node.handle_rx(&bytes, &mut |b: &[u8]| obs.wire(b));
        obs.out.sent.push((id, 0.0));
        id += 1;
    }
    // When each Reset reached the node (a frame due at the same instant
    // runs first, so this can be a few ms after the command's time).
    let mut resets: Vec<f64> = Vec::new();
    for c in &f.commands {
        node.advance_to(ns(c.at_s), &mut |b: &[u8]| obs.wire(b));
        obs.out.virtual_s = node.clock().now_s();
        let cmd = match c.send {
            Send::Button => {
                node.press_button(&mut |b: &[u8]| obs.wire(b));
                obs.out
                    .sent
                    .push((fois_firmware::node::dispatch::BUTTON_ID, c.at_s));
                id += 1;
                continue;
            }
            Send::CalibrateDark => Command::CalibrateDark,
            Send::AckAlarm => Command::AckAlarm,
            Send::GetInfo => Command::GetInfo,
            Send::GetConfig => Command::GetConfig,
            Send::StartStream => Command::StartStream {
                frame_period_ms: c.frame_period_ms,
            },
            Send::StopStream => Command::StopStream,
            Send::Reset => {
                resets.push(node.clock().now_s());
                Command::Reset
            }
        };
        let bytes = encode_to_vec(&HostFrame { id, cmd });
        node.handle_rx(&bytes, &mut |b: &[u8]| obs.wire(b));
        obs.out.sent.push((id, c.at_s));
        id += 1;
    }
    node.advance_to(ns(sc.end_s), &mut |b: &[u8]| obs.wire(b));
    let mut out = obs.out;
    out.virtual_s = node.clock().now_s();
    out.node_frames = node.frames();
    check_alarm_pin(&node, &resets, &mut out);
    out.wall = start.elapsed();
    Ok(out)
}

/// The alarm output must rise in the frame of every `IceOnset` and fall in
/// the frame of every `IceCleared`, or at a `Reset` (a new node starts with
/// its outputs off); checked when no frame was lost.
fn check_alarm_pin(node: &VirtualNode, resets_s: &[f64], out: &mut Outcome) {
    if out.seq_missing > 0 {
        return;
    }
    // Frames are at most 1 s apart (the slowest rate a scenario uses here is
    // well under that); the pin changes within the frame of its event.
    let within = 1.0;
    let edges = node.alarm_pin().edges();
    let rising = edges.iter().filter(|e| e.1).count();
    let onsets = out
        .events
        .iter()
        .filter(|e| e.kind == EventKind::IceOnset)
        .count();
    if rising != onsets {
        out.inconsistencies.push(format!(
            "alarm pin rose {rising} times for {onsets} IceOnset events"
        ));
    }
    for (t_ns, high) in edges {
        let t = t_ns as f64 * 1e-9;
        let want = if high {
            EventKind::IceOnset
        } else {
            EventKind::IceCleared
        };
        let by_event = out
            .events
            .iter()
            .any(|e| e.kind == want && t >= e.t_s && t - e.t_s < within);
        let by_reset = !high && resets_s.iter().any(|&r| (t - r).abs() < 1e-3);
        if !(by_event || by_reset) {
            out.inconsistencies.push(format!(
                "alarm pin went {} at {t:.3} s with no {want:?} event in that frame",
                if high { "high" } else { "low" },
            ));
        }
    }
}

/// Run `scenarios` on `threads` threads, the longest (in frames) first so
/// that the longest run sets the wall time; results in the input order.
pub fn run_all(scenarios: &[Scenario], threads: usize) -> Vec<anyhow::Result<Outcome>> {
    let frames = |sc: &Scenario| {
        let period_ms = sc
            .config
            .as_ref()
            .map_or(fois_protocol::Config::default().frame_period_ms, |c| {
                c.frame_period_ms
            });
        sc.end_s * 1000.0 / f64::from(period_ms.max(1))
    };
    let mut order: Vec<usize> = (0..scenarios.len()).collect();
    order.sort_by(|&a, &b| frames(&scenarios[b]).total_cmp(&frames(&scenarios[a])));
    let next = AtomicUsize::new(0);
    let mut slots: Vec<Option<anyhow::Result<Outcome>>> = Vec::new();
    slots.resize_with(scenarios.len(), || None);
    let results = std::sync::Mutex::new(slots);
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&i) = order.get(k) else { break };
                    let sc = &scenarios[i];
                    let mut r = run(sc);
                    if let Ok(o) = &mut r {
                        o.failures = crate::check::check(sc, o);
                    }
                    if let Ok(mut g) = results.lock() {
                        g[i] = Some(r);
                    }
                }
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err(anyhow::anyhow!("not run"))))
        .collect()
}

/// Threads to use: the machine's parallelism.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

impl Outcome {
    /// Nothing observed yet: a Sensor B run, checked, no sweep, no ice.
    fn empty(name: &str, class: Class) -> Self {
        Outcome {
            name: name.to_string(),
            class,
            sensor: "B",
            checked: true,
            sweep_lsb: None,
            virtual_s: 0.0,
            node_frames: 0,
            decoded: 0,
            measurements: 0,
            saturated: 0,
            hellos: 0,
            events: Vec::new(),
            replies: Vec::new(),
            sent: Vec::new(),
            stray_errors: 0,
            states: Vec::new(),
            final_state: None,
            seq_missing: 0,
            rejected: 0,
            link_dropped: 0,
            link_corrupted: 0,
            ice_start_s: None,
            inconsistencies: Vec::new(),
            i1_range_na: None,
            estimates: Vec::new(),
            warm_water_frames: 0,
            warm_water_called_ice: 0,
            wall: Duration::ZERO,
            failures: Vec::new(),
        }
    }
}

/// An empty outcome for the unit tests of the modules that read outcomes.
#[cfg(test)]
pub(crate) mod tests_support {
    use super::*;

    pub(crate) fn outcome(name: &str) -> Outcome {
        Outcome::empty(name, crate::scenario::Class::Rime)
    }
}
