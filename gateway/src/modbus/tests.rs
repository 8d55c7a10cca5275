use std::time::{Duration, Instant};

use fois_link::Reading;
use fois_link::fixtures::{gain_estimate, iced_measurement, rime_estimate};
use fois_protocol::{Medium, flags};

use super::*;
use crate::snapshot::NodeSnapshot;

const STALE: Duration = Duration::from_secs(2);

fn iced(t: Instant) -> NodeSnapshot {
    let (m, e, g) = (iced_measurement(), rime_estimate(), gain_estimate());
    let mut n = NodeSnapshot::new(0, Some("tower-3".into()), "/dev/x".into());
    n.link_up = true;
    n.reading = Some(Reading::new(&m, Some(&e), Some(&g)));
    n.seq = Some(0x0001_0002);
    n.received = Some(t);
    n.frames_lost = 3;
    n
}

#[test]
fn a_node_not_heard_from_is_stale_and_every_value_not_available() {
    let n = NodeSnapshot::new(0, None, "/dev/x".into());
    let r = register_map(&n, Instant::now(), STALE);
    assert_eq!(
        r,
        [
            status::STALE,
            0xFFFF, // state
            0,      // faults: none known
            0x8000,
            0x0000, // i1
            0x8000,
            0x0000, // i2
            0x8000, // temperature
            0xFFFF,
            0xFFFF,
            0xFFFF,
            0xFFFF, // thickness, sigma, medium, probability
            0xFFFF,
            0xFFFF,
            0xFFFF,
            0xFFFF, // gain, sigma
            0xFFFF,
            0xFFFF, // data age
            0xFFFF,
            0xFFFF, // seq
            0xFFFF, // vdda
            0,
            0,      // frames lost
            0,      // ack
            0x8000, // icing rate
            0xFFFF,
            0xFFFF, // its sigma, P(accreting)
        ]
    );
}

#[test]
fn an_iced_node_with_estimate_and_gain_in_scaled_integers() {
    let t0 = Instant::now();
    let r = register_map(&iced(t0), t0 + Duration::from_millis(1_234), STALE);
    let want_status = status::ALARM
        | status::ALARM_ACKED
        | status::ICE
        | status::LINK_UP
        | status::DATA
        | status::VALID
        | status::ESTIMATE
        | status::GAIN
        | status::DARK_BASELINE
        | status::FAULT;
    assert_eq!(r[0], want_status);
    assert_eq!(r[0], 0b111_1110_1111);
    assert_eq!(r[1], 2, "ice");
    assert_eq!(r[2], 1 << 2, "ntc_open; the alarm bits are no faults");
    assert_eq!((r[3], r[4]), (0, 1500), "1.5 µA in nA");
    assert_eq!((r[5], r[6]), (0xFFFF, 0xFF06), "-0.25 µA = -250 nA");
    assert_eq!(r[7], 0xFE00, "-5.12 °C = -512 × 0.01 °C");
    assert_eq!(r[8], 1250, "1.25 mm in µm");
    assert_eq!(r[9], 80);
    assert_eq!(r[10], 3, "rime");
    assert_eq!(r[11], 930, "0.93 in ‰");
    assert_eq!((r[12], r[13]), (0x0011, 0x8D34), "gain 1.15026 in ppm");
    assert_eq!((r[14], r[15]), (0, 61_000), "σ 0.061");
    assert_eq!((r[16], r[17]), (0, 1234), "1.234 s old, in ms");
    assert_eq!((r[18], r[19]), (1, 2), "seq 0x0001_0002");
    assert_eq!(r[20], 3300);
    assert_eq!((r[21], r[22]), (0, 3));
    assert_eq!(r[23], 0, "the ack register reads 0");
}

#[test]
fn the_stale_bit_follows_the_data_age_and_the_link_bit_the_link() {
    let t0 = Instant::now();
    let mut n = iced(t0);
    let at = |n: &NodeSnapshot, ms: u64| register_map(n, t0 + Duration::from_millis(ms), STALE);
    assert_eq!(at(&n, 2_000)[0] & status::STALE, 0, "2 s: not yet");
    let r = at(&n, 2_001);
    assert_ne!(r[0] & status::STALE, 0, "2.001 s: stale");
    assert_eq!((r[16], r[17]), (0, 2_001));
    // An hour and more: the age goes on in the pair's high word.
    let r = at(&n, 4_000_000);
    assert_eq!(
        (u32::from(r[16]) << 16) | u32::from(r[17]),
        4_000_000,
        "{r:?}"
    );
    n.link_up = false;
    let r = at(&n, 100);
    assert_eq!(r[0] & (status::LINK_UP | status::STALE), 0);
    assert_eq!(
        r[0] & status::DATA,
        status::DATA,
        "the last data still shown"
    );
}

#[test]
fn a_node_without_estimate_or_gain_says_so_and_values_are_clamped_short_of_not_available() {
    let t0 = Instant::now();
    let mut n = iced(t0);
    if let Some(m) = n.reading.as_mut() {
        m.estimate = None;
        m.gain = None;
        m.temperature_c = -400.0; // beyond i16's range at 0.01 °C
        m.i1_ua = -3e6; // beyond i32's range at 0.001 µA
    }
    let r = register_map(&n, t0, STALE);
    assert_eq!(r[0] & (status::ESTIMATE | status::GAIN), 0);
    assert_eq!(&r[8..16], &[0xFFFF; 8]);
    assert_eq!(r[7], 0x8001, "-327.67 °C, not 0x8000 (not available)");
    assert_eq!((r[3], r[4]), (0x8000, 0x0001), "i32::MIN + 1");
    // 65.535 mm, the largest µm count the wire carries, would read as "not
    // available": it is 65.534.
    if let Some(m) = n.reading.as_mut() {
        m.estimate = Some(fois_link::EstimateReading {
            thickness_mm: 65.535,
            thickness_sigma_mm: 0.0,
            medium: Medium::Glazed,
            medium_probability: 1.0,
        });
    }
    let r = register_map(&n, t0, STALE);
    assert_eq!(&r[8..12], &[65_534, 0, 2, 1000]);
}

#[test]
fn the_table_covers_every_register_once_in_order() {
    let mut next = 0;
    for f in &TABLE {
        assert_eq!(f.address, next, "{}", f.name);
        next += f.kind.width();
    }
    assert_eq!(usize::from(next), REGISTERS);
}

#[test]
fn the_readme_shows_this_table() {
    let readme = include_str!("../../README.md");
    let table = markdown_table();
    assert!(
        readme.contains(&table),
        "gateway/README.md's register table differs from modbus::TABLE; it is:\n\n{table}"
    );
}

#[test]
fn the_faults_register_names_the_protocols_fault_bits() {
    let what = TABLE[usize::from(FAULTS)].what;
    let mut n = 0;
    for (bit, name) in flags::NAMES {
        if bit & flags::FAULT_MASK != 0 {
            let text = format!("{} {name}", bit.trailing_zeros());
            assert!(what.contains(&text), "{text} missing from: {what}");
            n += 1;
        }
    }
    assert_eq!(what.matches(", ").count() + 1, n, "{what}");
}

mod answers;
