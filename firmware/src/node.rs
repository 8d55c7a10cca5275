//! The whole node behind the hardware traits: measurement, the ice rule,
//! outputs, persistence and the command link. The board binary, the host's
//! virtual node and the HIL suite all drive this same type.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{
    Ack, AckResult, Baseline, Command, Config, ConfigV1, DetectorState, DeviceFrame, DeviceMsg,
    ErrorCode, ErrorReply, Event, EventKind, FrameDecoder, GainEstimate, GainTarget, Hello,
    HostFrame, MAX_FRAME, Measurement, MeasurementV3, PROTOCOL_VERSION, encode, flags,
};

use crate::boot::RuleSnapshot;
use crate::dark_cal;
use crate::dispatch::{self, BUTTON_ID};
use crate::estimator::{Estimator, EstimatorParams};
use crate::gain_cal;
use crate::hal::{BoardInfo, PhotoAdc, Storage};
use crate::measure::{self, Currents};
use crate::ntc::{self, NtcReading};
use crate::persist::{self, LoadError, MAX_RECORD, Record};
use crate::rule::{Rule, RuleInput};
use crate::supply;
use crate::vref;

/// Firmware version sent in [`Hello`] (the crate's version).
pub const FIRMWARE_VERSION: [u8; 3] = [
    parse_u8(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_u8(env!("CARGO_PKG_VERSION_MINOR")),
    parse_u8(env!("CARGO_PKG_VERSION_PATCH")),
];

const fn parse_u8(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut i = 0;
    let mut v: u8 = 0;
    while i < b.len() {
        v = v.wrapping_mul(10).wrapping_add(b[i].wrapping_sub(b'0'));
        i += 1;
    }
    v
}

/// A change is saved once no further change came for this long, ms: a burst
/// of config changes and calibrations is one flash write.
pub const SAVE_QUIET_MS: u64 = 1_000;
/// ... but at most this long after the first unsaved change, ms.
pub const SAVE_MAX_DELAY_MS: u64 = 10_000;
/// Saves (and retries after a failed one) are at least this far apart, ms:
/// at most 8 640 a day, whatever a host sends (wear: `firmware/README.md`).
pub const SAVE_MIN_INTERVAL_MS: u64 = 10_000;

/// An unsaved change: when the first and the last one came.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PendingSave {
    first_ms: u64,
    last_ms: u64,
}

/// Everything one frame measured (also what a [`Measurement`] carries).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameValues {
    /// Net and ambient currents.
    pub currents: Currents,
    /// Air temperature, 0.01 °C.
    pub temperature_centi_c: i16,
    /// Temperature of the optoelectronics (the MCU's internal sensor: the
    /// LED and the phototransistors sit beside it), 0.01 °C.
    pub optics_centi_c: i16,
    /// V_DDA, mV (as measured).
    pub vdda_mv: u16,
    /// Measurement flags (validity, NTC, V_DDA); node flags are added later.
    pub flags: u16,
}

/// The node. Type parameters: ADC, LED (PB0), alarm output (PA9), indicator
/// (LD2, PA5), delay (settle waits), storage (config + baseline record).
pub struct Node<A, L, AL, IND, D, S>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
{
    adc: A,
    led: L,
    alarm: AL,
    indicator: IND,
    delay: D,
    storage: S,
    info: BoardInfo,
    config: Config,
    baseline: Option<Baseline>,
    config_defaulted: bool,
    storage_failed: bool,
    clock_fallback: bool,
    /// Boot faults the board found (`BOR_NOT_SET`, `STORE_SKIPPED`).
    boot_faults: u16,
    /// The PVD reports V_DD below its threshold: saves wait.
    supply_low: bool,
    /// A panic reset to report once: (line, resets in a row).
    panic_report: Option<(u32, u8)>,
    /// The record the storage holds, as far as the node knows.
    stored: Option<Record>,
    pending_save: Option<PendingSave>,
    last_save_ms: Option<u64>,
    rule: Rule,
    seq: u32,
    streaming: bool,
    stream_period_ms: Option<u32>,
    decoder: FrameDecoder<MAX_FRAME>,
    reported_faults: u16,
    reset_request: bool,
    last: Option<Measurement>,
    estimator: Estimator,
    last_frame_ms: Option<u64>,
    /// The learned gain as stored (at the temperature model's reference).
    gain_kept: Option<GainEstimate>,
    /// The last gain calibration against a target.
    gain_calibration: Option<GainEstimate>,
    /// `GAIN_OUT_OF_BAND` is raised (with hysteresis).
    gain_out_of_band: bool,
    /// When the learned gain was last considered for a save, ms.
    gain_checked_ms: u64,
}

