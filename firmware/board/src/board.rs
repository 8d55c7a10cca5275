//! The NUCLEO-F446RE board module: with `safety.rs` (watchdog, clock, brown-out,
//! PVD, backup registers, panics) and `link.rs` (the host link) the only
//! code that knows the STM32. It implements the library's seams with
//! embassy-stm32 (ADC, flash as `NorFlash`, erased at x32) and reads the
//! chip's identity (unique id, factory calibration, reset reason). Porting
//! to another STM32 means rewriting these three files.

use core::sync::atomic::{AtomicBool, AtomicU16, Ordering};

use embassy_stm32::Peri;
use embassy_stm32::adc::{Adc, SampleTime, Temperature, VrefInt};
use embassy_stm32::flash::{BANK1_REGION1, Bank1Region1, Blocking, Error as FlashError};
use embassy_stm32::gpio::Output;
use embassy_stm32::pac;
use embassy_stm32::pac::flash::vals::Psize;
use embassy_stm32::pac::gpio::vals::Moder;
use embassy_stm32::peripherals::{ADC1, PA0, PA1, PA4};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::hal::{FactoryCal, PhotoAdc};
use fois_firmware::platform::field_link::LONG_CABLE_BAUD;
use fois_firmware::platform::flash_layout::{CONFIG_STORE, Partition};
use fois_firmware::platform::reply_time::{RESET_DRAIN_BYTES, drain_ms};
use fois_protocol::ResetReason;

use crate::flash_controller::{self, ControllerError};
use crate::safety::Watchdog;

/// Board name sent in `Hello`.
pub const BOARD_NAME: &str = "NUCLEO-F446RE";

// Factory values in system memory (RM0390 / DS10693).
const VREFINT_CAL_ADDR: usize = 0x1FFF_7A2A;
const TS_CAL1_ADDR: usize = 0x1FFF_7A2C;
const TS_CAL2_ADDR: usize = 0x1FFF_7A2E;

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

// ---- Outputs from the first instant ----

/// The alarm (PA9) and LD2 (PA5) pins, and the field link's DE/RE̅ (PA8).
const ALARM_PIN: usize = 9;
const LD2_PIN: usize = 5;
#[cfg(feature = "field-link")]
const DE_PIN: usize = 8;

/// Drive the outputs before anything else (before the HSE probe, the clock
/// setup, the ADC and the flash store's scan): the alarm and LD2 at the
/// level of the rule resumed from the backup registers, and on the field
/// link the transceiver's DE/RE̅ low (listening, the bus released) instead
/// of floating until the link is set up. Through the PAC: only the port's
/// clock, the level, then the mode (no glitch: the output register is set
/// first). embassy's `Output::new` later takes the pins over at the same
/// levels (`embassy_stm32::init` only enables the GPIO clocks).
pub fn hold_outputs_early(alarm_on: bool) {
    pac::RCC.ahb1enr().modify(|w| w.set_gpioaen(true));
    let a = pac::GPIOA;
    for pin in [ALARM_PIN, LD2_PIN] {
        a.bsrr().write(|w| {
            if alarm_on {
                w.set_bs(pin, true)
            } else {
                w.set_br(pin, true)
            }
        });
        a.moder().modify(|w| w.set_moder(pin, Moder::OUTPUT));
    }
    #[cfg(feature = "field-link")]
    {
        a.bsrr().write(|w| w.set_br(DE_PIN, true));
        a.moder().modify(|w| w.set_moder(DE_PIN, Moder::OUTPUT));
    }
}

/// Set once the node has resumed the rule: until then the node's writes to
/// the alarm and LD2 are not applied (its constructor drives them for a
/// dry rule before `resume_rule` sets the resumed one).
static OUTPUTS_HELD: AtomicBool = AtomicBool::new(true);

