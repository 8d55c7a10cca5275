//! The node's configuration and the one rule that validates it.
//!
//! Device and host call the same [`Config::validate`], so a value the host
//! accepts is a value the node accepts. Every field has a name (the key of
//! `foisctl config set KEY=VALUE`), a unit, a range and a default in
//! [`FIELDS`].

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

/// Everything a user may tune on a node. Units are in the field names.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Output frame period, ms (100 = 10 Hz).
    pub frame_period_ms: u32,
    /// K: LED off/on cycles averaged per output frame.
    pub cycles_per_frame: u16,
    /// Wait after switching the LED before sampling, µs.
    pub settle_us: u16,
    /// Load resistor of phototransistor 1, Ω (I = V / R_L).
    pub load_r1_ohm: u32,
    /// Load resistor of phototransistor 2, Ω.
    pub load_r2_ohm: u32,
    /// Rise of I1 over its dark baseline that counts as a film (ice or water), nA.
    pub onset_rise_na: u32,
    /// N: consecutive frames above `onset_rise_na` before ice/wet is declared.
    pub onset_frames: u16,
    /// Rise of I1 below which the film counts as gone, nA (hysteresis; < onset).
    pub clear_rise_na: u32,
    /// M: consecutive frames below `clear_rise_na` before the state clears.
    pub clear_frames: u16,
    /// At or below this air temperature a film is ice, 0.01 °C.
    pub freeze_limit_centi_c: i16,
    /// Above this air temperature ice is cleared whatever the optics say, 0.01 °C.
    pub thaw_limit_centi_c: i16,
    /// Start streaming measurements at boot (otherwise wait for `StartStream`).
    pub stream_on_boot: bool,
    /// Version 3: temperature coefficient of the sensor's optical gain (LED
    /// output × phototransistor responsivity), ppm per kelvin of the
    /// optoelectronics' temperature (the MCU's internal sensor: the LED and
    /// the phototransistors sit with it). 0 = not calibrated.
    pub gain_tempco_ppm_per_k: i32,
    /// Version 3: standard deviation of that coefficient, ppm/K: how far the
    /// node's gain estimate may depart from the compensation as the
    /// temperature moves (wide when uncalibrated, narrow when measured).
    pub gain_tempco_sd_ppm_per_k: u32,
    /// Version 3: lower end of the plausible optical gain, ‰ of the response
    /// table's gain. Below it the node raises `GAIN_OUT_OF_BAND` (LED
    /// failing, face fouled).
    pub gain_low_permille: u16,
    /// Version 3: upper end of the plausible optical gain, ‰.
    pub gain_high_permille: u16,
}

/// The config as versions 1 and 2 carry it on the wire (the first twelve
/// fields of [`Config`], same order and types). Frozen: it is the payload of
/// [`Command::SetConfig`](crate::Command::SetConfig) and
/// [`AckResult::Config`](crate::AckResult::Config), which older nodes and
/// hosts speak. A version-3 node takes it and keeps its own values of the
/// newer fields.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)] // each field is the [`Config`] field of the same name
pub struct ConfigV1 {
    pub frame_period_ms: u32,
    pub cycles_per_frame: u16,
    pub settle_us: u16,
    pub load_r1_ohm: u32,
    pub load_r2_ohm: u32,
    pub onset_rise_na: u32,
    pub onset_frames: u16,
    pub clear_rise_na: u32,
    pub clear_frames: u16,
    pub freeze_limit_centi_c: i16,
    pub thaw_limit_centi_c: i16,
    pub stream_on_boot: bool,
}