impl<A, L, AL, IND, D, S> Node<A, L, AL, IND, D, S>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
{
    /// Build the node: loads config + baseline from `storage`. An empty store
    /// gives the defaults; a corrupt or old record, or a store that cannot
    /// be read, gives the defaults and the `CONFIG_DEFAULTED` fault. The LED
    /// and the outputs start off.
    pub fn new(
        adc: A,
        led: L,
        alarm: AL,
        indicator: IND,
        delay: D,
        mut storage: S,
        info: BoardInfo,
    ) -> Self {
        let mut buf = [0xFFu8; MAX_RECORD];
        let loaded = match storage.read(&mut buf) {
            Ok(n) => persist::decode(buf.get(..n).unwrap_or(&[])),
            Err(_) => Err(LoadError::Corrupt),
        };
        let (stored, config_defaulted) = match loaded {
            Ok(r) => (Some(r), false),
            Err(LoadError::Empty) => (None, false),
            Err(_) => (None, true),
        };
        let (config, baseline, gain_kept, gain_calibration) = match &stored {
            Some(r) => (r.config.clone(), r.baseline, r.gain, r.gain_calibration),
            None => (Config::default(), None, None, None),
        };
        let info = BoardInfo {
            cal: info.cal.or_typical(),
            ..info
        };
        let mut node = Node {
            adc,
            led,
            alarm,
            indicator,
            delay,
            storage,
            info,
            streaming: config.stream_on_boot,
            config,
            baseline,
            config_defaulted,
            storage_failed: false,
            clock_fallback: false,
            boot_faults: 0,
            supply_low: false,
            panic_report: None,
            stored,
            pending_save: None,
            last_save_ms: None,
            rule: Rule::new(),
            seq: 0,
            stream_period_ms: None,
            decoder: FrameDecoder::new(),
            reported_faults: 0,
            reset_request: false,
            last: None,
            estimator: Estimator::default(),
            last_frame_ms: None,
            gain_kept,
            gain_calibration,
            gain_out_of_band: false,
            gain_checked_ms: 0,
        };
        node.start_estimator();
        let _ = node.led.set_low();
        node.drive_outputs();
        node
    }

    /// Who this node is.
    pub fn hello(&self) -> Hello {
        Hello {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FIRMWARE_VERSION,
            board: Hello::board_from_str(self.info.board),
            unique_id: self.info.unique_id,
            reset_reason: self.info.reset_reason,
        }
    }

    /// Send a `Hello` frame.
    pub fn send_hello(&mut self, tx: &mut impl FnMut(&[u8])) {
        let hello = self.hello();
        self.send(DeviceMsg::Hello(hello), tx);
    }

