//! The one-screen legend `foisctl monitor` and `foisctl demo` print before
//! their first status line: what every number and word of the live view
//! means, for a reader who has not seen the sensor's documentation.

/// The legend (at most 24 lines of at most 100 columns; a test holds it).
pub const LEGEND: &str = "\
How to read the live view (first line of each block: the latest measurement)
  I1, I2    light the face sends back into the two receiving fibre channels, as net
            photocurrent in µA (LED on minus LED off). A dry face reads about 0;
            water and ice raise them, rime (white, bubbly) the most.
  ambient   the same two channels with the LED off (sun, lamps), µA; already subtracted.
  °C        air temperature at the node (its NTC): decides water (above the node's
            freeze limit) or ice (below).
  state     the node's decision: Dry, Wet (a film, not frozen) or ICE (the alarm rule).
  alarm     the alarm output: off, ON, or ON (acked): acknowledged, stays on while ice remains.
  est       the node's ice estimate: medium (water, glazed, rime), thickness ± σ in mm
            (σ: one standard deviation; the truth lies within ±2σ 95 times in 100)
            and p, the probability (0–1) that the medium is the one named.
  icing     how fast ice grows now, mm/h ± σ, and ACCRETING while an icing period is on
            (meteorological icing; p: the probability that ice accretes now).
  gain      the node's optical gain (LED, fibres, face; 1.000 = as designed) ± σ;
            OUT OF BAND: outside its configured band (LED failing, face fouled).
  FAULT     node faults by name (ntc_open, storage_failed, ...), with what to check.
  frames    frames received; lost: missing from the sequence; rejected: failed their check.
  truth     (demo only) what the simulator has on the face, in virtual time: compare est.
Events (ice_onset, wet_onset, icing_started, fault_raised, ...) print as lines above the status.";

#[cfg(test)]
mod tests {
    use super::*;

    /// One screen: ≤ 24 lines of ≤ 100 columns, every word of the status
    /// lines explained.
    #[test]
    fn the_legend_fits_one_screen_and_names_every_field() {
        let lines: Vec<&str> = LEGEND.lines().collect();
        assert!(lines.len() <= 24, "{} lines", lines.len());
        for l in &lines {
            assert!(
                l.chars().count() <= 100,
                "{} columns: {l}",
                l.chars().count()
            );
        }
        for word in [
            "I1, I2",
            "ambient",
            "°C",
            "state",
            "alarm",
            "est",
            "σ",
            " p,",
            "gain",
            "FAULT",
            "lost",
            "rejected",
            "truth",
            "icing",
            "ACCRETING",
        ] {
            assert!(LEGEND.contains(word), "{word} not explained");
        }
    }
}