impl ConfigV1 {
    /// This config's fields over `base`'s newer ones (how a version-3 node
    /// applies an older host's `SetConfig`).
    pub fn over(&self, base: &Config) -> Config {
        Config {
            frame_period_ms: self.frame_period_ms,
            cycles_per_frame: self.cycles_per_frame,
            settle_us: self.settle_us,
            load_r1_ohm: self.load_r1_ohm,
            load_r2_ohm: self.load_r2_ohm,
            onset_rise_na: self.onset_rise_na,
            onset_frames: self.onset_frames,
            clear_rise_na: self.clear_rise_na,
            clear_frames: self.clear_frames,
            freeze_limit_centi_c: self.freeze_limit_centi_c,
            thaw_limit_centi_c: self.thaw_limit_centi_c,
            stream_on_boot: self.stream_on_boot,
            ..base.clone()
        }
    }
}

impl From<ConfigV1> for Config {
    /// An older node's config: its fields, the defaults of the newer ones.
    fn from(old: ConfigV1) -> Config {
        old.over(&Config::default())
    }
}

impl From<&Config> for ConfigV1 {
    /// The part of a config that versions 1 and 2 carry.
    fn from(c: &Config) -> ConfigV1 {
        ConfigV1 {
            frame_period_ms: c.frame_period_ms,
            cycles_per_frame: c.cycles_per_frame,
            settle_us: c.settle_us,
            load_r1_ohm: c.load_r1_ohm,
            load_r2_ohm: c.load_r2_ohm,
            onset_rise_na: c.onset_rise_na,
            onset_frames: c.onset_frames,
            clear_rise_na: c.clear_rise_na,
            clear_frames: c.clear_frames,
            freeze_limit_centi_c: c.freeze_limit_centi_c,
            thaw_limit_centi_c: c.thaw_limit_centi_c,
            stream_on_boot: c.stream_on_boot,
        }
    }
}

impl Default for Config {
    /// The defaults, justified in `firmware/README.md` from the thesis's numbers.
    fn default() -> Self {
        Config {
            frame_period_ms: 100,
            cycles_per_frame: 8,
            settle_us: 200,
            load_r1_ohm: 10_000,
            load_r2_ohm: 10_000,
            onset_rise_na: 1_000,
            onset_frames: 30,
            clear_rise_na: 200,
            clear_frames: 300,
            freeze_limit_centi_c: 50,
            thaw_limit_centi_c: 250,
            stream_on_boot: true,
            gain_tempco_ppm_per_k: 0,
            gain_tempco_sd_ppm_per_k: 4_000,
            gain_low_permille: 600,
            gain_high_permille: 1_500,
        }
    }
}

/// The fields of [`Config`], in wire order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)] // each variant is the field of the same name
pub enum ConfigField {
    FramePeriodMs,
    CyclesPerFrame,
    SettleUs,
    LoadR1Ohm,
    LoadR2Ohm,
    OnsetRiseNa,
    OnsetFrames,
    ClearRiseNa,
    ClearFrames,
    FreezeLimitCentiC,
    ThawLimitCentiC,
    StreamOnBoot,
    GainTempcoPpmPerK,
    GainTempcoSdPpmPerK,
    GainLowPermille,
    GainHighPermille,
}

/// Why a config was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The field is below its minimum.
    BelowMin(ConfigField),
    /// The field is above its maximum.
    AboveMax(ConfigField),
    /// `clear_rise_na` must be below `onset_rise_na` (hysteresis).
    ClearNotBelowOnset,
    /// `thaw_limit_centi_c` must be above `freeze_limit_centi_c`.
    ThawNotAboveFreeze,
    /// K cycles of 2 × settle time do not fit in half a frame period.
    CyclesDoNotFitPeriod,
    /// No field has that name (host-side parsing only).
    UnknownField,
    /// The value is not a number of the field's kind (host-side parsing only).
    NotANumber,
    /// Version 3: `gain_low_permille` must be below `gain_high_permille`.
    GainBandEmpty,
}

