//! `scout decode`: candump text or serial hex to decoded frames, protocol v1 or v2.

use std::io::{BufRead, BufWriter, Write};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, ValueEnum};
use scout_clients::decode::{Protocol, decode_line, frame_json, frame_text};
use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;

#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// One JSON object per frame instead of text.
    #[arg(long)]
    json: bool,
    /// The chassis' maximum angular speed in rad/s (100 % of a command's angular byte).
    #[arg(long, default_value_t = DEFAULT_MAX_ANGULAR_SPEED)]
    max_angular: f64,
    /// The protocol of CAN frames: by their ids (v1's and v2's do not overlap), or forced.
    #[arg(long, value_enum, default_value_t = ProtocolArg::Auto)]
    protocol: ProtocolArg,
    /// Lines to decode, or files of them (an argument that names a file, as a black box's,
    /// is read line by line); standard input when none.
    #[arg(value_name = "LINE|FILE")]
    lines: Vec<String>,
}

/// `--protocol`.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum ProtocolArg {
    /// v1 ids as v1, v2 ids as v2.
    Auto,
    /// Protocol v1 (the 2019 SCOUT) only.
    V1,
    /// Protocol v2 (SCOUT 2.0, SCOUT MINI) only.
    V2,
}

pub fn run(args: &DecodeArgs) -> anyhow::Result<ExitCode> {
    let protocol = match args.protocol {
        ProtocolArg::Auto => Protocol::Auto,
        ProtocolArg::V1 => Protocol::V1,
        ProtocolArg::V2 => Protocol::V2,
    };
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut bad_lines = 0usize;
    let mut decode_one = |number: &str, line: &str| -> anyhow::Result<()> {
        // Blank lines, and `#` comments (a black box's header).
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            return Ok(());
        }
        match decode_line(line, protocol) {
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
            decode_one(&(index + 1).to_string(), &line)?;
        }
    } else {
        for (index, argument) in args.lines.iter().enumerate() {
            let path = std::path::Path::new(argument);
            if !path.is_file() {
                decode_one(&(index + 1).to_string(), argument)?;
                continue;
            }
            let file =
                std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
            for (number, line) in std::io::BufReader::new(file).lines().enumerate() {
                let line = line.with_context(|| format!("reading {}", path.display()))?;
                decode_one(&format!("{}:{}", path.display(), number + 1), &line)?;
            }
        }
    }
    out.flush()?;
    if bad_lines > 0 {
        eprintln!("scout decode: {bad_lines} line(s) could not be decoded");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
