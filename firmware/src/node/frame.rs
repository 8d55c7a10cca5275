//! One output frame: K LED-off/LED-on cycles, the currents, temperatures
//! and V_DDA ([`FrameValues`]), the ice rule, the outputs, the estimator,
//! and what the node reports (the measurement, the rule's transitions, the
//! node's faults raised and cleared).

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{DeviceMsg, Event, EventKind, IceEstimate, Measurement, MeasurementV5, flags};

use super::{Node, Report};
use crate::hal::PhotoAdc;
use crate::ice_rule::RuleInput;
use crate::measure::ntc::{self, NtcReading};
use crate::measure::photocurrent::{self, Currents};
use crate::measure::vref;
use crate::storage::Storage;
use crate::update::UpdateSlots;

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
    /// One output frame: K LED-off/LED-on cycles (settle waits through the
    /// delay), currents, temperature, V_DDA, the ice rule, the outputs, the
    /// ice estimator. Sends a `MeasurementV5` (the measurement with the
    /// estimate, the gain and the icing rate) if streaming, then any
    /// `Event`s (rule transition first, then faults raised/cleared, then
    /// an icing period's start or end).
    pub fn run_frame(&mut self, now_ms: u64, tx: &mut impl FnMut(&[u8])) {
        let values = self.measure_frame();
        let rise1_na = self.rise1_na(values.currents.net_na[0]);
        let valid = values.flags & flags::INVALID_MASK == 0;
        let air_known = values.flags & (flags::NTC_OPEN | flags::NTC_SHORT) == 0;
        let estimate = self.estimate(now_ms, &values, rise1_na, valid);
        self.track_gain(now_ms);
        let transition = self.rule.step(
            &self.config,
            RuleInput {
                rise1_na,
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
        let gain = self.gain_estimate();
        let icing = self.estimator.icing_estimate();
        self.last_report = Some(Report {
            seq: self.seq,
            estimate,
            gain,
            icing,
        });
        if self.streaming {
            let msg = MeasurementV5 {
                measurement: m.clone(),
                estimate,
                gain,
                icing,
            };
            self.send(DeviceMsg::MeasurementV5(msg), tx);
        }
        let event = |kind: EventKind, frames: u16| Event {
            uptime_ms: now_ms,
            kind,
            i1_na: m.i1_na,
            i2_na: m.i2_na,
            rise1_na,
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
        // An icing period (the estimator's P(accreting) with hysteresis).
        let icing = self.estimator.accreting();
        if icing != self.reported_icing {
            let kind = if icing {
                EventKind::IcingStarted
            } else {
                EventKind::IcingEnded
            };
            self.send(DeviceMsg::Event(event(kind, 0)), tx);
            self.reported_icing = icing;
        }
        if let Some((line, resets_in_row)) = self.panic_report.take() {
            let kind = EventKind::PanicReset {
                line,
                resets_in_row,
            };
            self.send(DeviceMsg::Event(event(kind, 1)), tx);
        }
        // The trial boot: confirmed, or a rollback reported (`updating`).
        if let Some(kind) = self.trial_after_frame(now_ms, valid, self.streaming) {
            self.send(DeviceMsg::Event(event(kind, 1)), tx);
        }
        self.last = Some(m);
        // After the frame, so a save's erase never delays a measurement.
        self.poll_storage(now_ms);
    }

    /// The rise of I1 over its dark baseline, nA (the rule's input; the
    /// estimator takes both channels' rises).
    pub(super) fn rise1_na(&self, i1_na: i32) -> i32 {
        let base1_na = self.baseline.map_or(0, |b| b.i1_na);
        i1_na.saturating_sub(base1_na)
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
    ) -> Option<IceEstimate> {
        let dt_s = self
            .last_frame_ms
            .map_or(0.0, |t| now_ms.saturating_sub(t) as f32 / 1000.0);
        self.last_frame_ms = Some(now_ms);
        let base2_na = self.baseline.map_or(0, |b| b.i2_na);
        let rise2_na = values.currents.net_na[1].saturating_sub(base2_na);
        let currents_ua = valid.then_some([rise1_na as f32 * 1e-3, rise2_na as f32 * 1e-3]);
        let ntc_ok = values.flags & (flags::NTC_OPEN | flags::NTC_SHORT) == 0;
        let air_temp_c = ntc_ok.then_some(f32::from(values.temperature_centi_c) * 0.01);
        self.estimator
            .set_optics_temp_c(Some(f32::from(values.optics_centi_c) * 0.01));
        self.estimator.step(dt_s, currents_ua, air_temp_c)
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

    pub(super) fn drive_outputs(&mut self) {
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
    pub(super) fn measure_frame(&mut self) -> FrameValues {
        let cal = self.info.cal;
        let vdda_mv = vref::vdda_mv(&cal, self.adc.read_vrefint());
        let mut flags = 0u16;
        if !vref::vdda_in_range(vdda_mv) {
            flags |= flags::VDDA_OUT_OF_RANGE;
        }
        let conv_mv = vref::vdda_for_conversion(vdda_mv);
        let acq = photocurrent::acquire(
            &mut self.adc,
            &mut self.led,
            &mut self.delay,
            self.config.cycles_per_frame,
            self.config.settle_us,
            photocurrent::saturation_code(conv_mv),
        );
        let currents = photocurrent::currents(
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
}
