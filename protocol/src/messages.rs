//! The messages that cross the wire, in both directions.
//!
//! Compatibility rules (see `protocol/README.md`): the field order and the
//! enum variant order of every type here are frozen for a given
//! [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION). [`Hello`] and the envelope
//! ([`DeviceFrame`]: `seq`, then variant 0 = `Hello`) never change shape, so a
//! host of any version can read which version a node speaks. Any other change
//! is breaking: add a message (a new variant at the end) and bump the version.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::config::{Config, ConfigError, ConfigV1};

/// Every frame a node sends: a sequence number that grows by one per frame
/// (wrapping), so the host can count lost frames, and the message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceFrame {
    /// Frame counter, +1 for every frame the node sends, of any kind.
    pub seq: u32,
    /// The message.
    pub msg: DeviceMsg,
}

/// Messages from the node to the host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DeviceMsg {
    /// Sent at boot and every second until streaming starts; frozen shape.
    Hello(Hello),
    /// One output frame of the synchronous detector.
    Measurement(Measurement),
    /// A detector or fault transition, with the values that caused it.
    Event(Event),
    /// A command was carried out.
    Ack(Ack),
    /// A command was refused or could not be read.
    Error(ErrorReply),
    /// Version 2: one output frame of the synchronous detector with the
    /// node's ice estimate. A version-2 node streams this instead of
    /// [`DeviceMsg::Measurement`]; a host reads both.
    MeasurementV2(MeasurementV2),
    /// Version 3: the measurement, the ice estimate and the node's estimate
    /// of its own optical gain. A version-3 node streams this instead of
    /// [`DeviceMsg::MeasurementV2`].
    MeasurementV3(MeasurementV3),
    /// Version 5: a [`MeasurementV3`]'s content and the node's icing rate
    /// and meteorological icing ([`IcingEstimate`]). A version-5 node
    /// streams this instead of [`DeviceMsg::MeasurementV3`].
    MeasurementV5(MeasurementV5),
}

impl DeviceMsg {
    /// The measurement of a [`DeviceMsg::Measurement`] (version 1, no
    /// estimate) or a [`DeviceMsg::MeasurementV2`], with its estimate if the
    /// node sent one. `None` for every other message.
    pub fn measurement(&self) -> Option<(&Measurement, Option<&IceEstimate>)> {
        match self {
            DeviceMsg::Measurement(m) => Some((m, None)),
            DeviceMsg::MeasurementV2(m) => Some((&m.measurement, m.estimate.as_ref())),
            DeviceMsg::MeasurementV3(m) => Some((&m.measurement, m.estimate.as_ref())),
            DeviceMsg::MeasurementV5(m) => Some((&m.measurement, m.estimate.as_ref())),
            _ => None,
        }
    }

    /// The node's optical gain estimate of a [`DeviceMsg::MeasurementV3`],
    /// if it sent one. `None` for every other message.
    pub fn gain(&self) -> Option<&GainEstimate> {
        match self {
            DeviceMsg::MeasurementV3(m) => m.gain.as_ref(),
            DeviceMsg::MeasurementV5(m) => m.gain.as_ref(),
            _ => None,
        }
    }

    /// The node's icing rate of a [`DeviceMsg::MeasurementV5`], if it sent
    /// one. `None` for every other message.
    pub fn icing(&self) -> Option<&IcingEstimate> {
        match self {
            DeviceMsg::MeasurementV5(m) => m.icing.as_ref(),
            _ => None,
        }
    }
}

/// Who the node is. Frozen: this shape never changes, whatever the version.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Hello {
    /// The [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION) the node speaks.
    pub protocol_version: u16,
    /// Firmware version, semantic: major, minor, patch.
    pub firmware_version: [u8; 3],
    /// Board name, ASCII, zero-padded (see [`Hello::board_name`]).
    pub board: [u8; 16],
    /// The MCU's 96-bit unique id.
    pub unique_id: [u8; 12],
    /// Why the node last reset.
    pub reset_reason: ResetReason,
}

