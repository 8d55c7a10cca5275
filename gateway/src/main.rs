//! `fois-gateway`: parses the command line, sets up the logs, runs the
//! gateway until Ctrl-C or SIGTERM; errors become exit codes
//! (`fois_gateway::cli`).

use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use fois_gateway::cli::{self, EXIT_NAME_CONFLICT, EXIT_USAGE, GatewayArgs, UsageError};
use fois_gateway::service::NameConflict;

/// Set by Ctrl-C or SIGTERM: the gateway stops cleanly.
static STOP: AtomicBool = AtomicBool::new(false);

fn main() {
    let args = GatewayArgs::parse();
    fois_gateway::logging::init(args.quiet, args.log_time, args.log_to);
    // The first Ctrl-C / SIGTERM stops cleanly; a second one exits at once.
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
    if let Err(e) = cli::run(args, &STOP) {
        eprintln!("fois-gateway: error: {e:#}");
        let code = if e.downcast_ref::<UsageError>().is_some() {
            EXIT_USAGE
        } else if e.downcast_ref::<NameConflict>().is_some() {
            EXIT_NAME_CONFLICT
        } else {
            1
        };
        std::process::exit(code);
    }
}