    /// One output frame: K LED-off/LED-on cycles (settle waits through the
    /// delay), currents, temperature, V_DDA, the ice rule, the outputs, the
    /// ice estimator. Sends a `MeasurementV3` (the measurement with the
    /// estimate) if streaming, then any `Event`s (rule transition first, then
    /// faults raised/cleared).
    pub fn run_frame(&mut self, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let values = self.measure_frame();
        let rise1 = self.rise1(values.currents.net_na[0]);
        let valid = values.flags & flags::INVALID_MASK == 0;
        let air_known = values.flags & (flags::NTC_OPEN | flags::NTC_SHORT) == 0;
        let estimate = self.estimate(now_ms, &values, rise1, valid);
        self.track_gain(now_ms);
        let transition = self.rule.step(
            &self.config,
            RuleInput {
                rise1_na: rise1,
                temperature_centi_c: values.temperature_centi_c,
                air_known,
                valid,
            },
        );
        self.drive_outputs();
        let flags = values.flags | self.node_flags();
        let m = Measurement {
            uptime_ms: now_ms,
            i1_na: values.currents.net_na[0],
            i2_na: values.currents.net_na[1],
            ambient1_na: values.currents.ambient_na[0],
            ambient2_na: values.currents.ambient_na[1],
            temperature_centi_c: values.temperature_centi_c,
            vdda_mv: values.vdda_mv,
            flags,
            state: self.rule.state(),
        };
        if self.streaming {
            let msg = MeasurementV3 {
                measurement: m.clone(),
                estimate,
                gain: self.gain_estimate(),
            };
            self.send(DeviceMsg::MeasurementV3(msg), tx);
        }
        let event = |kind: EventKind, frames: u16| Event {
            uptime_ms: now_ms,
            kind,
            i1_na: m.i1_na,
            i2_na: m.i2_na,
            rise1_na: rise1,
            temperature_centi_c: m.temperature_centi_c,
            frames,
        };
        if let Some(t) = transition {
            self.send(DeviceMsg::Event(event(t.kind, t.frames)), tx);
        }
        let faults = flags & flags::FAULT_MASK;
        let raised = faults & !self.reported_faults;
        let cleared = self.reported_faults & !faults;
        if raised != 0 {
            self.send(
                DeviceMsg::Event(event(EventKind::FaultRaised(raised), 1)),
                tx,
            );
        }
        if cleared != 0 {
            self.send(
                DeviceMsg::Event(event(EventKind::FaultCleared(cleared), 1)),
                tx,
            );
        }
        self.reported_faults = faults;
        if let Some((line, resets_in_row)) = self.panic_report.take() {
            let kind = EventKind::PanicReset {
                line,
                resets_in_row,
            };
            self.send(DeviceMsg::Event(event(kind, 1)), tx);
        }
        self.last = Some(m);
        // After the frame, so a save's erase never delays a measurement.
        self.poll_storage(now_ms);
    }

    /// When the pending change will be saved (`None`: nothing to save), ms
    /// on the `now_ms` clock. The driver calls [`Self::poll_storage`] then
    /// (`run_frame` also does, after its frame).
    pub fn save_due_ms(&self) -> Option<u64> {
        let p = self.pending_save?;
        let coalesced = p
            .last_ms
            .saturating_add(SAVE_QUIET_MS)
            .min(p.first_ms.saturating_add(SAVE_MAX_DELAY_MS));
        let earliest = self
            .last_save_ms
            .map_or(0, |t| t.saturating_add(SAVE_MIN_INTERVAL_MS));
        Some(coalesced.max(earliest))
    }

    /// Save the pending change if it is due. A failed save sets
    /// `STORAGE_FAILED` (reported as a fault event with the next frame) and
    /// is retried [`SAVE_MIN_INTERVAL_MS`] later.
    pub fn poll_storage(&mut self, now_ms: u64) {
        if self.save_due_ms().is_some_and(|due| now_ms >= due) {
            self.save(now_ms);
        }
    }

    /// True while a change waits to be saved.
    pub fn save_pending(&self) -> bool {
        self.pending_save.is_some()
    }

    /// Tell the node it runs on its internal oscillator because the external
    /// clock did not start (raises `CLOCK_FALLBACK`).
    pub fn set_clock_fallback(&mut self, fallback: bool) {
        self.clock_fallback = fallback;
    }

