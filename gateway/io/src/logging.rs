//! Logging of the gateway and the simulator: `tracing` to standard error, filtered by
//! `RUST_LOG` (default `info`), through a non-blocking writer that drops lines rather than hold
//! up the caller when standard error is slow (a terminal scrolled back, a full pipe).

use tracing_appender::non_blocking::{NonBlockingBuilder, WorkerGuard};
use tracing_subscriber::EnvFilter;

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
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .init();
    guard
}
