//! The field-safety parts that need registers: the watchdog (started before
//! anything else), the clock (the HSE probe, the clock security system and
//! its fail-over to HSI), the brown-out level (read only), the programmable
//! voltage detector, the backup registers, and the panic and HardFault
//! handlers that record the cause and reset at once. The decisions are the
//! library's (`fois_firmware::platform::boot`, `::clock_retry`, `::supply`,
//! `::watchdog`); this file only moves bits.

use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{ExceptionFrame, exception};
use embassy_stm32::pac;
use embassy_stm32::pac::iwdg::vals::{Key, Pr};
use embassy_stm32::pac::rcc::vals::{Pllm, Plln, Pllp, Pllq, Pllsrc, Sw};
use fois_firmware::platform::{boot, watchdog};

// ---- Watchdog ----

/// The independent watchdog, programmed through the PAC with the prescaler
/// and reload of `fois_firmware::platform::watchdog` (timeout ≥ 8.17 s at the fastest
/// LSI). Zero-sized and `Copy`, so the flash erase can feed it too.
#[derive(Clone, Copy)]
pub struct Watchdog(());

impl Watchdog {
    /// Start the IWDG, before `embassy_stm32::init` (which waits without a
    /// bound on HSERDY, PLLRDY and the LSI): a hang there resets the chip.
    /// The IWDG needs no clock enable and starts the LSI itself (RM0390
    /// §20, independent watchdog). It cannot be stopped again. In debug
    /// builds it is frozen while a debugger halts the core
    /// (DBGMCU_APB1_FZ.DBG_IWDG_STOP); release images leave it running.
    pub fn start_first() -> Self {
        if cfg!(debug_assertions) {
            pac::DBGMCU.apb1fzr().modify(|w| w.set_iwdg(true));
        }
        let iwdg = pac::IWDG;
        iwdg.kr().write(|w| w.set_key(Key::START));
        iwdg.kr().write(|w| w.set_key(Key::ENABLE));
        iwdg.pr()
            .write(|w| w.set_pr(Pr::from_bits(watchdog::IWDG_PR)));
        iwdg.rlr().write(|w| w.set_rl(watchdog::IWDG_RELOAD));
        // The new prescaler and reload apply once the LSI domain has taken
        // them (SR.PVU/RVU clear, a few LSI periods); the counter runs from
        // START with the reset values (/4, 4095: 0.35–0.96 s) until then.
        // Bounded: at 16 MHz 1 M polls are > 60 ms, far beyond 5 LSI periods.
        for _ in 0..1_000_000u32 {
            let sr = iwdg.sr().read();
            if !sr.pvu() && !sr.rvu() {
                break;
            }
        }
        iwdg.kr().write(|w| w.set_key(Key::RESET));
        Watchdog(())
    }

    /// Reload the counter.
    pub fn pet(self) {
        pac::IWDG.kr().write(|w| w.set_key(Key::RESET));
    }
}

// ---- Clock ----

/// Where an 8 MHz HSE comes from.
#[derive(Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum HseSource {
    /// The ST-LINK's MCO into PH0/OSC_IN (NUCLEO default solder bridges).
    Bypass,
    /// A crystal fitted at X3 (a field node without the ST-LINK's USB).
    Crystal,
}

/// How long each HSE mode may take to show HSERDY, in 1 ms steps. A bypass
/// clock that is there is ready at once; a crystal starts in ~2 ms
/// (datasheet t_SU(HSE)); ST's HAL waits 100 ms.
const HSE_PROBE_MS: u32 = 100;

/// Try the external clock with the chip still on HSI after reset: first the
/// ST-LINK's MCO (HSE bypass), then a crystal at X3. embassy-stm32 0.6 spins
/// on HSERDY without a timeout, so a board with neither would hang there.
pub fn probe_hse() -> Option<HseSource> {
    [(HseSource::Bypass, true), (HseSource::Crystal, false)]
        .into_iter()
        .find(|&(_, bypass)| hse_ready(bypass))
        .map(|(source, _)| source)
}

fn hse_ready(bypass: bool) -> bool {
    let rcc = pac::RCC;
    rcc.cr().modify(|w| w.set_hseon(false));
    // HSEBYP may only change while HSE is off (RM0390 §6.3.1). HSERDY
    // falls within six HSE periods; bounded all the same.
    for _ in 0..10_000u32 {
        if !rcc.cr().read().hserdy() {
            break;
        }
    }
    rcc.cr().modify(|w| w.set_hsebyp(bypass));
    rcc.cr().modify(|w| w.set_hseon(true));
    for _ in 0..HSE_PROBE_MS {
        if rcc.cr().read().hserdy() {
            return true;
        }
        // 16 000 cycles of the 16 MHz HSI = 1 ms.
        cortex_m::asm::delay(16_000);
    }
    rcc.cr().modify(|w| w.set_hseon(false));
    rcc.cr().modify(|w| w.set_hsebyp(false));
    false
}

