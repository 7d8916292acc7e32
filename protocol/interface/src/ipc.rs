//! The iceoryx2 service flavour every process uses, and where its shared objects live: files
//! in one directory on a tmpfs ([`ipc_dir`]) rather than POSIX shared memory in `/dev/shm`, so
//! that the directory's permissions decide who may be a local client. On an installed robot
//! that is `/run/scout`, the gateway user's with the group `scout`: its members (and root) are
//! clients; everyone else reaches only the stop endpoint. iceoryx2 gives its own objects
//! owner-only modes, which would shut out every user but the gateway's (and stall the gateway
//! on the objects a root client makes); built with its `dev_permissions`, they are open to
//! whoever can enter the directory, and the directory is the gate.

use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

use iceoryx2::prelude::{Config, SemanticString};
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    arc_sync_policy, bag, dynamic_storage, event, hash, monitoring, reactor,
    resizable_shared_memory, serialize, shared_memory, static_storage, zero_copy_connection,
};

/// The shared-memory directory of an installed robot: the gateway user's, group `scout`
/// (made by the Debian package).
pub const INSTALLED_IPC_DIR: &str = "/run/scout";

/// The Unix group whose members are local clients of an installed robot's gateway.
pub const CLIENT_GROUP: &str = "scout";

/// The iceoryx2 service flavour of every process: `ipc_threadsafe`'s ports (a mutex each:
/// the Python package waits on a subscriber with the GIL released), with every dynamic storage,
/// data segment, connection and event state a file in [`ipc_dir`].
#[derive(Debug, Clone)]
pub struct Ipc {}

/// A dynamic storage: a file in the shared-memory directory.
type FileStorage<T> = dynamic_storage::file::Storage<T>;
/// A data segment: a file in the shared-memory directory.
type FileMemory<Allocator> = shared_memory::file::Memory<Allocator>;

impl iceoryx2::service::Service for Ipc {
    type StaticStorage = static_storage::file::Storage;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: std::fmt::Debug + Send + Sync + ZeroCopySend + 'static> =
        FileStorage<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: std::fmt::Debug + Send + Sync + ZeroCopySend + 'static> = FileStorage<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = FileMemory<PoolAllocator>;
    type ResizableSharedMemory =
        resizable_shared_memory::dynamic::DynamicMemory<PoolAllocator, FileMemory<PoolAllocator>>;
    type Connection = zero_copy_connection::file::Connection;
    type Event = event::trigger::unix_datagram_socket::GenericUnixDatagramSocketTrigger<
        RelocatableCountingBitSet,
        FileStorage<event::trigger::State<RelocatableCountingBitSet, ()>>,
    >;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + std::fmt::Debug + Abandonable> =
        arc_sync_policy::mutex_protected::MutexProtected<T>;
    type BlackboardMgmt<KeyType: Send + Sync + std::fmt::Debug + ZeroCopySend + 'static> =
        FileStorage<KeyType>;
    type BlackboardPayload = FileMemory<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Ipc> for Ipc {}

/// Why the shared-memory directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum IpcDirError {
    /// The directory exists, but this user may not use it.
    #[error(
        "only members of the group '{group}' may use the gateway's shared memory in {}: \
         `sudo usermod -aG {group} $USER`, then log in again (stops work without it: `scout \
         estop`, `scout release`)",
        dir.display()
    )]
    NotInGroup {
        /// The directory.
        dir: PathBuf,
        /// Its group's name (or number).
        group: String,
    },
    /// It exists, but someone it should not trust could change it.
    #[error(
        "the shared-memory directory {} {why}: another user could read and forge what the \
         gateway and its clients share there; use one that only this user (or the group \
         '{CLIENT_GROUP}') can write, or set SCOUT_IPC_DIR",
        path.display()
    )]
    Unsafe {
        /// The directory.
        path: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// It could not be made or read.
    #[error("the shared-memory directory {}: {source}", path.display())]
    Io {
        /// The directory.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// Its path is not one iceoryx2 takes.
    #[error("the shared-memory directory {}: not a path iceoryx2 takes (too long?)", path.display())]
    Path {
        /// The directory.
        path: PathBuf,
    },
}

/// Where the shared objects live: `$SCOUT_IPC_DIR`; else [`INSTALLED_IPC_DIR`] where it exists
/// (an installed robot); else `/dev/shm/scout-UID`, this user's alone. Made if missing (for
/// this user alone) and checked: a directory, not a link, writable by no one outside its
/// owner and group; the installed one must be usable by this user (a member of its group).
pub fn ipc_dir() -> Result<PathBuf, IpcDirError> {
    let uid = nix::unistd::geteuid().as_raw();
    let (dir, private) = match std::env::var_os("SCOUT_IPC_DIR") {
        Some(dir) => (PathBuf::from(dir), false),
        None if Path::new(INSTALLED_IPC_DIR).exists() => (PathBuf::from(INSTALLED_IPC_DIR), false),
        None => (PathBuf::from(format!("/dev/shm/scout-{uid}")), true),
    };
    let io = |source| IpcDirError::Io {
        path: dir.clone(),
        source,
    };
    match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
        Ok(()) => {}
        Err(error) if error.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(error) => return Err(io(error)),
    }
    let metadata = std::fs::symlink_metadata(&dir).map_err(io)?;
    let unsafe_because = |why: String| IpcDirError::Unsafe {
        path: dir.clone(),
        why,
    };
    if metadata.file_type().is_symlink() {
        return Err(unsafe_because("is a symbolic link".into()));
    }
    if !metadata.is_dir() {
        return Err(unsafe_because("is not a directory".into()));
    }
    if metadata.mode() & 0o002 != 0 {
        return Err(unsafe_because(format!(
            "is writable by every user (mode {:o})",
            metadata.mode() & 0o7777
        )));
    }
    if private && (metadata.uid() != uid || metadata.mode() & 0o077 != 0) {
        return Err(unsafe_because(format!(
            "should be this user's alone (user {uid}, mode 700), but is user {}'s with mode {:o}",
            metadata.uid(),
            metadata.mode() & 0o7777
        )));
    }
    let full = nix::unistd::AccessFlags::R_OK
        | nix::unistd::AccessFlags::W_OK
        | nix::unistd::AccessFlags::X_OK;
    if nix::unistd::access(&dir, full).is_err() {
        let gid = nix::unistd::Gid::from_raw(metadata.gid());
        let group = nix::unistd::Group::from_gid(gid)
            .ok()
            .flatten()
            .map_or_else(|| gid.to_string(), |group| group.name);
        return Err(IpcDirError::NotInGroup { dir, group });
    }
    Ok(dir)
}

/// iceoryx2's configuration with every object in `dir`.
pub fn config_in(dir: &Path) -> Result<Config, IpcDirError> {
    let mut text = dir.as_os_str().as_encoded_bytes().to_vec();
    if !text.ends_with(b"/") {
        text.push(b'/');
    }
    let root = iceoryx2::prelude::Path::new(&text).map_err(|_| IpcDirError::Path {
        path: dir.to_owned(),
    })?;
    let mut config = Config::default();
    config.global.set_root_path(&root);
    Ok(config)
}
