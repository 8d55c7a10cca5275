//! Pure pieces of command handling: frame errors → replies, rate checks.
//! The commands themselves are carried out by [`crate::node::Node`].

use fois_protocol::{Config, ErrorCode, ErrorReply, FrameError};

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
