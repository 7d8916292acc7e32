//! The chassis port as an OS resource: a tty (serial or slcan adapter, or a pseudo-terminal), a
//! SocketCAN socket, or a gs_usb adapter in user space; read with a timeout and written without
//! blocking the caller for long.
//! SocketCAN reads also carry the kernel's count of frames it dropped because the receive queue
//! was full (`SO_RXQ_OVFL`), so no frame is lost without being counted.

use std::io::{self, Read, Write};
use std::path::Path;
use std::time::Duration;

use scout_protocol::CanFrame;
use serialport::{SerialPort, TTYPort};
use std::os::fd::AsRawFd as _;

use nix::sys::socket::{ControlMessageOwned, MsgFlags, recvmsg, setsockopt, sockopt};
use socketcan::{Frame as _, Socket, SocketOptions};

/// The serial link's speed (115200 8N1); slcan adapters on USB ignore it.
pub const BAUD_RATE: u32 = 115_200;

/// An open port.
#[derive(Debug)]
pub enum Port {
    /// A tty: serial, slcan adapter, or a pseudo-terminal.
    Tty(TTYPort),
    /// A SocketCAN socket.
    Can(CanPort),
    /// A gs_usb USB-CAN adapter, through usbfs.
    GsUsb(Box<scout_usb::GsUsbPort>),
}

/// A SocketCAN socket and the kernel's count of the frames it dropped for it.
#[derive(Debug)]
pub struct CanPort {
    socket: socketcan::CanSocket,
    /// The last `SO_RXQ_OVFL` count the kernel reported (cumulative for this socket).
    overflowed: u32,
}

/// What one read got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Incoming {
    /// Nothing within the timeout.
    Timeout,
    /// This many bytes, at the start of the buffer.
    Bytes(usize),
    /// A standard-id CAN data frame.
    Frame(CanFrame),
    /// A frame SCOUT v1 never sends: extended id or remote frame (with its raw id).
    Foreign(u32),
    /// An error frame the CAN driver reported.
    BusError(BusError),
    /// Bytes from a gs_usb adapter that are no host frame.
    Malformed(scout_protocol::gs_usb::Error),
}

/// An error frame from the CAN driver (`linux/can/error.h`): its class bits and the controller
/// status byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusError {
    /// The error class bits of the frame's id.
    pub class: u32,
    /// Byte 1: the controller's problems (warning, passive, overflow).
    pub controller: u8,
}

impl BusError {
    const BUS_OFF: u32 = 0x40;
    const CONTROLLER: u32 = 0x04;
    const RX_PASSIVE: u8 = 0x10;
    const TX_PASSIVE: u8 = 0x20;

    /// Whether the bus can no longer be trusted: bus-off, or the controller error-passive.
    pub fn is_fault(&self) -> bool {
        self.class & Self::BUS_OFF != 0
            || (self.class & Self::CONTROLLER != 0
                && self.controller & (Self::RX_PASSIVE | Self::TX_PASSIVE) != 0)
    }
}

impl std::fmt::Display for BusError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.class & Self::BUS_OFF != 0 {
            f.write_str("CAN bus-off")
        } else if self.is_fault() {
            write!(
                f,
                "CAN controller error-passive (0x{:02x})",
                self.controller
            )
        } else {
            write!(
                f,
                "CAN error frame (class 0x{:x}, controller 0x{:02x})",
                self.class, self.controller
            )
        }
    }
}

impl std::error::Error for BusError {}

impl Port {
    /// Opens a tty device at 115200 8N1, exclusively: a second opener is refused.
    pub fn open_tty(path: &Path) -> serialport::Result<Self> {
        let port = serialport::new(path.to_string_lossy(), BAUD_RATE)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(Duration::from_millis(10))
            .open_native()?;
        port.clear(serialport::ClearBuffer::All)?;
        Ok(Self::Tty(port))
    }