    /// Faults the board found at boot: the brown-out level in the option
    /// bytes is not the provisioned one (`BOR_NOT_SET`), or the node booted
    /// without its flash store after repeated panic resets
    /// (`STORE_SKIPPED`). Raised with the first frame.
    pub fn set_boot_faults(&mut self, bor_not_set: bool, store_skipped: bool) {
        self.boot_faults = 0;
        if bor_not_set {
            self.boot_faults |= flags::BOR_NOT_SET;
        }
        if store_skipped {
            self.boot_faults |= flags::STORE_SKIPPED;
        }
    }

    /// This boot followed a panic reset: send `EventKind::PanicReset` once,
    /// with the next frame.
    pub fn report_panic_reset(&mut self, line: u32, resets_in_row: u8) {
        self.panic_report = Some((line, resets_in_row));
    }

    /// The programmable voltage detector reports V_DD below its threshold:
    /// saves wait until it does not (and the last V_DDA is healthy:
    /// `supply`).
    pub fn set_supply_low(&mut self, low: bool) {
        self.supply_low = low;
    }

    /// The rule's state, for the board to keep across a reset.
    pub fn rule_snapshot(&self) -> RuleSnapshot {
        RuleSnapshot {
            state: self.rule.state(),
            acked: self.rule.acked(),
        }
    }

    /// Resume the rule's state after a reset (`boot::RuleSnapshot::resume`):
    /// the outputs follow at once.
    pub fn resume_rule(&mut self, snapshot: RuleSnapshot) {
        self.rule = Rule::resumed(snapshot.state, snapshot.acked);
        self.drive_outputs();
    }

    /// Bytes received from the host link, in any chunking. Each complete
    /// frame is answered through `tx`: an `Ack`, or an `Error` (garbled,
    /// unknown, out of range). Never stops the measurement.
    pub fn handle_rx(&mut self, bytes: &[u8], now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        for &b in bytes {
            match self.decoder.push::<HostFrame>(b) {
                None => {}
                Some(Ok(frame)) => self.execute(frame, now_ms, tx),
                Some(Err(e)) => {
                    self.send(DeviceMsg::Error(dispatch::frame_error_reply(e)), tx);
                }
            }
        }
    }

    /// The user button (B1). While iced it acknowledges the alarm (the
    /// output stays on while the ice holds); otherwise it runs a dark
    /// calibration (the user cleaned the dry face and pressed the button).
    /// Either way an unsolicited `Ack` (or `Error`) with id
    /// [`BUTTON_ID`](crate::dispatch::BUTTON_ID) reports what happened. The
    /// acknowledgement never writes flash.
    pub fn button_pressed(&mut self, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let cmd = if self.rule.alarm() {
            Command::AckAlarm
        } else {
            Command::CalibrateDark
        };
        self.execute(HostFrame { id: BUTTON_ID, cmd }, now_ms, tx);
    }

    /// The output frame period now in force, ms (the `StartStream` rate
    /// while streaming with one, else the config's).
    pub fn frame_period_ms(&self) -> u32 {
        self.stream_period_ms.unwrap_or(self.config.frame_period_ms)
    }

    /// True while measurements are streamed.
    pub fn is_streaming(&self) -> bool {
        self.streaming
    }

    /// The ice rule's state.
    pub fn state(&self) -> DetectorState {
        self.rule.state()
    }

    /// The config in force.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The dark baseline in use (`None`: zero baseline, `NO_BASELINE` flag).
    pub fn baseline(&self) -> Option<Baseline> {
        self.baseline
    }

    /// The last frame's measurement (also when not streaming).
    pub fn last_measurement(&self) -> Option<&Measurement> {
        self.last.as_ref()
    }

    /// The ice estimator (its posterior, its settings).
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// Set the estimator's settings (library settings, not part of the
    /// protocol `Config`); the filter starts afresh (with the kept gain).
    pub fn set_estimator_params(&mut self, params: EstimatorParams) {
        self.estimator = Estimator::new(params);
        self.start_estimator();
    }

