//! `fuse1090 decode`: frames from a file or stdin to JSON lines, one per Mode S
//! frame, with stateful CPR decoding as a live receiver would do it.

use std::io::{BufWriter, Read, Write};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::feed::capture::ClockKind;
use crate::feed::{detect_format, parser_for, FeedEvent, FeedStats, InputFormat};
use crate::modes::decoder::DecodeStats;
use crate::modes::json::DecodeRecord;
use crate::modes::{Decoder, DecoderConfig};

pub struct DecodeArgs {
    pub format: Option<InputFormat>,
    pub reference: Option<(f64, f64)>,
    pub clock: ClockKind,
    pub input: Option<String>,
}

/// Parses "LAT,LON".
pub fn parse_reference(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s.split_once(',').ok_or("expected LAT,LON")?;
    let lat: f64 = a.trim().parse().map_err(|_| format!("bad latitude {a:?}"))?;
    let lon: f64 = b.trim().parse().map_err(|_| format!("bad longitude {b:?}"))?;
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
        return Err(format!("{lat},{lon} is not a position"));
    }
    Ok((lat, lon))
}

pub fn run(args: DecodeArgs) -> Result<()> {
    let mut input: Box<dyn Read> = match args.input.as_deref() {
        None | Some("-") => Box::new(std::io::stdin().lock()),
        Some(path) => Box::new(std::fs::File::open(path).with_context(|| format!("cannot open {path}"))?),
    };
    let name = args.input.clone().unwrap_or_else(|| "stdin".into());
    let mut buf = vec![0u8; 1 << 16];
    let (format, filled) = detect(&mut input, &mut buf, args.format, &name)?;
    let mut parser = parser_for(format);
    let mut decoder = Decoder::new(DecoderConfig { reference: args.reference, ..Default::default() });
    let mut out = BufWriter::new(std::io::stdout().lock());
    let started = Instant::now();
    let mut arrival: Option<f64> = None;
    let mut io_error: Option<std::io::Error> = None;
    let clock = args.clock;
    let mut handle = |ev: FeedEvent| match ev {
        FeedEvent::ArrivalTime(t) => arrival = Some(t),
        FeedEvent::Frame(frame) => {
            // Data time wherever the data has one; live stdin without timing gets wall time.
            let t = if frame.has_timing() {
                clock.seconds(frame.timestamp)
            } else {
                arrival.unwrap_or_else(|| started.elapsed().as_secs_f64())
            };
            if let Ok(d) = decoder.decode(&frame, t) {
                let rec = DecodeRecord::new(&d, &frame);
                if io_error.is_none() {
                    if let Err(e) = serde_json::to_writer(&mut out, &rec)
                        .map_err(std::io::Error::from)
                        .and_then(|_| out.write_all(b"\n"))
                    {
                        io_error = Some(e);
                    }
                }
            }
        }
        FeedEvent::ReceiverId(_) | FeedEvent::ReceiverUuid(_) => {}
    };
    parser.push(&buf[..filled], &mut handle);
    loop {
        let n = input.read(&mut buf).with_context(|| format!("reading {name}"))?;
        if n == 0 {
            break;
        }
        parser.push(&buf[..n], &mut handle);
    }
    parser.finish(&mut handle);
    if let Some(e) = io_error.or_else(|| out.flush().err()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            return Err(e).context("writing output");
        }
    }
    let (fs, ds) = (parser.stats(), decoder.stats());
    eprintln!("{}", summary(fs, ds, decoder.aircraft_count()));
    if ds.mode_s == 0 {
        bail!("{name}: no Mode S frames found ({} bytes of {format:?} input)", fs.bytes);
    }
    Ok(())
}

/// Reads a prefix of the input into `buf` and finds its format (the one
/// given wins); the format and how much of `buf` was read.
fn detect(
    input: &mut dyn Read,
    buf: &mut [u8],
    given: Option<InputFormat>,
    name: &str,
) -> Result<(InputFormat, usize)> {
    let mut filled = 0;
    while filled < 4096 {
        let n = input.read(&mut buf[filled..]).with_context(|| format!("reading {name}"))?;
        if n == 0 {
            break;
        }
        filled += n;
    }
    match given.or_else(|| detect_format(&buf[..filled])) {
        Some(f) => Ok((f, filled)),
        None if filled == 0 => bail!("{name} is empty"),
        None => bail!("{name} is not Mode S data (neither Beast binary, AVR text nor hex lines)"),
    }
}

/// The run's counts, for stderr.
fn summary(fs: &FeedStats, ds: &DecodeStats, aircraft: usize) -> String {
    format!(
        "decode: {} frames ({} Mode S, {} Mode A/C), {} parity ok, {} corrected, {} parity bad, \
         {} address/parity from unknown addresses, {} garbage bytes, {} broken frames, \
         {} positions ({} unconfirmed), {} aircraft; Comm-B: {} identified, {} ambiguous, \
         {} contradicting the aircraft, {} fitting no register",
        fs.frames(),
        ds.mode_s,
        ds.mode_ac,
        ds.parity_ok,
        ds.corrected,
        ds.parity_bad,
        ds.address_parity_unknown,
        fs.garbage_bytes,
        fs.broken_frames,
        ds.positions_reliable,
        ds.positions_unconfirmed,
        aircraft,
        ds.commb.identified,
        ds.commb.ambiguous,
        ds.commb.contradicted,
        ds.commb.no_register,
    )
}