    /// Opens a SocketCAN interface.
    pub fn open_can(interface: &str) -> io::Result<Self> {
        let socket = socketcan::CanSocket::open(interface)?;
        socket.set_write_timeout(Duration::from_millis(5))?;
        // Bus-off and error-passive arrive as error frames: a gap for the gateway.
        socket.set_error_filter_accept_all()?;
        // Every read reports how many frames the kernel dropped for a full receive queue.
        setsockopt(&socket, sockopt::RxqOvfl, &1).map_err(io::Error::from)?;
        Ok(Self::Can(CanPort {
            socket,
            overflowed: 0,
        }))
    }

    /// Opens a gs_usb adapter (the one with `serial`, else the only one) at 500 kbit/s; a
    /// kernel driver bound to it is detached only when `detach` says so.
    pub fn open_gs_usb(serial: Option<&str>, detach: bool) -> Result<Self, scout_usb::OpenError> {
        scout_usb::GsUsbPort::open(serial, detach).map(|port| Self::GsUsb(Box::new(port)))
    }

    /// Frames dropped before they could be read: by the kernel, for a full receive queue
    /// (SocketCAN), or on a gs_usb adapter's way (see `GsUsbPort::overflowed_frames`); always
    /// 0 for a tty, whose driver does not count.
    pub fn overflowed_frames(&self) -> u64 {
        match self {
            Self::Tty(_) => 0,
            Self::Can(can) => u64::from(can.overflowed),
            Self::GsUsb(usb) => usb.overflowed_frames(),
        }
    }

    /// Waits at most `timeout` for input.
    pub fn read(&mut self, buffer: &mut [u8], timeout: Duration) -> io::Result<Incoming> {
        match self {
            Self::Tty(tty) => {
                tty.set_timeout(timeout)?;
                match tty.read(buffer) {
                    Ok(0) => Err(io::Error::new(io::ErrorKind::UnexpectedEof, "port closed")),
                    Ok(n) => Ok(Incoming::Bytes(n)),
                    Err(e) if is_timeout(&e) => Ok(Incoming::Timeout),
                    Err(e) => Err(e),
                }
            }
            Self::Can(can) => can.read(timeout),
            Self::GsUsb(usb) => Ok(match usb.read(timeout)? {
                None => Incoming::Timeout,
                Some(scout_usb::Input::Frame(frame)) => Incoming::Frame(frame),
                Some(scout_usb::Input::Foreign(can_id)) => Incoming::Foreign(can_id),
                Some(scout_usb::Input::BusError { class, data }) => Incoming::BusError(BusError {
                    class,
                    controller: data[1],
                }),
                Some(scout_usb::Input::Malformed(error)) => Incoming::Malformed(error),
            }),
        }
    }

    /// Writes bytes to a tty, waiting at most `timeout` for room; returns how many were written
    /// (fewer when the other end does not read).
    pub fn write_bytes(&mut self, bytes: &[u8], timeout: Duration) -> io::Result<usize> {
        let Self::Tty(tty) = self else {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "bytes need a tty port",
            ));
        };
        tty.set_timeout(timeout)?;
        let mut written = 0;
        while written < bytes.len() {
            match tty.write(&bytes[written..]) {
                Ok(0) => break,
                Ok(n) => written += n,
                Err(e) if is_timeout(&e) => break,
                Err(e) => return Err(e),
            }
        }
        Ok(written)
    }

    /// Sends one CAN frame on a SocketCAN socket or a gs_usb adapter.
    pub fn write_frame(&mut self, frame: &CanFrame) -> io::Result<()> {
        match self {
            Self::Can(CanPort { socket, .. }) => {
                let frame = socketcan::CanFrame::from_raw_id(u32::from(frame.id()), frame.data())
                    .ok_or_else(|| {
                    io::Error::new(io::ErrorKind::InvalidInput, "invalid CAN frame")
                })?;
                socket.write_frame(&frame)
            }
            Self::GsUsb(usb) => usb.write(frame),
            Self::Tty(_) => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "frames need a CAN socket or adapter",
            )),
        }
    }
}

/// Whether a read or write error means the bus or the adapter failed (`link_fault`), not that
/// the port went away (`link_lost`): an error frame of bus-off or error-passive, a full CAN
/// transmit queue, a downed interface, frames a gs_usb adapter could not put on the bus.
pub fn is_bus_fault(error: &io::Error) -> bool {
    matches!(
        error.raw_os_error(),
        Some(nix::libc::ENOBUFS | nix::libc::ENETDOWN)
    ) || error
        .get_ref()
        .is_some_and(|inner| inner.is::<BusError>() || inner.is::<scout_usb::Unacknowledged>())
}