impl Hello {
    /// Pack an ASCII board name (truncated to 16 bytes) into the fixed field.
    pub fn board_from_str(name: &str) -> [u8; 16] {
        let mut out = [0u8; 16];
        for (dst, src) in out.iter_mut().zip(name.bytes()) {
            *dst = src;
        }
        out
    }

    /// The board name without its zero padding (`"?"` if it is not UTF-8).
    pub fn board_name(&self) -> &str {
        let end = self
            .board
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(self.board.len());
        core::str::from_utf8(&self.board[..end]).unwrap_or("?")
    }
}

/// Why the MCU last reset (from the RCC reset flags on the STM32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetReason {
    /// Power-on or brown-out reset.
    PowerOn,
    /// The NRST pin (reset button, debugger).
    Pin,
    /// A software reset (the `Reset` command).
    Software,
    /// The independent watchdog fired: the firmware hung.
    IndependentWatchdog,
    /// The window watchdog fired.
    WindowWatchdog,
    /// Low-power management reset.
    LowPower,
    /// No flag was set, or several that do not fit one cause.
    Unknown,
}

/// What the ice rule currently concludes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DetectorState {
    /// No optical signature: the face is dry (I1 near its dark baseline).
    Dry,
    /// Optical signature above the freezing limit: water, not ice.
    Wet,
    /// Optical signature at or below the freezing limit: ice. Alarm output on.
    Ice,
}

impl DetectorState {
    /// The state as a lower-case word, `dry`, `wet` or `ice`: its name in
    /// text formats (scenario files, MQTT payloads).
    pub const fn name(self) -> &'static str {
        match self {
            DetectorState::Dry => "dry",
            DetectorState::Wet => "wet",
            DetectorState::Ice => "ice",
        }
    }
}

/// Bits of [`Measurement::flags`]. A frame with any `SATURATED_*` bit is
/// invalid: its currents must not be used.
pub mod flags {
    /// Channel 1 hit the ADC's full scale (too much ambient light): invalid.
    pub const SATURATED_CH1: u16 = 1 << 0;
    /// Channel 2 hit the ADC's full scale: invalid.
    pub const SATURATED_CH2: u16 = 1 << 1;
    /// The NTC reads open circuit (fault); temperature from the internal sensor.
    pub const NTC_OPEN: u16 = 1 << 2;
    /// The NTC reads short circuit (fault); temperature from the internal sensor.
    pub const NTC_SHORT: u16 = 1 << 3;
    /// The stored config was corrupt or of an old version: defaults in use.
    pub const CONFIG_DEFAULTED: u16 = 1 << 4;
    /// No dark baseline has been stored: the rule uses a zero baseline.
    pub const NO_BASELINE: u16 = 1 << 5;
    /// The alarm output (PA9) is on.
    pub const ALARM: u16 = 1 << 6;
    /// The alarm was acknowledged by the user (output stays on while iced).
    pub const ALARM_ACKED: u16 = 1 << 7;
    /// V_DDA measured through VREFINT is outside 2.0–3.6 V: currents doubtful.
    pub const VDDA_OUT_OF_RANGE: u16 = 1 << 8;
    /// The persisted config or baseline could not be written to flash.
    pub const STORAGE_FAILED: u16 = 1 << 9;
    /// Version 2: the external clock (HSE, 8 MHz from the ST-LINK) did not
    /// start: the node runs on its internal RC oscillator, whose drift over
    /// temperature can exceed what the UART tolerates.
    pub const CLOCK_FALLBACK: u16 = 1 << 10;
    /// Version 3: the brown-out reset level in the option bytes is not the
    /// one set when the board was provisioned: the node may run on a
    /// sagging supply instead of resetting.
    pub const BOR_NOT_SET: u16 = 1 << 11;
    /// Version 3: the node booted without its flash store after repeated
    /// panic resets in a row: defaults in use, nothing is saved until reset.
    pub const STORE_SKIPPED: u16 = 1 << 12;
    /// Version 3: the estimated optical gain left the configured plausible
    /// band (`gain_low_permille`…`gain_high_permille`): LED failing, face
    /// fouled or scratched. A maintenance signal.
    pub const GAIN_OUT_OF_BAND: u16 = 1 << 13;