    /// The optical gain estimate as the protocol carries it (at the optics'
    /// temperature now), once the estimator has one.
    pub fn gain_estimate(&self) -> Option<GainEstimate> {
        self.estimator
            .gain()
            .map(|g| gain_cal::to_estimate(g.gain, g.sigma))
    }

    /// The learned gain as kept in the store (`None`: none kept).
    pub fn gain_kept(&self) -> Option<GainEstimate> {
        self.gain_kept
    }

    /// Frames sent so far (the next frame's sequence number).
    pub fn next_seq(&self) -> u32 {
        self.seq
    }

    /// True once after a `Reset` command was acknowledged: the board then
    /// resets; the virtual node builds a new `Node`.
    pub fn take_reset_request(&mut self) -> bool {
        core::mem::replace(&mut self.reset_request, false)
    }

    /// Give the parts back (tests, the virtual node's restart).
    pub fn into_parts(self) -> (A, L, AL, IND, D, S) {
        (
            self.adc,
            self.led,
            self.alarm,
            self.indicator,
            self.delay,
            self.storage,
        )
    }

    // ---- internals ----

    fn rise1(&self, i1_na: i32) -> i32 {
        let base = self.baseline.map_or(0, |b| b.i1_na);
        i1_na.saturating_sub(base)
    }

    /// Feed the estimator: the baseline-corrected currents of a valid frame
    /// (an invalid or saturated one only predicts) and the NTC's air
    /// temperature (none when the NTC is open or shorted: the internal
    /// sensor that stands in for the rule reads the die, not the air).
    fn estimate(
        &mut self,
        now_ms: u64,
        values: &FrameValues,
        rise1_na: i32,
        valid: bool,
    ) -> Option<fois_protocol::IceEstimate> {
        let dt_s = self
            .last_frame_ms
            .map_or(0.0, |t| now_ms.saturating_sub(t) as f32 / 1000.0);
        self.last_frame_ms = Some(now_ms);
        let base2 = self.baseline.map_or(0, |b| b.i2_na);
        let rise2_na = values.currents.net_na[1].saturating_sub(base2);
        let currents_ua = valid.then_some([rise1_na as f32 * 1e-3, rise2_na as f32 * 1e-3]);
        let ntc_ok = values.flags & (flags::NTC_OPEN | flags::NTC_SHORT) == 0;
        let air_temp_c = ntc_ok.then_some(f32::from(values.temperature_centi_c) * 0.01);
        self.estimator
            .set_optics_temp_c(Some(f32::from(values.optics_centi_c) * 0.01));
        self.estimator.step(dt_s, currents_ua, air_temp_c)
    }

    /// The estimator's temperature model from the config, and its gain
    /// prior: the kept learned gain (widened), else the last calibration,
    /// else unknown.
    fn start_estimator(&mut self) {
        self.estimator.set_temperature_model(
            self.config.gain_tempco_ppm_per_k,
            self.config.gain_tempco_sd_ppm_per_k,
        );
        // A kept gain that is the calibration itself is not widened.
        let kept = self
            .gain_kept
            .filter(|k| Some(*k) != self.gain_calibration)
            .as_ref()
            .and_then(gain_cal::from_estimate);
        let calibrated = self
            .gain_calibration
            .as_ref()
            .and_then(gain_cal::from_estimate);
        match (kept, calibrated) {
            (Some((g, sd)), _) => {
                let (g, sd) = gain_cal::prior_from_kept(g, sd);
                self.estimator.set_gain_prior(g, sd);
            }
            (None, Some((g, sd))) => self.estimator.set_gain_prior(g, sd),
            (None, None) => self.estimator.reset_gain(),
        }
    }