/// A read or write that ended without data but without a fault: a timeout, or a signal (Ctrl-C,
/// SIGTERM) interrupting the wait.
fn is_timeout(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// `timeout` as a socket's receive timeout: at least a microsecond. The socket takes whole
/// microseconds, and zero there means "wait for ever": a wait of a few hundred nanoseconds (what
/// is left until the next feedback) blocked scout-sim on an idle bus until a frame came, which
/// none did (a CI run caught it).
fn socket_timeout(timeout: Duration) -> Duration {
    timeout.max(Duration::from_micros(1))
}

impl CanPort {
    /// Reads one frame, waiting at most `timeout` (zero: only what is already queued).
    fn read(&mut self, timeout: Duration) -> io::Result<Incoming> {
        let flags = if timeout.is_zero() {
            MsgFlags::MSG_DONTWAIT
        } else {
            self.socket.set_read_timeout(socket_timeout(timeout))?;
            MsgFlags::empty()
        };
        let mut frame = [0u8; wire::FRAME_LEN];
        let mut control = nix::cmsg_space!(u32);
        let mut iov = [io::IoSliceMut::new(&mut frame)];
        let received =
            match recvmsg::<()>(self.socket.as_raw_fd(), &mut iov, Some(&mut control), flags) {
                Ok(received) => received,
                Err(errno) => {
                    let error = io::Error::from(errno);
                    return if is_timeout(&error) {
                        Ok(Incoming::Timeout)
                    } else {
                        Err(error)
                    };
                }
            };
        for message in received.cmsgs().map_err(io::Error::from)? {
            if let ControlMessageOwned::RxqOvfl(count) = message {
                self.overflowed = count;
            }
        }
        if received.bytes != wire::FRAME_LEN {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "a SocketCAN read of {} bytes, not one {}-byte CAN frame (a CAN FD \
                     interface?)",
                    received.bytes,
                    wire::FRAME_LEN
                ),
            ));
        }
        Ok(wire::parse(&frame))
    }
}

/// Linux's `struct can_frame` (`linux/can.h`) as named byte ranges.
mod wire {
    use super::{BusError, Incoming};
    use scout_protocol::CanFrame;

    /// The size of one classic CAN frame.
    pub const FRAME_LEN: usize = 16;
    /// `can_id`: the identifier and the flags below, in the host's byte order.
    const ID: std::ops::Range<usize> = 0..4;
    /// `len`: the payload length (0-8).
    const LEN: usize = 4;
    /// `data`: up to 8 payload bytes.
    const DATA: std::ops::Range<usize> = 8..16;

    const EXTENDED_FLAG: u32 = 0x8000_0000;
    const REMOTE_FLAG: u32 = 0x4000_0000;
    const ERROR_FLAG: u32 = 0x2000_0000;
    const EXTENDED_MASK: u32 = 0x1FFF_FFFF;
    const STANDARD_MASK: u32 = 0x7FF;

    /// What one `struct can_frame` says.
    pub fn parse(frame: &[u8; FRAME_LEN]) -> Incoming {
        let mut id = [0u8; 4];
        id.copy_from_slice(&frame[ID]);
        let can_id = u32::from_ne_bytes(id);
        let data = &frame[DATA][..usize::from(frame[LEN]).min(8)];
        if can_id & ERROR_FLAG != 0 {
            return Incoming::BusError(BusError {
                class: can_id & EXTENDED_MASK,
                controller: frame[DATA.start + 1],
            });
        }
        if can_id & (EXTENDED_FLAG | REMOTE_FLAG) != 0 {
            return Incoming::Foreign(can_id & EXTENDED_MASK);
        }
        let id = (can_id & STANDARD_MASK) as u16;
        CanFrame::new(id, data).map_or(Incoming::Foreign(u32::from(id)), Incoming::Frame)
    }