    /// Bits that make a frame's currents unusable.
    pub const INVALID_MASK: u16 = SATURATED_CH1 | SATURATED_CH2;
    /// Bits that are faults (raised/cleared by [`EventKind`](crate::EventKind)).
    pub const FAULT_MASK: u16 = NTC_OPEN
        | NTC_SHORT
        | CONFIG_DEFAULTED
        | VDDA_OUT_OF_RANGE
        | STORAGE_FAILED
        | CLOCK_FALLBACK
        | BOR_NOT_SET
        | STORE_SKIPPED
        | GAIN_OUT_OF_BAND;

    /// Every defined bit with its name in text formats (CSV logs, MQTT
    /// payloads, Modbus documentation): the one list of flag names.
    pub const NAMES: [(u16, &str); 14] = [
        (SATURATED_CH1, "saturated_ch1"),
        (SATURATED_CH2, "saturated_ch2"),
        (NTC_OPEN, "ntc_open"),
        (NTC_SHORT, "ntc_short"),
        (CONFIG_DEFAULTED, "config_defaulted"),
        (NO_BASELINE, "no_baseline"),
        (ALARM, "alarm"),
        (ALARM_ACKED, "alarm_acked"),
        (VDDA_OUT_OF_RANGE, "vdda_out_of_range"),
        (STORAGE_FAILED, "storage_failed"),
        (CLOCK_FALLBACK, "clock_fallback"),
        (BOR_NOT_SET, "bor_not_set"),
        (STORE_SKIPPED, "store_skipped"),
        (GAIN_OUT_OF_BAND, "gain_out_of_band"),
    ];

    /// The name of one bit (`None` for a reserved bit or several bits).
    pub fn name(bit: u16) -> Option<&'static str> {
        NAMES.iter().find(|(b, _)| *b == bit).map(|(_, n)| *n)
    }

    /// The names of the bits set in `bits`, in bit order (reserved bits are
    /// skipped: hosts ignore bits they do not know).
    pub fn names(bits: u16) -> impl Iterator<Item = &'static str> {
        NAMES
            .iter()
            .filter(move |(b, _)| bits & b != 0)
            .map(|(_, n)| *n)
    }
}

/// One output frame: K LED-on/LED-off cycles averaged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Measurement {
    /// Milliseconds since boot.
    pub uptime_ms: u64,
    /// Channel 1 net photocurrent (LED on − LED off), nA.
    pub i1_na: i32,
    /// Channel 2 net photocurrent (LED on − LED off), nA.
    pub i2_na: i32,
    /// Channel 1 ambient level (LED off), nA.
    pub ambient1_na: u32,
    /// Channel 2 ambient level (LED off), nA.
    pub ambient2_na: u32,
    /// Air temperature, 0.01 °C (NTC; internal sensor when the NTC fails).
    pub temperature_centi_c: i16,
    /// Analog supply measured through VREFINT, mV.
    pub vdda_mv: u16,
    /// Validity and fault bits, see [`flags`].
    pub flags: u16,
    /// The ice rule's state after this frame.
    pub state: DetectorState,
}

impl Measurement {
    /// True when the currents may be used (no saturation).
    pub fn is_valid(&self) -> bool {
        self.flags & flags::INVALID_MASK == 0
    }
}

