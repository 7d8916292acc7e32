//! The chassis port as an OS resource: a tty (serial or slcan adapter, or a pseudo-terminal) or
//! a SocketCAN socket, read with a timeout and written without blocking the caller for long.

use std::io::{self, Read, Write};
use std::path::Path;
use std::time::Duration;

use scout_protocol::CanFrame;
use serialport::{SerialPort, TTYPort};
use socketcan::{EmbeddedFrame, Frame, Socket, SocketOptions};

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
    /// A frame SCOUT v1 never sends: extended id or remote frame (with its raw id).
    Foreign(u32),
    /// An error frame the CAN driver reported.
    BusError(BusError),
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
        socketcan::CanFrame::Error(error) => Incoming::BusError(BusError {
            class: error.error_bits(),
            controller: error.data().get(1).copied().unwrap_or(0),
        }),
        socketcan::CanFrame::Data(_) | socketcan::CanFrame::Remote(_) => Incoming::Foreign(raw_id),
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

#[cfg(test)]
mod tests {
    use super::*;

    fn error_frame(class: u32, controller: u8) -> Incoming {
        let frame =
            socketcan::CanErrorFrame::new_error(class, &[0, controller]).expect("an error frame");
        from_socketcan(&socketcan::CanFrame::Error(frame))
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
