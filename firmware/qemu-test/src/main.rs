//! The firmware's hardware-free logic (`fois_firmware`, no embassy) on an
//! emulated Cortex-M4F: QEMU `mps2-an386`, semihosting for output and the
//! exit code, `-icount shift=0` for exact, repeatable instruction counts.
//!
//! 1. Tests: NTC/VREFINT maths on the real FPU, the persisted record, the
//!    flash store (sequential-storage through `block_on` on a RAM flash, with
//!    a power cut mid-save), the ice rule, and the whole `Node` on a
//!    simulated board (currents, ambient flicker, ice onset → alarm pin +
//!    event, commands in, garbage in), and the bootloader's swap and
//!    rollback (`boot_swap`).
//! 2. A measurement loop that counts the instructions of one output frame:
//!    SysTick runs from the core clock and QEMU drives it from the virtual
//!    clock, which under `-icount shift=0` advances exactly 1 ns per guest
//!    instruction. The instructions per SysTick tick are first measured on a
//!    loop of known length (2 instructions per iteration), then the node runs
//!    F and 2F frames and the difference divided by F is one frame's cost
//!    (start-up costs cancel).
#![no_std]
#![no_main]

use core::cell::Cell;
use core::convert::Infallible;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hprintln};
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use fois_firmware::estimator::Estimator;
use fois_firmware::hal::{BoardInfo, FactoryCal, PhotoAdc};
use fois_firmware::ice_rule::{Rule, RuleInput};
use fois_firmware::measure::{ntc, vref};
use fois_firmware::node::Node;
use fois_firmware::sim_board::{self, SimBoard};
use fois_firmware::storage::flash_store::FlashStore;
use fois_firmware::storage::ram_flash::{PowerCut, RamFlash};
use fois_firmware::storage::record;
use fois_firmware::storage::{MemStorage, Storage};
use fois_protocol::{
    Ack, AckResult, Command, Config, DetectorState, DeviceFrame, DeviceMsg, ErrorCode, ErrorReply,
    EventKind, FrameDecoder, HostFrame, MAX_FRAME, encode, flags,
};

mod update_bench;

// ---------------------------------------------------------------- timing --

static WRAPS: AtomicU32 = AtomicU32::new(0);
const RELOAD: u32 = 0x00FF_FFFF;

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// SysTick ticks since start (24-bit counter + wrap count).
fn ticks() -> u64 {
    loop {
        let w1 = WRAPS.load(Ordering::Relaxed);
        let cur = SYST::get_current();
        let w2 = WRAPS.load(Ordering::Relaxed);
        if w1 == w2 {
            return u64::from(w1) * u64::from(RELOAD + 1) + u64::from(RELOAD - cur);
        }
    }
}

/// Exactly `2 * n` instructions (subs + bne per iteration).
#[inline(never)]
fn known_loop(n: u32) {
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {0}, {0}, #1",
            "bne 2b",
            inout(reg) n => _,
            options(nomem, nostack),
        );
    }
}

// ------------------------------------------------------- simulated board --

// The firmware's scripted board (`fois_firmware::sim_board`, the same one the
// host tests use), borrowed by the node's ADC, pins and delay.
type SimNode<'a> = sim_board::SimNode<&'a SimBoard, MemStorage>;

fn sim_node(w: &SimBoard, storage: MemStorage) -> SimNode<'_> {
    sim_board::sim_node(w, storage, "qemu")
}

/// Collects what a node sends and decodes it.
struct Sink {
    dec: FrameDecoder<MAX_FRAME>,
    frames: [Option<DeviceFrame>; 8],
    n: usize,
    bad: u32,
}

impl Sink {
    fn new() -> Self {
        Sink {
            dec: FrameDecoder::new(),
            frames: Default::default(),
            n: 0,
            bad: 0,
        }
    }
    fn push(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.dec.push::<DeviceFrame>(b) {
                Some(Ok(f)) => {
                    if let Some(slot) = self.frames.get_mut(self.n) {
                        *slot = Some(f);
                    }
                    self.n += 1;
                }
                Some(Err(_)) => self.bad += 1,
                None => {}
            }
        }
    }
    fn take(&mut self) -> impl Iterator<Item = DeviceMsg> + '_ {
        self.n = 0;
        self.frames
            .iter_mut()
            .filter_map(|f| f.take().map(|f| f.msg))
    }
}