/// Version 2: a [`Measurement`] (same fields, same encoding) and the node's
/// estimate of the accretion on its face.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MeasurementV2 {
    /// The frame's currents, temperature, flags and detector state.
    pub measurement: Measurement,
    /// The ice estimate after this frame; `None` when the node has none
    /// (estimator not running, e.g. not yet initialised).
    pub estimate: Option<IceEstimate>,
}

/// Version 3: a [`MeasurementV2`]'s content and the node's estimate of its
/// own optical gain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MeasurementV3 {
    /// The frame's currents, temperature, flags and detector state.
    pub measurement: Measurement,
    /// The ice estimate after this frame, if any.
    pub estimate: Option<IceEstimate>,
    /// The optical gain estimate, if the node has one.
    pub gain: Option<GainEstimate>,
}

/// Version 5: a [`MeasurementV3`]'s content and the node's icing rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MeasurementV5 {
    /// The frame's currents, temperature, flags and detector state.
    pub measurement: Measurement,
    /// The ice estimate after this frame, if any.
    pub estimate: Option<IceEstimate>,
    /// The optical gain estimate, if the node has one.
    pub gain: Option<GainEstimate>,
    /// The icing rate and meteorological icing, if the node has them.
    pub icing: Option<IcingEstimate>,
}

/// Version 5: how fast ice grows on the face now (meteorological icing:
/// ice accreting now, IEA Wind Task 19), as the node's growth history
/// estimates it; the ice present (instrumental icing) is the
/// [`IceEstimate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IcingEstimate {
    /// Posterior mean growth rate, µm/h (0 while nothing grows; saturates
    /// at 65 535 µm/h).
    pub rate_um_per_h: u16,
    /// Its standard deviation, µm/h (saturates).
    pub sigma_um_per_h: u16,
    /// Probability that ice accretes now, ‰ (0–1000).
    pub accreting_permille: u16,
    /// An icing period is on (the probability with hysteresis; its start
    /// and end are [`EventKind::IcingStarted`] / [`EventKind::IcingEnded`]).
    pub accreting: bool,
}

/// Version 3: the sensor's relative optical gain (LED output × fibre
/// coupling × phototransistor responsivity × load resistor, against the
/// gain the node's response table was built for) as the node estimates it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainEstimate {
    /// Estimated gain, ppm (1 000 000 = the response table's gain).
    pub gain_ppm: u32,
    /// Its standard deviation, ppm.
    pub sigma_ppm: u32,
}

impl GainEstimate {
    /// The gain as a plain factor (1.0 = the response table's gain).
    pub fn gain(&self) -> f64 {
        f64::from(self.gain_ppm) * 1e-6
    }

    /// Its standard deviation as a plain factor.
    pub fn sigma(&self) -> f64 {
        f64::from(self.sigma_ppm) * 1e-6
    }
}

/// Version 3: a calibration target's expected net currents at the response
/// table's gain (gain 1), for [`Command::CalibrateGain`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainTarget {
    /// Expected channel 1 net current, nA.
    pub i1_na: u32,
    /// Expected channel 2 net current, nA.
    pub i2_na: u32,
}

/// What covers the sensor face, as the node's estimator sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Medium {
    /// Nothing: a bare, dry face (thickness 0).
    Dry,
    /// Liquid water.
    Water,
    /// Glazed (clear) ice.
    Glazed,
    /// Rime ice (full of air bubbles).
    Rime,
}

impl Medium {
    /// The medium as a lower-case word, `dry`, `water`, `glazed` or `rime`.
    pub const fn name(self) -> &'static str {
        match self {
            Medium::Dry => "dry",
            Medium::Water => "water",
            Medium::Glazed => "glazed",
            Medium::Rime => "rime",
        }
    }
}

/// The node's estimate of the accretion: thickness with its uncertainty and
/// the most likely medium (posterior of the node's Bayes filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IceEstimate {
    /// Posterior mean thickness, µm (saturates at 65 535 µm).
    pub thickness_um: u16,
    /// Posterior standard deviation of the thickness, µm (saturates).
    pub sigma_um: u16,
    /// The most likely medium.
    pub medium: Medium,
    /// Posterior probability of that medium, ‰ (0–1000).
    pub probability_permille: u16,
}

