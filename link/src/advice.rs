//! What to do after a calibration was refused, in words: the node's
//! `ErrorCode` for `calibrate-dark` or `calibrate-gain` turned into the
//! step a user takes next (clean and dry the face, put the target on,
//! shade the face, `--force` when the change is real).

use fois_protocol::{CalibrationRefusal as R, ErrorCode};

use crate::reading::ua;

/// Which calibration was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Calibration {
    /// `calibrate-dark`: the dry, clean face as the dark baseline.
    Dark,
    /// `calibrate-gain`: the reference target on the face.
    Gain,
}

/// The next step after `code` refused `cal`, one or two sentences; `None`
/// for a code that is not a calibration's refusal.
pub fn calibration_advice(cal: Calibration, code: &ErrorCode) -> Option<String> {
    let text = match (code, cal) {
        (ErrorCode::FaceNotDry(f), _) => format!(
            "the node sees water or ice on the face (state {}, I1 rise {:.3} µA): clean and dry \
             the face, wait for the state to read dry, then retry. Only if the face is clean and \
             dry and reads wet because the optics changed (a new LED, much more crosstalk), use \
             --force",
            f.state.name(),
            ua(f.rise1_na.into())
        ),
        (ErrorCode::NotDry, _) => "the node sees water or ice on the face, or the baseline would \
             move further than the noise allows (something on the face): clean and dry the face, \
             wait for the state to read dry, then retry"
            .into(),
        (ErrorCode::BaselineShift(s), _) => format!(
            "the baseline would move from I1 {:.3} → {:.3} µA, I2 {:.3} → {:.3} µA, more than \
             {:.3} µA: something on the face (a starting film, dirt)? Look at it. If the face is \
             clean and dry and the change is real (new LED, cleaned window), use --force",
            ua(s.old.i1_na.into()),
            ua(s.new.i1_na.into()),
            ua(s.old.i2_na.into()),
            ua(s.new.i2_na.into()),
            ua(s.allowed_na.into())
        ),
        (ErrorCode::CalibrationRefused(R::Step), Calibration::Gain) => {
            "no target on the face? Put the reference target on, hold it still, then retry".into()
        }
        (ErrorCode::CalibrationRefused(R::Step), Calibration::Dark) => "the currents jumped: \
             the light changed (a cloud edge) or something moved in front of the face. Keep the \
             face clear, wait for steady light or shade it, then retry"
            .into(),
        (ErrorCode::CalibrationRefused(R::Trend), Calibration::Dark) => "the currents drifted: \
             a film drying off after cleaning, or the light slowly changing. Wait a few minutes \
             for the face to dry, then retry"
            .into(),
        (ErrorCode::CalibrationRefused(R::Trend), Calibration::Gain) => "the currents drifted: \
             the target is sliding or the face under it is drying. Seat the target firmly on \
             the dry face, then retry"
            .into(),
        (ErrorCode::CalibrationRefused(R::Noisy), _) => "too noisy to reach the accuracy in \
             time (flickering light, strong sun): shade the face, then retry"
            .into(),
        (ErrorCode::CalibrationRefused(R::Saturated), _) => {
            "too much ambient light for the channels: shade the face, then retry".into()
        }
        (ErrorCode::CalibrationRefused(R::ImplausibleGain), _) => "the gain the target implies \
             is outside what the node accepts: is the right target on the face, seated flat, \
             and are --i1-ua/--i2-ua its currents at gain 1 (its data sheet)?"
            .into(),
        (ErrorCode::CalibrationRefused(R::InvalidTarget), _) => "the target's currents are \
             zero or too small to measure: check --i1-ua/--i2-ua against its data sheet"
            .into(),
        (ErrorCode::CalibrationFailed, _) => "the channels were not steady or saturated: shade \
             the face, keep it clear, then retry"
            .into(),
        _ => return None,
    };
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::{Baseline, BaselineShift, DetectorState, FaceReading};

    #[test]
    fn every_refusal_says_what_to_do() {
        let shift = ErrorCode::BaselineShift(BaselineShift {
            old: Baseline {
                i1_na: 120,
                i2_na: -40,
            },
            new: Baseline {
                i1_na: 474,
                i2_na: 95,
            },
            allowed_na: 250,
        });
        let a = calibration_advice(Calibration::Dark, &shift).unwrap();
        assert!(a.contains("I1 0.120 → 0.474 µA"), "{a}");
        assert!(
            a.contains("more than 0.250 µA") && a.contains("--force"),
            "{a}"
        );
        let wet = ErrorCode::FaceNotDry(FaceReading {
            state: DetectorState::Wet,
            rise1_na: 1_830,
        });
        let a = calibration_advice(Calibration::Dark, &wet).unwrap();
        assert!(a.contains("state wet, I1 rise 1.830 µA"), "{a}");
        assert!(a.contains("clean and dry the face"), "{a}");
        let step = ErrorCode::CalibrationRefused(R::Step);
        let g = calibration_advice(Calibration::Gain, &step).unwrap();
        assert!(g.starts_with("no target on the face?"), "{g}");
        let d = calibration_advice(Calibration::Dark, &step).unwrap();
        assert!(!d.contains("target"), "{d}");
        for r in [
            R::Saturated,
            R::Trend,
            R::Step,
            R::Noisy,
            R::ImplausibleGain,
            R::InvalidTarget,
        ] {
            for cal in [Calibration::Dark, Calibration::Gain] {
                let code = ErrorCode::CalibrationRefused(r);
                assert!(calibration_advice(cal, &code).is_some(), "{r:?}");
            }
        }
        assert!(calibration_advice(Calibration::Dark, &ErrorCode::NotDry).is_some());
        assert_eq!(
            calibration_advice(Calibration::Dark, &ErrorCode::InvalidRate),
            None
        );
    }
}
