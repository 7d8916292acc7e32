//! Logging of the gateway and the simulator: `tracing` to standard error, filtered by
//! `RUST_LOG` (default [`DEFAULT_FILTER`]), through a non-blocking writer that drops lines rather than hold
//! up the caller when standard error is slow (a terminal scrolled back, a full pipe).

use tracing_appender::non_blocking::{NonBlockingBuilder, WorkerGuard};
use tracing_subscriber::EnvFilter;

/// What is logged when `RUST_LOG` is not set: `info`, but for zenoh's warning that gossip
/// scouting is off, which it is by design (`docs/remote.md`): said at every start, it would
/// teach people to read past warnings.
pub const DEFAULT_FILTER: &str = "info,zenoh::net::routing::hat::peer=error";

/// Installs the subscriber; keep the guard alive until exit so that queued lines are written.
pub fn init() -> WorkerGuard {
    let (writer, guard) = NonBlockingBuilder::default()
        .lossy(true)
        .finish(std::io::stderr());
    tracing_subscriber::fmt()
        .with_writer(writer)
        .with_target(false)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_FILTER)),
        )
        .init();
    guard
}
