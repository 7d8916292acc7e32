//! `scout`: the command-line tool for a SCOUT chassis. Exit codes: 0 success, 1 the command ran
//! but something it was given was bad (a line `scout decode` could not decode), 2 usage error.

use std::io::{BufRead, BufWriter, ErrorKind, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use scout_clients::decode::{decode_line, frame_json, frame_text};
use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;

/// Command-line tool for an AgileX SCOUT chassis.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Decode candump lines (screen, log or compact format) or serial frames as hex.
    ///
    /// Reads the lines given as arguments, or standard input when there are none:
    /// `candump can0 | scout decode`. Prints one line (or JSON object) per frame; a bad line is
    /// reported on standard error with its line number and the rest is still decoded.
    Decode(DecodeArgs),
}

#[derive(Debug, Args)]
struct DecodeArgs {
    /// One JSON object per frame instead of text.
    #[arg(long)]
    json: bool,
    /// The chassis' maximum angular speed in rad/s (100 % of a command's angular byte).
    #[arg(long, default_value_t = DEFAULT_MAX_ANGULAR_SPEED)]
    max_angular: f64,
    /// Lines to decode; standard input when none.
    lines: Vec<String>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Decode(args) => decode(&args),
    };
    match result {
        Ok(code) => code,
        Err(error) if is_broken_pipe(&error) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error
        .downcast_ref::<std::io::Error>()
        .is_some_and(|e| e.kind() == ErrorKind::BrokenPipe)
}

fn decode(args: &DecodeArgs) -> anyhow::Result<ExitCode> {
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut bad_lines = 0usize;
    let mut decode_one = |number: usize, line: &str| -> anyhow::Result<()> {
        if line.trim().is_empty() {
            return Ok(());
        }
        match decode_line(line) {
            Ok(frames) => {
                for frame in frames {
                    if args.json {
                        writeln!(out, "{}", frame_json(&frame, args.max_angular))?;
                    } else {
                        writeln!(out, "{}", frame_text(&frame, args.max_angular))?;
                    }
                }
            }
            Err(error) => {
                bad_lines += 1;
                eprintln!("scout decode: line {number}: {error}: {}", line.trim());
            }
        }
        Ok(())
    };
    if args.lines.is_empty() {
        for (index, line) in std::io::stdin().lock().lines().enumerate() {
            let line = line.context("reading standard input")?;
            decode_one(index + 1, &line)?;
        }
    } else {
        for (index, line) in args.lines.iter().enumerate() {
            decode_one(index + 1, line)?;
        }
    }
    out.flush()?;
    if bad_lines > 0 {
        eprintln!("scout decode: {bad_lines} line(s) could not be decoded");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
