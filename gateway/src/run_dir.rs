//! The gateway's run directory: where its device locks, its unclean-exit marker and (by
//! default) its black box live. Trusted only when nobody but its owner can change it: a
//! directory (not a link), owned by this user or root, writable by no one else; and its files
//! are opened without following links. Never a place another user can create first (`/tmp`).

use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// The run directory of a gateway run by root without `SCOUT_RUN_DIR` (`sudo scout-gateway`).
pub const ROOT_RUN_DIR: &str = "/run/scout-gateway";

/// Why the run directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// Neither `SCOUT_RUN_DIR` nor `XDG_RUNTIME_DIR` says where, and this is not root.
    #[error(
        "no run directory: set SCOUT_RUN_DIR to a directory only this user can write (the \
         systemd unit uses /var/lib/scout), or run in a login session (XDG_RUNTIME_DIR)"
    )]
    NotSet,
    /// It exists, but someone other than its owner could change what is in it.
    #[error(
        "the run directory {} {why}: another user could replace the gateway's locks and its \
         unclean-exit marker there; use a directory of this user's that only it can write \
         (chmod go-w {}, or another SCOUT_RUN_DIR)",
        path.display(), path.display()
    )]
    Unsafe {
        /// The directory.
        path: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// It could not be made or read.
    #[error("the run directory {}: {source}", path.display())]
    Io {
        /// The directory.
        path: PathBuf,
        /// What failed.
        source: io::Error,
    },
}

/// Where the run directory is: `$SCOUT_RUN_DIR`; else, for root, [`ROOT_RUN_DIR`]; else
/// `$XDG_RUNTIME_DIR/scout`. Nothing is checked here ([`prepare`] does).
pub fn locate() -> Result<PathBuf, RunDirError> {
    if let Some(dir) = std::env::var_os("SCOUT_RUN_DIR") {
        return Ok(dir.into());
    }
    if nix::unistd::geteuid().is_root() {
        return Ok(PathBuf::from(ROOT_RUN_DIR));
    }
    match std::env::var_os("XDG_RUNTIME_DIR") {
        Some(runtime) => Ok(Path::new(&runtime).join("scout")),
        None => Err(RunDirError::NotSet),
    }
}

/// The run directory, made if missing (only this user may enter it) and checked ([`check`]).
pub fn prepare() -> Result<PathBuf, RunDirError> {
    let dir = locate()?;
    private(&dir)?;
    Ok(dir)
}

/// Makes `dir` if missing (mode 0700) and checks that only its owner can change it.
pub fn private(dir: &Path) -> Result<(), RunDirError> {
    let io = |source| RunDirError::Io {
        path: dir.to_owned(),
        source,
    };
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(error) if error.kind() == io::ErrorKind::AlreadyExists => {}
        Err(error) if error.kind() == io::ErrorKind::NotFound => {
            // Its parents first (theirs are not this check's to judge), then itself.
            if let Some(parent) = dir.parent() {
                std::fs::create_dir_all(parent).map_err(io)?;
            }
            match std::fs::DirBuilder::new().mode(0o700).create(dir) {
                Ok(()) => {}
                Err(error) if error.kind() == io::ErrorKind::AlreadyExists => {}
                Err(error) => return Err(io(error)),
            }
        }
        Err(error) => return Err(io(error)),
    }
    let metadata = std::fs::symlink_metadata(dir).map_err(io)?;
    check(dir, &metadata, nix::unistd::geteuid().as_raw())
}

/// Whether a directory with `metadata` may be trusted by user `uid`: a directory, not a link,
/// owned by `uid` or root, and writable by neither its group nor others.
pub fn check(dir: &Path, metadata: &std::fs::Metadata, uid: u32) -> Result<(), RunDirError> {
    let why = if metadata.file_type().is_symlink() {
        "is a symbolic link".to_owned()
    } else if !metadata.is_dir() {
        "is not a directory".to_owned()
    } else if metadata.uid() != uid && metadata.uid() != 0 {
        format!(
            "belongs to user {} (this is user {uid}, and root may be trusted too)",
            metadata.uid()
        )
    } else if metadata.mode() & 0o022 != 0 {
        format!(
            "is writable by {} (mode {:o})",
            if metadata.mode() & 0o002 != 0 {
                "every user"
            } else {
                "its group"
            },
            metadata.mode() & 0o7777
        )
    } else {
        return Ok(());
    };
    Err(RunDirError::Unsafe {
        path: dir.to_owned(),
        why,
    })
}

/// Opens (creating if missing, mode 0600) `path` for reading and writing without following a
/// link: a link planted in its place is an error, never a way to another file.
pub fn open_file(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .custom_flags(nix::fcntl::OFlag::O_NOFOLLOW.bits())
        .open(path)
}

/// Creates `path` anew (mode 0600): fails if anything, a link included, is there.
pub fn create_new(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(nix::fcntl::OFlag::O_NOFOLLOW.bits())
        .open(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn scratch(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("scout-rundir-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch");
        dir
    }

    #[test]
    fn a_missing_directory_is_made_for_this_user_alone() {
        let base = scratch("made");
        let dir = base.join("a/run");
        private(&dir).expect("made");
        let mode = std::fs::metadata(&dir).expect("made").mode() & 0o777;
        assert_eq!(mode, 0o700);
        let _ = std::fs::remove_dir_all(&base);
    }

    #[test]
    fn a_directory_others_can_change_is_refused_with_what_to_do() {
        let base = scratch("unsafe");
        let open = base.join("open");
        std::fs::create_dir(&open).expect("dir");
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o1777)).expect("chmod");
        let refused = private(&open).expect_err("world-writable");
        assert!(
            refused.to_string().contains("writable by every user"),
            "{refused}"
        );
        assert!(refused.to_string().contains("chmod go-w"), "{refused}");
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o770)).expect("chmod");
        let refused = private(&open).expect_err("group-writable");
        assert!(refused.to_string().contains("its group"), "{refused}");
        let link = base.join("link");
        std::os::unix::fs::symlink(&open, &link).expect("link");
        let refused = private(&link).expect_err("a link");
        assert!(refused.to_string().contains("symbolic link"), "{refused}");
        // Another user's (as root: handed to user 4242; else judged as if by another user).
        let me = nix::unistd::geteuid().as_raw();
        let judge = if me == 0 {
            std::os::unix::fs::chown(&open, Some(4242), None).expect("chown");
            0
        } else {
            me + 1
        };
        let metadata = std::fs::symlink_metadata(&open).expect("open");
        let refused = check(&open, &metadata, judge).expect_err("another's");
        assert!(refused.to_string().contains("belongs to user"), "{refused}");
        let _ = std::fs::remove_dir_all(&base);
    }

    #[test]
    fn files_are_opened_without_following_links() {
        let base = scratch("links");
        let target = base.join("precious");
        std::fs::write(&target, "keep me").expect("target");
        let planted = base.join("robot.lock");
        std::os::unix::fs::symlink(&target, &planted).expect("link");
        open_file(&planted).expect_err("a link is not followed");
        create_new(&planted).expect_err("nor replaced");
        assert_eq!(std::fs::read_to_string(&target).expect("intact"), "keep me");
        create_new(&base.join("fresh")).expect("a new file");
        let _ = std::fs::remove_dir_all(&base);
    }
}
