//! The `fuse1090` binary: a thin clap front end over the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use fuse1090::cmd;
use fuse1090::feed::InputFormat;

#[derive(Parser)]
#[command(name = "fuse1090", version, about = "ADS-B / Mode S receive-and-fuse daemon")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Decode frames to JSON lines, one per Mode S frame.
    Decode {
        /// Input format (default: detected from the first bytes).
        #[arg(long, value_parser = clap::value_parser!(InputFormat))]
        format: Option<InputFormat>,
        /// Receiver position LAT,LON (deg), for surface and local CPR decoding.
        #[arg(long, value_parser = cmd::decode::parse_reference, allow_hyphen_values = true)]
        reference: Option<(f64, f64)>,
        /// How receiver timestamps count time.
        #[arg(long, value_enum, default_value = "beast12")]
        clock: cmd::decode::ClockKind,
        /// File to read, or - for stdin (the default).
        input: Option<String>,
    },
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Decode { format, reference, clock, input } => {
            cmd::decode::run(cmd::decode::DecodeArgs { format, reference, clock, input })
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fuse1090: {e:#}");
            ExitCode::FAILURE
        }
    }
}