/// The clock config: SYSCLK 16 MHz either way (so the ADC clock, sample
/// times, the timer and the baud dividers are the same). With the 8 MHz HSE:
/// PLL 8 / 4 × 64 / 8 = 16 MHz (VCO input 2 MHz, VCO 128 MHz, both in
/// range); without it HSI 16 MHz (±1 % at 25 °C, −8 / +4.5 % over
/// −40…105 °C: `fois_firmware::platform::field_link`, hence CLOCK_FALLBACK). The
/// low-speed domain stays off: embassy would otherwise select the LSI as
/// the RTC clock at the first boot after a power-on and reset the backup
/// domain to do so, which clears the backup registers.
pub fn clock_config(hse: Option<HseSource>) -> embassy_stm32::Config {
    use embassy_stm32::rcc::{
        Hse, HseMode, LsConfig, Pll, PllMul, PllPDiv, PllPreDiv, PllSource, Sysclk,
    };
    let mut config = embassy_stm32::Config::default();
    config.rcc.ls = LsConfig::off();
    if let Some(source) = hse {
        config.rcc.hse = Some(Hse {
            freq: embassy_stm32::time::Hertz(8_000_000),
            mode: match source {
                HseSource::Bypass => HseMode::Bypass,
                HseSource::Crystal => HseMode::Oscillator,
            },
        });
        config.rcc.pll_src = PllSource::HSE;
        config.rcc.pll = Some(Pll {
            prediv: PllPreDiv::DIV4,
            mul: PllMul::MUL64,
            divp: Some(PllPDiv::DIV8),
            divq: None,
            divr: None,
        });
        config.rcc.sys = Sysclk::PLL1_P;
    }
    config
}

/// Polls of PLLRDY and of the clock switch before a retry gives up
/// (≥ 10 ms at 16 MHz; the PLL locks in ≤ 0.2 ms, datasheet t_LOCK).
const PLL_POLLS: u32 = 40_000;

/// Try the HSE again while the chip runs on HSI (after a failed probe at
/// boot or a fail-over by the clock security system; when, is the
/// library's `platform::clock_retry`). Probes the HSE as at boot; if it is
/// there, sets the PLL up as `clock_config` does (8 / 4 × 64 / 8 = 16 MHz),
/// waits for its lock (bounded), switches SYSCLK to it and turns the clock
/// security system on again. SYSCLK stays 16 MHz, so the flash wait states
/// (0), the bus prescalers, the baud dividers and the timer are unchanged;
/// the switch itself is glitch-free (RM0390 §6.2.6). Blocks ≤ 210 ms
/// (`clock_retry::RETRY_COST_MAX_MS`). Anything that fails leaves the chip
/// on HSI with the HSE and the PLL off.
pub fn try_restore_hse() -> Option<HseSource> {
    let rcc = pac::RCC;
    if rcc.cfgr().read().sws() != Sw::HSI {
        return None;
    }
    // The PLL may only be configured while off (the fail-over turned it off).
    rcc.cr().modify(|w| w.set_pllon(false));
    let source = probe_hse()?;
    rcc.pllcfgr().modify(|w| {
        w.set_pllsrc(Pllsrc::HSE);
        w.set_pllm(Pllm::DIV4);
        w.set_plln(Plln::MUL64);
        w.set_pllp(Pllp::DIV8);
        w.set_pllq(Pllq::DIV8);
    });
    rcc.cr().modify(|w| w.set_pllon(true));
    let locked = (0..PLL_POLLS).any(|_| rcc.cr().read().pllrdy());
    if locked {
        rcc.cfgr().modify(|w| w.set_sw(Sw::PLL1_P));
        if (0..PLL_POLLS).any(|_| rcc.cfgr().read().sws() == Sw::PLL1_P) {
            CLOCK_FAILED.store(false, Ordering::Relaxed);
            enable_css();
            return Some(source);
        }
        rcc.cfgr().modify(|w| w.set_sw(Sw::HSI));
    }
    rcc.cr().modify(|w| {
        w.set_pllon(false);
        w.set_hseon(false);
    });
    None
}

/// The chip runs on HSI (no HSE at boot, or a fail-over not yet undone).
pub fn on_hsi() -> bool {
    pac::RCC.cfgr().read().sws() == Sw::HSI
}

/// Set by the NMI when the clock security system switched the chip to HSI.
static CLOCK_FAILED: AtomicBool = AtomicBool::new(false);

/// Turn the clock security system on (with the HSE in use). If the HSE
/// stops, the hardware switches SYSCLK to HSI, turns the HSE and the PLL
/// off and raises the NMI (RM0390 §6.2.7): no reset, and since SYSCLK is
/// 16 MHz either way nothing else changes speed.
pub fn enable_css() {
    pac::RCC.cr().modify(|w| w.set_csson(true));
}

/// True once the clock security system has switched to HSI.
pub fn clock_failed() -> bool {
    CLOCK_FAILED.load(Ordering::Relaxed)
}

