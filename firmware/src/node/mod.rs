//! The whole node behind the hardware traits: measurement, the ice rule,
//! outputs, persistence and the command link. The board binary, the host's
//! virtual node and the HIL suite all drive this same type.
//!
//! This file holds the node's state and its life cycle (build, what the
//! board tells it, what it reports about itself). What it does is in the
//! files beside it:
//! - [`dispatch`]: the host's commands and the button, decoded and carried
//!   out (one `match` over every command);
//! - [`frame`]: one output frame — measure, rule, estimate, outputs, report;
//! - [`saving`]: when the record is written (coalescing, rate limit,
//!   retries);
//! - [`gain_keeping`]: the learned optical gain — the estimator's prior, the
//!   out-of-band flag, when it is worth keeping;
//! - [`modbus_view`]: the node as its Modbus registers show it, and a
//!   Modbus write's actions carried out;
//! - [`updating`]: the firmware transfer's commands and the trial boot
//!   (self-test, confirmation, rollback report) on the node's
//!   [`UpdateSlots`].

pub mod dispatch;
pub mod frame;
pub mod gain_keeping;
pub mod modbus_view;
pub mod saving;
pub mod updating;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{
    Baseline, Config, DetectorState, DeviceFrame, DeviceMsg, FrameDecoder, GainEstimate, Hello,
    LinkSettings, MAX_FRAME, Measurement, PROTOCOL_VERSION, encode, flags,
};

use crate::estimator::{Estimator, EstimatorParams};
use crate::hal::{BoardInfo, PhotoAdc};
use crate::ice_rule::Rule;
use crate::platform::boot::RuleSnapshot;
use crate::storage::Storage;
use crate::storage::record::{self, LoadError, MAX_RECORD, Record};
use crate::update::{NoUpdates, Trial, UpdateSlots};

/// Firmware version sent in [`Hello`] (the crate's version; it lives with
/// the updater, whose version rule compares against it).
pub use crate::update::FIRMWARE_VERSION;

/// An unsaved change: when the first and the last one came (when it is
/// written: [`saving`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PendingSave {
    first_ms: u64,
    last_ms: u64,
}

/// What the last frame reported beside its [`Measurement`]: the registers
/// of the Modbus link show them together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Report {
    /// The frame's sequence number (the one its measurement frame carries
    /// when streaming).
    pub seq: u32,
    /// The ice estimate after the frame.
    pub estimate: Option<fois_protocol::IceEstimate>,
    /// The optical gain estimate.
    pub gain: Option<GainEstimate>,
    /// The icing rate after the frame.
    pub icing: Option<fois_protocol::IcingEstimate>,
}

/// The node. Type parameters: ADC, LED (PB0), alarm output (PA9), indicator
/// (LD2, PA5), delay (settle waits), storage (config + baseline record).
pub struct Node<A, L, AL, IND, D, S, U = NoUpdates>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
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
    /// Failed saves in a row (the retries back off: `saving`).
    save_failures: u32,
    rule: Rule,
    seq: u32,
    streaming: bool,
    stream_period_ms: Option<u32>,
    decoder: FrameDecoder<MAX_FRAME>,
    reported_faults: u16,
    /// The icing period the node last reported (`IcingStarted` /
    /// `IcingEnded`).
    reported_icing: bool,
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
    /// The host link's protocol and Modbus settings (stored in the record).
    link: LinkSettings,
    /// The last measurement frame's estimate, gain and sequence number
    /// (what the Modbus registers show with [`Node::last_measurement`]).
    last_report: Option<Report>,
    /// The update slots (firmware transfer, boot state: [`updating`]).
    updates: U,
    /// The running image's trial boot (self-test, confirmation, rollback).
    trial: Trial,
}

impl<A, L, AL, IND, D, S, U> Node<A, L, AL, IND, D, S, U>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
{
    /// Build the node with its update slots (see [`Node::new`]): the running
    /// image's boot state comes from `updates` (on trial, the node confirms
    /// it after its self-test or asks for the reset that rolls it back:
    /// [`updating`]).
    #[allow(clippy::too_many_arguments)]
    pub fn new_with_updates(
        adc: A,
        led: L,
        alarm: AL,
        indicator: IND,
        delay: D,
        mut storage: S,
        info: BoardInfo,
        updates: U,
    ) -> Self {
        let mut buf = [0xFFu8; MAX_RECORD];
        let loaded = match storage.read(&mut buf) {
            Ok(n) => record::decode(buf.get(..n).unwrap_or(&[])),
            Err(_) => Err(LoadError::Corrupt),
        };
        let (stored, config_defaulted) = match loaded {
            Ok(r) => (Some(r), false),
            Err(LoadError::Empty) => (None, false),
            Err(_) => (None, true),
        };
        let (config, baseline, gain_kept, gain_calibration, link) = match &stored {
            Some(r) => (
                r.config.clone(),
                r.baseline,
                r.gain,
                r.gain_calibration,
                r.link,
            ),
            None => (Config::default(), None, None, None, LinkSettings::default()),
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
            save_failures: 0,
            rule: Rule::new(),
            seq: 0,
            stream_period_ms: None,
            decoder: FrameDecoder::new(),
            reported_faults: 0,
            reported_icing: false,
            reset_request: false,
            last: None,
            estimator: Estimator::default(),
            last_frame_ms: None,
            gain_kept,
            gain_calibration,
            gain_out_of_band: false,
            gain_checked_ms: 0,
            link,
            last_report: None,
            trial: Trial::new(
                updates.image_state(),
                updates.running_version(),
                !config_defaulted,
            ),
            updates,
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
            firmware_version: self.updates.running_version(),
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
    /// `storage::supply`).
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

    /// Resume the rule's state after a reset (`platform::boot::RuleSnapshot::resume`):
    /// the outputs follow at once.
    pub fn resume_rule(&mut self, snapshot: RuleSnapshot) {
        self.rule = Rule::resumed(snapshot.state, snapshot.acked);
        self.drive_outputs();
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

    /// The last frame's sequence number, estimate and gain.
    pub fn last_report(&self) -> Option<&Report> {
        self.last_report.as_ref()
    }

    /// The host link's protocol and Modbus settings in force.
    pub fn link_settings(&self) -> LinkSettings {
        self.link
    }

    /// The button was held at power-up: the host link goes back to the
    /// framed protocol (saved at once), the way back when the host no
    /// longer speaks Modbus. Returns true if it changed (the board then
    /// sets its link up framed).
    pub fn button_held_at_boot(&mut self, now_ms: u64) -> bool {
        if self.link.protocol == fois_protocol::LinkProtocol::Framed {
            return false;
        }
        self.link = self.link.framed();
        self.changed(now_ms);
        if self.pending_save.is_some() {
            self.save(now_ms);
        }
        true
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
        self.into_parts_and_updates().0
    }

    /// Give the parts and the update slots back (the virtual node's
    /// restart into a new image).
    pub fn into_parts_and_updates(self) -> ((A, L, AL, IND, D, S), U) {
        (
            (
                self.adc,
                self.led,
                self.alarm,
                self.indicator,
                self.delay,
                self.storage,
            ),
            self.updates,
        )
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
    /// and the outputs start off. No update slots ([`NoUpdates`]): the
    /// firmware transfer's commands are unknown to it
    /// ([`Node::new_with_updates`] builds one that takes updates).
    pub fn new(
        adc: A,
        led: L,
        alarm: AL,
        indicator: IND,
        delay: D,
        storage: S,
        info: BoardInfo,
    ) -> Self {
        Self::new_with_updates(adc, led, alarm, indicator, delay, storage, info, NoUpdates)
    }
}
