//! The command dispatch: bytes from the host link become frames, each frame
//! one command carried out by the node ([`Node::handle_rx`] →
//! `execute`, one `match` over every [`Command`]), answered by an `Ack` or an
//! `Error`; the user button runs the same path. Also the pure pieces: frame
//! errors → replies, a `StartStream` rate checked against the config.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{
    Ack, AckResult, Command, Config, ConfigV1, DetectorState, DeviceMsg, ErrorCode, ErrorReply,
    FaceReading, FrameError, GainTarget, HostFrame, flags,
};

use super::Node;
use super::updating::refusal_code;
use crate::calibration::{dark, gain};
use crate::hal::PhotoAdc;
use crate::storage::Storage;
use crate::update::UpdateSlots;

/// Id of the unsolicited [`fois_protocol::Ack`] frames that report what the
/// user button did (no host command has this id unless the host chooses it).
pub const BUTTON_ID: u16 = u16::MAX;

/// The reply to a frame that could not be read as a command.
pub fn frame_error_reply(err: FrameError) -> ErrorReply {
    let code = match err {
        FrameError::Garbled | FrameError::Crc => ErrorCode::Garbled,
        FrameError::Oversized => ErrorCode::Oversized,
        FrameError::Malformed => ErrorCode::UnknownCommand,
    };
    ErrorReply { id: None, code }
}

/// The answer to the version-1 `CalibrateDark` for a refusal of the guarded
/// calibration: an older host cannot decode the version-4 codes, so "the
/// face is not dry" and "the baseline would move too far" (something on the
/// face) both become the `NotDry` it knows.
pub fn old_dark_code(code: ErrorCode) -> ErrorCode {
    match code {
        ErrorCode::FaceNotDry(_) | ErrorCode::BaselineShift(_) => ErrorCode::NotDry,
        other => other,
    }
}

