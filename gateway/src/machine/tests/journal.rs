//! The nodes' lines in the gateway's log, captured from `tracing` as the
//! journal would get them: an ice onset with its numbers, a fault as a
//! warning, an acknowledgement once, and the rate limit with its count.

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use fois_protocol::{
    DeviceFrame, DeviceMsg, Event, EventKind, IceEstimate, MeasurementV3, Medium, SeqEvent, flags,
};

use super::super::Gateway;
use super::super::journal::{LINES_PER_WINDOW, WINDOW};
use super::{gateway, iced_measurement, up};
use crate::reader::{NodeMsg, NodeUpdate};

/// A `tracing` writer into a shared buffer.
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Captured {
    fn lines(&self) -> Vec<String> {
        String::from_utf8_lossy(&self.0.lock().unwrap())
            .lines()
            .map(|l| l.trim().to_string())
            .collect()
    }
}

/// Run `f` with the log (INFO and above, no time, no colour) captured.
fn logged(f: impl FnOnce()) -> Vec<String> {
    let out = Captured::default();
    let writer = out.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_writer(move || writer.clone())
        .with_max_level(tracing::Level::INFO)
        .with_ansi(false)
        .with_target(false)
        .without_time()
        .finish();
    tracing::subscriber::with_default(subscriber, f);
    out.lines()
}

fn frame(seq: u32, msg: DeviceMsg) -> NodeMsg {
    NodeMsg {
        node: 0,
        host_unix_ms: 2_000,
        update: NodeUpdate::Frame(DeviceFrame { seq, msg }, SeqEvent::InOrder),
    }
}

fn measurement(seq: u32, flags: u16) -> NodeMsg {
    frame(
        seq,
        DeviceMsg::MeasurementV3(MeasurementV3 {
            measurement: iced_measurement(u64::from(seq) * 100, flags),
            estimate: Some(IceEstimate {
                thickness_um: 1_240,
                sigma_um: 310,
                medium: Medium::Glazed,
                probability_permille: 870,
            }),
            gain: None,
        }),
    )
}

fn event(seq: u32, kind: EventKind) -> NodeMsg {
    frame(
        seq,
        DeviceMsg::Event(Event {
            uptime_ms: u64::from(seq) * 100,
            kind,
            i1_na: 30_000,
            i2_na: 9_000,
            rise1_na: 25_000,
            temperature_centi_c: -512,
            frames: 12,
        }),
    )
}

fn connected_node() -> (tempfile::TempDir, Gateway) {
    let dir = tempfile::tempdir().unwrap();
    let mut gw = gateway(dir.path(), "");
    gw.on_node(up(), Instant::now());
    (dir, gw)
}

#[test]
fn an_ice_onset_is_an_info_line_with_thickness_medium_and_temperature() {
    let (_dir, mut gw) = connected_node();
    let t0 = Instant::now();
    let lines = logged(|| {
        gw.on_node(measurement(1, flags::ALARM), t0);
        gw.on_node(event(2, EventKind::IceOnset), t0);
    });
    assert_eq!(
        lines,
        [
            "INFO node a: ice onset (alarm on): estimate 1.2 ± 0.3 mm glazed (p 0.87), -5.1 °C, channel 1 \
          +25.0 µA over its dark baseline for 12 frame(s)"
        ]
    );
    // The MQTT record went to the queue as before (link_up, measurement, event).
    assert_eq!(gw.pending(), 3);
}

#[test]
fn a_fault_is_a_warning_naming_it_and_an_acknowledgement_is_logged_once() {
    let (_dir, mut gw) = connected_node();
    let t0 = Instant::now();
    let lines = logged(|| {
        gw.on_node(event(1, EventKind::FaultRaised(flags::NTC_OPEN)), t0);
        gw.on_node(measurement(2, flags::ALARM), t0);
        gw.on_node(measurement(3, flags::ALARM | flags::ALARM_ACKED), t0);
        gw.on_node(measurement(4, flags::ALARM | flags::ALARM_ACKED), t0);
        gw.on_node(event(5, EventKind::WetOnset), t0);
        gw.on_node(
            NodeMsg {
                node: 0,
                host_unix_ms: 3_000,
                update: NodeUpdate::Down("no frame for 8 s".into()),
            },
            t0,
        );
    });
    assert_eq!(
        lines,
        [
            "WARN node a: fault raised: ntc_open (-5.1 °C)",
            "INFO node a: alarm acknowledged (the output stays on while ice remains): estimate 1.2 ± 0.3 mm \
             glazed (p 0.87), -5.0 °C",
            "INFO node a: wet (a water film above freezing, no alarm): estimate 1.2 ± 0.3 mm glazed \
             (p 0.87), -5.1 °C, channel 1 +25.0 µA over its dark baseline for 12 frame(s)",
            "WARN node a on /dev/a: link lost (no frame for 8 s); reconnecting",
        ]
    );
}

#[test]
fn a_flapping_node_is_held_to_five_lines_per_kind_and_the_rest_counted() {
    let (_dir, mut gw) = connected_node();
    let t0 = Instant::now();
    let lines = logged(|| {
        for i in 0..20u32 {
            let t = t0 + Duration::from_secs(u64::from(i) * 10);
            gw.on_node(event(2 * i + 1, EventKind::IceOnset), t);
            gw.on_node(event(2 * i + 2, EventKind::IceCleared), t);
            gw.tick(t, Duration::from_secs(3600));
        }
        // The window ends: the count is written at the next tick.
        gw.tick(t0 + WINDOW, Duration::from_secs(3600));
    });
    let onsets = lines.iter().filter(|l| l.contains("ice onset")).count();
    let cleared = lines.iter().filter(|l| l.contains("ice cleared")).count();
    assert_eq!((onsets, cleared), (5, 5), "{lines:#?}");
    assert_eq!(LINES_PER_WINDOW, 5);
    let counts: Vec<&String> = lines.iter().filter(|l| l.contains("left out")).collect();
    assert_eq!(
        counts,
        [
            "WARN node a: 15 more `ice_cleared` line(s) were left out of the log in the last 600 s \
             (at most 5 per node and kind per 600 s are written; every event still went to MQTT)",
            "WARN node a: 15 more `ice_onset` line(s) were left out of the log in the last 600 s \
             (at most 5 per node and kind per 600 s are written; every event still went to MQTT)",
        ]
    );
    // Every event still became a record: link_up and 40 events.
    assert_eq!(gw.pending(), 41);
}
