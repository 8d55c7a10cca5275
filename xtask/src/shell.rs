//! Running programs: echoed, failing on a non-zero exit; whether one is on
//! the `PATH`.

use std::process::Command;

use anyhow::{Context, Result, bail};

/// Run a command, echoing it, failing on a non-zero exit.
pub(crate) fn run(program: &str, args: &[&str]) -> Result<()> {
    eprintln!("\n$ {program} {}", args.join(" "));
    check(Command::new(program).args(args), program, args, "")
}

/// [`run`] in the directory `dir`.
pub(crate) fn run_in(dir: &str, program: &str, args: &[&str]) -> Result<()> {
    eprintln!("\n$ (cd {dir} && {program} {})", args.join(" "));
    check(
        Command::new(program).args(args).current_dir(dir),
        program,
        args,
        &format!(" in {dir}"),
    )
}

/// Run `cmd`; an error names the program, its arguments and `where_`.
fn check(cmd: &mut Command, program: &str, args: &[&str], where_: &str) -> Result<()> {
    let status = cmd
        .status()
        .with_context(|| format!("could not start `{program}`"))?;
    if !status.success() {
        bail!("`{program} {}`{where_} failed ({status})", args.join(" "));
    }
    Ok(())
}

/// Whether `program` is on the `PATH`.
pub(crate) fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program} >/dev/null 2>&1")])
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}