/// The largest load resistor the node accepts, Ω: the STM32F446
/// datasheet's limit on the external input impedance, R_AIN ≤ 50 kΩ (ADC
/// characteristics table).
///
/// The sampling time settles more: the ADC samples its input on C_ADC
/// through the switch R_ADC for k ADC clock cycles, and the source (the
/// phototransistor's emitter node, at most R_L) must charge it to within
/// ¼ LSB (RM0390, ADC, "external input impedance"; datasheet, equation 1):
///
/// R_AIN ≤ (k − 0.5) / (f_ADC × C_ADC × ln(2^(N+2))) − R_ADC
///
/// With the board's photo sampling time k = 56 cycles at f_ADC = 8 MHz,
/// N = 12 bit, and the datasheet's worst C_ADC = 7 pF and R_ADC = 6 kΩ:
/// 55.5 / (8 MHz × 7 pF × ln 16384) − 6 kΩ = 96.1 kΩ. But the datasheet
/// specifies the converter only up to 50 kΩ of source impedance (its
/// accuracy figures, leakage and crosstalk are stated within that), so the
/// rule stops there. (At 50 kΩ one ADC step is 16 nA: far finer than the
/// 1 µA onset.)
pub const LOAD_R_MAX_OHM: u32 = 50_000;

/// Name, unit, range and meaning of one field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldSpec {
    /// Which field.
    pub field: ConfigField,
    /// The key used by `foisctl config set KEY=VALUE`.
    pub name: &'static str,
    /// Unit, for display.
    pub unit: &'static str,
    /// Smallest allowed value.
    pub min: i64,
    /// Largest allowed value.
    pub max: i64,
    /// One line for `--help` and `config get`.
    pub doc: &'static str,
    /// The first protocol version whose config carries the field (1 or 3):
    /// a host shows and sets only the fields of the node's version.
    pub since_version: u16,
}

const fn spec(
    field: ConfigField,
    name: &'static str,
    unit: &'static str,
    min: i64,
    max: i64,
    doc: &'static str,
) -> FieldSpec {
    FieldSpec {
        field,
        name,
        unit,
        min,
        max,
        doc,
        since_version: 1,
    }
}

const fn spec_v3(
    field: ConfigField,
    name: &'static str,
    unit: &'static str,
    min: i64,
    max: i64,
    doc: &'static str,
) -> FieldSpec {
    FieldSpec {
        since_version: 3,
        ..spec(field, name, unit, min, max, doc)
    }
}

/// Every field, in wire order, with its rule.
pub const FIELDS: [FieldSpec; 16] = [
    spec(
        ConfigField::FramePeriodMs,
        "frame_period_ms",
        "ms",
        20,
        600_000,
        "output frame period (100 ms = 10 Hz)",
    ),
    spec(
        ConfigField::CyclesPerFrame,
        "cycles_per_frame",
        "cycles",
        1,
        64,
        "K: LED off/on cycles averaged per frame",
    ),
    spec(
        ConfigField::SettleUs,
        "settle_us",
        "us",
        20,
        5_000,
        "settle time after switching the LED before sampling",
    ),
    spec(
        ConfigField::LoadR1Ohm,
        "load_r1_ohm",
        "ohm",
        1_000,
        LOAD_R_MAX_OHM as i64,
        "load resistor of phototransistor 1 (at most what the ADC sampling settles)",
    ),
    spec(
        ConfigField::LoadR2Ohm,
        "load_r2_ohm",
        "ohm",
        1_000,
        LOAD_R_MAX_OHM as i64,
        "load resistor of phototransistor 2 (at most what the ADC sampling settles)",
    ),
    spec(
        ConfigField::OnsetRiseNa,
        "onset_rise_na",
        "nA",
        50,
        100_000,
        "I1 rise over the dark baseline that counts as a film",
    ),
    spec(
        ConfigField::OnsetFrames,
        "onset_frames",
        "frames",
        1,
        1_000,
        "N: consecutive frames above onset before ice/wet",
    ),
    spec(
        ConfigField::ClearRiseNa,
        "clear_rise_na",
        "nA",
        0,
        100_000,
        "I1 rise below which the film is gone (must be < onset)",
    ),
    spec(
        ConfigField::ClearFrames,
        "clear_frames",
        "frames",
        1,
        10_000,
        "M: consecutive frames below clear before the state clears",
    ),
    spec(
        ConfigField::FreezeLimitCentiC,
        "freeze_limit_centi_c",
        "0.01 C",
        -2_000,
        1_000,
        "at or below this air temperature a film is ice",
    ),
    spec(
        ConfigField::ThawLimitCentiC,
        "thaw_limit_centi_c",
        "0.01 C",
        -1_900,
        3_000,
        "above this air temperature ice clears (must be > freeze)",
    ),
    spec(
        ConfigField::StreamOnBoot,
        "stream_on_boot",
        "0/1",
        0,
        1,
        "stream measurements at boot",
    ),
    spec_v3(
        ConfigField::GainTempcoPpmPerK,
        "gain_tempco_ppm_per_k",
        "ppm/K",
        -20_000,
        20_000,
        "temperature coefficient of the optical gain (0 = not calibrated)",
    ),
    spec_v3(
        ConfigField::GainTempcoSdPpmPerK,
        "gain_tempco_sd_ppm_per_k",
        "ppm/K",
        0,
        20_000,
        "uncertainty of that coefficient (wide when uncalibrated)",
    ),
    spec_v3(
        ConfigField::GainLowPermille,
        "gain_low_permille",
        "permille",
        100,
        1_000,
        "optical gain below this raises GAIN_OUT_OF_BAND (LED failing, face fouled)",
    ),
    spec_v3(
        ConfigField::GainHighPermille,
        "gain_high_permille",
        "permille",
        1_000,
        10_000,
        "optical gain above this raises GAIN_OUT_OF_BAND (must be > low)",
    ),
];