/// An output pin that keeps the level `hold_outputs_early` gave it until
/// [`release_outputs`].
pub struct HeldOutput(Output<'static>);

impl HeldOutput {
    /// Wrap a pin (created at the held level).
    pub fn new(pin: Output<'static>) -> Self {
        HeldOutput(pin)
    }
}

/// From now on the node drives the alarm and LD2 (call it right before
/// `Node::resume_rule`, which drives them to the same level).
pub fn release_outputs() {
    OUTPUTS_HELD.store(false, Ordering::Relaxed);
}

impl embedded_hal::digital::ErrorType for HeldOutput {
    type Error = core::convert::Infallible;
}

impl embedded_hal::digital::OutputPin for HeldOutput {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        if !OUTPUTS_HELD.load(Ordering::Relaxed) {
            self.0.set_low();
        }
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        if !OUTPUTS_HELD.load(Ordering::Relaxed) {
            self.0.set_high();
        }
        Ok(())
    }
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
/// VREFINT and the temperature sensor, single conversions. embassy-stm32
/// 0.6's `blocking_read` powers the converter down and up around every
/// conversion (ADON off, on, a 3 µs t_STAB wait, the sequence and sample
/// time rewritten) — tens of µs per photo pair, which stretch the settle gap
/// Δ of the synchronous detection and its flicker residual. So embassy sets
/// the ADC up (clock, prescaler, pins in analog mode, VREFINT) and every
/// conversion after that is ours, through the PAC, with the converter kept
/// on: SQR3 ← channel, SWSTART, EOC — 56 + 12 ADC cycles = 8.5 µs at 8 MHz
/// per channel (RM0390 §13, ADC: single conversions, channel-wise sampling time).
pub struct BoardAdc {
    /// Owns ADC1 (its clock and prescaler stay as embassy set them).
    _adc: Adc<'static, ADC1>,
}

// ADC clock: PCLK2 16 MHz / 2 = 8 MHz. 56 cycles = 7 µs sampling: settles
// sources up to 96 kΩ to ¼ LSB (RM0390 / datasheet eq. 1 with C_ADC = 7 pF,
// R_ADC = 6 kΩ), beyond the datasheet's R_AIN limit of 50 kΩ at which the
// config rule caps the load resistors (fois_protocol::LOAD_R_MAX_OHM). The
// internal channels need ≥ 10 µs
// (112 cycles).
const PHOTO_SAMPLE: SampleTime = SampleTime::CYCLES56;
const NTC_SAMPLE: SampleTime = SampleTime::CYCLES84;
const INTERNAL_SAMPLE: SampleTime = SampleTime::CYCLES144;
/// ADC1 channels (RM0390 §13, ADC; the F446's temperature sensor is on 18).
const CH_PHOTO1: u8 = 0;
const CH_PHOTO2: u8 = 1;
const CH_NTC: u8 = 4;
const CH_VREFINT: u8 = 17;
const CH_TEMP: u8 = 18;
/// Polls of EOC before a conversion counts as failed (code 0: the node
/// then flags V_DDA or the NTC): ≥ 4 ms, a conversion takes ≤ 19 µs.
const EOC_POLLS: u32 = 10_000;

impl BoardAdc {
    /// Take ADC1 and the pins; enable VREFINT and the temperature sensor;
    /// set every channel's sample time once.
    pub fn new(
        adc: Peri<'static, ADC1>,
        mut photo1: Peri<'static, PA0>,
        mut photo2: Peri<'static, PA1>,
        mut ntc: Peri<'static, PA4>,
    ) -> Self {
        let mut adc = Adc::new(adc);
        let _vrefint: VrefInt = adc.enable_vrefint();
        let _temp: Temperature = adc.enable_temperature();
        // One embassy read per pin puts it in analog mode and leaves the
        // converter powered (ADON); the pins are not touched again.
        adc.blocking_read(&mut photo1, PHOTO_SAMPLE);
        adc.blocking_read(&mut photo2, PHOTO_SAMPLE);
        adc.blocking_read(&mut ntc, NTC_SAMPLE);
        let r = pac::ADC1;
        r.smpr2().modify(|w| {
            w.set_smp(usize::from(CH_PHOTO1), PHOTO_SAMPLE);
            w.set_smp(usize::from(CH_PHOTO2), PHOTO_SAMPLE);
            w.set_smp(usize::from(CH_NTC), NTC_SAMPLE);
        });
        r.smpr1().modify(|w| {
            w.set_smp(usize::from(CH_VREFINT - 10), INTERNAL_SAMPLE);
            w.set_smp(usize::from(CH_TEMP - 10), INTERNAL_SAMPLE);
        });
        r.sqr1().modify(|w| w.set_l(0));
        // VREFINT and the sensor need 10 µs to start.
        embassy_time::block_for(embassy_time::Duration::from_micros(20));
        BoardAdc { _adc: adc }
    }

    fn convert(channel: u8) -> u16 {
        let r = pac::ADC1;
        r.sqr3().write(|w| w.set_sq(0, channel));
        r.sr().modify(|w| w.set_eoc(false));
        r.cr2().modify(|w| w.set_swstart(true));
        for _ in 0..EOC_POLLS {
            if r.sr().read().eoc() {
                return r.dr().read().data();
            }
        }
        0
    }

    /// How long one `read_photo` takes, CPU cycles (the mean of 16, by the
    /// DWT cycle counter; `None` if the core peripherals are taken): the
    /// conversion part of the settle gap Δ, logged at boot.
    pub fn measure_photo_pair_cycles(&mut self) -> Option<u32> {
        let mut cp = cortex_m::Peripherals::take()?;
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();
        let start = cortex_m::peripheral::DWT::cycle_count();
        for _ in 0..16 {
            self.read_photo();
        }
        Some(cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) / 16)
    }
}