/// A transition of the detector or of a fault.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Event {
    /// Milliseconds since boot.
    pub uptime_ms: u64,
    /// What happened.
    pub kind: EventKind,
    /// Channel 1 net current of the frame that caused it, nA.
    pub i1_na: i32,
    /// Channel 2 net current of the frame that caused it, nA.
    pub i2_na: i32,
    /// Channel 1 rise over its dark baseline, nA (what the rule compares).
    pub rise1_na: i32,
    /// Air temperature, 0.01 °C.
    pub temperature_centi_c: i16,
    /// Consecutive frames that met the condition.
    pub frames: u16,
}

/// Kinds of [`Event`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EventKind {
    /// Dry/wet → ice: the alarm output goes on.
    IceOnset,
    /// Ice → dry/wet: the alarm output goes off.
    IceCleared,
    /// Dry → wet: a water film above the freezing limit (no alarm).
    WetOnset,
    /// Wet → dry.
    WetCleared,
    /// Fault bits (see [`flags::FAULT_MASK`]) that became set.
    FaultRaised(u16),
    /// Fault bits that became clear.
    FaultCleared(u16),
    /// Version 3: sent once after a boot that followed a panic reset.
    PanicReset {
        /// Source line of the panic in the firmware (0 when unknown).
        line: u32,
        /// Panic resets in a row, this one included; at the node's limit it
        /// boots without its flash store (`STORE_SKIPPED`).
        resets_in_row: u8,
    },
    /// Version 5: an icing period starts (P(accreting) rose above the
    /// node's start threshold): ice accretes now.
    IcingStarted,
    /// Version 5: the icing period ends (P(accreting) fell below the end
    /// threshold): nothing accretes now (ice may remain).
    IcingEnded,
    /// Version 6: a new image passed its self-test on its trial boot and is
    /// confirmed: it runs from now on.
    ImageConfirmed {
        /// The confirmed image's version.
        version: crate::FirmwareVersion,
    },
    /// Version 6: a new image failed its trial boot (no self-test within
    /// its time, a watchdog or a panic); the bootloader put the previous
    /// image back, which sends this once after its boot.
    ImageRolledBack {
        /// The version that failed.
        failed: crate::FirmwareVersion,
        /// The version running again.
        running: crate::FirmwareVersion,
    },
}

impl EventKind {
    /// The kind as a snake_case word without its fault bits (`ice_onset`,
    /// `ice_cleared`, `wet_onset`, `wet_cleared`, `fault_raised`,
    /// `fault_cleared`, `panic_reset`, `icing_started`, `icing_ended`,
    /// `image_confirmed`, `image_rolled_back`): its
    /// name in text formats (scenario files, MQTT payloads).
    pub const fn name(&self) -> &'static str {
        match self {
            EventKind::IceOnset => "ice_onset",
            EventKind::IceCleared => "ice_cleared",
            EventKind::WetOnset => "wet_onset",
            EventKind::WetCleared => "wet_cleared",
            EventKind::FaultRaised(_) => "fault_raised",
            EventKind::FaultCleared(_) => "fault_cleared",
            EventKind::PanicReset { .. } => "panic_reset",
            EventKind::IcingStarted => "icing_started",
            EventKind::IcingEnded => "icing_ended",
            EventKind::ImageConfirmed { .. } => "image_confirmed",
            EventKind::ImageRolledBack { .. } => "image_rolled_back",
        }
    }
}

/// A command carried out; `id` is the command's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ack {
    /// The id of the [`HostFrame`] answered.
    pub id: u16,
    /// What the command produced.
    pub result: AckResult,
}

