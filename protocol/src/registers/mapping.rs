//! A measurement as registers: the one mapping from a frame's integers to
//! the measurement block, used by the node (RTU) and the gateway (TCP).

use super::table::{
    ACCRETING_PROBABILITY, ACK, FAULTS, FRAMES_LOST, GAIN, GAIN_SIGMA, I1, I2, ICING_RATE,
    ICING_RATE_SIGMA, Kind, MEDIUM, MEDIUM_PROBABILITY, NA_I16, NA_I32, NA_U16, NA_U32, REGISTERS,
    SEQ, STATE, STATUS, TABLE, TEMPERATURE, THICKNESS, THICKNESS_SIGMA, VDDA, status,
};
use crate::{DetectorState, GainEstimate, IceEstimate, IcingEstimate, Measurement, Medium, flags};

/// The icing rate a node reports, in the registers' units (from the
/// frame's [`IcingEstimate`]: `From`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IcingRate {
    /// Accretion rate, 0.01 mm/h.
    pub rate_centi_mm_per_h: i16,
    /// Its standard deviation, 0.01 mm/h.
    pub sigma_centi_mm_per_h: u16,
    /// The node says ice is accreting.
    pub accreting: bool,
    /// The probability that it is, ‰.
    pub accreting_permille: u16,
}

impl From<&IcingEstimate> for IcingRate {
    /// µm/h to 0.01 mm/h (10 µm/h), rounded half up, saturating.
    fn from(i: &IcingEstimate) -> Self {
        let centi = |um: u16| (um / 10).saturating_add(u16::from(um % 10 >= 5));
        IcingRate {
            rate_centi_mm_per_h: i16::try_from(centi(i.rate_um_per_h)).unwrap_or(i16::MAX),
            sigma_centi_mm_per_h: centi(i.sigma_um_per_h),
            accreting: i.accreting,
            accreting_permille: i.accreting_permille,
        }
    }
}

/// One measurement as the registers show it: the wire's integers.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// The frame's currents, temperature, flags and state.
    pub measurement: &'a Measurement,
    /// The frame's sequence number.
    pub seq: u32,
    /// The ice estimate, if any.
    pub estimate: Option<&'a IceEstimate>,
    /// The optical gain estimate, if any.
    pub gain: Option<&'a GainEstimate>,
    /// The icing rate, if the node reports one.
    pub icing: Option<IcingRate>,
}

/// The measurement block with every value "not available" and the status
/// word [`status::STALE`] (no measurement).
pub fn not_available() -> [u16; REGISTERS] {
    let mut r = [0u16; REGISTERS];
    for f in &TABLE {
        let (hi, lo) = match f.kind {
            Kind::Bits => (0, 0),
            Kind::Enum | Kind::U16 => (NA_U16, 0),
            Kind::I16 => (NA_I16, 0),
            Kind::U32 => ((NA_U32 >> 16) as u16, NA_U32 as u16),
            Kind::I32 => ((NA_I32 >> 16) as u16, NA_I32 as u16),
        };
        set(&mut r, f.address, hi);
        if f.kind.width() == 2 {
            set(&mut r, f.address + 1, lo);
        }
    }
    set(&mut r, ACK, 0);
    set(&mut r, FRAMES_LOST, 0);
    set(&mut r, FRAMES_LOST + 1, 0);
    set(&mut r, STATUS, status::STALE);
    r
}

/// The measurement block of `s`: the "not available" block with the
/// sample's values and status bits (not [`status::LINK_UP`], not
/// [`status::STALE`]: the server's own); the gateway-only registers stay
/// as they are.
pub fn measurement_registers(r: &mut [u16; REGISTERS], s: &Sample<'_>) {
    let m = s.measurement;
    let mut bits = status::DATA;
    for (on, bit) in [
        (m.flags & flags::ALARM != 0, status::ALARM),
        (m.flags & flags::ALARM_ACKED != 0, status::ALARM_ACKED),
        (m.state == DetectorState::Ice, status::ICE),
        (m.is_valid(), status::VALID),
        (s.estimate.is_some(), status::ESTIMATE),
        (s.gain.is_some(), status::GAIN),
        (m.flags & flags::NO_BASELINE == 0, status::DARK_BASELINE),
        (m.flags & flags::FAULT_MASK != 0, status::FAULT),
        (s.icing.is_some(), status::ICING_RATE),
        (s.icing.is_some_and(|i| i.accreting), status::ACCRETING),
    ] {
        if on {
            bits |= bit;
        }
    }
    let keep = r.get(usize::from(STATUS)).copied().unwrap_or(0) & (status::LINK_UP | status::STALE);
    set(r, STATUS, bits | keep);
    set(r, STATE, state_code(m.state));
    set(r, FAULTS, m.flags & flags::FAULT_MASK);
    set32(r, I1, i32_reg(m.i1_na));
    set32(r, I2, i32_reg(m.i2_na));
    set(r, TEMPERATURE, i16_reg(m.temperature_centi_c));
    set(r, VDDA, u16_reg(m.vdda_mv));
    set32(r, SEQ, s.seq);
    if let Some(e) = s.estimate {
        set(r, THICKNESS, u16_reg(e.thickness_um));
        set(r, THICKNESS_SIGMA, u16_reg(e.sigma_um));
        set(r, MEDIUM, medium_code(e.medium));
        set(r, MEDIUM_PROBABILITY, u16_reg(e.probability_permille));
    }
    if let Some(g) = s.gain {
        set32(r, GAIN, u32_reg(g.gain_ppm));
        set32(r, GAIN_SIGMA, u32_reg(g.sigma_ppm));
    }
    if let Some(i) = s.icing {
        set(r, ICING_RATE, i16_reg(i.rate_centi_mm_per_h));
        set(r, ICING_RATE_SIGMA, u16_reg(i.sigma_centi_mm_per_h));
        set(r, ACCRETING_PROBABILITY, u16_reg(i.accreting_permille));
    }
}

