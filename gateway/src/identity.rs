//! Who a requesting process is, by the operating system: its executable (device and inode),
//! its users and its groups, read from `/proc/PID`; and whether that makes it an operator.
//! Never from a name the process chose: a client may call itself anything, and a copy or link
//! of a program under another name is another file (or, a hard link, the very same program).
//!
//! The control thread asks this for a stop-endpoint datagram, so the cost is bounded whatever
//! the sender does: only procfs files whose size the sender cannot choose are read, and at most
//! [`MAX_PROC_READ`] bytes of each; the executable is `statx` of `/proc/PID/exe` with
//! `AT_STATX_DONT_SYNC` (the kernel's link to the file it mapped: no path is resolved, and a
//! file on a FUSE or network mount is not asked for fresh attributes, so a sender cannot stall
//! the call). Its memory map (`/proc/PID/maps`, read once, is as long as the sender makes it:
//! a process with 60 000 mappings froze the control loop for over a second) is never read.

use std::io::Read;
use std::path::{Path, PathBuf};

use rustix::fs::{AtFlags, CWD, StatxFlags};

use crate::arbiter::OperatorConfig;

/// The most bytes read of one procfs file: `/proc/PID/status` is about 1.5 KB; only its
/// `Groups:` line grows (with the supplementary groups, which only root sets), and groups past
/// this are not seen (not an operator by them).
pub const MAX_PROC_READ: usize = 16 * 1024;

/// A process's identity as the kernel reports it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ProcessIdentity {
    /// The executable's device (major, minor) and inode (`None`: unreadable, or the process is
    /// gone).
    pub executable: Option<(u64, u64, u64)>,
    /// Real and effective user ids.
    pub uids: Vec<u32>,
    /// Primary (real, effective) and supplementary group ids.
    pub gids: Vec<u32>,
}

impl ProcessIdentity {
    /// Reads process `pid`'s identity; what cannot be read is left empty (never an operator).
    pub fn of(pid: u32) -> Self {
        let executable = file_id(Path::new(&format!("/proc/{pid}/exe")));
        // The status holds the process's name, which may be any bytes.
        let status = read_bounded(&format!("/proc/{pid}/status"));
        let (uids, gids) = ids_of_status(&String::from_utf8_lossy(&status));
        Self {
            executable,
            uids,
            gids,
        }
    }
}

/// At most [`MAX_PROC_READ`] bytes of a file (nothing if it cannot be read).
fn read_bounded(path: &str) -> Vec<u8> {
    let mut bytes = Vec::new();
    if let Ok(file) = std::fs::File::open(path) {
        let _ = file.take(MAX_PROC_READ as u64).read_to_end(&mut bytes);
    }
    bytes
}

/// A file's device (major, minor) and inode, from the attributes the kernel holds (no FUSE or
/// NFS round trip). For `/proc/PID/exe`, the file the process runs, whatever its path now.
fn file_id(path: &Path) -> Option<(u64, u64, u64)> {
    let stat = rustix::fs::statx(CWD, path, AtFlags::STATX_DONT_SYNC, StatxFlags::INO).ok()?;
    Some((
        u64::from(stat.stx_dev_major),
        u64::from(stat.stx_dev_minor),
        stat.stx_ino,
    ))
}

/// The `Uid:` (real, effective) and the `Gid:` (real, effective) and `Groups:` ids of a
/// `/proc/PID/status` text.
fn ids_of_status(status: &str) -> (Vec<u32>, Vec<u32>) {
    let ids = |line: &str, take: usize| -> Vec<u32> {
        line.split_whitespace()
            .skip(1)
            .take(take)
            .filter_map(|id| id.parse().ok())
            .collect()
    };
    let mut uids = Vec::new();
    let mut gids = Vec::new();
    for line in status.lines() {
        if line.starts_with("Uid:") {
            uids = ids(line, 2);
        } else if line.starts_with("Gid:") {
            gids.extend(ids(line, 2));
        } else if line.starts_with("Groups:") {
            gids.extend(ids(line, usize::MAX));
        }
    }
    (uids, gids)
}

/// Decides the operator role from a process's identity: one of the operator programs run by
/// the gateway's own user or root, or any process of a configured user or group.
#[derive(Debug, Clone)]
pub struct Operators {
    programs: Vec<PathBuf>,
    /// The users whose runs of an operator program count: the gateway's and root.
    program_users: Vec<u32>,
    uids: Vec<u32>,
    gids: Vec<u32>,
}

impl Operators {
    /// The rules of `config`; relative program paths are taken in `beside` (the directory of
    /// the gateway's own executable).
    pub fn new(config: &OperatorConfig, beside: &Path) -> Self {
        Self {
            program_users: vec![0, nix::unistd::getuid().as_raw()],
            programs: config
                .programs
                .iter()
                .map(|program| beside.join(program))
                .collect(),
            uids: config.uids.clone(),
            gids: config.gids.clone(),
        }
    }