    /// After each frame: the out-of-band flag, and once an hour (not in the
    /// first hour after boot) whether the learned gain is worth keeping.
    fn track_gain(&mut self, now_ms: u64) {
        let Some(g) = self.estimator.gain() else {
            return;
        };
        let band = (
            f32::from(self.config.gain_low_permille) * 1e-3,
            f32::from(self.config.gain_high_permille) * 1e-3,
        );
        self.gain_out_of_band = gain_cal::out_of_band(self.gain_out_of_band, g.gain, g.sigma, band);
        if now_ms
            < self
                .gain_checked_ms
                .saturating_add(gain_cal::SAVE_GAIN_INTERVAL_MS)
        {
            return;
        }
        self.gain_checked_ms = now_ms;
        // Kept at the reference temperature: the compensation taken out.
        let at_ref = g.gain / self.estimator.compensation();
        // A kept gain that is the calibration itself is not widened.
        let kept = self
            .gain_kept
            .filter(|k| Some(*k) != self.gain_calibration)
            .as_ref()
            .and_then(gain_cal::from_estimate);
        if gain_cal::worth_saving((at_ref, g.sigma), kept) {
            self.gain_kept = Some(gain_cal::to_estimate(at_ref, g.sigma));
            self.changed(now_ms);
        }
    }

    fn node_flags(&self) -> u16 {
        let mut f = 0;
        if self.config_defaulted {
            f |= flags::CONFIG_DEFAULTED;
        }
        if self.storage_failed {
            f |= flags::STORAGE_FAILED;
        }
        if self.clock_fallback {
            f |= flags::CLOCK_FALLBACK;
        }
        f |= self.boot_faults;
        if self.baseline.is_none() {
            f |= flags::NO_BASELINE;
        }
        if self.rule.alarm() {
            f |= flags::ALARM;
        }
        if self.rule.acked() {
            f |= flags::ALARM_ACKED;
        }
        if self.gain_out_of_band {
            f |= flags::GAIN_OUT_OF_BAND;
        }
        f
    }

    fn drive_outputs(&mut self) {
        let on = self.rule.alarm();
        if on {
            let _ = self.alarm.set_high();
            let _ = self.indicator.set_high();
        } else {
            let _ = self.alarm.set_low();
            let _ = self.indicator.set_low();
        }
    }

    /// Acquire one frame and convert it (no rule, no output). V_DDA is
    /// measured first: it sets this frame's saturation code.
    fn measure_frame(&mut self) -> FrameValues {
        let cal = self.info.cal;
        let vdda_mv = vref::vdda_mv(&cal, self.adc.read_vrefint());
        let mut flags = 0u16;
        if !vref::vdda_in_range(vdda_mv) {
            flags |= flags::VDDA_OUT_OF_RANGE;
        }
        let conv_mv = vref::vdda_for_conversion(vdda_mv);
        let acq = measure::acquire(
            &mut self.adc,
            &mut self.led,
            &mut self.delay,
            self.config.cycles_per_frame,
            self.config.settle_us,
            measure::saturation_code(conv_mv),
        );
        let currents = measure::currents(
            &acq,
            conv_mv,
            [self.config.load_r1_ohm, self.config.load_r2_ohm],
        );
        if acq.saturated[0] {
            flags |= flags::SATURATED_CH1;
        }
        if acq.saturated[1] {
            flags |= flags::SATURATED_CH2;
        }
        let optics_centi_c =
            vref::internal_temp_centi_c(&cal, self.adc.read_internal_temp(), conv_mv);
        let temperature_centi_c = match ntc::temperature(self.adc.read_ntc()) {
            NtcReading::Ok(t) => t,
            fault => {
                flags |= if fault == NtcReading::Open {
                    flags::NTC_OPEN
                } else {
                    flags::NTC_SHORT
                };
                optics_centi_c
            }
        };
        FrameValues {
            currents,
            temperature_centi_c,
            optics_centi_c,
            vdda_mv,
            flags,
        }
    }

