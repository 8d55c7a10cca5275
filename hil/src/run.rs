//! The runner: a [`Scenario`] → the virtual hardware (`fois_vnode`) and the
//! firmware's own `Node` in virtual time → the bytes of its UART → the
//! protocol's [`FrameDecoder`] → an [`Outcome`] made only of decoded frames,
//! with the environment's [`Truth`] beside each event.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use fois_protocol::{
    Command, DetectorState, DeviceFrame, DeviceMsg, EventKind, FrameDecoder, HostFrame, MAX_FRAME,
    SeqEvent, SeqTracker, encode_to_vec, flags,
};
use fois_sim::streams::SplitMix64;
use fois_vnode::{Cover, Environment, NodeOptions, VirtualNode};

use crate::outcome::{EstSample, IcingSample, Outcome, ReplySeen, Seen, WATER_FREEZING_BAND_C};
use crate::scenario::{Scenario, Send, ice_start_s};

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
        let icing = f.msg.icing().map(|i| IcingSample {
            rate_mm_per_h: f64::from(i.rate_um_per_h) / 1000.0,
            sigma_mm_per_h: f64::from(i.sigma_um_per_h) / 1000.0,
            p_accreting: f64::from(i.accreting_permille) / 1000.0,
            accreting: i.accreting,
        });
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
                    true_rate_mm_per_h: true_growth_rate(&self.env, m.uptime_ms, truth.cover),
                    icing,
                });
            }
        }
        match f.msg {
            DeviceMsg::Hello(_) => o.hellos += 1,
            DeviceMsg::Measurement(m)
            | DeviceMsg::MeasurementV2(fois_protocol::MeasurementV2 { measurement: m, .. })
            | DeviceMsg::MeasurementV3(fois_protocol::MeasurementV3 { measurement: m, .. })
            | DeviceMsg::MeasurementV5(fois_protocol::MeasurementV5 { measurement: m, .. }) => {
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
            // The icing period's start and end (protocol 5) are the growth
            // history's, not the rule's: counted apart, so every rule and
            // fault expectation stays as it was.
            DeviceMsg::Event(e)
                if matches!(e.kind, EventKind::IcingStarted | EventKind::IcingEnded) =>
            {
                o.icing_events.push((e.uptime_ms as f64 / 1000.0, e.kind));
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

/// The rate at which ice grows at `uptime_ms`, mm/h: the segment's, if
/// ice covers the face and grows (0 on a dry face, water, a pause, melting).
fn true_growth_rate(env: &Environment, uptime_ms: u64, cover: Cover) -> f64 {
    if cover.ice_kind().is_none() || cover == Cover::Water {
        return 0.0;
    }
    let tl = env.timeline();
    tl.segments()
        .get(tl.index_at(uptime_ms as f64 / 1000.0))
        .map_or(0.0, |s| s.rate_mm_per_h.max(0.0))
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
            Send::CalibrateDarkV4 => Command::CalibrateDarkV4 { force: false },
            Send::CalibrateDarkForced => Command::CalibrateDarkV4 { force: true },
            Send::AckAlarm => Command::AckAlarm,
            Send::AckAlarmV4 => Command::AckAlarmV4,
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