impl PhotoAdc for BoardAdc {
    fn read_photo(&mut self) -> [u16; 2] {
        [Self::convert(CH_PHOTO1), Self::convert(CH_PHOTO2)]
    }
    fn read_ntc(&mut self) -> u16 {
        Self::convert(CH_NTC)
    }
    fn read_vrefint(&mut self) -> u16 {
        Self::convert(CH_VREFINT)
    }
    fn read_internal_temp(&mut self) -> u16 {
        Self::convert(CH_TEMP)
    }
}

// ---- Flash: the config store ----

/// The store's two sectors: 2 and 3, 0x0800_8000..0x0801_0000
/// (`fois_firmware::platform::flash_layout::CONFIG_STORE`), in the first of
/// embassy-stm32's flash regions (sectors 0–3, based at 0x0800_0000).
const STORE: Partition = CONFIG_STORE;
const STORE_SECTOR_BYTES: u32 = fois_firmware::storage::flash_store::BOARD_SECTOR_BYTES as u32;
const _: () = assert!(STORE.largest_sector_bytes() == STORE_SECTOR_BYTES);
// The store lies in the first region, which starts at the flash's start.
const _: () =
    assert!(BANK1_REGION1.offset == 0 && STORE.offset() + STORE.bytes() <= BANK1_REGION1.size);
/// x32 parallelism needs V_DD ≥ 2.7 V (RM0390 §3.5, program/erase
/// parallelism); the node starts a save only above it (`storage::supply`).
const X32_MIN_VDDA_MV: u16 = fois_firmware::storage::supply::FLASH_WRITE_MIN_VDDA_MV;

/// The V_DDA of the last frame, mV (0 before the first one): chooses the
/// erase parallelism.
pub static LAST_VDDA_MV: AtomicU16 = AtomicU16::new(0);

/// Set by the transmit task from the start of a burst until the USART
/// reported transmission complete (and DE is low again on the field link).
pub static LINK_SENDING: AtomicBool = AtomicBool::new(false);

/// The longest a sector erase waits for the link to finish its burst, ms:
/// everything queued drained at the slowest rate (852 ms).
const ERASE_WAITS_FOR_LINK_MS: u32 = drain_ms(RESET_DRAIN_BYTES, LONG_CABLE_BAUD);

/// Before an erase stalls the CPU (and with it the interrupt that drops
/// DE/RE̅ at transmission complete) for up to 2.6 s: let the burst on the
/// wire end. The transmit task runs on the higher-priority executor, so it
/// finishes while this waits (bounded).
fn wait_for_link_idle() {
    let start = embassy_time::Instant::now();
    let bound = embassy_time::Duration::from_millis(u64::from(ERASE_WAITS_FOR_LINK_MS));
    while LINK_SENDING.load(Ordering::Acquire) && start.elapsed() < bound {
        core::hint::spin_loop();
    }
}

/// Erase sector `snb` through the PAC at x32 (x16 below 2.7 V or before
/// the first V_DDA reading), because embassy-stm32 0.6 leaves PSIZE at x8
/// for erases (up to 4 s per 128 KiB sector instead of 2 s). The watchdog
/// is fed right before the erase (after the link's burst ended) and right
/// after it. Every erase of the board's flash (the store, the update's
/// slots: `slots.rs`) goes through here.
pub fn erase_sector(snb: u8, wdg: Watchdog) -> Result<(), FlashError> {
    let psize = if LAST_VDDA_MV.load(Ordering::Relaxed) >= X32_MIN_VDDA_MV {
        Psize::PSIZE32
    } else {
        Psize::PSIZE16
    };
    wdg.pet();
    wait_for_link_idle();
    wdg.pet();
    flash_controller::unlock();
    flash_controller::start_sector_erase(snb, psize);
    // The CPU stalls here on its next instruction fetch until the erase
    // ends (one bank): 1–2 s at x32 for 128 KiB, 0.25–0.5 s for 16 KiB.
    let reported = flash_controller::finish();
    // Stale lines of the erased sector must not be served from the data
    // cache (if anything enabled it).
    let flash = pac::FLASH;
    if flash.acr().read().dcen() {
        flash.acr().modify(|w| w.set_dcen(false));
        flash.acr().modify(|w| w.set_dcrst(true));
        flash.acr().modify(|w| w.set_dcrst(false));
        flash.acr().modify(|w| w.set_dcen(true));
    }
    wdg.pet();
    reported.map_err(|e| match e {
        ControllerError::Sequence => FlashError::Seq,
        ControllerError::Parallelism => FlashError::Parallelism,
        ControllerError::Alignment => FlashError::Unaligned,
        ControllerError::Protected => FlashError::Protected,
        ControllerError::Operation => FlashError::Prog,
    })
}