    /// The bytes of a `struct can_frame` (tests build frames the kernel would deliver).
    #[cfg(test)]
    pub fn emit(can_id: u32, data: &[u8]) -> [u8; FRAME_LEN] {
        let mut frame = [0u8; FRAME_LEN];
        frame[ID].copy_from_slice(&can_id.to_ne_bytes());
        frame[LEN] = data.len() as u8;
        frame[DATA][..data.len()].copy_from_slice(data);
        frame
    }
}

impl std::os::fd::AsRawFd for Port {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        match self {
            Self::Tty(tty) => tty.as_raw_fd(),
            Self::Can(can) => can.socket.as_raw_fd(),
            Self::GsUsb(usb) => usb.as_raw_fd(),
        }
    }
}

/// Whether `interface` exists as a network interface (SocketCAN tests skip when it does not).
pub fn can_interface_exists(interface: &str) -> bool {
    Path::new("/sys/class/net").join(interface).exists()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error_frame(class: u32, controller: u8) -> Incoming {
        wire::parse(&wire::emit(
            0x2000_0000 | class,
            &[0, controller, 0, 0, 0, 0, 0, 0],
        ))
    }

    #[test]
    fn a_wait_shorter_than_a_microsecond_is_a_microsecond_not_for_ever() {
        assert_eq!(
            socket_timeout(Duration::from_nanos(500)),
            Duration::from_micros(1)
        );
        assert_eq!(
            socket_timeout(Duration::from_millis(5)),
            Duration::from_millis(5)
        );
    }

    #[test]
    fn can_frames_parse_as_the_kernel_lays_them_out() {
        // 0x151 with a payload of 8 bytes, as `struct can_frame` in the host's byte order.
        let data = [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x03];
        let Incoming::Frame(frame) = wire::parse(&wire::emit(0x151, &data)) else {
            panic!("a standard data frame")
        };
        assert_eq!((frame.id(), frame.data()), (0x151, &data[..]));
        let Incoming::Frame(short) = wire::parse(&wire::emit(0x421, &[1])) else {
            panic!("a standard data frame")
        };
        assert_eq!(short.data(), &[1]);
        assert_eq!(
            wire::parse(&wire::emit(0x8000_0000 | 0x18FF_0001, &[])),
            Incoming::Foreign(0x18FF_0001),
            "an extended id"
        );
        assert_eq!(
            wire::parse(&wire::emit(0x4000_0000 | 0x151, &[])),
            Incoming::Foreign(0x151),
            "a remote frame"
        );
        let mut too_long = wire::emit(0x151, &data);
        too_long[4] = 15;
        assert!(
            matches!(wire::parse(&too_long), Incoming::Frame(f) if f.data().len() == 8),
            "a length over 8 reads 8 bytes"
        );
    }

    #[test]
    fn bus_faults_are_told_from_a_lost_port() {
        let fault = |error: io::Error| is_bus_fault(&error);
        assert!(fault(io::Error::from_raw_os_error(nix::libc::ENOBUFS)));
        assert!(fault(io::Error::from_raw_os_error(nix::libc::ENETDOWN)));
        assert!(fault(io::Error::other(BusError {
            class: 0x40,
            controller: 0
        })));
        assert!(fault(io::Error::other(scout_usb::Unacknowledged {
            frames: 10,
            untaken: 0
        })));
        assert!(!fault(io::Error::from_raw_os_error(nix::libc::ENODEV)));
        assert!(!fault(io::Error::new(
            io::ErrorKind::NotConnected,
            "unplugged"
        )));
    }

    #[test]
    fn bus_off_and_error_passive_are_faults_other_error_frames_are_not() {
        let Incoming::BusError(bus_off) = error_frame(0x40, 0) else {
            panic!("not an error frame")
        };
        assert!(bus_off.is_fault());
        assert_eq!(bus_off.to_string(), "CAN bus-off");
        let Incoming::BusError(passive) = error_frame(0x04, 0x20) else {
            panic!("not an error frame")
        };
        assert!(passive.is_fault(), "{passive}");
        let Incoming::BusError(warning) = error_frame(0x04, 0x04) else {
            panic!("not an error frame")
        };
        assert!(!warning.is_fault(), "a warning is counted, not a gap");
    }
}
