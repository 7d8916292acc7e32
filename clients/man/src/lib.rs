//! The programs' manual pages (section 1), made from their command-line definitions by
//! clap_mangen: `SCOUT_GENERATE_MAN=DIR PROGRAM` writes PROGRAM's pages into DIR and exits, which
//! is how the Debian package gets them (`tests/release/deb`).

use std::io;
use std::path::{Path, PathBuf};

/// The variable that asks a program for its manual pages, naming the directory to write them to.
pub const GENERATE_MAN: &str = "SCOUT_GENERATE_MAN";

/// If [`GENERATE_MAN`] is set: writes the pages of `command` into the directory it names,
/// prints their paths and exits (0; 1 when they could not be written). Otherwise returns.
/// Call it first in `main`, before parsing the arguments.
pub fn exit_if_asked(command: impl FnOnce() -> clap::Command) {
    let Some(dir) = std::env::var_os(GENERATE_MAN) else {
        return;
    };
    let dir = PathBuf::from(dir);
    // The pages are named by the program's file (`scout-gateway`), whatever its usage calls it
    // (`scout doctor`).
    let program = std::env::args_os()
        .next()
        .map(PathBuf::from)
        .and_then(|path| {
            path.file_name()
                .map(|name| name.to_string_lossy().into_owned())
        });
    let mut command = command();
    if let Some(program) = program {
        command = command.name(program);
    }
    match write_pages(&command, &dir) {
        Ok(written) => {
            for path in written {
                println!("{}", path.display());
            }
            std::process::exit(0);
        }
        Err(error) => {
            eprintln!(
                "writing the manual pages into {}: {error} (is it a writable directory?)",
                dir.display()
            );
            std::process::exit(1);
        }
    }
}

/// Writes the page of `command` (`NAME.1`) and of each of its subcommands (`NAME-SUB.1`, as
/// git's), into `dir`; returns their paths. A subcommand that hands its arguments to another
/// program (it takes no `--help` of its own: `scout web` runs `scout-web`) gets no page: that
/// program's page is its page.
pub fn write_pages(command: &clap::Command, dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut command = command.clone();
    command.build();
    let mut written = Vec::new();
    let name = command.get_name().to_owned();
    let version = command.get_version().map(str::to_owned);
    write_page(&command, &name, version.as_deref(), dir, &mut written)?;
    Ok(written)
}

/// Writes the page of `command` as `name`, with the program's `version`, then its subcommands'.
fn write_page(
    command: &clap::Command,
    name: &str,
    version: Option<&str>,
    dir: &Path,
    written: &mut Vec<PathBuf>,
) -> io::Result<()> {
    let mut page = command.clone().name(name.to_owned());
    if let Some(version) = version {
        page = page.version(version.to_owned());
    }
    let mut text = Vec::new();
    clap_mangen::Man::new(page).render(&mut text)?;
    let path = dir.join(format!("{name}.1"));
    std::fs::write(&path, text)?;
    written.push(path);
    for sub in command.get_subcommands() {
        if sub.is_hide_set() || sub.is_disable_help_flag_set() || sub.get_name() == "help" {
            continue;
        }
        let sub_name = format!("{name}-{}", sub.get_name());
        write_page(sub, &sub_name, version, dir, written)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Arg, Command};

    #[test]
    fn a_page_per_command_and_subcommand_none_for_a_companion() {
        let command = Command::new("scout")
            .version("1.2.3")
            .about("Drive a robot")
            .subcommand(
                Command::new("drive")
                    .about("Drive at a speed")
                    .arg(Arg::new("linear").long("linear").help("The speed, m/s")),
            )
            .subcommand(
                Command::new("web")
                    .about("Runs scout-web")
                    .disable_help_flag(true),
            );
        let dir = std::env::temp_dir().join(format!("scout-man-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let written = write_pages(&command, &dir).unwrap();
        let names: Vec<String> = written
            .iter()
            .map(|path| path.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["scout.1", "scout-drive.1"]);
        let drive = std::fs::read_to_string(dir.join("scout-drive.1")).unwrap();
        assert!(drive.contains(".TH scout-drive 1"), "{drive}");
        assert!(drive.contains("The speed, m/s"), "{drive}");
        assert!(drive.contains("1.2.3"), "{drive}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
