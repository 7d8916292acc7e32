//! Waiting on the chassis port, the clients' wake-up event and the stop endpoint at once, so
//! that a request (a safety stop above all) is handled the moment it arrives, not at the next
//! read timeout.
//!
//! This is the crate's one `unsafe`: iceoryx2 and serialport hand out raw file descriptors, and
//! `poll` needs them borrowed. Each descriptor is borrowed from an object the caller holds by
//! reference for the whole call, so it stays open while polled.
#![allow(unsafe_code)]

use std::io;
use std::os::fd::{AsRawFd, BorrowedFd, RawFd};
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::FileDescriptorBased;
use nix::poll::{PollFd, PollFlags, ppoll};
use nix::sys::time::TimeSpec;
use scout_interface::Ipc;

/// What the wait found. The wake-up event needs no flag: the driver drains it every iteration
/// (see `Driver::handle_requests`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ready {
    /// The port has input.
    pub port: bool,
}

/// Waits at most `timeout` until `port` (if any), `wake` or the stop endpoint `stops` (unless
/// it rests) is readable. A signal ends the wait early with nothing ready.
pub fn wait(
    port: Option<&dyn AsRawFd>,
    wake: &Listener<Ipc>,
    stops: Option<BorrowedFd<'_>>,
    timeout: Duration,
) -> io::Result<Ready> {
    // SAFETY: `native_handle` returns the descriptor the listener owns; `wake` is borrowed for
    // this whole function, so the descriptor stays open while polled.
    let wake_fd: RawFd = unsafe { wake.file_descriptor().native_handle() };
    let port_fd = port.map(AsRawFd::as_raw_fd);
    // SAFETY: both descriptors belong to objects borrowed for this whole function (above).
    let borrow = |fd: RawFd| unsafe { BorrowedFd::borrow_raw(fd) };
    // A slot without a descriptor polls the wake-up event for nothing.
    let unused = || PollFd::new(borrow(wake_fd), PollFlags::empty());
    let mut fds = [
        PollFd::new(borrow(wake_fd), PollFlags::POLLIN),
        stops.map_or_else(unused, |fd| PollFd::new(fd, PollFlags::POLLIN)),
        port_fd.map_or_else(unused, |fd| PollFd::new(borrow(fd), PollFlags::POLLIN)),
    ];
    match ppoll(&mut fds, Some(TimeSpec::from_duration(timeout)), None) {
        Ok(_) => {}
        Err(nix::errno::Errno::EINTR) => return Ok(Ready::default()),
        Err(errno) => return Err(errno.into()),
    }
    let readable = |fd: &PollFd<'_>| {
        fd.revents().is_some_and(|r| {
            r.intersects(PollFlags::POLLIN | PollFlags::POLLERR | PollFlags::POLLHUP)
        })
    };
    Ok(Ready {
        port: port_fd.is_some() && readable(&fds[2]),
    })
}
