//! `scout ros2`: runs the `scout-ros2` program with the same arguments. The ROS 2 bridge and its
//! middleware live in a crate of their own (`clients/ros2`), so `scout` carries none of it.

use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Command, ExitCode};

use clap::Args;

#[derive(Debug, Args)]
pub struct Ros2Args {
    /// Arguments for `scout-ros2` (`scout ros2 --help` lists them).
    #[arg(
        trailing_var_arg = true,
        allow_hyphen_values = true,
        value_name = "ARGS"
    )]
    args: Vec<OsString>,
}

/// The program that serves `scout ros2`.
const PROGRAM: &str = "scout-ros2";

/// `scout-ros2` beside this executable (an install or a cargo build puts them together), else
/// the one on PATH.
fn program() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(PROGRAM)))
        .filter(|path| path.is_file())
        .unwrap_or_else(|| PathBuf::from(PROGRAM))
}

pub fn run(args: &Ros2Args) -> anyhow::Result<ExitCode> {
    let program = program();
    // On success `exec` does not return: the bridge takes this process, its signals and its
    // exit code.
    let error = Command::new(&program).args(&args.args).exec();
    Err(anyhow::anyhow!(
        "cannot run {}: {error}; `scout ros2` needs the scout-ros2 program beside scout or on \
         PATH (`cargo install --path clients/ros2`)",
        program.display()
    ))
}