/// The frame period a `StartStream` asks for, checked by the config rule: the
/// period must be in range and the K cycles must fit in it.
pub fn stream_period(cfg: &Config, requested: Option<u32>) -> Result<u32, ErrorCode> {
    let Some(period) = requested else {
        return Ok(cfg.frame_period_ms);
    };
    let trial = Config {
        frame_period_ms: period,
        ..cfg.clone()
    };
    match trial.validate() {
        Ok(()) => Ok(period),
        Err(_) => Err(ErrorCode::InvalidRate),
    }
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
    /// Bytes received from the host link, in any chunking. Each complete
    /// frame is answered through `tx`: an `Ack`, or an `Error` (garbled,
    /// unknown, out of range). Never stops the measurement.
    pub fn handle_rx(&mut self, bytes: &[u8], now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        for &b in bytes {
            match self.decoder.push::<HostFrame>(b) {
                None => {}
                Some(Ok(frame)) => {
                    self.trial.link_answered();
                    self.execute(frame, now_ms, tx);
                }
                Some(Err(e)) => {
                    self.send(DeviceMsg::Error(frame_error_reply(e)), tx);
                }
            }
        }
    }

    /// The user button (B1). While iced it acknowledges the alarm (the
    /// output stays on while the ice holds); otherwise it runs a dark
    /// calibration (the user cleaned the dry face and pressed the button).
    /// Either way an unsolicited `Ack` (or `Error`) with id
    /// [`BUTTON_ID`] reports what happened. The
    /// acknowledgement never writes flash.
    pub fn button_pressed(&mut self, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let cmd = if self.rule.alarm() {
            Command::AckAlarm
        } else {
            Command::CalibrateDark
        };
        self.execute(HostFrame { id: BUTTON_ID, cmd }, now_ms, tx);
    }

    fn reply(&mut self, id: u16, result: Result<AckResult, ErrorCode>, tx: &mut impl FnMut(&[u8])) {
        let msg = match result {
            Ok(result) => DeviceMsg::Ack(Ack { id, result }),
            Err(code) => DeviceMsg::Error(ErrorReply { id: Some(id), code }),
        };
        self.send(msg, tx);
    }

    fn execute(&mut self, frame: HostFrame, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let result = self.command(frame.cmd, now_ms);
        self.reply(frame.id, result, tx);
    }

    /// Carry out one command and give its result (what the framed link
    /// answers in an `Ack` or `Error`; the Modbus link's writes come here
    /// too, `crate::modbus`).
    pub fn command(&mut self, cmd: Command, now_ms: u64) -> Result<AckResult, ErrorCode> {
        match cmd {
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
                match stream_period(&self.config, frame_period_ms) {
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
            // The version-1 command is guarded as the version-4 one, answered
            // with the codes an older host knows.
            Command::CalibrateDark => self.calibrate_dark(now_ms, false).map_err(old_dark_code),
            Command::CalibrateDarkV4 { force } => self.calibrate_dark(now_ms, force),
            // An older host keeps its answer, alarm or not.
            Command::AckAlarm => {
                self.rule.acknowledge();
                Ok(AckResult::AlarmAcknowledged)
            }
            Command::AckAlarmV4 => Ok(if self.rule.acknowledge() {
                AckResult::AlarmAcknowledged
            } else {
                AckResult::NoAlarm
            }),
            Command::Reset => {
                // Whatever waits to be saved is saved before the reset.
                if self.pending_save.is_some() {
                    self.save(now_ms);
                }
                self.reset_request = true;
                Ok(AckResult::Resetting)
            }
            Command::GetLinkSettings => Ok(AckResult::LinkSettings(self.link)),
            // A change of the link is saved at once and applied by a reset
            // after the answer (which goes out in the old protocol): the
            // board sets its UART up from the record at boot.
            Command::SetLinkSettings(link) => {
                link.validate().map_err(ErrorCode::InvalidLinkSettings)?;
                let changed = link != self.link;
                self.link = link;
                self.changed(now_ms);
                if changed {
                    if self.pending_save.is_some() {
                        self.save(now_ms);
                    }
                    self.reset_request = true;
                }
                Ok(AckResult::LinkSettings(self.link))
            }
            // The firmware transfer (version 6): `updating`, on the update
            // slots (a node without answers `UnknownCommand`).
            Command::UpdateBegin(begin) => self
                .updates
                .begin(&begin)
                .map(AckResult::UpdateStatus)
                .map_err(refusal_code),
            Command::UpdateChunk(chunk) => self
                .updates
                .chunk(&chunk)
                .map(AckResult::UpdateStatus)
                .map_err(refusal_code),
            Command::GetUpdateStatus => self
                .updates
                .status()
                .map(AckResult::UpdateStatus)
                .map_err(refusal_code),
            Command::UpdateVerify(signature) => {
                let board = fois_protocol::Hello::board_from_str(self.info.board);
                self.updates
                    .verify(&signature, &board)
                    .map(AckResult::UpdateStatus)
                    .map_err(refusal_code)
            }
            Command::UpdateCommit => self.commit_update(now_ms),
            Command::UpdateAbort => self
                .updates
                .abort()
                .map(AckResult::UpdateStatus)
                .map_err(refusal_code),
            Command::GetImageInfo => Ok(AckResult::ImageInfo(self.image_info())),
        }
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
            && stream_period(&self.config, Some(p)).is_err()
        {
            self.stream_period_ms = None;
        }
        self.changed(now_ms);
        Ok(())
    }

    /// A dark calibration; unless `force`d, refused when the rule is not
    /// dry (`FaceNotDry`) or the new baseline moved too far from the stored
    /// one (`BaselineShift`, `calibration::dark::check_shift`).
    fn calibrate_dark(&mut self, now_ms: u64, force: bool) -> Result<AckResult, ErrorCode> {
        let state = self.rule.state();
        if !force && state != DetectorState::Dry {
            // An iced or wet face is not a dark reference (water would
            // become the baseline and hide the next film).
            let rise1_na = self.last.as_ref().map_or(0, |m| self.rise1_na(m.i1_na));
            return Err(ErrorCode::FaceNotDry(FaceReading { state, rise1_na }));
        }
        // Average as long as the noise needs, within the time bound; refuse
        // a trend, a step, too much noise or saturation (`calibration::dark`).
        let baseline = dark::run(
            &mut self.adc,
            &mut self.led,
            &mut self.delay,
            &self.config,
            &self.info.cal,
        )
        .map_err(ErrorCode::CalibrationRefused)?
        .baseline;
        if !force {
            dark::check_shift(self.baseline, baseline, &self.config)
                .map_err(ErrorCode::BaselineShift)?;
        }
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
    /// [`gain::GAIN_CAL_FRAMES`] frames (baseline-corrected), fit the
    /// gain, make it the estimator's prior and keep it.
    fn calibrate_gain(&mut self, target: GainTarget, now_ms: u64) -> Result<AckResult, ErrorCode> {
        let mut frames = [None; gain::GAIN_CAL_FRAMES];
        let base = self.baseline.unwrap_or_default();
        let mut optics_c = 0.0f32;
        for f in frames.iter_mut() {
            let v = self.measure_frame();
            optics_c += f32::from(v.optics_centi_c) * 0.01 / gain::GAIN_CAL_FRAMES as f32;
            if v.flags & flags::INVALID_MASK == 0 {
                *f = Some([
                    v.currents.net_na[0].saturating_sub(base.i1_na),
                    v.currents.net_na[1].saturating_sub(base.i2_na),
                ]);
            }
        }
        self.estimator.set_optics_temp_c(Some(optics_c));
        let c = gain::calibrate(&frames, target, self.estimator.compensation())
            .map_err(ErrorCode::CalibrationRefused)?;
        let kept = gain::to_estimate(c.gain, c.sd);
        self.gain_calibration = Some(kept);
        self.gain_kept = Some(kept);
        self.estimator.set_gain_prior(c.gain, c.sd);
        self.changed(now_ms);
        Ok(AckResult::GainCalibrated(kept))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates() {
        let c = Config::default();
        assert_eq!(stream_period(&c, None), Ok(c.frame_period_ms));
        assert_eq!(stream_period(&c, Some(1_000)), Ok(1_000));
        assert_eq!(stream_period(&c, Some(19)), Err(ErrorCode::InvalidRate));
        assert_eq!(
            stream_period(&c, Some(600_001)),
            Err(ErrorCode::InvalidRate)
        );
        assert_eq!(stream_period(&c, Some(0)), Err(ErrorCode::InvalidRate));
    }

    #[test]
    fn an_older_host_gets_codes_it_knows() {
        use fois_protocol::{Baseline, BaselineShift, CalibrationRefusal};
        let shift = ErrorCode::BaselineShift(BaselineShift {
            old: Baseline::default(),
            new: Baseline {
                i1_na: 400,
                i2_na: 0,
            },
            allowed_na: 250,
        });
        let wet = ErrorCode::FaceNotDry(FaceReading {
            state: DetectorState::Wet,
            rise1_na: 1_500,
        });
        assert_eq!(old_dark_code(shift), ErrorCode::NotDry);
        assert_eq!(old_dark_code(wet), ErrorCode::NotDry);
        let step = ErrorCode::CalibrationRefused(CalibrationRefusal::Step);
        assert_eq!(old_dark_code(step), step);
    }

    #[test]
    fn frame_errors() {
        assert_eq!(frame_error_reply(FrameError::Crc).code, ErrorCode::Garbled);
        assert_eq!(
            frame_error_reply(FrameError::Oversized).code,
            ErrorCode::Oversized
        );
        assert_eq!(
            frame_error_reply(FrameError::Malformed).code,
            ErrorCode::UnknownCommand
        );
    }
}