    /// The rules of `config` for this gateway, its programs beside its own executable.
    pub fn for_this_gateway(config: &OperatorConfig) -> Self {
        let beside = std::env::current_exe()
            .ok()
            .and_then(|exe| exe.parent().map(Path::to_path_buf))
            .unwrap_or_default();
        Self::new(config, &beside)
    }

    /// Whether a process of `identity` is an operator. The programs are looked up now, so a
    /// rebuilt or reinstalled `scout` is recognised without restarting the gateway.
    pub fn is_operator(&self, identity: &ProcessIdentity) -> bool {
        // Unknown users (an unreadable status) make no operator.
        let by_program = identity.executable.is_some_and(|executable| {
            self.programs
                .iter()
                .any(|program| file_id(program) == Some(executable))
        }) && !identity.uids.is_empty()
            && identity
                .uids
                .iter()
                .all(|uid| self.program_users.contains(uid));
        by_program
            || identity.uids.iter().any(|uid| self.uids.contains(uid))
            || identity.gids.iter().any(|gid| self.gids.contains(gid))
    }

    /// Whether process `pid` is an operator.
    pub fn is_operator_pid(&self, pid: u32) -> bool {
        self.is_operator(&ProcessIdentity::of(pid))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("scout-identity-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    #[test]
    fn status_ids_are_read() {
        let status = "Name:\tscout\nUid:\t1000\t1001\t1000\t1000\nGid:\t100\t100\t100\t100\nGroups:\t20 27 1000 \n";
        assert_eq!(
            ids_of_status(status),
            (vec![1000, 1001], vec![100, 100, 20, 27, 1000])
        );
        assert_eq!(ids_of_status(""), (vec![], vec![]));
    }

    #[test]
    fn the_executable_is_the_file_the_process_runs() {
        let me = std::env::current_exe().expect("exe");
        let mine = ProcessIdentity::of(std::process::id()).executable;
        assert!(mine.is_some());
        assert_eq!(mine, file_id(&me));
        assert_eq!(file_id(Path::new("/nonexistent/scout")), None);
    }

    #[test]
    fn a_status_longer_than_the_bound_is_cut() {
        let dir = temp_dir("long-status");
        let long = dir.join("status");
        std::fs::write(&long, vec![b'x'; 4 * MAX_PROC_READ]).expect("write");
        assert_eq!(read_bounded(&long.to_string_lossy()).len(), MAX_PROC_READ);
        assert!(read_bounded("/nonexistent/status").is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn this_process_is_read_from_proc() {
        let me = ProcessIdentity::of(std::process::id());
        assert!(me.executable.is_some());
        assert!(!me.uids.is_empty() && !me.gids.is_empty());
        assert_eq!(ProcessIdentity::of(u32::MAX), ProcessIdentity::default());
    }

    #[test]
    fn the_program_is_the_file_not_its_name() {
        let dir = temp_dir("program");
        let scout = dir.join("scout");
        std::fs::write(&scout, b"the real scout").expect("write");
        let operators = Operators::new(&OperatorConfig::default(), &dir);
        let me = nix::unistd::getuid().as_raw();
        let real = ProcessIdentity {
            executable: file_id(&scout),
            uids: vec![me],
            gids: Vec::new(),
        };
        assert!(operators.is_operator(&real));
        // Run by another user (not root), the program gives no role.
        let stranger = ProcessIdentity {
            uids: vec![me.wrapping_add(4321).max(1)],
            ..real.clone()
        };
        assert!(!operators.is_operator(&stranger));
        // Unknown users (a status that could not be read) make no operator.
        let unknown = ProcessIdentity {
            uids: Vec::new(),
            ..real.clone()
        };
        assert!(!operators.is_operator(&unknown));
        // A copy named scout elsewhere is another file.
        let elsewhere = temp_dir("copy");
        let copy = elsewhere.join("scout");
        std::fs::copy(&scout, &copy).expect("copy");
        let impostor = ProcessIdentity {
            executable: file_id(&copy),
            uids: vec![me],
            gids: Vec::new(),
        };
        assert!(!operators.is_operator(&impostor));
        // A hard link is the same file: the same program, so the same role.
        let link = elsewhere.join("not-scout");
        std::fs::hard_link(&scout, &link).expect("link");
        assert!(operators.is_operator(&ProcessIdentity {
            executable: file_id(&link),
            uids: vec![me],
            gids: Vec::new(),
        }));
        let _ = std::fs::remove_dir_all(dir);
        let _ = std::fs::remove_dir_all(elsewhere);
    }

    #[test]
    fn users_and_groups_make_operators() {
        let operators = Operators::new(
            &OperatorConfig {
                programs: Vec::new(),
                uids: vec![1000],
                gids: vec![27],
            },
            Path::new("/nonexistent"),
        );
        let user = |uids: Vec<u32>, gids: Vec<u32>| ProcessIdentity {
            executable: None,
            uids,
            gids,
        };
        assert!(operators.is_operator(&user(vec![1000], vec![])));
        assert!(operators.is_operator(&user(vec![5], vec![100, 27])));
        assert!(!operators.is_operator(&user(vec![5], vec![100])));
        assert!(!operators.is_operator(&ProcessIdentity::default()));
    }
}
