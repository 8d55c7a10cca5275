//! `foisctl`: the FOIS host tool. Parses the command line and dispatches it
//! to its command (`fois_host::cmd`); errors become exit codes
//! (`fois_host::exit`).

use clap::Parser;
use fois_host::cmd::Cli;
use fois_host::exit;

fn main() {
    // Die quietly on a closed pipe (`foisctl config get | head -1`) like
    // other Unix tools, instead of failing to print.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE at start-up,
    // before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    // The figures' font is embedded: register it once, before any drawing.
    fois_host::plot::register_fonts();
    if let Err(e) = cli.run() {
        eprintln!("foisctl: error: {e:#}");
        if let Some(h) = exit::hint(&e) {
            eprintln!("foisctl: hint: {h}");
        }
        std::process::exit(exit::code_of(&e));
    }
}