/// Erase the sectors of `part` that hold `from..to` (offsets from the
/// partition's start, whole sectors of `sector_bytes`), one at a time.
pub fn erase_partition(
    part: Partition,
    sector_bytes: u32,
    from: u32,
    to: u32,
    wdg: Watchdog,
) -> Result<(), FlashError> {
    if !from.is_multiple_of(sector_bytes) || !to.is_multiple_of(sector_bytes) {
        return Err(FlashError::Unaligned);
    }
    if from > to || to > part.bytes() {
        return Err(FlashError::Size);
    }
    let mut at = from;
    while at < to {
        let snb = part.sector_at(at).ok_or(FlashError::Size)?;
        erase_sector(snb, wdg)?;
        at += sector_bytes;
    }
    Ok(())
}

/// Sectors 2 and 3 as one `NorFlash` of two 16 KiB pages (offset 0 =
/// 0x0800_8000). Reads and programming go through embassy-stm32's first
/// flash region (which programs at x32); erases through [`erase_sector`].
pub struct BoardFlash {
    region: Bank1Region1<'static, Blocking>,
    wdg: Watchdog,
}

impl BoardFlash {
    /// Over embassy-stm32's first flash region (sectors 0–3).
    pub fn new(region: Bank1Region1<'static, Blocking>, wdg: Watchdog) -> Self {
        BoardFlash { region, wdg }
    }

    /// The store's range in this flash's addresses.
    pub const RANGE: core::ops::Range<u32> = 0..STORE.bytes();

    /// Offset in the region of the store's byte `offset`.
    const fn in_region(offset: u32) -> u32 {
        STORE.offset() - BANK1_REGION1.offset + offset
    }
}

impl ErrorType for BoardFlash {
    type Error = FlashError;
}

impl ReadNorFlash for BoardFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        if offset.saturating_add(bytes.len() as u32) > STORE.bytes() {
            return Err(FlashError::Size);
        }
        self.region.blocking_read(Self::in_region(offset), bytes)
    }
    fn capacity(&self) -> usize {
        STORE.bytes() as usize
    }
}

impl NorFlash for BoardFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = STORE_SECTOR_BYTES as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        erase_partition(STORE, STORE_SECTOR_BYTES, from, to, self.wdg)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        if offset.saturating_add(bytes.len() as u32) > STORE.bytes() {
            return Err(FlashError::Size);
        }
        self.region.blocking_write(Self::in_region(offset), bytes)
    }
}

// ---- The link's transmitter ----

/// The link USART's TC flag (SR.TC: the last stop bit left and nothing
/// waits in the data register).
pub fn link_tx_complete() -> bool {
    #[cfg(feature = "field-link")]
    let usart = pac::USART6;
    #[cfg(not(feature = "field-link"))]
    let usart = pac::USART2;
    usart.sr().read().tc()
}

// ---- The field link's receive line ----

/// USART6 RX (PC7): its input register reads the pin in its alternate
/// function too.
#[cfg(feature = "field-link")]
const FIELD_RX_PIN: usize = 7;

/// The field link's RX line stayed high (idle, no start bit) for `us`:
/// sampled directly, because the receive task stamps line activity only
/// when it wakes (half a buffer or an IDLE), so a host command still
/// arriving would look like a quiet line. Busy-waits `us` (≤ 1.6 ms at
/// 19 200 Bd) on the transmit task's executor.
#[cfg(feature = "field-link")]
pub fn field_rx_idle_for(us: u32) -> bool {
    use embassy_stm32::pac::gpio::vals::Idr;
    let start = embassy_time::Instant::now();
    let span = embassy_time::Duration::from_micros(u64::from(us));
    while start.elapsed() < span {
        if pac::GPIOC.idr().read().idr(FIELD_RX_PIN) == Idr::LOW {
            return false;
        }
    }
    true
}