impl ConfigField {
    /// The field's rule.
    pub fn spec(self) -> &'static FieldSpec {
        // FIELDS is in the enum's order; the match keeps that true at compile time.
        let index = match self {
            ConfigField::FramePeriodMs => 0,
            ConfigField::CyclesPerFrame => 1,
            ConfigField::SettleUs => 2,
            ConfigField::LoadR1Ohm => 3,
            ConfigField::LoadR2Ohm => 4,
            ConfigField::OnsetRiseNa => 5,
            ConfigField::OnsetFrames => 6,
            ConfigField::ClearRiseNa => 7,
            ConfigField::ClearFrames => 8,
            ConfigField::FreezeLimitCentiC => 9,
            ConfigField::ThawLimitCentiC => 10,
            ConfigField::StreamOnBoot => 11,
            ConfigField::GainTempcoPpmPerK => 12,
            ConfigField::GainTempcoSdPpmPerK => 13,
            ConfigField::GainLowPermille => 14,
            ConfigField::GainHighPermille => 15,
        };
        &FIELDS[index]
    }

    /// The field of that key (`"onset_rise_na"`), if any.
    pub fn from_name(name: &str) -> Option<ConfigField> {
        FIELDS.iter().find(|s| s.name == name).map(|s| s.field)
    }

    /// The key of this field.
    pub fn name(self) -> &'static str {
        self.spec().name
    }
}

impl Config {
    /// The value of a field, widened to i64.
    pub fn get(&self, field: ConfigField) -> i64 {
        match field {
            ConfigField::FramePeriodMs => self.frame_period_ms.into(),
            ConfigField::CyclesPerFrame => self.cycles_per_frame.into(),
            ConfigField::SettleUs => self.settle_us.into(),
            ConfigField::LoadR1Ohm => self.load_r1_ohm.into(),
            ConfigField::LoadR2Ohm => self.load_r2_ohm.into(),
            ConfigField::OnsetRiseNa => self.onset_rise_na.into(),
            ConfigField::OnsetFrames => self.onset_frames.into(),
            ConfigField::ClearRiseNa => self.clear_rise_na.into(),
            ConfigField::ClearFrames => self.clear_frames.into(),
            ConfigField::FreezeLimitCentiC => self.freeze_limit_centi_c.into(),
            ConfigField::ThawLimitCentiC => self.thaw_limit_centi_c.into(),
            ConfigField::StreamOnBoot => self.stream_on_boot.into(),
            ConfigField::GainTempcoPpmPerK => self.gain_tempco_ppm_per_k.into(),
            ConfigField::GainTempcoSdPpmPerK => self.gain_tempco_sd_ppm_per_k.into(),
            ConfigField::GainLowPermille => self.gain_low_permille.into(),
            ConfigField::GainHighPermille => self.gain_high_permille.into(),
        }
    }