/// The result carried by an [`Ack`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AckResult {
    /// Answer to [`Command::GetInfo`].
    Info(Hello),
    /// Answer of a version-1/2 node to [`Command::GetConfig`] and of any
    /// node to [`Command::SetConfig`] (the config now in force, in the
    /// version-1 shape).
    Config(ConfigV1),
    /// Streaming runs at this frame period.
    Streaming {
        /// Output frame period, ms.
        frame_period_ms: u32,
    },
    /// Streaming stopped.
    Stopped,
    /// Dark calibration done: the new baseline (net currents of a dry face).
    DarkCalibrated(Baseline),
    /// The alarm was acknowledged.
    AlarmAcknowledged,
    /// The node resets right after this frame.
    Resetting,
    /// Version 3: answer to [`Command::GetConfig`] and
    /// [`Command::SetConfigV3`]: the whole config now in force.
    ConfigV3(Config),
    /// Version 3: gain calibration done: the gain now in force (it becomes
    /// the estimator's prior and is saved).
    GainCalibrated(GainEstimate),
    /// Version 3: the learned gain was forgotten; the estimator starts again
    /// from its wide prior.
    GainReset,
    /// Version 4: answer to [`Command::AckAlarmV4`] when no alarm is on:
    /// there was nothing to acknowledge and nothing changed.
    NoAlarm,
    /// Version 5: answer to [`Command::GetLinkSettings`] and
    /// [`Command::SetLinkSettings`]: the link settings now stored (a
    /// change of protocol takes effect after this answer).
    LinkSettings(crate::LinkSettings),
    /// Version 6: answer to the transfer's commands ([`Command::UpdateBegin`],
    /// [`Command::UpdateChunk`], [`Command::GetUpdateStatus`],
    /// [`Command::UpdateVerify`], [`Command::UpdateAbort`]): where it stands.
    UpdateStatus(crate::UpdateStatus),
    /// Version 6: answer to [`Command::GetImageInfo`].
    ImageInfo(crate::ImageInfo),
    /// Version 6: answer to [`Command::UpdateCommit`]: the node resets
    /// right after this frame into the new image, on trial.
    UpdateCommitted {
        /// The version the node boots next.
        version: crate::FirmwareVersion,
    },
}

/// Dark (dry-face) baseline of both channels, subtracted by the ice rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Baseline {
    /// Channel 1 net current of the dry face, nA.
    pub i1_na: i32,
    /// Channel 2 net current of the dry face, nA.
    pub i2_na: i32,
}

/// A command refused, or a frame that could not be read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorReply {
    /// The id of the command, or `None` when the frame was unreadable.
    pub id: Option<u16>,
    /// Why.
    pub code: ErrorCode,
}

/// Reasons for an [`ErrorReply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// A frame failed COBS decoding or its CRC: nothing was carried out.
    Garbled,
    /// A frame passed its CRC but is not a command of this version.
    UnknownCommand,
    /// A frame was longer than [`MAX_FRAME`](crate::MAX_FRAME).
    Oversized,
    /// The config was refused; nothing changed.
    InvalidConfig(ConfigError),
    /// The requested frame period is out of range.
    InvalidRate,
    /// Dark calibration refused: the channels are not steady or saturated.
    CalibrationFailed,
    /// Writing flash failed; the change holds until the next reset.
    StorageFailed,
    /// Version 2: dark calibration refused because the detector is not
    /// `Dry` (water or ice on the face would become the baseline).
    NotDry,
    /// Version 3: a dark or gain calibration was refused, and why. (A
    /// version-3 node sends this instead of `CalibrationFailed`.)
    CalibrationRefused(CalibrationRefusal),
    /// Version 4: an unforced [`Command::CalibrateDarkV4`] was refused
    /// because the new baseline is further from the stored one than the
    /// noise allows (something on the face, or the optics changed). The
    /// old `CalibrateDark` is answered `NotDry` for the same refusal.
    BaselineShift(BaselineShift),
    /// Version 4: [`Command::CalibrateDarkV4`] refused because the detector
    /// is not `Dry`, with what it sees (the old command gets `NotDry`).
    FaceNotDry(FaceReading),
    /// Version 5: [`Command::SetLinkSettings`] refused; nothing changed.
    InvalidLinkSettings(crate::LinkSettingsError),
    /// Version 6: a piece of a firmware transfer refused; nothing changed.
    UpdateRefused(crate::UpdateRefusal),
}

