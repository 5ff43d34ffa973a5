//! Subcommands of the `fuse1090` binary. Each drives the library; none holds
//! processing logic of its own.

pub mod decode;
pub mod eval;
pub mod replay;
pub mod run;
pub mod sim;
pub mod unit_limits;

/// Writes to stdout; a reader that went away (`| head`) is not an error.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// `fuse1090 check-config FILE`: every problem at once, or nothing (exit 0).
pub fn check_config(file: &std::path::Path) -> anyhow::Result<()> {
    crate::config::Config::load(file)?;
    print_stdout(&format!("{}: ok\n", file.display()))
}
