//! Synchronous detection: codes → volts → currents.
//!
//! One output frame samples both channels with the LED off, then K times: LED
//! on, settle, sample; LED off, settle, sample. So every LED-on sample `on_k`
//! sits between two LED-off samples `off_k` and `off_{k+1}` taken one settle
//! time before and after it, and the net signal of a cycle is
//! `on_k − (off_k + off_{k+1}) / 2`. Averaging the two neighbours cancels any
//! ambient change that is linear over the cycle (the first-order term of a
//! mains flicker), leaving only its curvature: for a 100 Hz flicker of
//! amplitude A and a settle time Δ the error is at most A·(2π·100 Hz·Δ)²/2,
//! 0.8 % of A at Δ = 200 µs (a plain on − off difference would leave
//! A·2π·100 Hz·Δ = 12.6 % of A). The K cycles are averaged.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;

use crate::hal::{ADC_MAX, PhotoAdc};

/// The ADC's own limit: a sample at or above this code is saturated at any
/// supply (98 % of full scale).
pub const ADC_SATURATION_CODE: u16 = 4_000;
/// V_CE(sat) of the phototransistor, mV. The thesis (§4.5.1) does not name
/// the part; small NPN phototransistors give 0.2–0.4 V at their rated
/// current, so the worst of that range is taken: the emitter, where the
/// load resistor and the ADC sit, cannot rise above V_DD − V_CE(sat).
pub const PHOTO_VCE_SAT_MV: u16 = 400;
/// Margin below the clip level, mV (the V_DD ≠ V_DDA difference on the
/// board, ADC offset and gain error, a few codes of noise).
pub const CLIP_MARGIN_MV: u16 = 100;

/// The code at and above which a photo sample counts as saturated, for the
/// V_DDA (mV) measured in this frame. The phototransistor's collector sits
/// on the 3V3 rail, which also feeds V_DDA (the ADC reference) on the
/// NUCLEO-F446RE, so its output clips at V_DDA − V_CE(sat): in codes
/// 4095 × (V_DDA − V_CE(sat) − margin) / V_DDA. At 3.3 V that is 3 475
/// codes (2.8 V), where the old fixed 4 000 codes (3.22 V) sat above the
/// clip and strong sun went unflagged.
pub fn saturation_code(vdda_mv: u16) -> u16 {
    let vdda = u32::from(vdda_mv.max(1));
    let headroom = u32::from(PHOTO_VCE_SAT_MV + CLIP_MARGIN_MV);
    let clip = u32::from(ADC_MAX) * vdda.saturating_sub(headroom) / vdda;
    (clip as u16).min(ADC_SATURATION_CODE)
}

/// The raw sums of one frame's K cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Acquisition {
    /// Σ_k (2·on_k − off_k − off_{k+1}) per channel: twice the net code sum.
    pub sum2_net: [i32; 2],
    /// Σ of the K+1 LED-off codes per channel.
    pub sum_off: [u32; 2],
    /// K, the number of LED-on samples.
    pub cycles: u16,
    /// A sample of the channel reached the saturation code.
    pub saturated: [bool; 2],
}

/// Run K LED off/on cycles and sum them; a sample at or above
/// `saturation_code` (see [`saturation_code`]) marks its channel saturated.
/// Leaves the LED off. LED pin errors are ignored (the STM32's are
/// infallible; a stuck LED shows as no signal).
pub fn acquire<A, L, D>(
    adc: &mut A,
    led: &mut L,
    delay: &mut D,
    cycles: u16,
    settle_us: u16,
    saturation_code: u16,
) -> Acquisition
where
    A: PhotoAdc,
    L: OutputPin,
    D: DelayNs,
{
    let cycles = cycles.max(1);
    let settle = u32::from(settle_us);
    let mut acq = Acquisition {
        cycles,
        ..Acquisition::default()
    };
    let _ = led.set_low();
    delay.delay_us(settle);
    let mut prev_off = read(adc, &mut acq, saturation_code);
    add_off(&mut acq, prev_off);
    for _ in 0..cycles {
        let _ = led.set_high();
        delay.delay_us(settle);
        let on = read(adc, &mut acq, saturation_code);
        let _ = led.set_low();
        delay.delay_us(settle);
        let off = read(adc, &mut acq, saturation_code);
        add_off(&mut acq, off);
        for ch in 0..2 {
            let (o, a, b) = (
                i32::from(on.get(ch).copied().unwrap_or(0)),
                i32::from(prev_off.get(ch).copied().unwrap_or(0)),
                i32::from(off.get(ch).copied().unwrap_or(0)),
            );
            if let Some(s) = acq.sum2_net.get_mut(ch) {
                *s = s.saturating_add(2 * o - a - b);
            }
        }
        prev_off = off;
    }
    acq
}