/// Version 4: a dark calibration that would move the baseline too far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BaselineShift {
    /// The baseline in force (the stored one).
    pub old: Baseline,
    /// The baseline this calibration measured (not applied).
    pub new: Baseline,
    /// The largest shift of either channel accepted without `force`, nA.
    pub allowed_na: u32,
}

impl BaselineShift {
    /// The larger of the two channels' shifts, nA.
    pub fn shift_na(&self) -> u32 {
        let d = |a: i32, b: i32| (i64::from(b) - i64::from(a)).unsigned_abs();
        d(self.old.i1_na, self.new.i1_na)
            .max(d(self.old.i2_na, self.new.i2_na))
            .min(u64::from(u32::MAX)) as u32
    }
}

/// Version 4: what the detector sees when a dark calibration finds the
/// face not dry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaceReading {
    /// The ice rule's state (`Wet` or `Ice`).
    pub state: DetectorState,
    /// Channel 1 rise over the baseline of the last valid frame, nA.
    pub rise1_na: i32,
}

/// Version 3: why a calibration was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationRefusal {
    /// A channel saturated (too much ambient light).
    Saturated,
    /// The currents drifted steadily during the calibration (a trend).
    Trend,
    /// The currents jumped during the calibration (a step: a cloud edge,
    /// a hand, a drop).
    Step,
    /// The noise was too high to reach the required accuracy in the time
    /// the calibration may take.
    Noisy,
    /// The gain the target implies is outside what the node accepts.
    ImplausibleGain,
    /// The target's expected currents are unusable (zero, or too small to
    /// measure).
    InvalidTarget,
}

impl CalibrationRefusal {
    /// A short sentence for users.
    pub const fn describe(self) -> &'static str {
        match self {
            CalibrationRefusal::Saturated => "a channel saturated (too much ambient light)",
            CalibrationRefusal::Trend => "the currents drifted during the calibration",
            CalibrationRefusal::Step => {
                "the currents jumped during the calibration (light changed, something moved)"
            }
            CalibrationRefusal::Noisy => "too noisy to reach the required accuracy in time",
            CalibrationRefusal::ImplausibleGain => {
                "the implied gain is outside the plausible range"
            }
            CalibrationRefusal::InvalidTarget => "the target's expected currents are unusable",
        }
    }
}

/// A frame from the host: an id (echoed in the answer) and a command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HostFrame {
    /// Chosen by the host; the node's [`Ack`] or [`ErrorReply`] carries it back.
    pub id: u16,
    /// The command.
    pub cmd: Command,
}

