//! The NUCLEO-F446RE board module: the only code that knows the STM32. It
//! implements the library's seams with embassy-stm32 (ADC, flash) and reads
//! the chip's identity (unique id, factory calibration, reset reason).
//! Porting to another STM32 means rewriting this file.

use embassy_stm32::Peri;
use embassy_stm32::adc::{Adc, SampleTime, Temperature, VrefInt};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::{ADC1, PA0, PA1, PA4};
use fois_firmware::hal::{FactoryCal, PhotoAdc, Storage, StorageError};
use fois_protocol::ResetReason;

/// Board name sent in `Hello`.
pub const BOARD_NAME: &str = "NUCLEO-F446RE";

// Factory values in system memory (RM0390 / DS10693).
const VREFINT_CAL_ADDR: usize = 0x1FFF_7A2A;
const TS_CAL1_ADDR: usize = 0x1FFF_7A2C;
const TS_CAL2_ADDR: usize = 0x1FFF_7A2E;

/// Flash sector 7: 128 KiB at 0x0806_0000, kept out of the program by memory.x.
const STORAGE_OFFSET: u32 = 0x0006_0000;
const STORAGE_SIZE: u32 = 0x0002_0000;
/// Flash is programmed in words.
const WRITE_SIZE: usize = 4;

/// The factory calibration values.
pub fn factory_cal() -> FactoryCal {
    // SAFETY: fixed, always-readable system-memory addresses of the F446.
    let read = |addr: usize| unsafe { core::ptr::read_volatile(addr as *const u16) };
    FactoryCal {
        vrefint_cal: read(VREFINT_CAL_ADDR),
        ts_cal1: read(TS_CAL1_ADDR),
        ts_cal2: read(TS_CAL2_ADDR),
    }
}

/// The 96-bit unique id (0x1FFF_7A10).
pub fn unique_id() -> [u8; 12] {
    embassy_stm32::uid::uid()
}

/// Why the chip reset, from the RCC CSR flags; the flags are then cleared so
/// the next reset reports only its own cause.
pub fn take_reset_reason() -> ResetReason {
    let rcc = embassy_stm32::pac::RCC;
    let csr = rcc.csr().read();
    // Precedence: the most specific cause wins (a watchdog or software reset
    // also pulses NRST, so PINRST is set with them).
    let reason = if csr.wdgrstf() {
        ResetReason::IndependentWatchdog
    } else if csr.wwdgrstf() {
        ResetReason::WindowWatchdog
    } else if csr.lpwrrstf() {
        ResetReason::LowPower
    } else if csr.sftrstf() {
        ResetReason::Software
    } else if csr.porrstf() || csr.borrstf() {
        ResetReason::PowerOn
    } else if csr.padrstf() {
        ResetReason::Pin
    } else {
        ResetReason::Unknown
    };
    rcc.csr().modify(|w| w.set_rmvf(true));
    reason
}

/// A short name for the log.
pub fn reset_reason_name(r: ResetReason) -> &'static str {
    match r {
        ResetReason::PowerOn => "power-on",
        ResetReason::Pin => "pin",
        ResetReason::Software => "software",
        ResetReason::IndependentWatchdog => "independent watchdog",
        ResetReason::WindowWatchdog => "window watchdog",
        ResetReason::LowPower => "low power",
        ResetReason::Unknown => "unknown",
    }
}

/// ADC1 with the node's channels: PA0, PA1 (phototransistors), PA4 (NTC),
/// VREFINT and the temperature sensor, all single blocking conversions.
pub struct BoardAdc {
    adc: Adc<'static, ADC1>,
    photo1: Peri<'static, PA0>,
    photo2: Peri<'static, PA1>,
    ntc: Peri<'static, PA4>,
    vrefint: VrefInt,
    temp: Temperature,
}

impl BoardAdc {
    /// Take ADC1 and the pins; enables VREFINT and the temperature sensor.
    pub fn new(
        adc: Peri<'static, ADC1>,
        photo1: Peri<'static, PA0>,
        photo2: Peri<'static, PA1>,
        ntc: Peri<'static, PA4>,
    ) -> Self {
        let adc = Adc::new(adc);
        let vrefint = adc.enable_vrefint();
        let temp = adc.enable_temperature();
        // VREFINT and the sensor need 10 µs to start.
        embassy_time::block_for(embassy_time::Duration::from_micros(20));
        BoardAdc {
            adc,
            photo1,
            photo2,
            ntc,
            vrefint,
            temp,
        }
    }
}

// ADC clock: PCLK2 16 MHz / 2 = 8 MHz. 56 cycles = 7 µs sampling, enough for
// the 10 kΩ load resistors; the internal channels need ≥ 10 µs (112 cycles).
const PHOTO_SAMPLE: SampleTime = SampleTime::CYCLES56;
const NTC_SAMPLE: SampleTime = SampleTime::CYCLES84;
const INTERNAL_SAMPLE: SampleTime = SampleTime::CYCLES144;

impl PhotoAdc for BoardAdc {
    fn read_photo(&mut self) -> [u16; 2] {
        [
            self.adc.blocking_read(&mut self.photo1, PHOTO_SAMPLE),
            self.adc.blocking_read(&mut self.photo2, PHOTO_SAMPLE),
        ]
    }
    fn read_ntc(&mut self) -> u16 {
        self.adc.blocking_read(&mut self.ntc, NTC_SAMPLE)
    }
    fn read_vrefint(&mut self) -> u16 {
        self.adc.blocking_read(&mut self.vrefint, INTERNAL_SAMPLE)
    }
    fn read_internal_temp(&mut self) -> u16 {
        self.adc.blocking_read(&mut self.temp, INTERNAL_SAMPLE)
    }
}

/// The config/baseline record in flash sector 7.
pub struct FlashStorage {
    flash: Flash<'static, Blocking>,
}

impl FlashStorage {
    /// Take the flash controller.
    pub fn new(flash: Flash<'static, Blocking>) -> Self {
        FlashStorage { flash }
    }
}

impl Storage for FlashStorage {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        let n = buf.len().min(STORAGE_SIZE as usize);
        let dst = buf.get_mut(..n).ok_or(StorageError::Read)?;
        self.flash
            .blocking_read(STORAGE_OFFSET, dst)
            .map_err(|_| StorageError::Read)?;
        Ok(n)
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        // Pad to whole words with 0xFF (what erased flash reads anyway).
        let mut buf = [0xFFu8; 256];
        let padded = data.len().div_ceil(WRITE_SIZE) * WRITE_SIZE;
        buf.get_mut(..data.len())
            .ok_or(StorageError::TooLarge)?
            .copy_from_slice(data);
        let words = buf.get(..padded).ok_or(StorageError::TooLarge)?;
        // Erasing the 128 KiB sector takes 1–2 s (the CPU stalls on flash
        // reads meanwhile); the watchdog timeout allows for it.
        self.flash
            .blocking_erase(STORAGE_OFFSET, STORAGE_OFFSET + STORAGE_SIZE)
            .map_err(|_| StorageError::Write)?;
        self.flash
            .blocking_write(STORAGE_OFFSET, words)
            .map_err(|_| StorageError::Write)?;
        // Read back: a write that does not verify is a failure.
        let mut check = [0u8; 256];
        let back = check.get_mut(..padded).ok_or(StorageError::TooLarge)?;
        self.flash
            .blocking_read(STORAGE_OFFSET, back)
            .map_err(|_| StorageError::Read)?;
        if back != words {
            return Err(StorageError::Write);
        }
        Ok(())
    }
}
