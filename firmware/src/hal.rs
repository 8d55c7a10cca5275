//! The hardware seams (ARCHITECTURE.md): the ADC and who the board is; the
//! persisted record's seam is [`crate::storage::Storage`]. The board module implements these with
//! embassy-stm32; host tests, the virtual node and the HIL suite implement
//! them with a simulated ADC. LED (PB0), alarm output (PA9) and LD2 (PA5) are
//! `embedded_hal::digital::OutputPin`s; settle waits use
//! `embedded_hal::delay::DelayNs`.

use fois_protocol::ResetReason;

/// Full scale of the 12-bit ADC.
pub const ADC_MAX: u16 = 4095;

/// One ADC sampling the node's analogue inputs. All codes are 12 bit, 0..=4095
/// (larger values are clamped by the logic, never trusted).
pub trait PhotoAdc {
    /// One conversion of each phototransistor channel (PA0, PA1): 12-bit codes 0..=4095.
    fn read_photo(&mut self) -> [u16; 2];
    /// NTC divider code (PA4), 12 bit.
    fn read_ntc(&mut self) -> u16;
    /// VREFINT code, 12 bit (V_DDA = 3.3 V * VREFINT_CAL / code).
    fn read_vrefint(&mut self) -> u16;
    /// Internal temperature sensor code, 12 bit.
    fn read_internal_temp(&mut self) -> u16;
}

/// Factory calibration values of the MCU (system memory on the STM32F4:
/// VREFINT_CAL 0x1FFF7A2A, TS_CAL1 0x1FFF7A2C (30 °C), TS_CAL2 0x1FFF7A2E
/// (110 °C), all taken at V_DDA = 3.3 V).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FactoryCal {
    /// VREFINT code at V_DDA = 3.3 V.
    pub vrefint_cal: u16,
    /// Internal temperature sensor code at 30 °C, V_DDA = 3.3 V.
    pub ts_cal1: u16,
    /// Internal temperature sensor code at 110 °C, V_DDA = 3.3 V.
    pub ts_cal2: u16,
}

impl FactoryCal {
    /// Typical values of an STM32F446 (datasheet: VREFINT 1.21 V, V_25 0.76 V,
    /// slope 2.5 mV/°C), for simulations and as a fallback when the stored
    /// values are implausible.
    pub const TYPICAL: FactoryCal = FactoryCal {
        vrefint_cal: 1502,
        ts_cal1: 958,
        ts_cal2: 1206,
    };

    /// `self` if plausible, otherwise [`FactoryCal::TYPICAL`] (erased or
    /// damaged system memory must not produce absurd readings).
    pub fn or_typical(self) -> FactoryCal {
        let vref_ok = (1300..=1700).contains(&self.vrefint_cal);
        let ts_ok = (700..=1200).contains(&self.ts_cal1)
            && self.ts_cal2 > self.ts_cal1.saturating_add(100)
            && self.ts_cal2 < 1600;
        FactoryCal {
            vrefint_cal: if vref_ok {
                self.vrefint_cal
            } else {
                Self::TYPICAL.vrefint_cal
            },
            ts_cal1: if ts_ok {
                self.ts_cal1
            } else {
                Self::TYPICAL.ts_cal1
            },
            ts_cal2: if ts_ok {
                self.ts_cal2
            } else {
                Self::TYPICAL.ts_cal2
            },
        }
    }
}

/// Who the board is: goes into [`fois_protocol::Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardInfo {
    /// Board name (ASCII, at most 16 bytes are sent).
    pub board: &'static str,
    /// The MCU's 96-bit unique id.
    pub unique_id: [u8; 12],
    /// Why the MCU last reset.
    pub reset_reason: ResetReason,
    /// Factory calibration values.
    pub cal: FactoryCal,
}

impl BoardInfo {
    /// A simulated board (virtual node, tests): typical calibration, power-on reset.
    pub const fn simulated(board: &'static str) -> BoardInfo {
        BoardInfo {
            board,
            unique_id: [0; 12],
            reset_reason: ResetReason::PowerOn,
            cal: FactoryCal::TYPICAL,
        }
    }
}