/// Commands from the host. Every one is answered by an `Ack` or an `Error`.
// `UpdateChunk` carries its 256 bytes inline: no_std has no box, and a
// command lives once, on the stack of the dispatch that carries it out.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Answer with the node's [`Hello`].
    GetInfo,
    /// Answer with the config in force.
    GetConfig,
    /// Validate, apply and persist a config of the version-1 shape (a
    /// version-3 node keeps its values of the newer fields).
    SetConfig(ConfigV1),
    /// Stream measurements at this frame period (ms), or at the config's when `None`.
    StartStream {
        /// Output frame period, ms; `None` = the config's `frame_period_ms`.
        frame_period_ms: Option<u32>,
    },
    /// Stop streaming measurements (events and answers still flow).
    StopStream,
    /// Take the current readings of a dry, clean face as the dark baseline.
    CalibrateDark,
    /// Acknowledge the ice alarm.
    AckAlarm,
    /// Reset the node.
    Reset,
    /// Version 3: validate, apply and persist a whole config.
    SetConfigV3(Config),
    /// Version 3: with a reference target of known response on the face,
    /// measure the optical gain and make it the estimator's prior.
    CalibrateGain(GainTarget),
    /// Version 3: forget the learned optical gain (back to the wide prior).
    ResetGain,
    /// Version 4: a dark calibration guarded against moving the baseline
    /// further than the noise allows from the stored one; `force` takes the
    /// reading anyway (the user asserts the face is clean and dry: a new
    /// LED, a cleaned window). Refusals: `FaceNotDry`, `BaselineShift`,
    /// `CalibrationRefused`.
    CalibrateDarkV4 {
        /// Skip the dry-state and baseline-shift guards (never the checks
        /// of the reading itself: step, trend, noise, saturation).
        force: bool,
    },
    /// Version 4: acknowledge the ice alarm; answered `NoAlarm` when none
    /// is on.
    AckAlarmV4,
    /// Version 5: answer with the link settings ([`AckResult::LinkSettings`]).
    GetLinkSettings,
    /// Version 5: validate, store and apply the link settings: the protocol
    /// (framed or Modbus RTU), the Modbus address and parity. The answer
    /// goes out in the old protocol; the new one is in force after it.
    SetLinkSettings(crate::LinkSettings),
    /// Version 6: start a firmware transfer, or resume the one in progress
    /// when the digest is its (`protocol/src/update.rs`).
    UpdateBegin(crate::UpdateBegin),
    /// Version 6: write one piece of the image at the offset the node expects.
    UpdateChunk(crate::UpdateChunk),
    /// Version 6: where the transfer stands (after a link drop or a power cut).
    GetUpdateStatus,
    /// Version 6: check the whole image (digest, trailer, version rule,
    /// signature); nothing is marked.
    UpdateVerify(crate::ImageSignature),
    /// Version 6: boot the verified image next, on trial; the node resets
    /// after the answer.
    UpdateCommit,
    /// Version 6: abandon the transfer (the slot is never booted).
    UpdateAbort,
    /// Version 6: which image runs ([`AckResult::ImageInfo`]).
    GetImageInfo,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flag_names_cover_every_defined_bit_once() {
        let mut all = 0u16;
        for (bit, name) in flags::NAMES {
            assert_eq!(bit.count_ones(), 1, "{name}");
            assert_eq!(all & bit, 0, "{name} listed twice");
            all |= bit;
            assert_eq!(flags::name(bit), Some(name));
        }
        // Bits 0..=13 are defined, 14 and 15 reserved.
        assert_eq!(all, 0x3FFF);
        assert_eq!(flags::FAULT_MASK & !all, 0);
        assert_eq!(flags::name(1 << 14), None);
        let names: Vec<_> =
            flags::names(flags::ALARM | flags::GAIN_OUT_OF_BAND | (1 << 15)).collect();
        assert_eq!(names, ["alarm", "gain_out_of_band"]);
    }

    #[test]
    fn gain_reads_only_from_version_3_measurements() {
        let m = Measurement {
            uptime_ms: 0,
            i1_na: 0,
            i2_na: 0,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: 0,
            vdda_mv: 3_300,
            flags: 0,
            state: DetectorState::Dry,
        };
        let gain = GainEstimate {
            gain_ppm: 1_150_000,
            sigma_ppm: 60_000,
        };
        let v3 = DeviceMsg::MeasurementV3(MeasurementV3 {
            measurement: m.clone(),
            estimate: None,
            gain: Some(gain),
        });
        assert_eq!(v3.gain(), Some(&gain));
        assert_eq!(v3.measurement(), Some((&m, None)));
        assert!((gain.gain() - 1.15).abs() < 1e-12 && (gain.sigma() - 0.06).abs() < 1e-12);
        assert_eq!(DeviceMsg::Measurement(m).gain(), None);
    }
}