#[exception]
unsafe fn NonMaskableInt() {
    let rcc = pac::RCC;
    if rcc.cir().read().cssf() {
        // CSSF holds the NMI until cleared; the write must have reached
        // the RCC before the exception returns, or the NMI is taken again
        // (the bus write buffer: ARM's guidance on clearing interrupt
        // sources at the end of a handler).
        rcc.cir().modify(|w| w.set_cssc(true));
        cortex_m::asm::dsb();
        CLOCK_FAILED.store(true, Ordering::Relaxed);
    }
}

// ---- Brown-out level and supply ----

/// BOR level 3 (FLASH_OPTCR.BOR_LEV = 0b00): reset below ≈ 2.7 V (RM0390
/// §5.2.2, and the option bytes in §3.6). Set when the board is
/// provisioned (`firmware/README.md`, "Provisioning: the brown-out
/// level"); the firmware only reads it. The factory value is "off" (0b11:
/// only the ≈ 1.7 V power-on reset).
const BOR_LEVEL_3: u8 = 0b00;

/// True when the option bytes hold the provisioned brown-out level.
pub fn bor_level_set() -> bool {
    pac::FLASH.optcr().read().bor_lev() == BOR_LEVEL_3
}

/// PVD threshold PLS = 0b110: 2.8 V (RM0390 §5.4.1, PWR_CR.PLS).
const PVD_LEVEL_2V8: u8 = 0b110;

/// Turn the programmable voltage detector on (after `embassy_stm32::init`,
/// which resets the PWR block).
pub fn enable_pvd() {
    pac::RCC.apb1enr().modify(|w| w.set_pwren(true));
    pac::PWR.cr1().modify(|w| {
        w.set_pls(PVD_LEVEL_2V8);
        w.set_pvde(true);
    });
}

/// V_DD is below the PVD threshold (PWR_CSR.PVDO).
pub fn supply_low() -> bool {
    pac::PWR.csr1().read().pvdo()
}

// ---- Backup registers ----

/// First backup register of the panic record, and of the rule snapshot.
const PANIC_AT: usize = 0;
const RULE_AT: usize = PANIC_AT + boot::PANIC_WORDS;

/// Enable writes to the backup domain: the PWR clock, then PWR_CR.DBP
/// (RM0390 §5.1.2). Reads need neither.
fn backup_access() {
    pac::RCC.apb1enr().modify(|w| w.set_pwren(true));
    pac::PWR.cr1().modify(|w| w.set_dbp(true));
}

fn read_words<const N: usize>(first: usize) -> [u32; N] {
    core::array::from_fn(|i| pac::RTC.bkpr(first + i).read().bkp())
}

fn write_words(first: usize, words: &[u32]) {
    backup_access();
    for (i, w) in words.iter().enumerate() {
        pac::RTC.bkpr(first + i).write(|r| r.set_bkp(*w));
    }
}

// ---- Reset cause ----

/// Why the chip reset, from the RCC CSR flags (the library decides:
/// `boot::ResetCause::from_flags`); the flags are then cleared so the next
/// reset reports only its own cause. Readable before the clock setup.
pub fn take_reset_cause() -> boot::ResetCause {
    let rcc = pac::RCC;
    let csr = rcc.csr().read();
    let flags = boot::ResetFlags {
        low_power: csr.lpwrrstf(),
        window_watchdog: csr.wwdgrstf(),
        independent_watchdog: csr.wdgrstf(),
        software: csr.sftrstf(),
        power_on: csr.porrstf(),
        pin: csr.padrstf(),
        brown_out: csr.borrstf(),
    };
    rcc.csr().modify(|w| w.set_rmvf(true));
    boot::ResetCause::from_flags(flags)
}

/// The panic record's words.
pub fn panic_words() -> [u32; boot::PANIC_WORDS] {
    read_words(PANIC_AT)
}

/// Write the panic record's words.
pub fn set_panic_words(words: [u32; boot::PANIC_WORDS]) {
    write_words(PANIC_AT, &words);
}

/// The rule snapshot's words.
pub fn rule_words() -> [u32; boot::RULE_WORDS] {
    read_words(RULE_AT)
}

/// Write the rule snapshot's words.
pub fn set_rule_words(words: [u32; boot::RULE_WORDS]) {
    write_words(RULE_AT, &words);
}

// ---- Panics and faults ----

/// Record one more panic reset in a row at `line` and reset at once: the
/// next boot reports it, resumes the rule's state (the alarm output is
/// driven from the backup registers before anything else) and skips the
/// store's read after several unhealthy resets in a row.
fn record_and_reset(line: u32) -> ! {
    set_panic_words(boot::record_panic(panic_words(), line));
    cortex_m::peripheral::SCB::sys_reset()
}

/// Set by the first panic: a panic while logging it (the logger taken
/// twice) goes straight to the record and the reset.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    let line = info.location().map_or(0, |l| l.line());
    if !PANICKING.swap(true, Ordering::Relaxed) {
        // RTT never blocks (defmt-rtt `disable-blocking-mode`): with no
        // probe this costs nothing.
        defmt::error!("panic at line {}: resetting", line);
    }
    record_and_reset(line)
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    record_and_reset(0)
}
