//! scout-io: what the two programs that face the chassis (scout-gateway and scout-sim) share
//! with the operating system.
//!
//! - [`port`]: the chassis port as an OS resource: a tty (serial, slcan adapter, pseudo-terminal),
//!   a SocketCAN socket, or a gs_usb adapter in user space (`scout-usb`).
//! - [`logging`]: `tracing` to standard error, never blocking the caller.
//! - [`notify`]: the service manager's notifications (systemd's readiness and watchdog).
//! - [`raise_priority`]: real-time scheduling for the thread that keeps the wire's time.

pub mod logging;
pub mod notify;
pub mod port;

pub use port::{BusError, Incoming, Port, is_bus_fault};
pub use scout_usb;

/// Puts the calling thread under SCHED_FIFO at `priority` (0: leaves it alone).
pub fn raise_priority(priority: u8, what: &str) {
    use thread_priority::{
        RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
        set_thread_priority_and_policy, thread_native_id,
    };
    if priority == 0 {
        return;
    }
    let result = ThreadPriorityValue::try_from(priority)
        .map_err(|e| format!("{e:?}"))
        .and_then(|value| {
            set_thread_priority_and_policy(
                thread_native_id(),
                ThreadPriority::Crossplatform(value),
                ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
            )
            .map_err(|e| format!("{e:?}"))
        });
    match result {
        Ok(()) => tracing::info!("{what} at real-time priority {priority} (SCHED_FIFO)"),
        Err(error) => tracing::info!(
            "{what} at normal priority ({error}): grant CAP_SYS_NICE or an rtprio limit for timing that holds under load"
        ),
    }
}
