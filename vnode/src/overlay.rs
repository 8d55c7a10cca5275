//! Overlays: temporary changes laid over a timeline's segments (a sun
//! step, a noise burst, repeated), as the `[[overlay]]` tables of a
//! scenario file give them. Shared by `foisctl virtual-node --scenario` and
//! the hardware-in-loop suite, so a file runs the same in both.

use serde::Deserialize;

use crate::environment::Segment;

/// A temporary change: from `start_s` for `duration_s`, repeated `repeat`
/// times every `period_s`. Sets the given keys over whatever the segments say.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OverlaySpec {
    /// First start, s.
    pub start_s: f64,
    /// Length of each occurrence, s.
    pub duration_s: f64,
    /// Occurrences (default 1).
    #[serde(default = "one_u32")]
    pub repeat: u32,
    /// Start-to-start period when `repeat` > 1, s.
    pub period_s: Option<f64>,
    /// Ambient DC per channel during the overlay, µA.
    pub ambient_ua: Option<[f64; 2]>,
    /// Flicker amplitude per channel during the overlay, µA.
    pub flicker_ua: Option<[f64; 2]>,
    /// ADC noise during the overlay, rms LSB.
    pub adc_noise_lsb: Option<f64>,
}

fn one_u32() -> u32 {
    1
}

/// Occurrences of the overlays: (start, end, overlay index), validated.
fn intervals(overlays: &[OverlaySpec]) -> Result<Vec<(f64, f64, usize)>, String> {
    let mut out = Vec::new();
    for (i, o) in overlays.iter().enumerate() {
        let n = i + 1;
        if !(o.start_s.is_finite() && o.start_s >= 0.0) {
            return Err(format!("[[overlay]] #{n}: start_s must be ≥ 0"));
        }
        if !(o.duration_s.is_finite() && o.duration_s > 0.0) {
            return Err(format!("[[overlay]] #{n}: duration_s must be > 0"));
        }
        if o.repeat == 0 {
            return Err(format!("[[overlay]] #{n}: repeat must be ≥ 1"));
        }
        let period = match (o.repeat, o.period_s) {
            (1, p) => p.unwrap_or(0.0),
            (_, Some(p)) if p.is_finite() && p > o.duration_s => p,
            (_, _) => {
                return Err(format!(
                    "[[overlay]] #{n}: repeat > 1 needs period_s > duration_s"
                ));
            }
        };
        if !(o.ambient_ua.is_some() || o.flicker_ua.is_some() || o.adc_noise_lsb.is_some()) {
            return Err(format!(
                "[[overlay]] #{n}: sets nothing (ambient_ua, flicker_ua or adc_noise_lsb)"
            ));
        }
        for k in 0..o.repeat {
            let a = o.start_s + f64::from(k) * period;
            out.push((a, a + o.duration_s, i));
        }
    }
    Ok(out)
}

/// Split the segments at every overlay edge and apply the overlays. Ramps
/// are split into sub-ramps; thickness stays continuous.
pub fn apply(segments: Vec<Segment>, overlays: &[OverlaySpec]) -> Result<Vec<Segment>, String> {
    let intervals = intervals(overlays)?;
    if intervals.is_empty() {
        return Ok(segments);
    }
    let mut cuts: Vec<f64> = intervals.iter().flat_map(|&(a, b, _)| [a, b]).collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut out = Vec::new();
    let mut t0 = 0.0;
    for seg in segments {
        let t1 = t0 + seg.duration_s;
        let mut edges = vec![t0];
        edges.extend(cuts.iter().copied().filter(|&c| c > t0 && c < t1));
        edges.push(t1);
        for (k, w) in edges.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            if b <= a {
                continue;
            }
            let frac = |t: f64| (t - t0) / seg.duration_s;
            let lerp = |x: f64, end: Option<f64>, f: f64| end.map_or(x, |e| x + (e - x) * f);
            let mut piece = seg.clone();
            piece.duration_s = b - a;
            piece.air_temp_c = lerp(seg.air_temp_c, seg.air_temp_end_c, frac(a));
            piece.air_temp_end_c = seg
                .air_temp_end_c
                .map(|_| lerp(seg.air_temp_c, seg.air_temp_end_c, frac(b)));
            piece.led_factor = lerp(seg.led_factor, seg.led_factor_end, frac(a));
            piece.led_factor_end = seg
                .led_factor_end
                .map(|_| lerp(seg.led_factor, seg.led_factor_end, frac(b)));
            piece.face_transmission =
                lerp(seg.face_transmission, seg.face_transmission_end, frac(a));
            piece.face_transmission_end = seg
                .face_transmission_end
                .map(|_| lerp(seg.face_transmission, seg.face_transmission_end, frac(b)));
            if k > 0 {
                piece.start_thickness_mm = None;
            }
            let mid = 0.5 * (a + b);
            for &(oa, ob, i) in &intervals {
                if mid >= oa && mid < ob {
                    let o = &overlays[i];
                    if let Some(x) = o.ambient_ua {
                        piece.ambient_ua = x;
                    }
                    if let Some(x) = o.flicker_ua {
                        piece.flicker_ua = x;
                    }
                    if let Some(x) = o.adc_noise_lsb {
                        piece.adc_noise_lsb = x;
                    }
                }
            }
            out.push(piece);
        }
        t0 = t1;
    }
    Ok(out)
}
