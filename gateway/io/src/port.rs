//! The chassis port as an OS resource: a tty (serial or slcan adapter, or a pseudo-terminal) or
//! a SocketCAN socket, read with a timeout and written without blocking the caller for long.

use std::io::{self, Read, Write};
use std::path::Path;
use std::time::Duration;

use scout_protocol::CanFrame;
use serialport::{SerialPort, TTYPort};
use socketcan::{EmbeddedFrame, Frame, Socket};

/// The serial link's speed (115200 8N1); slcan adapters on USB ignore it.
pub const BAUD_RATE: u32 = 115_200;

/// An open port.
#[derive(Debug)]
pub enum Port {
    /// A tty: serial, slcan adapter, or a pseudo-terminal.
    Tty(TTYPort),
    /// A SocketCAN socket.
    Can(socketcan::CanSocket),
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
    /// A frame SCOUT v1 never sends: extended id, remote or error frame (with its raw id).
    Foreign(u32),
}

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
        Ok(Self::Can(socket))
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
            Self::Can(socket) => {
                socket.set_read_timeout(timeout.max(Duration::from_micros(100)))?;
                match socket.read_frame() {
                    Ok(frame) => Ok(from_socketcan(&frame)),
                    Err(e) if is_timeout(&e) => Ok(Incoming::Timeout),
                    Err(e) => Err(e),
                }
            }
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

    /// Sends one CAN frame on a SocketCAN socket.
    pub fn write_frame(&mut self, frame: &CanFrame) -> io::Result<()> {
        let Self::Can(socket) = self else {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "frames need a CAN socket",
            ));
        };
        let frame = socketcan::CanFrame::from_raw_id(u32::from(frame.id()), frame.data())
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "invalid CAN frame"))?;
        socket.write_frame(&frame)
    }
}

/// A read or write that ended without data but without a fault: a timeout, or a signal (Ctrl-C,
/// SIGTERM) interrupting the wait.
fn is_timeout(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

fn from_socketcan(frame: &socketcan::CanFrame) -> Incoming {
    let raw_id = frame.raw_id();
    match frame {
        socketcan::CanFrame::Data(data) if !data.is_extended() => {
            CanFrame::new(raw_id as u16, data.data())
                .map_or(Incoming::Foreign(raw_id), Incoming::Frame)
        }
        _ => Incoming::Foreign(raw_id),
    }
}

impl std::os::fd::AsRawFd for Port {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        match self {
            Self::Tty(tty) => tty.as_raw_fd(),
            Self::Can(socket) => socket.as_raw_fd(),
        }
    }
}

/// Whether `interface` exists as a network interface (SocketCAN tests skip when it does not).
pub fn can_interface_exists(interface: &str) -> bool {
    Path::new("/sys/class/net").join(interface).exists()
}