fn read<A: PhotoAdc>(adc: &mut A, acq: &mut Acquisition, saturation_code: u16) -> [u16; 2] {
    let mut codes = adc.read_photo();
    for (code, sat) in codes.iter_mut().zip(acq.saturated.iter_mut()) {
        *code = (*code).min(ADC_MAX);
        if *code >= saturation_code {
            *sat = true;
        }
    }
    codes
}

fn add_off(acq: &mut Acquisition, off: [u16; 2]) {
    for (sum, code) in acq.sum_off.iter_mut().zip(off) {
        *sum = sum.saturating_add(u32::from(code));
    }
}

/// Currents of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Currents {
    /// Net photocurrent (LED on − LED off) per channel, nA.
    pub net_na: [i32; 2],
    /// Ambient (LED off) current per channel, nA.
    pub ambient_na: [u32; 2],
}

/// Convert a code sum to nA: I = V / R_L, V = code × V_DDA / 4095.
/// `count` codes were summed. Rounded to nearest, saturating.
pub fn code_sum_to_na(sum: i64, count: i64, vdda_mv: u16, load_ohm: u32) -> i64 {
    let den = count
        .saturating_mul(i64::from(ADC_MAX))
        .saturating_mul(i64::from(load_ohm.max(1)));
    if den <= 0 {
        return 0;
    }
    // mV / Ω = mA; × 1e6 → nA.
    let num = sum
        .saturating_mul(i64::from(vdda_mv))
        .saturating_mul(1_000_000);
    let half = den / 2;
    if num >= 0 {
        num.saturating_add(half) / den
    } else {
        num.saturating_sub(half) / den
    }
}

/// Currents from an acquisition, the supply (mV) and the two load resistors (Ω).
pub fn currents(acq: &Acquisition, vdda_mv: u16, load_ohm: [u32; 2]) -> Currents {
    let k = i64::from(acq.cycles.max(1));
    let mut out = Currents::default();
    for ch in 0..2 {
        let r = load_ohm.get(ch).copied().unwrap_or(1);
        let net = acq.sum2_net.get(ch).copied().unwrap_or(0);
        let off = acq.sum_off.get(ch).copied().unwrap_or(0);
        let net_na = code_sum_to_na(i64::from(net), 2 * k, vdda_mv, r);
        let amb_na = code_sum_to_na(i64::from(off), k + 1, vdda_mv, r);
        if let Some(n) = out.net_na.get_mut(ch) {
            *n = net_na.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
        }
        if let Some(a) = out.ambient_na.get_mut(ch) {
            *a = amb_na.clamp(0, i64::from(u32::MAX)) as u32;
        }
    }
    out
}

/// nA per ADC step at this supply and load resistor (for bounds and docs).
pub fn na_per_lsb(vdda_mv: u16, load_ohm: u32) -> f32 {
    f32::from(vdda_mv) * 1.0e6 / (f32::from(ADC_MAX) * load_ohm.max(1) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn volts_to_current() {
        // 2047.5 codes at 3.3 V = 1.65 V over 10 kΩ = 165 µA.
        assert_eq!(code_sum_to_na(4095, 2, 3_300, 10_000), 165_000);
        assert_eq!(code_sum_to_na(-4095, 2, 3_300, 10_000), -165_000);
        // One step at 3.3 V, 10 kΩ: 80.6 nA.
        assert_eq!(code_sum_to_na(1, 1, 3_300, 10_000), 81);
        assert_eq!(code_sum_to_na(1, 0, 3_300, 10_000), 0);
        assert_eq!(code_sum_to_na(i64::MAX, 1, 3_300, 0), i64::MAX / 4095);
    }

    #[test]
    fn saturation_follows_the_supply() {
        // 3.3 V: clip at 2.9 V, flagged from 2.8 V = 4095 × 2.8 / 3.3.
        assert_eq!(saturation_code(3_300), 3_474);
        // 3.0 V: from 2.5 V.
        assert_eq!(saturation_code(3_000), 3_412);
        // 3.6 V: from 3.1 V = 3526 codes.
        assert_eq!(saturation_code(3_600), 3_526);
        // Absurd supplies never go above the ADC's own limit or wrap.
        assert_eq!(saturation_code(u16::MAX), ADC_SATURATION_CODE);
        assert_eq!(saturation_code(0), 0);
        assert_eq!(saturation_code(400), 0);
    }

    #[test]
    fn currents_average_k_cycles() {
        let acq = Acquisition {
            // 8 cycles of a net 124.1 codes (10 µA at 3.3 V / 10 kΩ): 2·8·124.1.
            sum2_net: [1_986, -16],
            sum_off: [9 * 100, 0],
            cycles: 8,
            saturated: [false; 2],
        };
        let c = currents(&acq, 3_300, [10_000, 10_000]);
        assert!((c.net_na[0] - 10_000).abs() < 10, "{:?}", c);
        assert_eq!(c.net_na[1], -81);
        assert_eq!(c.ambient_na, [8_059, 0]);
    }
}
