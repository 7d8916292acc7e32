//! What the gateway talks to: a port with its framing (serial, slcan, SocketCAN, a gs_usb
//! adapter) or the chassis simulator in-process (`--sim`). Messages in and out; the control loop does the rest.

use std::io;
use std::path::PathBuf;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use scout_interface::Ipc;
use scout_io::{Incoming, Port};
use scout_protocol::Transport;
use scout_protocol::link::{Outgoing, RxError, RxEvent, StreamFraming, decode_can, encode_stream};
use scout_protocol::slcan::{self, Bitrate, Slcan};
use scout_protocol::version::Protocol;
use scout_sim::{Chassis, Feedback, SimParams};

use crate::lock::{Lock, LockError};

use crate::wait::{Ready, wait};
/// The gs_usb adapters plugged in (for `scout doctor`: the gateway's own way of finding them).
pub use scout_io::scout_usb::{Adapter as GsUsbAdapter, adapters as gs_usb_adapters};

/// Which device, before it is opened.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceSpec {
    /// An RS232 port.
    Serial(PathBuf),
    /// A serial-line CAN adapter.
    Slcan(PathBuf),
    /// A SocketCAN interface.
    Can(String),
    /// A gs_usb USB-CAN adapter in user space.
    GsUsb {
        /// Its serial number; `None`: the only adapter plugged in.
        serial: Option<String>,
        /// Detach a kernel driver bound to it (never done unasked).
        detach: bool,
    },
    /// The simulated chassis, in-process, with the firmware of `protocol`.
    Sim {
        /// Its parameters (boxed: they outweigh every other way in).
        params: Box<SimParams>,
        /// Its firmware's protocol.
        protocol: Protocol,
    },
}

impl DeviceSpec {
    /// The transport.
    pub fn transport(&self) -> Transport {
        match self {
            Self::Serial(_) => Transport::Serial,
            Self::Slcan(_) => Transport::Slcan,
            Self::Can(_) => Transport::Can,
            Self::GsUsb { .. } => Transport::GsUsb,
            Self::Sim { .. } => Transport::Sim,
        }
    }

    /// The device path or interface, as shown to people.
    pub fn name(&self) -> String {
        match self {
            Self::Serial(path) | Self::Slcan(path) => path.display().to_string(),
            Self::Can(interface) => interface.clone(),
            Self::GsUsb {
                serial: Some(serial),
                ..
            } => serial.clone(),
            Self::GsUsb { serial: None, .. } => "(the only adapter)".into(),
            Self::Sim { .. } => "simulator".into(),
        }
    }

    /// The lock that makes this gateway the device's only owner while it is open: keyed by what
    /// the path resolves to now (a re-enumerated adapter is another device).
    fn lock(&self) -> Result<Option<Lock>, OpenError> {
        let key = match self {
            Self::Serial(path) | Self::Slcan(path) => std::fs::canonicalize(path)
                .unwrap_or_else(|_| path.clone())
                .display()
                .to_string(),
            Self::Can(interface) => format!("can-{interface}"),
            Self::GsUsb { serial, .. } => {
                format!("gs-usb-{}", serial.as_deref().unwrap_or("only"))
            }
            Self::Sim { .. } => return Ok(None),
        };
        let what = format!("device {}", self.name());
        Ok(Some(Lock::acquire(&format!("device-{key}"), &what, "")?))
    }

    /// Opens the device; `now` is the gateway's clock (the simulator starts its time there).
    pub fn open(&self, now: Duration) -> Result<Device, OpenError> {
        let transport = self.transport();
        let lock = self.lock()?;
        let port = match self {
            Self::Serial(path) | Self::Slcan(path) => {
                Port::open_tty(path).map_err(io::Error::from)?
            }
            Self::Can(interface) => Port::open_can(interface)?,
            Self::GsUsb { serial, detach } => Port::open_gs_usb(serial.as_deref(), *detach)?,
            Self::Sim { params, protocol } => {
                // The model's clock reads zero at `epoch`, the gateway's time of opening.
                let chassis = Chassis::new(SimParams::clone(params), Transport::Sim);
                let chassis = Box::new(match protocol {
                    Protocol::V1 => chassis,
                    Protocol::V2 => chassis.with_protocol_v2(),
                });
                return Ok(Device::Sim {
                    chassis,
                    epoch: now,
                });
            }
        };
        let mut device = Device::Port {
            port,
            framing: StreamFraming::new(transport),
            transport,
            out: Vec::new(),
            _lock: lock,
        };
        if transport == Transport::Slcan {
            device.set_up_slcan()?;
        }
        Ok(device)
    }
}