/// One frame; the clock then moves to the end of the frame period.
fn step(node: &mut SimNode<'_>, w: &SimBoard, sink: &mut Sink) {
    w.run_frame(node, &mut |b| sink.push(b));
}

fn measurement(sink: &mut Sink) -> Option<fois_protocol::Measurement> {
    sink.take().find_map(|m| match m {
        DeviceMsg::MeasurementV5(m) => Some(m.measurement),
        _ => None,
    })
}

// ------------------------------------------------------------------ tests --

type TestResult = Result<(), &'static str>;
type Test = (&'static str, fn() -> TestResult);

macro_rules! check {
    ($cond:expr, $($fmt:tt)+) => {
        if !$cond {
            hprintln!("    check failed: {}", stringify!($cond));
            hprintln!($($fmt)+);
            return Err(stringify!($cond));
        }
    };
}

// After `check!`, which it uses.
mod boot_swap;

fn t_ntc_and_vref() -> TestResult {
    let cases: [(u16, i16); 4] = [(3337, -500), (3156, 0), (2997, 400), (2738, 1_000)];
    for (code, want) in cases {
        let ntc::NtcReading::Ok(t) = ntc::temperature(code) else {
            return Err("NTC read as a fault");
        };
        check!(
            (t - want).abs() <= 8,
            "    code {} -> {} (want {})",
            code,
            t,
            want
        );
    }
    check!(ntc::temperature(4095) == ntc::NtcReading::Open, "    open");
    check!(ntc::temperature(0) == ntc::NtcReading::Short, "    short");
    let cal = FactoryCal::TYPICAL;
    check!(vref::vdda_mv(&cal, cal.vrefint_cal) == 3_300, "    vdda");
    let v = vref::vdda_mv(&cal, 1652);
    check!((2_995..=3_005).contains(&v), "    vdda at 3.0 V: {}", v);
    Ok(())
}

fn t_persist() -> TestResult {
    let rec = record::Record {
        config: Config {
            onset_rise_na: 1_500,
            ..Config::default()
        },
        baseline: Some(fois_protocol::Baseline {
            i1_na: 12,
            i2_na: -3,
        }),
        gain: Some(fois_protocol::GainEstimate {
            gain_ppm: 870_000,
            sigma_ppm: 26_100,
        }),
        gain_calibration: None,
        link: fois_protocol::LinkSettings::default(),
    };
    let mut buf = [0u8; record::MAX_RECORD];
    let n = record::encode(&rec, &mut buf);
    check!(
        record::decode(buf.get(..n).unwrap_or(&[])) == Ok(rec.clone()),
        "    round trip"
    );
    for i in 0..n {
        let mut b = buf;
        b[i] ^= 0x04;
        check!(
            record::decode(&b[..n]).is_err(),
            "    flip in byte {} accepted",
            i
        );
    }
    check!(
        record::decode(&[0xFF; 32]) == Err(record::LoadError::Empty),
        "    erased"
    );
    Ok(())
}

/// The config store as the board runs it: sequential-storage's async map
/// driven by `block_on` over a blocking flash, here 2 × 1 KiB of RAM. Saves
/// go round both pages; a power cut in the middle of a save leaves the old
/// record, and the store saves again after the "reboot".
fn t_flash_store() -> TestResult {
    static mut MEM: [u8; 2048] = [0xFF; 2048];
    // SAFETY: the only reference to MEM, taken once in this test.
    let mem: &'static mut [u8; 2048] = unsafe { &mut *core::ptr::addr_of_mut!(MEM) };
    let flash: RamFlash<&mut [u8], 1024, 2> = RamFlash::new(&mut mem[..]);
    let Ok(mut st) = FlashStore::new(flash, 0..2048) else {
        check!(false, "    layout");
        return Ok(());
    };
    let mut buf = [0u8; record::MAX_RECORD];
    check!(st.read(&mut buf) == Ok(0), "    erased = empty");
    let record = |k: u32| {
        let rec = record::Record {
            config: Config {
                onset_rise_na: 1_000 + k,
                ..Config::default()
            },
            baseline: None,
            gain: None,
            gain_calibration: None,
            link: fois_protocol::LinkSettings::default(),
        };
        let mut b = [0u8; record::MAX_RECORD];
        let n = record::encode(&rec, &mut b);
        (b, n)
    };
    let mut saved = 0;
    let depth = stack_depth_of(|| {
        for k in 0..60 {
            let (b, n) = record(k);
            saved += usize::from(st.write(&b[..n]).is_ok());
        }
    });
    STORE_SAVE_STACK.store(depth, core::sync::atomic::Ordering::Relaxed);
    check!(saved == 60, "    saved {} of 60", saved);
    let mut flash = st.into_flash();
    check!(
        flash.counters().erases >= 2,
        "    erases {}",
        flash.counters().erases
    );
    // Cut 20 bytes into the next save.
    flash.cut_power(PowerCut::AfterBytes(20));
    let Ok(mut st) = FlashStore::new(flash, 0..2048) else {
        return Ok(());
    };
    let (b, n) = record(60);
    check!(st.write(&b[..n]).is_err(), "    the cut save failed");
    let mut flash = st.into_flash();
    flash.power_on();
    let Ok(mut st) = FlashStore::new(flash, 0..2048) else {
        return Ok(());
    };
    let (old, n_old) = record(59);
    let got = st.read(&mut buf);
    check!(
        got == Ok(n_old) && buf[..n_old] == old[..n_old],
        "    old record after the cut: {:?}",
        got
    );
    check!(st.write(&b[..n]).is_ok(), "    saves again");
    let got = st.read(&mut buf);
    check!(got == Ok(n) && buf[..n] == b[..n], "    new record");
    Ok(())
}

fn t_rule() -> TestResult {
    let c = Config::default();
    let cold = RuleInput {
        rise1_na: c.onset_rise_na as i32 + 1,
        temperature_centi_c: c.freeze_limit_centi_c,
        air_known: true,
        valid: true,
    };
    let mut r = Rule::new();
    for _ in 1..c.onset_frames {
        check!(r.step(&c, cold).is_none(), "    fired early");
    }
    let t = r.step(&c, cold);
    check!(
        t.map(|t| t.kind) == Some(EventKind::IceOnset),
        "    no onset at N"
    );
    // One field wrong: 0.01 °C warmer → wet.
    let mut r = Rule::new();
    let warm = RuleInput {
        temperature_centi_c: c.freeze_limit_centi_c + 1,
        ..cold
    };
    let mut kinds = [None; 2];
    for _ in 0..c.onset_frames {
        if let Some(t) = r.step(&c, warm) {
            kinds[0] = Some(t.kind);
        }
    }
    check!(
        kinds[0] == Some(EventKind::WetOnset),
        "    warm film not wet"
    );
    Ok(())
}

fn t_node_currents_and_commands() -> TestResult {
    let w = SimBoard::new();
    let mut node = sim_node(&w, MemStorage::new());
    let mut sink = Sink::new();
    w.set(|s| {
        s.signal_na = [12_000.0, 4_000.0];
        s.ambient_na = [30_000.0, 5_000.0];
    });
    step(&mut node, &w, &mut sink);
    let Some(m) = measurement(&mut sink) else {
        return Err("no measurement");
    };
    check!((m.i1_na - 12_000).abs() <= 81, "    i1 {}", m.i1_na);
    check!((m.i2_na - 4_000).abs() <= 81, "    i2 {}", m.i2_na);
    check!(
        (m.ambient1_na as i32 - 30_000).abs() <= 81,
        "    amb1 {}",
        m.ambient1_na
    );
    check!(
        (m.temperature_centi_c - 1_000).abs() <= 8,
        "    temp {}",
        m.temperature_centi_c
    );
    check!(m.flags == flags::NO_BASELINE, "    flags {:#x}", m.flags);

    // A command, split in two chunks, is answered.
    let mut wire = [0u8; MAX_FRAME];
    let n = encode(
        &HostFrame {
            id: 5,
            cmd: Command::GetConfig,
        },
        &mut wire,
    )
    .unwrap_or(0);
    let (a, b) = wire.split_at(n / 2);
    node.handle_rx(a, 0, &mut |x| sink.push(x));
    node.handle_rx(b.get(..n - n / 2).unwrap_or(&[]), 0, &mut |x| sink.push(x));
    let got = sink.take().next();
    check!(
        got == Some(DeviceMsg::Ack(Ack {
            id: 5,
            result: AckResult::ConfigV3(Config::default())
        })),
        "    {:?}",
        got
    );
    // Garbage is answered with an error and the measurement goes on.
    node.handle_rx(&[0x42, 0x42, 0x00], 0, &mut |x| sink.push(x));
    let got = sink.take().next();
    check!(
        got == Some(DeviceMsg::Error(ErrorReply {
            id: None,
            code: ErrorCode::Garbled
        })),
        "    {:?}",
        got
    );
    step(&mut node, &w, &mut sink);
    check!(measurement(&mut sink).is_some(), "    measuring stopped");
    check!(sink.bad == 0, "    the node sent a bad frame");
    Ok(())
}

fn t_node_ice_onset_drives_the_alarm() -> TestResult {
    let w = SimBoard::new();
    let mut node = sim_node(&w, MemStorage::new());
    let mut sink = Sink::new();
    w.set(|s| {
        s.ntc_code = Some(3194); // -1 °C
        s.signal_na = [2_500.0, 800.0];
    });
    let n = node.config().onset_frames;
    for i in 1..=n {
        step(&mut node, &w, &mut sink);
        let mut onset = false;
        for msg in sink.take() {
            if let DeviceMsg::Event(e) = msg {
                onset = e.kind == EventKind::IceOnset && e.frames == n;
            }
        }
        check!(onset == (i == n), "    frame {}: onset {}", i, onset);
    }
    check!(node.state() == DetectorState::Ice, "    state");
    check!(w.alarm.get() && w.indicator.get(), "    alarm pins");
    Ok(())
}

fn t_flicker_bound() -> TestResult {
    // 50 µA DC + 25 µA at 100 Hz: |ΔI| ≤ A·(2πfΔ)²/2 + 1 LSB = 309 nA.
    let w = SimBoard::new();
    let mut node = sim_node(&w, MemStorage::new());
    let mut sink = Sink::new();
    w.set(|s| s.signal_na = [5_000.0, 1_500.0]);
    step(&mut node, &w, &mut sink);
    let Some(dark) = measurement(&mut sink) else {
        return Err("no measurement");
    };
    let mut worst = 0i32;
    for k in 0..16 {
        let w = SimBoard::new();
        let mut node = sim_node(&w, MemStorage::new());
        w.set(|s| {
            s.signal_na = [5_000.0, 1_500.0];
            s.ambient_na = [50_000.0, 50_000.0];
            s.flicker_na = [25_000.0; 2];
            s.flicker_phase = f64::from(k) * core::f64::consts::TAU / 16.0;
        });
        for _ in 0..2 {
            step(&mut node, &w, &mut sink);
            let Some(m) = measurement(&mut sink) else {
                return Err("no measurement");
            };
            worst = worst
                .max((m.i1_na - dark.i1_na).abs())
                .max((m.i2_na - dark.i2_na).abs());
        }
    }
    hprintln!(
        "    flicker 25 uA at 100 Hz: worst |dI| = {} nA (bound 309 nA)",
        worst
    );
    check!(worst <= 309, "    worst {}", worst);
    Ok(())
}

// -------------------------------------------------------------- benchmark --

// The benchmark's own fakes, not the simulated board: the count must be the
// node's work, so the ADC is a few integer operations and the pins and the
// delay do nothing but store a level.

struct Pin<'a>(&'a Cell<bool>);
impl ErrorType for Pin<'_> {
    type Error = Infallible;
}
impl OutputPin for Pin<'_> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.set(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.set(true);
        Ok(())
    }
}

