//! The client API: connect to a robot's gateway by name and read its state.

use std::path::Path;
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use scout_interface::StatePayload;
use scout_interface::failure::{Failure, FailureKind};
use scout_interface::robot::{BadRobotName, Program, RobotName};
use scout_interface::services::{self, Ipc, Role, ServiceError};

/// What can go wrong talking to a gateway.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The robot name is not valid.
    #[error(transparent)]
    BadName(#[from] BadRobotName),
    /// The client name is not valid.
    #[error("client name `{0}` must be 1 to 32 bytes")]
    BadClientName(String),
    /// The gateway's services could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// This process's iceoryx2 node could not be created (the shared-memory directory is not
    /// this user's to use, or iceoryx2 refused).
    #[error(transparent)]
    Node(#[from] services::NodeError),
    /// A subscriber could not be created.
    #[error("subscribing: {0:?}")]
    Subscribe(iceoryx2::port::subscriber::SubscriberCreateError),
    /// A listener could not be created.
    #[error("listening for state events: {0:?}")]
    Listen(iceoryx2::port::listener::ListenerCreateError),
    /// Receiving failed.
    #[error("receiving: {0:?}")]
    Receive(iceoryx2::port::ReceiveError),
    /// Waiting for a state event failed.
    #[error("waiting for the state: {0:?}")]
    Wait(iceoryx2::port::listener::ListenerWaitError),
    /// A control port could not be created.
    #[error(transparent)]
    ControlPort(#[from] services::ControlPortError),
    /// Shared memory is (nearly) full: iceoryx2 would die of SIGBUS writing into it.
    #[error(
        "{path} has {free} bytes free, less than the {needed} a client needs: free some (a full tmpfs kills iceoryx2 programs with SIGBUS){largest}; `scout estop` and `scout release` still work, they need no shared memory"
    )]
    SharedMemoryFull {
        /// The shared-memory directory.
        path: String,
        /// Bytes free there.
        free: u64,
        /// Bytes a client needs at least.
        needed: u64,
        /// What fills it most, in words (empty: nothing could be listed).
        largest: String,
    },
    /// The stop endpoint's socket could not be made.
    #[error(transparent)]
    StopSocket(scout_interface::stop_socket::StopSocketError),
}

impl ClientError {
    /// Whether it means this process has no shared memory to use (full, or not this user's):
    /// the stop endpoint still works.
    pub fn no_shared_memory(&self) -> bool {
        matches!(
            self,
            Self::SharedMemoryFull { .. } | Self::Node(services::NodeError::Dir(_))
        )
    }
}

impl FailureKind for ClientError {
    fn kind(&self) -> Failure {
        match self {
            Self::BadName(_) | Self::BadClientName(_) => Failure::Usage,
            Self::Service(error) => error.kind(),
            Self::ControlPort(error) => error.kind(),
            Self::StopSocket(error) => error.kind(),
            Self::Node(_)
            | Self::Subscribe(_)
            | Self::Listen(_)
            | Self::Receive(_)
            | Self::Wait(_)
            | Self::SharedMemoryFull { .. } => Failure::Failed,
        }
    }
}

/// The least free space a client needs in the shared-memory directory.
const SHARED_MEMORY_NEEDED: u64 = 1 << 20;

/// Refuses, with an error, to map shared memory that is already full: writing into a page a
/// full tmpfs cannot back kills the process with SIGBUS, where an error says what to do.
fn check_shared_memory() -> Result<(), ClientError> {
    let dir = scout_interface::ipc::ipc_dir().map_err(services::NodeError::from)?;
    match nix::sys::statvfs::statvfs(&dir) {
        Ok(stat) => {
            let free = stat.blocks_available() * stat.fragment_size();
            if free < SHARED_MEMORY_NEEDED {
                // What fills the file system: the directory's own files, or its neighbours.
                let fs = if dir.starts_with("/dev/shm") {
                    Path::new("/dev/shm")
                } else {
                    dir.as_path()
                };
                return Err(ClientError::SharedMemoryFull {
                    path: dir.display().to_string(),
                    free,
                    needed: SHARED_MEMORY_NEEDED,
                    largest: largest_files(fs),
                });
            }
            Ok(())
        }
        // No such file system to look at: iceoryx2 says what is wrong when it tries.
        Err(_) => Ok(()),
    }
}

/// The files that fill `dir` most (the three largest of its first 10 000 entries), as
/// "; the largest there: NAME (SIZE), ..." (empty when none can be listed).
fn largest_files(dir: &Path) -> String {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return String::new();
    };
    let mut sizes: Vec<(u64, String)> = entries
        .take(10_000)
        .filter_map(|entry| {
            let entry = entry.ok()?;
            let size = entry.metadata().ok()?.len();
            Some((size, entry.file_name().to_string_lossy().into_owned()))
        })
        .collect();
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    let named: Vec<String> = sizes
        .iter()
        .take(3)
        .map(|(size, name)| format!("{name} ({:.1} MiB)", *size as f64 / f64::from(1 << 20)))
        .collect();
    if named.is_empty() {
        String::new()
    } else {
        format!("; the largest there: {}", named.join(", "))
    }
}

/// A connection to one robot's gateway.
#[derive(Debug)]
pub struct Robot {
    name: String,
    node: Node<Ipc>,
}

impl Robot {
    /// Connects to the gateway serving robot `name`. Fails with [`ServiceError::NoGateway`]
    /// when none runs, and with [`ServiceError::Incompatible`] when it was built from another
    /// version of the interface.
    pub fn connect(name: &str) -> Result<Self, ClientError> {
        let robot = RobotName::new(name)?;
        check_shared_memory()?;
        services::quiet_iceoryx2_logs();
        // Best effort: a failed clean-up of dead processes' leftovers does not stop a client.
        let _ = services::remove_dead_nodes();
        let node = services::node(&robot.node(Program::Client))?;
        services::state_services(&node, name, Role::Client)?;
        Ok(Self {
            name: name.to_owned(),
            node,
        })
    }

    /// The robot's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The iceoryx2 node of this process.
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// Subscribes to the chassis state. The latest state is available at once.
    pub fn subscribe(&self) -> Result<StateSubscriber, ClientError> {
        let (state, events) = services::state_services(&self.node, &self.name, Role::Client)?;
        let subscriber = state
            .subscriber_builder()
            .create()
            .map_err(ClientError::Subscribe)?;
        let listener = events
            .listener_builder()
            .create()
            .map_err(ClientError::Listen)?;
        Ok(StateSubscriber {
            subscriber,
            listener,
        })
    }
}

/// Receives the state a gateway publishes.
#[derive(Debug)]
pub struct StateSubscriber {
    subscriber: Subscriber<Ipc, StatePayload, ()>,
    listener: Listener<Ipc>,
}

impl StateSubscriber {
    /// The newest state received since the last call, without waiting; older ones are skipped.
    pub fn try_latest(&self) -> Result<Option<StatePayload>, ClientError> {
        services::latest(&self.subscriber).map_err(ClientError::Receive)
    }

    /// The next state, in order, without waiting.
    pub fn try_next(&self) -> Result<Option<StatePayload>, ClientError> {
        Ok(self
            .subscriber
            .receive()
            .map_err(ClientError::Receive)?
            .map(|sample| *sample))
    }

    /// Blocks (without polling) until a state arrives or `timeout` passes; returns the next one
    /// in order.
    pub fn next_timeout(&self, timeout: Duration) -> Result<Option<StatePayload>, ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(state) = self.try_next()? {
                return Ok(Some(state));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.listener
                .timed_wait(|_| {}, left)
                .map_err(ClientError::Wait)?;
        }
    }
}
