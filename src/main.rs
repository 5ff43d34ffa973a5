//! The `fuse1090` binary: a thin clap front end over the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use fuse1090::cmd;
use fuse1090::feed::capture::ClockKind;
use fuse1090::feed::InputFormat;
use fuse1090::fuse::Method;

/// mimalloc, not the system's: its per-thread heaps take the stages' frees
/// of each other's buffers cheaply, and it backs them with huge pages (the
/// tracker's table of aircraft is tens of MB of random access), together
/// 3-5% off `run --capture` on the scale world (fourteen runs spread over
/// an hour and six back to back, each beside the system allocator's;
/// output byte-identical) for 70 MB more memory. The live service turns
/// the huge pages off again (`live::no_huge_pages`).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
        /// How receiver timestamps count time: beast12 (12 MHz counter) or gps.
        #[arg(long, default_value = "beast12")]
        clock: ClockKind,
        /// File to read, or - for stdin (the default).
        input: Option<String>,
    },
    /// The pipeline: live from --config, or offline over a capture.
    Run {
        /// Configuration file (TOML); built-in defaults without it.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Process this capture offline, driven by its own times.
        #[arg(long)]
        capture: Option<PathBuf>,
        /// Where the offline run writes its event stream (JSON lines).
        #[arg(long)]
        output: Option<PathBuf>,
        /// Also publish per-source (adsb, mlat) tracks.
        #[arg(long)]
        source_tracks: bool,
    },
    /// Accuracy of a track stream against the truth of a simulation.
    /// With --seeds N and --scenario (no --truth/--tracks): a Monte Carlo
    /// table of every fusion method over N simulations of the scenario.
    Eval {
        #[arg(long, required_unless_present = "seeds")]
        truth: Option<PathBuf>,
        #[arg(long, required_unless_present = "seeds")]
        tracks: Option<PathBuf>,
        /// Monte Carlo: simulate the scenario under N seeds (1..=N unless
        /// --first-seed says otherwise).
        #[arg(long, requires = "scenario")]
        seeds: Option<u64>,
        /// Monte Carlo: the first of the N seeds, so that seeds a scenario was
        /// tuned on can be left out.
        #[arg(long, requires = "seeds", default_value_t = 1)]
        first_seed: u64,
        /// Monte Carlo: only this fusion method (every one by default); the
        /// single-source rows (MLAT fixes and tracks, ADS-B tracks) come with it.
        #[arg(long, requires = "seeds")]
        method: Option<Method>,
        /// Configuration for the Monte Carlo runs.
        #[arg(long, requires = "seeds")]
        config: Option<PathBuf>,
        /// The simulated scenario: MLAT fixes are then also compared with the
        /// Cramér-Rao bound of their geometry.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Machine-readable report.
        #[arg(long)]
        json: bool,
    },
    /// Simulate a scenario: writes DIR/capture.txt and DIR/truth.jsonl.
    Sim {
        #[arg(long)]
        scenario: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// Stream a capture's receivers to a running daemon over real sockets,
    /// one connection per receiver, in real time (or X times faster).
    Replay {
        capture: PathBuf,
        /// The daemon's configuration: which input takes which receiver.
        #[arg(long)]
        config: PathBuf,
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
    /// Validate a configuration: exit 0, or print every problem with its location.
    CheckConfig { file: PathBuf },
    /// Print a systemd drop-in that limits the service's sockets and peers
    /// to those the configuration names (see systemd/README and docs/service.md).
    UnitLimits {
        file: PathBuf,
        /// A further address the service may talk to (e.g. a Prometheus server).
        #[arg(long)]
        allow: Vec<std::net::IpAddr>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The daemon and replay log what they do; batch commands only problems.
    let live = matches!(&cli.command, Command::Run { capture: None, .. } | Command::Replay { .. });
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(if live { "info" } else { "warn" }));
    // Colours only on a terminal: journald and log files get plain text.
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    tracing_subscriber::fmt().with_env_filter(filter).with_ansi(ansi).with_writer(std::io::stderr).init();
    let result = match cli.command {
        Command::Decode { format, reference, clock, input } => {
            cmd::decode::run(cmd::decode::DecodeArgs { format, reference, clock, input })
        }
        Command::Run { config, capture, output, source_tracks } => {
            cmd::run::run(cmd::run::RunArgs { config, capture, output, source_tracks })
        }
        Command::Sim { scenario, out } => cmd::sim::run(&scenario, &out),
        Command::Replay { capture, config, speed } => cmd::replay::run(&capture, &config, speed),
        Command::CheckConfig { file } => cmd::check_config(&file),
        Command::UnitLimits { file, allow } => cmd::unit_limits::run(&file, &allow),
        Command::Eval { truth, tracks, scenario, seeds, first_seed, method, config, json } => {
            match (seeds, truth, tracks) {
                (Some(n), _, _) => cmd::eval::monte_carlo(cmd::eval::MonteCarloArgs {
                    scenario: scenario.as_deref(),
                    seeds: first_seed..first_seed.saturating_add(n),
                    method,
                    config: config.as_deref(),
                    json,
                }),
                (None, Some(truth), Some(tracks)) => {
                    cmd::eval::run(&truth, &tracks, scenario.as_deref(), json)
                }
                _ => Err(anyhow::anyhow!("eval needs --truth and --tracks, or --scenario and --seeds")),
            }
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
