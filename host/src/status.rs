//! The live view's status lines of `foisctl monitor` and `foisctl demo`
//! (what [`crate::legend`] explains): the last measurement, the state with
//! the alarm and the ice estimate, the counters with the optical gain, and
//! the node's faults by name.

use fois_link::reading::{celsius, ua};
use fois_link::text::{estimate_text, gain_text, icing_text};
use fois_protocol::{DetectorState, GainEstimate, IceEstimate, IcingEstimate, Measurement, flags};

/// Totals at the end of a monitor run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MonitorSummary {
    /// Frames decoded.
    pub frames: u64,
    /// Measurements received.
    pub measurements: u64,
    /// Frames missing from the sequence.
    pub lost: u64,
    /// Frames the decoder rejected.
    pub rejected: u64,
    /// Times the link was lost.
    pub disconnects: u64,
    /// Rows written to the log.
    pub log_rows: u64,
    /// The last measurement.
    pub last: Option<Measurement>,
    /// The ice estimate of the last measurement (`None` for a protocol v1
    /// node, which sends none, and until a v2 node has one).
    pub last_estimate: Option<IceEstimate>,
    /// The optical gain estimate of the last measurement (protocol v3
    /// nodes).
    pub last_gain: Option<GainEstimate>,
    /// The icing rate of the last measurement (protocol v5 nodes).
    pub last_icing: Option<IcingEstimate>,
    /// Ice onsets seen.
    pub ice_onsets: u64,
}

/// The status from the last measurement and the counters: three lines of at
/// most 80 columns (measurement; state, alarm and the node's ice estimate;
/// counters and the optical gain). The estimate reads `est ICE rime 2.3 ±
/// 0.3 mm (p 0.97)`, or `est —` when the node sends none (protocol v1, or no
/// valid frame yet); the gain `gain 1.150 ± 0.060` (protocol v3 nodes).
pub fn status_lines(m: Option<&Measurement>, s: &MonitorSummary) -> [String; 3] {
    let mut counters = format!(
        "frames {}  lost {}  rejected {}",
        s.frames, s.lost, s.rejected
    );
    if let Some(g) = &s.last_gain {
        counters.push_str("  ");
        counters.push_str(&gain_text(g));
        if m.is_some_and(|m| m.flags & flags::GAIN_OUT_OF_BAND != 0) {
            counters.push_str(" OUT OF BAND");
        }
    }
    let Some(m) = m else {
        return [
            "waiting for measurements".to_string(),
            String::new(),
            counters,
        ];
    };
    let alarm = match (
        m.flags & flags::ALARM != 0,
        m.flags & flags::ALARM_ACKED != 0,
    ) {
        (true, true) => "ON (acked)",
        (true, false) => "ON",
        _ => "off",
    };
    let state = match m.state {
        DetectorState::Dry => "Dry",
        DetectorState::Wet => "Wet",
        DetectorState::Ice => "ICE",
    };
    [
        format!(
            "I1 {:8.3} µA  I2 {:8.3} µA  ambient {:.2}/{:.2} µA  {:6.2} °C",
            ua(m.i1_na.into()),
            ua(m.i2_na.into()),
            ua(m.ambient1_na.into()),
            ua(m.ambient2_na.into()),
            celsius(m.temperature_centi_c),
        ),
        format!(
            "state {state:3}  alarm {alarm:10}  est {}{}",
            s.last_estimate
                .as_ref()
                .map_or_else(|| "—".to_string(), estimate_text),
            if m.is_valid() { "" } else { "  SATURATED" }
        ),
        counters,
    ]
}

/// The faults the node reports in `m`, by name (`faults ntc_open`), with
/// what they mean for the readings; `None` when there is none.
pub fn fault_line(m: &Measurement) -> Option<String> {
    let names = fois_link::reading::fault_names(m.flags);
    if names.is_empty() {
        return None;
    }
    let mut hints = Vec::new();
    if m.flags & (flags::NTC_OPEN | flags::NTC_SHORT) != 0 {
        hints.push("temperature from the MCU's internal sensor: check the NTC wiring");
    }
    if m.flags & flags::GAIN_OUT_OF_BAND != 0 {
        hints.push("optical gain outside its band: clean the face, check the LED");
    }
    if m.flags & flags::STORAGE_FAILED != 0 {
        hints.push("config or baseline not saved to flash");
    }
    let mut line = format!("FAULT {}", names.join(", "));
    if !hints.is_empty() {
        line.push_str(" (");
        line.push_str(&hints.join("; "));
        line.push(')');
    }
    Some(line)
}

/// The icing rate and meteorological icing (protocol v5 nodes): `icing
/// rate 2.15 ± 0.60 mm/h ACCRETING (p 0.94)`; `None` when the node sends
/// none.
pub fn icing_line(s: &MonitorSummary) -> Option<String> {
    s.last_icing
        .as_ref()
        .map(|i| format!("icing {}", icing_text(i)))
}

/// The status on one line (plain output).
pub fn status_line(m: Option<&Measurement>, s: &MonitorSummary) -> String {
    let [a, b, c] = status_lines(m, s);
    match icing_line(s) {
        Some(i) => format!("{a}  | {b}  | {i}  | {c}"),
        None => format!("{a}  | {b}  | {c}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::Medium;
    use fois_protocol::{GainEstimate, IceEstimate};

    fn meas() -> Measurement {
        Measurement {
            uptime_ms: 1000,
            i1_na: 123_456,
            i2_na: 45_678,
            ambient1_na: 300_000,
            ambient2_na: 150_000,
            temperature_centi_c: -2_345,
            vdda_mv: 3300,
            flags: flags::ALARM | flags::ALARM_ACKED,
            state: DetectorState::Ice,
        }
    }

    #[test]
    fn status_shows_the_estimate_or_a_dash_within_80_columns() {
        let mut sum = MonitorSummary {
            frames: 9_999_999,
            lost: 99_999,
            rejected: 99_999,
            ..MonitorSummary::default()
        };
        let lines = status_lines(Some(&meas()), &sum);
        assert!(lines[1].contains("est —"), "{lines:?}");
        sum.last_estimate = Some(IceEstimate {
            thickness_um: 12_345,
            sigma_um: 1_456,
            medium: Medium::Glazed,
            probability_permille: 512,
        });
        sum.last_gain = Some(GainEstimate {
            gain_ppm: 1_150_000,
            sigma_ppm: 60_000,
        });
        let lines = status_lines(Some(&meas()), &sum);
        assert_eq!(
            lines[1],
            "state ICE  alarm ON (acked)  est ICE glazed 12.3 ± 1.5 mm (p 0.51)"
        );
        assert_eq!(
            lines[2],
            "frames 9999999  lost 99999  rejected 99999  gain 1.150 ± 0.060"
        );
        for l in &lines {
            assert!(
                l.chars().count() <= 80,
                "{} columns: {l}",
                l.chars().count()
            );
        }
        assert_eq!(icing_line(&sum), None);
        sum.last_icing = Some(IcingEstimate {
            rate_um_per_h: 12_150,
            sigma_um_per_h: 10_600,
            accreting_permille: 1000,
            accreting: true,
        });
        let line = icing_line(&sum).unwrap();
        assert_eq!(line, "icing rate 12.15 ± 10.60 mm/h ACCRETING (p 1.00)");
        assert!(line.chars().count() <= 80);
    }
}