struct BenchAdc<'a> {
    led: &'a Cell<bool>,
    lcg: u32,
}

impl PhotoAdc for BenchAdc<'_> {
    fn read_photo(&mut self) -> [u16; 2] {
        self.lcg = self.lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = (self.lcg >> 29) as u16; // 0..7 codes
        let on = if self.led.get() { 150 } else { 0 };
        [400 + on + noise, 200 + on / 3 + noise]
    }
    fn read_ntc(&mut self) -> u16 {
        3194
    }
    fn read_vrefint(&mut self) -> u16 {
        FactoryCal::TYPICAL.vrefint_cal
    }
    fn read_internal_temp(&mut self) -> u16 {
        FactoryCal::TYPICAL.ts_cal1
    }
}

struct NoDelay;
impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// The estimator's budget: instructions per second of operation.
const ESTIMATOR_BUDGET_PER_S: u32 = 600_000;

/// Ticks for `frames` steps of the ice estimator alone (10 Hz frames, rime
/// at ~5 mm: I1 ≈ 25.2 µA, I2 ≈ 9.6 µA with a little noise, −8 °C).
fn bench_estimator(est: &mut Estimator, frames: u32, lcg: &mut u32) -> u64 {
    let t0 = ticks();
    for _ in 0..frames {
        *lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let n = ((*lcg >> 24) as f32 - 128.0) * 1e-3; // ±0.13 µA
        let _ = est.step(0.1, Some([25.2 + n, 9.6 - n]), Some(-8.0));
    }
    ticks() - t0
}