/// Why a device did not open.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// Another gateway owns it.
    #[error(transparent)]
    Owned(#[from] LockError),
    /// The OS refused (missing, permissions, busy with another program...).
    #[error(transparent)]
    Io(#[from] io::Error),
    /// The gs_usb adapter is missing, ambiguous, held by a driver or would not start.
    #[error(transparent)]
    GsUsb(#[from] scout_io::scout_usb::OpenError),
}

/// An open device.
#[derive(Debug)]
pub enum Device {
    /// A real port.
    Port {
        /// The OS resource.
        port: Port,
        /// The stream decoder (serial, slcan); `None` for SocketCAN.
        framing: Option<StreamFraming>,
        /// How messages are framed.
        transport: Transport,
        /// Bytes being encoded for one write.
        out: Vec<u8>,
        /// Ownership of the device while open.
        _lock: Option<Lock>,
    },
    /// The simulated chassis.
    Sim {
        /// The model.
        chassis: Box<Chassis>,
        /// The gateway time at which the model's time started.
        epoch: Duration,
    },
}

/// Longest a write may hold up the control loop.
/// Reads of the port per receive: a flood is drained at its rate yet never holds the loop long.
const MAX_READS_PER_RECEIVE: usize = 64;

const WRITE_TIMEOUT: Duration = Duration::from_millis(2);

/// Writes all of `bytes` or fails: a port that does not take 13 bytes in 2 ms is not draining.
fn write_all(port: &mut Port, bytes: &[u8]) -> io::Result<()> {
    let written = port.write_bytes(bytes, WRITE_TIMEOUT)?;
    if written < bytes.len() {
        return Err(io::Error::new(
            io::ErrorKind::TimedOut,
            format!(
                "the port took {written} of {} bytes: the device does not read",
                bytes.len()
            ),
        ));
    }
    Ok(())
}

impl Device {
    fn set_up_slcan(&mut self) -> io::Result<()> {
        let Self::Port { port, .. } = self else {
            return Ok(());
        };
        let mut setup = Vec::new();
        for command in [Slcan::Close, Slcan::SetBitrate(Bitrate::SCOUT), Slcan::Open] {
            setup.extend_from_slice(slcan::encode(&command).as_bytes());
        }
        write_all(port, &setup)
    }

    /// Sends one frame.
    pub fn send(&mut self, frame: &Outgoing, now: Duration) -> io::Result<()> {
        match self {
            Self::Sim { chassis, epoch } => {
                let at = now.saturating_sub(*epoch);
                match frame {
                    Outgoing::V1(counted) => chassis.handle_message(at, *counted),
                    Outgoing::V2(message) => chassis.handle_v2(at, *message),
                };
                Ok(())
            }
            Self::Port {
                port: port @ (Port::Can(_) | Port::GsUsb(_)),
                ..
            } => port.write_frame(&frame.can_frame()),
            Self::Port {
                port,
                transport,
                out,
                ..
            } => {
                out.clear();
                encode_stream(*transport, frame, out)
                    .map_err(|error| io::Error::new(io::ErrorKind::Unsupported, error))?;
                write_all(port, out)
            }
        }
    }

    /// Waits until `deadline` at the latest for input or a client's wake-up; `now` is when the
    /// caller last read the clock. The simulator's input is due at its feedback times.
    pub fn wait(
        &self,
        now: Duration,
        deadline: Duration,
        wake: &Listener<Ipc>,
        stops: Option<std::os::fd::BorrowedFd<'_>>,
    ) -> io::Result<Ready> {
        match self {
            Self::Sim { chassis, epoch } => {
                let due = chassis.next_feedback_at() + *epoch;
                wait(None, wake, stops, deadline.min(due).saturating_sub(now))
            }
            Self::Port { port, .. } => wait(Some(port), wake, stops, deadline.saturating_sub(now)),
        }
    }

    /// Reads what arrived by `now` (the port only when `readable`), handing every event it
    /// completes to `on_event`.
    pub fn receive(
        &mut self,
        now: Duration,
        readable: bool,
        buffer: &mut [u8],
        mut on_event: impl FnMut(RxEvent),
    ) -> io::Result<()> {
        match self {
            Self::Sim { chassis, epoch } => {
                match chassis.poll_feedback(now.saturating_sub(*epoch)) {
                    Some(Feedback::V1(batch)) => batch
                        .into_iter()
                        .for_each(|counted| on_event(RxEvent::Message(counted))),
                    Some(Feedback::V2(frames)) => frames
                        .into_iter()
                        .for_each(|message| on_event(RxEvent::V2(message))),
                    None => {}
                }
            }
            Self::Port { port, framing, .. } => {
                if !readable {
                    return Ok(());
                }
                // Everything already queued, up to a bound: a flood of frames is read at the
                // rate it comes (the kernel's queue does not overflow behind a slow loop) yet
                // never holds the loop past a tick.
                for _ in 0..MAX_READS_PER_RECEIVE {
                    match port.read(buffer, Duration::ZERO)? {
                        Incoming::Timeout => break,
                        Incoming::Bytes(n) => {
                            if let Some(framing) = framing {
                                framing.push(&buffer[..n], &mut on_event);
                            }
                        }
                        Incoming::Frame(frame) => on_event(decode_can(&frame)),
                        Incoming::Foreign(id) => {
                            on_event(RxEvent::Rejected(RxError::ForeignFrame(id)));
                        }
                        // Bus-off or error-passive: the caller closes the port (a link fault).
                        Incoming::BusError(error) if error.is_fault() => {
                            return Err(io::Error::other(error));
                        }
                        Incoming::BusError(error) => {
                            on_event(RxEvent::Rejected(RxError::ForeignFrame(error.class)));
                        }
                        Incoming::Malformed(error) => {
                            on_event(RxEvent::Rejected(RxError::GsUsb(error)));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Frames the kernel dropped for a full receive queue on the current port.
    pub fn overflowed_frames(&self) -> u64 {
        match self {
            Self::Port { port, .. } => port.overflowed_frames(),
            Self::Sim { .. } => 0,
        }
    }

    /// Bytes the stream decoder threw away so far.
    pub fn discarded_bytes(&self) -> u64 {
        match self {
            Self::Port {
                framing: Some(framing),
                ..
            } => framing.discarded_bytes(),
            Self::Port { framing: None, .. } | Self::Sim { .. } => 0,
        }
    }
}