/// A u16 value, kept off the "not available" value.
pub const fn u16_reg(v: u16) -> u16 {
    if v == NA_U16 { NA_U16 - 1 } else { v }
}

/// An i16 value, kept off the "not available" value.
pub const fn i16_reg(v: i16) -> u16 {
    if v == i16::MIN {
        (i16::MIN + 1) as u16
    } else {
        v as u16
    }
}

/// A u32 value, kept off the "not available" value.
pub const fn u32_reg(v: u32) -> u32 {
    if v == NA_U32 { NA_U32 - 1 } else { v }
}

/// An i32 value, kept off the "not available" value.
pub const fn i32_reg(v: i32) -> u32 {
    if v == i32::MIN {
        (i32::MIN + 1) as u32
    } else {
        v as u32
    }
}

/// Set register `addr` (ignored outside the block).
pub fn set(r: &mut [u16], addr: u16, v: u16) {
    if let Some(x) = r.get_mut(usize::from(addr)) {
        *x = v;
    }
}

/// Set the pair at `addr`, high word first.
pub fn set32(r: &mut [u16], addr: u16, v: u32) {
    set(r, addr, (v >> 16) as u16);
    set(r, addr.saturating_add(1), v as u16);
}

/// The state register's code.
pub const fn state_code(s: DetectorState) -> u16 {
    match s {
        DetectorState::Dry => 0,
        DetectorState::Wet => 1,
        DetectorState::Ice => 2,
    }
}

/// The medium register's code.
pub const fn medium_code(m: Medium) -> u16 {
    match m {
        Medium::Dry => 0,
        Medium::Water => 1,
        Medium::Glazed => 2,
        Medium::Rime => 3,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sample_in_the_wire_integers_and_the_not_available_values_kept_off() {
        let m = Measurement {
            uptime_ms: 5,
            i1_na: i32::MIN,
            i2_na: -250,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: i16::MIN,
            vdda_mv: 3300,
            flags: flags::ALARM | flags::NTC_OPEN,
            state: DetectorState::Ice,
        };
        let e = IceEstimate {
            thickness_um: u16::MAX,
            sigma_um: 80,
            medium: Medium::Rime,
            probability_permille: 900,
        };
        let mut r = not_available();
        let icing = IcingRate {
            rate_centi_mm_per_h: -150,
            sigma_centi_mm_per_h: 20,
            accreting: true,
            accreting_permille: 950,
        };
        measurement_registers(
            &mut r,
            &Sample {
                measurement: &m,
                seq: 0x0001_0002,
                estimate: Some(&e),
                gain: None,
                icing: Some(icing),
            },
        );
        assert_eq!(
            r[0],
            status::STALE
                | status::DATA
                | status::ALARM
                | status::ICE
                | status::VALID
                | status::ESTIMATE
                | status::DARK_BASELINE
                | status::FAULT
                | status::ICING_RATE
                | status::ACCRETING
        );
        assert_eq!((r[3], r[4]), (0x8000, 0x0001), "i32::MIN kept off NA");
        assert_eq!((r[5], r[6]), (0xFFFF, 0xFF06));
        assert_eq!(r[7], 0x8001);
        assert_eq!(r[8], 0xFFFE);
        assert_eq!((r[12], r[13]), (0xFFFF, 0xFFFF), "no gain: NA");
        assert_eq!((r[18], r[19]), (1, 2));
        assert_eq!(r[24], (-150i16) as u16);
        assert_eq!((r[25], r[26]), (20, 950));
        let fresh = not_available();
        assert_eq!((fresh[24], fresh[25], fresh[26]), (NA_I16, NA_U16, NA_U16));
        assert_eq!((fresh[21], fresh[22], fresh[23]), (0, 0, 0));
    }
}