fn t_estimator_rime_and_bad_input() -> TestResult {
    // A calibrated gain (with the gain unknown, rime's mean at 5 mm reads
    // like 10 mm at 0.86× the gain: a wide σ, tested on the host).
    let mut est = Estimator::default();
    est.set_gain_prior(1.0, 0.01);
    check!(
        est.step(0.0, Some([f32::NAN, 1.0]), Some(-8.0)).is_none(),
        "    NaN gave an estimate"
    );
    // Rime at ~5 mm (the table's mean), 60 s of 10 Hz frames.
    let mut last = None;
    for _ in 0..600 {
        last = est.step(0.1, Some([25.17, 9.64]), Some(-8.0));
    }
    let Some(e) = last else {
        return Err("no estimate");
    };
    hprintln!(
        "    rime mean at 5 mm: {} ± {} um, {:?} ({} permille)",
        e.thickness_um,
        e.sigma_um,
        e.medium,
        e.probability_permille
    );
    check!(
        e.medium == fois_protocol::Medium::Rime && e.probability_permille > 900,
        "    medium {:?}",
        e
    );
    check!(
        (e.thickness_um as i32 - 5_000).abs() < 600 && e.sigma_um < 800,
        "    thickness {:?}",
        e
    );
    Ok(())
}

/// Ticks for `frames` frames of a streaming node with the default config.
fn bench<P: FnMut(&[u8])>(
    node: &mut Node<BenchAdc<'_>, Pin<'_>, Pin<'_>, Pin<'_>, NoDelay, MemStorage>,
    frames: u32,
    tx: &mut P,
) -> u64 {
    let t0 = ticks();
    for i in 0..frames {
        node.run_frame(u64::from(i) * 100, tx);
    }
    ticks() - t0
}

