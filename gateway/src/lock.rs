//! Exclusive ownership of a device: one gateway per tty or CAN interface, by advisory file locks
//! that the kernel releases when the process dies (even by SIGKILL). The robot name's lock is the
//! stop endpoint's abstract socket ([`crate::stop_endpoint`]), global whatever the run directory.

use std::fs::{File, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::PathBuf;

use crate::run_dir::{self, RunDirError};

/// Why a lock was not taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another live process holds it.
    #[error("{what} is already owned by another scout-gateway{}: stop it first{hint}", holder.map(|pid| format!(" (pid {pid})")).unwrap_or_default())]
    Held {
        /// What the lock protects, for people.
        what: String,
        /// The holder's pid, if it wrote one.
        holder: Option<u32>,
        /// What else to do.
        hint: &'static str,
    },
    /// The run directory cannot be trusted or made.
    #[error(transparent)]
    RunDir(#[from] RunDirError),
    /// The lock file could not be used.
    #[error("lock file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
}

/// A held lock; released when dropped or when the process ends.
#[derive(Debug)]
pub struct Lock {
    _file: File,
}

impl Lock {
    /// Takes the lock called `key` in the run directory ([`run_dir::prepare`]), describing it
    /// as `what` in errors. The file is opened without following links.
    pub fn acquire(key: &str, what: &str, hint: &'static str) -> Result<Lock, LockError> {
        let dir = run_dir::prepare()?;
        let path = dir.join(format!("{}.lock", sanitize(key)));
        let io = |source| LockError::Io {
            path: path.clone(),
            source,
        };
        let mut file = run_dir::open_file(&path).map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                return Err(LockError::Held {
                    what: what.to_owned(),
                    holder: text.trim().parse().ok(),
                    hint,
                });
            }
            Err(TryLockError::Error(source)) => return Err(io(source)),
        }
        file.set_len(0).map_err(io)?;
        file.rewind().map_err(io)?;
        write!(file, "{}", std::process::id()).map_err(io)?;
        Ok(Lock { _file: file })
    }
}

/// A file name for any key: letters, digits, `-`, `_` and `.` kept, the rest `_`.
fn sanitize(key: &str) -> String {
    key.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn second_holder_is_refused_with_the_pid() {
        let key = format!(
            "test-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        );
        let first = Lock::acquire(&key, "robot 'x'", "").expect("first lock");
        let second = Lock::acquire(&key, "robot 'x'", "").expect_err("second lock refused");
        let message = second.to_string();
        assert!(
            message.contains(&format!("pid {}", std::process::id())),
            "{message}"
        );
        drop(first);
        Lock::acquire(&key, "robot 'x'", "").expect("free again after the first is dropped");
        if let Ok(dir) = run_dir::locate() {
            let _ = std::fs::remove_file(dir.join(format!("{}.lock", sanitize(&key))));
        }
    }

    #[test]
    fn keys_become_file_names() {
        assert_eq!(sanitize("device-/dev/ttyUSB0"), "device-_dev_ttyUSB0");
    }
}
