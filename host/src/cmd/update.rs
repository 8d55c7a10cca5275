//! `foisctl update --port P --image F`: send a signed image to a node over
//! its link with a progress bar (bytes, rate, time left), resumable (run it
//! again after a cut: the node keeps what it has), each refusal named and
//! given its own exit code (`exit::UPDATE_TABLE`). The driver is
//! `fois_link::update`'s.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use fois_link::text::version_text;
use fois_link::update::{Step, UpdateEvent, UpdateOptions, update};
use fois_link::{Link, open_port};
use indicatif::{ProgressBar, ProgressStyle};

use super::args::PortArgs;
use super::sign::read_image;

/// `foisctl update`.
#[derive(Debug, Args)]
pub struct UpdateArgs {
    /// The serial port of the node.
    #[command(flatten)]
    pub port: PortArgs,
    /// The signed image (`foisctl sign`).
    #[arg(long, value_name = "IMAGE.fois")]
    pub image: PathBuf,
    /// How long one command waits for its answer, ms.
    #[arg(long, default_value_t = fois_protocol::REPLY_TIMEOUT_MS, value_name = "MS",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub timeout_ms: u64,
    /// How long a down link (no answers, port gone) is tried again before
    /// giving up (exit 4; run again to continue), s.
    #[arg(long, default_value_t = 60, value_name = "S",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub resume_timeout_s: u64,
    /// How long the new image has to boot and confirm itself (its
    /// self-test), s.
    #[arg(long, default_value_t = 120, value_name = "S",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub confirm_timeout_s: u64,
    /// Leave the node's measurement stream running during the transfer
    /// (by default it is stopped, and started again at the end, to give the
    /// transfer the line; the node measures and drives its alarm either way).
    #[arg(long)]
    pub keep_stream: bool,
    /// No progress bar: one line per step (logs, scripts).
    #[arg(long)]
    pub plain: bool,
}

impl UpdateArgs {
    /// The driver's options.
    pub fn options(&self) -> UpdateOptions {
        UpdateOptions {
            reply_timeout: Duration::from_millis(self.timeout_ms),
            resume_timeout: Duration::from_secs(self.resume_timeout_s),
            confirm_timeout: Duration::from_secs(self.confirm_timeout_s),
            quiet_stream: !self.keep_stream,
            ..UpdateOptions::default()
        }
    }
}

/// What a step is doing, for the bar's message.
fn step_text(step: Step) -> &'static str {
    match step {
        Step::Connect => "connecting",
        Step::Begin => "beginning (the node erases its update slot)",
        Step::Transfer => "sending",
        Step::Verify => "verifying (digest, trailer, version, signature)",
        Step::Commit => "committing",
        Step::Reboot => "waiting for the node to boot the new image",
        Step::Confirm => "waiting for the new image to confirm itself",
    }
}

/// `foisctl update ...`.
pub fn run(args: &UpdateArgs) -> anyhow::Result<()> {
    let image = read_image(&args.image)?;
    println!(
        "image {} for {}: {} bytes to send",
        version_text(image.version()),
        image.board_name(),
        image.image_len()
    );
    let path = args.port.port.clone();
    let baud = args.port.baud;
    let port = open_port(&path, baud)?;
    let mut link = Link::new(port, path.clone());
    let _ = link.port_mut().clear(serialport::ClearBuffer::Input);

    let bar = if args.plain {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(u64::from(image.image_len()))
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{msg}\n[{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} ETA {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let plain = args.plain;
    let mut on_event = |e: UpdateEvent| match e {
        UpdateEvent::Step(s) => {
            if plain {
                println!("{}", step_text(s));
            }
            bar.set_message(step_text(s));
        }
        UpdateEvent::Progress { done, .. } => bar.set_position(u64::from(done)),
        UpdateEvent::Retry { step, offset } => bar.println(format!(
            "no answer or a garbled one at {} (byte {offset}): sent again",
            step.name()
        )),
        UpdateEvent::Resumed { from } => {
            bar.set_position(u64::from(from));
            bar.println(format!("the node has {from} bytes: continuing from there"));
        }
    };
    let mut reopen = || open_port(&path, baud);
    let result = update(
        &mut link,
        &image,
        &args.options(),
        Some(&mut reopen),
        &mut on_event,
    );
    bar.finish_and_clear();
    let report = result?;
    if report.already_running {
        println!(
            "the node runs {} already, confirmed: nothing sent",
            version_text(report.running)
        );
    } else {
        println!(
            "updated {} -> {}: confirmed after its trial boot; transfer {:.1} s{}{}",
            version_text(report.from_version),
            version_text(report.running),
            report.transfer_time.as_secs_f64(),
            if report.started_at > 0 {
                format!(", continued from byte {}", report.started_at)
            } else {
                String::new()
            },
            if report.retries + report.resumes > 0 {
                format!(", {} resent, {} resumed", report.retries, report.resumes)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}
