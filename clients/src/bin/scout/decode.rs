//! `scout decode`: candump text or serial hex to decoded frames.

use std::io::{BufRead, BufWriter, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;
use scout_clients::decode::{decode_line, frame_json, frame_text};
use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;

#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// One JSON object per frame instead of text.
    #[arg(long)]
    json: bool,
    /// The chassis' maximum angular speed in rad/s (100 % of a command's angular byte).
    #[arg(long, default_value_t = DEFAULT_MAX_ANGULAR_SPEED)]
    max_angular: f64,
    /// Lines to decode; standard input when none.
    lines: Vec<String>,
}

pub fn run(args: &DecodeArgs) -> anyhow::Result<ExitCode> {
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
