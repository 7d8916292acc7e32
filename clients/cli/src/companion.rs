//! `scout ros2`, `scout record`, `scout foxglove`, `scout web` and `scout doctor`: run a companion
//! program (`scout-ros2`, `scout-foxglove`, `scout-web`, `scout-doctor`) with the same arguments.
//! The ROS 2 bridge, the Foxglove SDK, the web server and the gateway's device code live in crates
//! of their own (`clients/ros2`, `clients/foxglove`, `clients/web`, `clients/doctor`), so `scout`
//! carries none of them.

use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Command, ExitCode};

use clap::Args;

/// Everything after the subcommand, for the companion program.
#[derive(Debug, Args)]
pub struct CompanionArgs {
    /// Arguments for the program (`--help` lists them).
    #[arg(
        trailing_var_arg = true,
        allow_hyphen_values = true,
        value_name = "ARGS"
    )]
    args: Vec<OsString>,
}

/// A program that serves some `scout` subcommands, and the crate that installs it.
#[derive(Debug, Clone, Copy)]
pub struct Companion {
    /// The executable's name.
    pub program: &'static str,
    /// Its crate's folder, for the install hint.
    pub crate_path: &'static str,
}

/// `scout ros2`.
pub const ROS2: Companion = Companion {
    program: "scout-ros2",
    crate_path: "clients/ros2",
};

/// `scout record`, `scout foxglove`.
pub const FOXGLOVE: Companion = Companion {
    program: "scout-foxglove",
    crate_path: "clients/foxglove",
};

/// `scout web`.
pub const WEB: Companion = Companion {
    program: "scout-web",
    crate_path: "clients/web/cli",
};

/// `scout doctor`.
pub const DOCTOR: Companion = Companion {
    program: "scout-doctor",
    crate_path: "clients/doctor",
};

/// The program beside this executable (an install or a cargo build puts them together), else
/// the one on PATH.
fn program(name: &str) -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(name)))
        .filter(|path| path.is_file())
        .unwrap_or_else(|| PathBuf::from(name))
}

/// Runs `companion` with `leading` and then the user's arguments, in this process.
pub fn run(
    companion: Companion,
    leading: &[&str],
    args: &CompanionArgs,
) -> anyhow::Result<ExitCode> {
    let program = program(companion.program);
    // On success `exec` does not return: the program takes this process, its signals and its
    // exit code.
    let error = Command::new(&program).args(leading).args(&args.args).exec();
    Err(anyhow::anyhow!(
        "cannot run {}: {error}; this command needs the {} program beside scout or on PATH \
         (`cargo install --locked --path {}`, or `cargo build --release --locked` for every program)",
        program.display(),
        companion.program,
        companion.crate_path,
    ))
}