/// The stack below `main`'s frame is painted with this before the runs.
const STACK_PAINT: u32 = 0x5A5A_A5A5;
/// How far below `main`'s frame the paint reaches, bytes.
const STACK_PAINT_SPAN: usize = 32 * 1024;
/// The painting function's own frame is left unpainted, bytes.
const STACK_PAINT_SKIP: usize = 512;

/// Paint the stack from `sp` − [`STACK_PAINT_SPAN`] up to `sp` −
/// [`STACK_PAINT_SKIP`] (the RAM of mps2-an386 is 1 MiB: nothing else lives
/// there).
#[inline(never)]
fn paint_stack(sp: usize) {
    let mut a = sp - STACK_PAINT_SPAN;
    while a < sp - STACK_PAINT_SKIP {
        // SAFETY: an aligned word of RAM below the live stack, which no
        // other data uses (statics sit at the bottom of the 1 MiB RAM).
        unsafe { core::ptr::write_volatile(a as *mut u32, STACK_PAINT) };
        a += 4;
    }
}

/// The deepest the stack went below `sp` since [`paint_stack`], bytes.
fn stack_high_water(sp: usize) -> usize {
    let mut a = sp - STACK_PAINT_SPAN;
    // SAFETY: as in `paint_stack`: read only.
    while a < sp - STACK_PAINT_SKIP
        && unsafe { core::ptr::read_volatile(a as *const u32) } == STACK_PAINT
    {
        a += 4;
    }
    sp - a
}