    fn send(&mut self, msg: DeviceMsg, tx: &mut impl FnMut(&[u8])) {
        let frame = DeviceFrame { seq: self.seq, msg };
        let mut buf = [0u8; MAX_FRAME];
        if let Ok(n) = encode(&frame, &mut buf)
            && let Some(bytes) = buf.get(..n)
        {
            tx(bytes);
            self.seq = self.seq.wrapping_add(1);
        }
    }

    fn reply(&mut self, id: u16, result: Result<AckResult, ErrorCode>, tx: &mut impl FnMut(&[u8])) {
        let msg = match result {
            Ok(result) => DeviceMsg::Ack(Ack { id, result }),
            Err(code) => DeviceMsg::Error(ErrorReply { id: Some(id), code }),
        };
        self.send(msg, tx);
    }

    fn execute(&mut self, frame: HostFrame, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let id = frame.id;
        let result = match frame.cmd {
            Command::GetInfo => Ok(AckResult::Info(self.hello())),
            Command::GetConfig => Ok(AckResult::ConfigV3(self.config.clone())),
            // An older host's config: its twelve fields over the node's gain fields.
            Command::SetConfig(cfg) => self
                .set_config(cfg.over(&self.config), now_ms)
                .map(|()| AckResult::Config(ConfigV1::from(&self.config))),
            Command::SetConfigV3(cfg) => self
                .set_config(cfg, now_ms)
                .map(|()| AckResult::ConfigV3(self.config.clone())),
            Command::CalibrateGain(target) => self.calibrate_gain(target, now_ms),
            Command::ResetGain => {
                self.gain_kept = None;
                self.gain_calibration = None;
                self.estimator.reset_gain();
                self.changed(now_ms);
                Ok(AckResult::GainReset)
            }
            Command::StartStream { frame_period_ms } => {
                match dispatch::stream_period(&self.config, frame_period_ms) {
                    Ok(period) => {
                        self.streaming = true;
                        self.stream_period_ms = frame_period_ms.map(|_| period);
                        Ok(AckResult::Streaming {
                            frame_period_ms: period,
                        })
                    }
                    Err(code) => Err(code),
                }
            }
            Command::StopStream => {
                self.streaming = false;
                self.stream_period_ms = None;
                Ok(AckResult::Stopped)
            }
            Command::CalibrateDark => self.calibrate_dark(now_ms),
            Command::AckAlarm => {
                self.rule.acknowledge();
                Ok(AckResult::AlarmAcknowledged)
            }
            Command::Reset => {
                // Whatever waits to be saved is saved before the reset.
                if self.pending_save.is_some() {
                    self.save(now_ms);
                }
                self.reset_request = true;
                Ok(AckResult::Resetting)
            }
        };
        self.reply(id, result, tx);
    }

    fn set_config(&mut self, cfg: Config, now_ms: u64) -> Result<(), ErrorCode> {
        cfg.validate().map_err(ErrorCode::InvalidConfig)?;
        self.config = cfg;
        self.estimator.set_temperature_model(
            self.config.gain_tempco_ppm_per_k,
            self.config.gain_tempco_sd_ppm_per_k,
        );
        self.config_defaulted = false;
        // A StartStream rate that no longer fits the new K × settle is dropped.
        if let Some(p) = self.stream_period_ms
            && dispatch::stream_period(&self.config, Some(p)).is_err()
        {
            self.stream_period_ms = None;
        }
        self.changed(now_ms);
        Ok(())
    }