    /// Set one field after checking it against its range. Cross-field rules
    /// are checked by [`Config::validate`]; call it before applying.
    pub fn set(&mut self, field: ConfigField, value: i64) -> Result<(), ConfigError> {
        let spec = field.spec();
        if value < spec.min {
            return Err(ConfigError::BelowMin(field));
        }
        if value > spec.max {
            return Err(ConfigError::AboveMax(field));
        }
        // Every range in FIELDS fits its field's type, so the conversions
        // below cannot fail; map a failure to AboveMax all the same.
        let too_big = ConfigError::AboveMax(field);
        match field {
            ConfigField::FramePeriodMs => {
                self.frame_period_ms = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::CyclesPerFrame => {
                self.cycles_per_frame = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::SettleUs => self.settle_us = value.try_into().map_err(|_| too_big)?,
            ConfigField::LoadR1Ohm => self.load_r1_ohm = value.try_into().map_err(|_| too_big)?,
            ConfigField::LoadR2Ohm => self.load_r2_ohm = value.try_into().map_err(|_| too_big)?,
            ConfigField::OnsetRiseNa => {
                self.onset_rise_na = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::OnsetFrames => {
                self.onset_frames = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::ClearRiseNa => {
                self.clear_rise_na = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::ClearFrames => {
                self.clear_frames = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::FreezeLimitCentiC => {
                self.freeze_limit_centi_c = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::ThawLimitCentiC => {
                self.thaw_limit_centi_c = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::StreamOnBoot => self.stream_on_boot = value != 0,
            ConfigField::GainTempcoPpmPerK => {
                self.gain_tempco_ppm_per_k = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::GainTempcoSdPpmPerK => {
                self.gain_tempco_sd_ppm_per_k = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::GainLowPermille => {
                self.gain_low_permille = value.try_into().map_err(|_| too_big)?
            }
            ConfigField::GainHighPermille => {
                self.gain_high_permille = value.try_into().map_err(|_| too_big)?
            }
        }
        Ok(())
    }

    /// Parse `KEY=VALUE` text (as typed by a user) and set the field. Values
    /// are integers in the field's unit; `stream_on_boot` also takes
    /// `true`/`false`.
    pub fn set_from_str(&mut self, key: &str, value: &str) -> Result<ConfigField, ConfigError> {
        let field = ConfigField::from_name(key.trim()).ok_or(ConfigError::UnknownField)?;
        let value = value.trim();
        let number = match (field, value) {
            (ConfigField::StreamOnBoot, "true") => 1,
            (ConfigField::StreamOnBoot, "false") => 0,
            _ => value.parse::<i64>().map_err(|_| ConfigError::NotANumber)?,
        };
        self.set(field, number)?;
        Ok(field)
    }

    /// The whole rule: every field in range, and the cross-field rules.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for spec in FIELDS.iter() {
            let value = self.get(spec.field);
            if value < spec.min {
                return Err(ConfigError::BelowMin(spec.field));
            }
            if value > spec.max {
                return Err(ConfigError::AboveMax(spec.field));
            }
        }
        if self.clear_rise_na >= self.onset_rise_na {
            return Err(ConfigError::ClearNotBelowOnset);
        }
        if self.thaw_limit_centi_c <= self.freeze_limit_centi_c {
            return Err(ConfigError::ThawNotAboveFreeze);
        }
        if self.gain_low_permille >= self.gain_high_permille {
            return Err(ConfigError::GainBandEmpty);
        }
        // Each cycle holds the LED off and on for a settle time each; the K
        // cycles must leave at least half the frame period free.
        let busy_us = u64::from(self.cycles_per_frame) * 2 * u64::from(self.settle_us);
        if busy_us * 2 > u64::from(self.frame_period_ms) * 1_000 {
            return Err(ConfigError::CyclesDoNotFitPeriod);
        }
        Ok(())
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::BelowMin(field) => {
                let s = field.spec();
                write!(f, "{} is below its minimum {} {}", s.name, s.min, s.unit)
            }
            ConfigError::AboveMax(field) => {
                let s = field.spec();
                write!(f, "{} is above its maximum {} {}", s.name, s.max, s.unit)
            }
            ConfigError::ClearNotBelowOnset => {
                f.write_str("clear_rise_na must be below onset_rise_na (hysteresis)")
            }
            ConfigError::ThawNotAboveFreeze => {
                f.write_str("thaw_limit_centi_c must be above freeze_limit_centi_c")
            }
            ConfigError::CyclesDoNotFitPeriod => {
                f.write_str("cycles_per_frame x 2 x settle_us must fit in half of frame_period_ms")
            }
            ConfigError::UnknownField => f.write_str("no config field has that name"),
            ConfigError::NotANumber => f.write_str("the value is not an integer"),
            ConfigError::GainBandEmpty => {
                f.write_str("gain_low_permille must be below gain_high_permille")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        assert_eq!(Config::default().validate(), Ok(()));
    }

    #[test]
    fn fields_table_is_in_enum_order_and_defaults_in_range() {
        let c = Config::default();
        for (i, s) in FIELDS.iter().enumerate() {
            assert_eq!(s.field.spec().name, s.name, "row {i}");
            assert_eq!(*s.field.spec(), FIELDS[i]);
            let v = c.get(s.field);
            assert!(
                s.min <= v && v <= s.max,
                "{} default {v} out of range",
                s.name
            );
        }
    }

    #[test]
    fn each_field_one_past_its_range_is_refused() {
        for s in FIELDS.iter() {
            let mut c = Config::default();
            assert_eq!(
                c.set(s.field, s.min - 1),
                Err(ConfigError::BelowMin(s.field))
            );
            assert_eq!(
                c.set(s.field, s.max + 1),
                Err(ConfigError::AboveMax(s.field))
            );
            assert_eq!(c, Config::default(), "a refused set changed {}", s.name);
            assert_eq!(c.set(s.field, s.max), Ok(()));
            assert_eq!(c.get(s.field), s.max);
        }
    }

    /// The R_L limit is the datasheet's R_AIN maximum, which the sampling
    /// time settles with room to spare (RM0390 / datasheet eq. 1).
    #[test]
    fn load_resistor_limit_settles_in_the_sampling_time() {
        let (k, f_adc_hz, c_adc_f, r_adc_ohm, n_bits) = (56.0f64, 8.0e6, 7.0e-12, 6_000.0, 12);
        let r_ain_max = (k - 0.5) / (f_adc_hz * c_adc_f * (2f64.powi(n_bits + 2)).ln()) - r_adc_ohm;
        assert!((r_ain_max - 96_100.0).abs() < 100.0, "{r_ain_max}");
        assert!(f64::from(LOAD_R_MAX_OHM) <= r_ain_max);
        assert_eq!(LOAD_R_MAX_OHM, 50_000, "the datasheet's R_AIN limit");
        let mut c = Config::default();
        assert_eq!(c.set(ConfigField::LoadR1Ohm, 50_000), Ok(()));
        assert_eq!(
            c.set(ConfigField::LoadR2Ohm, 50_001),
            Err(ConfigError::AboveMax(ConfigField::LoadR2Ohm))
        );
        // The former limit (90 kΩ) is refused now.
        assert_eq!(
            c.set(ConfigField::LoadR2Ohm, 90_000),
            Err(ConfigError::AboveMax(ConfigField::LoadR2Ohm))
        );
        // The former limit (1 MΩ) is refused by the shared rule.
        c.load_r1_ohm = 1_000_000;
        assert_eq!(
            c.validate(),
            Err(ConfigError::AboveMax(ConfigField::LoadR1Ohm))
        );
    }

    #[test]
    fn cross_field_rules() {
        let mut c = Config::default();
        c.clear_rise_na = c.onset_rise_na;
        assert_eq!(c.validate(), Err(ConfigError::ClearNotBelowOnset));
        let mut c = Config::default();
        c.thaw_limit_centi_c = c.freeze_limit_centi_c;
        assert_eq!(c.validate(), Err(ConfigError::ThawNotAboveFreeze));
        let mut c = Config {
            gain_low_permille: 1_000,
            gain_high_permille: 1_000,
            ..Config::default()
        };
        assert_eq!(c.validate(), Err(ConfigError::GainBandEmpty));
        c.gain_high_permille = 1_001;
        assert_eq!(c.validate(), Ok(()));
        // 64 cycles x 2 x 5000 us = 640 ms > half of 100 ms.
        let mut c = Config {
            cycles_per_frame: 64,
            settle_us: 5_000,
            ..Config::default()
        };
        assert_eq!(c.validate(), Err(ConfigError::CyclesDoNotFitPeriod));
        c.frame_period_ms = 1_280;
        assert_eq!(c.validate(), Ok(()));
    }

    #[test]
    fn set_from_str_parses_keys_and_refuses_garbage() {
        let mut c = Config::default();
        assert_eq!(
            c.set_from_str("onset_rise_na", " 1500 "),
            Ok(ConfigField::OnsetRiseNa)
        );
        assert_eq!(c.onset_rise_na, 1_500);
        assert_eq!(
            c.set_from_str("stream_on_boot", "false"),
            Ok(ConfigField::StreamOnBoot)
        );
        assert!(!c.stream_on_boot);
        assert_eq!(c.set_from_str("nope", "1"), Err(ConfigError::UnknownField));
        assert_eq!(
            c.set_from_str("settle_us", "2x"),
            Err(ConfigError::NotANumber)
        );
        assert_eq!(
            c.set_from_str("settle_us", "99999999999999999999"),
            Err(ConfigError::NotANumber)
        );
        assert_eq!(
            c.set_from_str("freeze_limit_centi_c", "-2001"),
            Err(ConfigError::BelowMin(ConfigField::FreezeLimitCentiC))
        );
    }

    #[test]
    fn the_v1_shape_is_the_first_twelve_fields() {
        // The fields a version-1/2 node knows are exactly those marked so,
        // and they come first (wire order).
        let v1: Vec<_> = FIELDS.iter().filter(|s| s.since_version == 1).collect();
        assert_eq!(v1.len(), 12);
        assert!(FIELDS[..12].iter().all(|s| s.since_version == 1));
        assert!(FIELDS[12..].iter().all(|s| s.since_version == 3));

        let node = Config {
            gain_tempco_ppm_per_k: -3_500,
            gain_low_permille: 800,
            ..Config::default()
        };
        let old_host = ConfigV1 {
            onset_rise_na: 2_000,
            ..ConfigV1::from(&Config::default())
        };
        // An older host's SetConfig changes its twelve fields and keeps the node's gain fields.
        let applied = old_host.over(&node);
        assert_eq!(applied.onset_rise_na, 2_000);
        assert_eq!(applied.gain_tempco_ppm_per_k, -3_500);
        assert_eq!(applied.gain_low_permille, 800);
        assert_eq!(ConfigV1::from(&applied), old_host);
        // An older node's config reads with the newer fields at their defaults.
        let read = Config::from(old_host.clone());
        assert_eq!(read.gain_tempco_sd_ppm_per_k, 4_000);
        assert_eq!(read.onset_rise_na, 2_000);
    }
}
