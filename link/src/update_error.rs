//! What the update driver ([`crate::update`]) reports: the steps of a
//! transfer, its events (progress, retries, resumes), its report, and every
//! way it can fail, each named.

use std::time::Duration;

use fois_protocol::{ErrorCode, FirmwareVersion, ImageState, UpdateRefusal};

use crate::LinkError;
use crate::text::version_text;

/// The steps of an update, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Handshake and `GetImageInfo`.
    Connect,
    /// `UpdateBegin` (the node erases its slot, or resumes).
    Begin,
    /// `UpdateChunk`s.
    Transfer,
    /// `UpdateVerify`.
    Verify,
    /// `UpdateCommit`.
    Commit,
    /// Waiting for the node to boot the new image (its `Hello`).
    Reboot,
    /// Waiting for the new image to confirm itself (or roll back).
    Confirm,
}

impl Step {
    /// The step as a word (MQTT payloads, messages).
    pub const fn name(self) -> &'static str {
        match self {
            Step::Connect => "connect",
            Step::Begin => "begin",
            Step::Transfer => "transfer",
            Step::Verify => "verify",
            Step::Commit => "commit",
            Step::Reboot => "reboot",
            Step::Confirm => "confirm",
        }
    }
}

/// What the driver tells its caller as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum UpdateEvent {
    /// A step starts.
    Step(Step),
    /// Bytes of the image the node has (`done` of `total`).
    Progress {
        /// Bytes the node vouches for.
        done: u32,
        /// Bytes of body and trailer.
        total: u32,
    },
    /// A command is sent again (no answer in time, or a garbled one).
    Retry {
        /// The step.
        step: Step,
        /// The image offset, during the transfer.
        offset: u32,
    },
    /// The transfer continues where the node says (a previous run's bytes,
    /// or after a link drop or a node reset).
    Resumed {
        /// The node's next offset.
        from: u32,
    },
}

/// How an update ended well.
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateReport {
    /// The version the node ran before.
    pub from_version: FirmwareVersion,
    /// The version it runs now (the image's).
    pub running: FirmwareVersion,
    /// The node already ran this image, confirmed: nothing was sent.
    pub already_running: bool,
    /// Where the first begin started (non-zero: a previous run's bytes
    /// were kept).
    pub started_at: u32,
    /// Commands sent again.
    pub retries: u32,
    /// Times the transfer was picked up again where the node said: after a
    /// link drop or a reset, or a resent chunk it had taken already.
    pub resumes: u32,
    /// Time from the first begin to the verify's answer.
    pub transfer_time: Duration,
}

/// Why an update failed. Nothing the node did not verify is ever booted.
#[derive(Debug, thiserror::Error)]
pub enum UpdateError {
    /// Connecting failed (port, handshake, incompatible node).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The node's protocol has no update commands.
    #[error(
        "the node speaks protocol version {node}; updates over the link need version \
         {since} or later (update this node once with a debug probe: `cargo fw-run`)"
    )]
    NodeTooOld {
        /// The node's protocol version.
        node: u16,
        /// The first version with the update commands.
        since: u16,
    },
    /// The image (checked on the host against the node's image info) or a
    /// piece of the transfer (by the node) was refused.
    #[error("{} refused at {}: {}{}", if *.by_host { "the image was" } else { "the node" },
            .step.name(), .refusal.describe(), refusal_detail(.refusal))]
    Refused {
        /// Where.
        step: Step,
        /// Why.
        refusal: UpdateRefusal,
        /// Checked on the host before anything was sent.
        by_host: bool,
    },
    /// The node answered with another error.
    #[error("the node answered {code:?} at {}{}", .step.name(),
            if matches!(.code, ErrorCode::UnknownCommand) {
                " (its firmware does not know the update commands: no updater built in)"
            } else { "" })]
    NodeError {
        /// Where.
        step: Step,
        /// Its code.
        code: ErrorCode,
    },
    /// The node answered something that is not the answer of the step.
    #[error("unexpected answer at {}: {answer}", .step.name())]
    Unexpected {
        /// Where.
        step: Step,
        /// The answer, as text.
        answer: String,
    },
    /// The link stayed down (no answer, port gone) longer than allowed. The
    /// node keeps what it has: running the update again continues.
    #[error(
        "the link to the node stayed down at {} for {waited_ms} ms ({cause}); the node has \
         {offset} of {total} bytes: run the update again to continue from there",
        .step.name()
    )]
    LinkDown {
        /// Where.
        step: Step,
        /// Bytes the node had, as last known.
        offset: u32,
        /// Bytes of the image.
        total: u32,
        /// How long the driver tried.
        waited_ms: u64,
        /// The last failure.
        cause: String,
    },
    /// The node did not come back after its commit.
    #[error("the node did not come back within {waited_ms} ms of the commit")]
    NoBoot {
        /// How long the driver waited.
        waited_ms: u64,
    },
    /// The new image failed its trial: the bootloader put the old one back.
    #[error(
        "the new image {} failed its trial boot; the node rolled back and runs {}",
        version_text(*.failed), version_text(*.running)
    )]
    RolledBack {
        /// The version that failed.
        failed: FirmwareVersion,
        /// The version running again.
        running: FirmwareVersion,
    },
    /// The node came back but did not confirm the new image in time.
    #[error(
        "the node runs {} ({state:?}) and did not confirm {} within {waited_ms} ms",
        version_text(*.running), version_text(*.expected)
    )]
    NotConfirmed {
        /// The version it runs.
        running: FirmwareVersion,
        /// The image's version.
        expected: FirmwareVersion,
        /// Its boot state, as last known.
        state: ImageState,
        /// How long the driver waited.
        waited_ms: u64,
    },
}

/// The numbers of a refusal, after its sentence.
fn refusal_detail(r: &UpdateRefusal) -> String {
    match *r {
        UpdateRefusal::BadLength { max_bytes } => format!(" (the slot takes {max_bytes} bytes)"),
        UpdateRefusal::OutOfOrder { expected_offset } => {
            format!(" (expected offset {expected_offset})")
        }
        UpdateRefusal::Incomplete { next_offset } => format!(" (next offset {next_offset})"),
        UpdateRefusal::OlderVersion { running, image } => format!(
            " (running {}, image {}; sign with --downgrade to go back on purpose)",
            version_text(running),
            version_text(image)
        ),
        _ => String::new(),
    }
}