    fn calibrate_dark(&mut self, now_ms: u64) -> Result<AckResult, ErrorCode> {
        if self.rule.state() != DetectorState::Dry {
            // An iced or wet face is not a dark reference (water would
            // become the baseline and hide the next film).
            return Err(ErrorCode::NotDry);
        }
        // Average as long as the noise needs, within the time bound; refuse
        // a trend, a step, too much noise or saturation (`dark_cal`).
        let baseline = dark_cal::run(
            &mut self.adc,
            &mut self.led,
            &mut self.delay,
            &self.config,
            &self.info.cal,
        )
        .map_err(ErrorCode::CalibrationRefused)?
        .baseline;
        self.baseline = Some(baseline);
        // A clean, dry face: the estimator starts from "dry", and the
        // learned gain (which may hold the dirt just cleaned off) returns to
        // the last calibration, or to unknown.
        self.gain_kept = self.gain_calibration;
        self.start_estimator();
        self.estimator.set_dry();
        self.changed(now_ms);
        Ok(AckResult::DarkCalibrated(baseline))
    }

    /// A gain calibration: the target is on the face; average
    /// [`gain_cal::GAIN_CAL_FRAMES`] frames (baseline-corrected), fit the
    /// gain, make it the estimator's prior and keep it.
    fn calibrate_gain(&mut self, target: GainTarget, now_ms: u64) -> Result<AckResult, ErrorCode> {
        let mut frames = [None; gain_cal::GAIN_CAL_FRAMES];
        let base = self.baseline.unwrap_or_default();
        let mut optics_c = 0.0f32;
        for f in frames.iter_mut() {
            let v = self.measure_frame();
            optics_c += f32::from(v.optics_centi_c) * 0.01 / gain_cal::GAIN_CAL_FRAMES as f32;
            if v.flags & flags::INVALID_MASK == 0 {
                *f = Some([
                    v.currents.net_na[0].saturating_sub(base.i1_na),
                    v.currents.net_na[1].saturating_sub(base.i2_na),
                ]);
            }
        }
        self.estimator.set_optics_temp_c(Some(optics_c));
        let c = gain_cal::calibrate(&frames, target, self.estimator.compensation())
            .map_err(ErrorCode::CalibrationRefused)?;
        let kept = gain_cal::to_estimate(c.gain, c.sd);
        self.gain_calibration = Some(kept);
        self.gain_kept = Some(kept);
        self.estimator.set_gain_prior(c.gain, c.sd);
        self.changed(now_ms);
        Ok(AckResult::GainCalibrated(kept))
    }

    /// The record the node would store now.
    fn record(&self) -> Record {
        Record {
            config: self.config.clone(),
            baseline: self.baseline,
            gain: self.gain_kept,
            gain_calibration: self.gain_calibration,
        }
    }

    /// Config or baseline changed: schedule a save, unless the storage
    /// already holds exactly this (then a pending save is dropped).
    fn changed(&mut self, now_ms: u64) {
        if self.stored.as_ref() == Some(&self.record()) && !self.storage_failed {
            self.pending_save = None;
            return;
        }
        self.pending_save = Some(match self.pending_save {
            Some(p) => PendingSave {
                last_ms: now_ms,
                ..p
            },
            None => PendingSave {
                first_ms: now_ms,
                last_ms: now_ms,
            },
        });
    }

    /// Write the record now, if the supply allows (else it stays pending).
    fn save(&mut self, now_ms: u64) {
        // V_DDA now, not the last frame's: a save can come before the first
        // frame (a `Reset` right after a `SetConfig`) or long after one.
        let vdda_mv = vref::vdda_mv(&self.info.cal, self.adc.read_vrefint());
        if !supply::flash_write_allowed(vdda_mv, self.supply_low) {
            return;
        }
        let record = self.record();
        let mut buf = [0u8; MAX_RECORD];
        let n = persist::encode(&record, &mut buf);
        let written = match buf.get(..n) {
            Some(bytes) if n > 0 => self.storage.write(bytes).is_ok(),
            _ => false,
        };
        self.last_save_ms = Some(now_ms);
        self.storage_failed = !written;
        if written {
            self.stored = Some(record);
            self.pending_save = None;
        } else {
            // Retry once the interval has passed.
            self.pending_save = Some(PendingSave {
                first_ms: now_ms,
                last_ms: now_ms,
            });
        }
    }
}