/// How deep `f` takes the stack below the caller's frame, bytes.
#[inline(never)]
fn stack_depth_of(f: impl FnOnce()) -> usize {
    let sp = cortex_m::register::msp::read() as usize;
    paint_stack(sp);
    f();
    stack_high_water(sp)
}

/// The deepest flash store save measured in `t_flash_store`, bytes.
static STORE_SAVE_STACK: core::sync::atomic::AtomicUsize = core::sync::atomic::AtomicUsize::new(0);

#[entry]
fn main() -> ! {
    // main's frame holds the node and the estimators of the benches; the
    // stack below it is painted before the node's frames and before the
    // estimator's worst seconds: what they overwrite is their deepest call
    // path (the tests before build nodes on their own stacks; the board
    // keeps its node in a static).
    let sp = cortex_m::register::msp::read() as usize;
    let mut cp = match cortex_m::Peripherals::take() {
        Some(cp) => cp,
        None => fail("core peripherals taken"),
    };
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(RELOAD);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();

    let tests: [Test; 9] = [
        ("ntc_and_vref", t_ntc_and_vref),
        ("persist", t_persist),
        ("flash_store", t_flash_store),
        ("rule", t_rule),
        ("node_currents_and_commands", t_node_currents_and_commands),
        (
            "node_ice_onset_drives_the_alarm",
            t_node_ice_onset_drives_the_alarm,
        ),
        ("flicker_bound", t_flicker_bound),
        (
            "estimator_rime_and_bad_input",
            t_estimator_rime_and_bad_input,
        ),
        (
            "bootloader_swap_and_rollback",
            boot_swap::t_bootloader_swap_and_rollback,
        ),
    ];
    hprintln!("running {} tests on the emulated Cortex-M4F", tests.len());
    let mut failed = 0;
    for (name, f) in tests {
        match f() {
            Ok(()) => hprintln!("test {} ... ok", name),
            Err(e) => {
                hprintln!("test {} ... FAILED ({})", name, e);
                failed += 1;
            }
        }
    }
    hprintln!(
        "test result: {}. {} passed; {} failed",
        if failed == 0 { "ok" } else { "FAILED" },
        tests.len() - failed,
        failed
    );

    // Instructions per SysTick tick, from a loop of known length.
    const LOOP: u32 = 2_000_000;
    let t0 = ticks();
    known_loop(LOOP);
    let t_loop = ticks() - t0;
    let t0 = ticks();
    known_loop(2 * LOOP);
    let t_loop2 = ticks() - t0;
    let loop_ticks = t_loop2.saturating_sub(t_loop).max(1); // 2·LOOP instructions
    let insn_per_tick = (2 * LOOP) as f32 / loop_ticks as f32;
    hprintln!(
        "SysTick calibration: {} instructions in {} ticks = {} instructions per tick",
        2 * LOOP,
        loop_ticks,
        insn_per_tick
    );

    // The bootloader's swap and rollback of one 128 KiB page (RAM flash).
    let insn = |t: u32| (t as f32 * insn_per_tick + 0.5) as u64;
    hprintln!(
        "bootloader swap of a 128 KiB image: {} instructions; rollback: {} instructions (RAM flash, 2 KiB copy buffer)",
        insn(boot_swap::SWAP_TICKS.load(Ordering::Relaxed)),
        insn(boot_swap::REVERT_TICKS.load(Ordering::Relaxed))
    );

    // The measurement loop: default config (K = 8), streaming, frames encoded.
    let led = Cell::new(false);
    let (alarm, ind) = (Cell::new(false), Cell::new(false));
    let mut node = Node::new(
        BenchAdc { led: &led, lcg: 1 },
        Pin(&led),
        Pin(&alarm),
        Pin(&ind),
        NoDelay,
        MemStorage::new(),
        BoardInfo::simulated("qemu"),
    );
    let mut bytes = 0usize;
    let mut tx = |b: &[u8]| bytes += b.len();
    paint_stack(sp);
    bench(&mut node, 10, &mut tx); // warm-up
    const F: u32 = 200;
    let t_f = bench(&mut node, F, &mut tx);
    let t_2f = bench(&mut node, 2 * F, &mut tx);
    let frame_ticks = t_2f.saturating_sub(t_f) as f32 / F as f32;
    let stack_node = stack_high_water(sp);
    let per_frame = (frame_ticks * insn_per_tick + 0.5) as u32;
    hprintln!(
        "measurement loop: K = {} cycles/frame, {} and {} frames, {} bytes sent",
        node.config().cycles_per_frame,
        F,
        2 * F,
        bytes
    );
    hprintln!("instructions per frame: {}", per_frame);
    // At 16 MHz (the board's HSI clock, ~1 instruction/cycle) that is this
    // many µs of CPU per frame, beside the 17 settle waits.
    hprintln!("  (about {} us of CPU per frame at 16 MHz)", per_frame / 16);

    // The ice estimator's share: its step alone, F and 2F frames.
    let mut est = Estimator::default();
    let mut lcg = 7u32;
    bench_estimator(&mut est, 10, &mut lcg); // warm-up (initialised)
    let e_f = bench_estimator(&mut est, F, &mut lcg);
    let e_2f = bench_estimator(&mut est, 2 * F, &mut lcg);
    let est_frame = ((e_2f.saturating_sub(e_f) as f32 / F as f32) * insn_per_tick + 0.5) as u32;
    hprintln!(
        "estimator instructions per step: {} (mean over 10 Hz frames, one update a second: {} per second of operation, budget {})",
        est_frame,
        est_frame * 10,
        ESTIMATOR_BUDGET_PER_S
    );
    // Worst case: every state alive (a weak signal that several media at
    // several thicknesses explain, after a long gap that spread the
    // posterior over the grid), then 10 Hz frames of the same signal.
    let mut est = Estimator::default();
    let _ = est.step(0.0, Some([0.4, 0.5]), Some(0.0));
    for _ in 0..20 {
        let _ = est.step(3_600.0, None, Some(0.0));
    }
    // Two windows of the change look, the second a frame short: its change
    // is weighed within the seconds measured (the history's parts with it).
    let window_s = est.params().history.change_window_s;
    let _ = est.step(window_s, Some([0.4, 0.5]), Some(0.0));
    let _ = est.step(window_s - 0.1, Some([0.4, 0.5]), Some(0.0));
    let mut worst = 0u32;
    let mut alive = 0usize;
    paint_stack(sp);
    // 48 seconds: more than one period of the growth history, whose parts
    // (the change look's among them) fall in different seconds.
    for _ in 0..48 {
        // One second of 10 Hz frames: nine gathered, one update of the bank.
        let t0 = ticks();
        for _ in 0..10 {
            let _ = est.step(0.1, Some([0.4, 0.5]), Some(0.0));
        }
        let t = ((ticks() - t0) as f32 * insn_per_tick) as u32;
        worst = worst.max(t);
        let (dry, cells) = est.cells();
        alive = usize::from(dry > 0.0) + cells.iter().flatten().filter(|c| **c > 0.0).count();
    }
    hprintln!(
        "estimator worst case: {} instructions per second of 10 Hz frames ({} of {} states alive in the likeliest of {} gain hypotheses; ±1 tick = ±40)",
        worst,
        alive,
        1 + 3 * fois_firmware::estimator::ROWS,
        fois_firmware::estimator::GAINS
    );
    hprintln!(
        "stack high-water mark below main's frame: {} bytes in the node's frames (610), {} bytes in the estimator's worst seconds (48)",
        stack_node,
        stack_high_water(sp)
    );
    if est_frame * 10 > ESTIMATOR_BUDGET_PER_S || worst > ESTIMATOR_BUDGET_PER_S {
        hprintln!("error: the estimator is over its budget");
        failed += 1;
    }

    // The firmware updater: a chunk, the verify and the commit of a 90 KiB image.
    if !update_bench::run(insn_per_tick) {
        hprintln!("error: the update bench failed");
        failed += 1;
    }

    // What the board's 32 KiB part must leave above its statics (memory.x).
    hprintln!(
        "stack depth: a flash store save {} B (below the caller's frame)",
        STORE_SAVE_STACK.load(core::sync::atomic::Ordering::Relaxed)
    );

    if failed == 0 && per_frame > 0 && est_frame > 0 {
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::bkpt();
    }
}

fn fail(msg: &str) -> ! {
    hprintln!("error: {}", msg);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::bkpt();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::bkpt();
    }
}
