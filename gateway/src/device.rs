//! What the gateway talks to: a port with its framing (serial, slcan, SocketCAN) or the chassis
//! simulator in-process (`--sim`). Messages in and out; the control loop does the rest.

use std::io;
use std::path::PathBuf;
use std::time::Duration;

use scout_clients::ipc::TransportKind;
use scout_protocol::slcan::{self, Bitrate, Slcan};
use scout_protocol::{ControlMode, Counted, can};

use iceoryx2::port::listener::Listener;
use scout_clients::ipc::Ipc;

use crate::link::{RxError, RxEvent, StreamFraming, Transport, decode_can, encode_stream};
use crate::lock::{Lock, LockError};
use crate::port::{Incoming, Port};
use crate::sim::{Chassis, SimParams};
use crate::wait::wait;

/// Which device, before it is opened.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceSpec {
    /// An RS232 port.
    Serial(PathBuf),
    /// A serial-line CAN adapter.
    Slcan(PathBuf),
    /// A SocketCAN interface.
    Can(String),
    /// The simulated chassis, in-process.
    Sim(SimParams),
}

impl DeviceSpec {
    /// The transport kind published in the state.
    pub fn kind(&self) -> TransportKind {
        match self {
            Self::Serial(_) => TransportKind::Serial,
            Self::Slcan(_) => TransportKind::Slcan,
            Self::Can(_) => TransportKind::Can,
            Self::Sim(_) => TransportKind::Sim,
        }
    }

    /// The device path or interface, as shown to people.
    pub fn name(&self) -> String {
        match self {
            Self::Serial(path) | Self::Slcan(path) => path.display().to_string(),
            Self::Can(interface) => interface.clone(),
            Self::Sim(_) => "simulator".into(),
        }
    }

    /// The control mode every motion command must carry on this device.
    pub fn control_mode(&self) -> ControlMode {
        match self {
            Self::Serial(_) => ControlMode::Serial,
            _ => ControlMode::Can,
        }
    }

    fn link_transport(&self) -> Transport {
        match self {
            Self::Serial(_) => Transport::Serial,
            Self::Slcan(_) => Transport::Slcan,
            Self::Can(_) | Self::Sim(_) => Transport::Can,
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
            Self::Sim(_) => return Ok(None),
        };
        let what = format!("device {}", self.name());
        Ok(Some(Lock::acquire(&format!("device-{key}"), &what, "")?))
    }

    /// Opens the device; `now` is the gateway's clock (the simulator starts its time there).
    pub fn open(&self, now: Duration) -> Result<Device, OpenError> {
        let transport = self.link_transport();
        let lock = self.lock()?;
        let port = match self {
            Self::Serial(path) | Self::Slcan(path) => {
                Port::open_tty(path).map_err(io::Error::from)?
            }
            Self::Can(interface) => Port::open_can(interface)?,
            Self::Sim(params) => {
                let mut chassis = Box::new(Chassis::new(params.clone(), Transport::Can));
                // The model's clock starts at zero: bring it to the gateway's time.
                let _ = chassis.poll_feedback(now);
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

    /// Sends one message.
    pub fn send(&mut self, counted: &Counted, now: Duration) -> io::Result<()> {
        match self {
            Self::Sim { chassis, epoch } => {
                chassis.handle_message(now.saturating_sub(*epoch), *counted);
                Ok(())
            }
            Self::Port {
                port: port @ Port::Can(_),
                ..
            } => port.write_frame(&can::encode(&counted.message, counted.count)),
            Self::Port {
                port,
                transport,
                out,
                ..
            } => {
                out.clear();
                encode_stream(*transport, &counted.message, counted.count, out);
                write_all(port, out)
            }
        }
    }

    /// Waits at most `timeout` for input or a client's wake-up, and hands every event the input
    /// completes to `on_event`. Returns whether a client woke it.
    pub fn receive(
        &mut self,
        buffer: &mut [u8],
        timeout: Duration,
        wake: &Listener<Ipc>,
        now: impl Fn() -> Duration,
        mut on_event: impl FnMut(RxEvent),
    ) -> io::Result<bool> {
        match self {
            Self::Sim { chassis, epoch } => {
                let due = chassis.next_feedback_at() + *epoch;
                let ready = wait(None, wake, due.min(now() + timeout).saturating_sub(now()))?;
                if let Some(batch) = chassis.poll_feedback(now().saturating_sub(*epoch)) {
                    batch
                        .into_iter()
                        .for_each(|counted| on_event(RxEvent::Message(counted)));
                }
                Ok(ready.wake)
            }
            Self::Port { port, framing, .. } => {
                let ready = wait(Some(&*port), wake, timeout)?;
                if !ready.port {
                    return Ok(ready.wake);
                }
                match port.read(buffer, Duration::ZERO)? {
                    Incoming::Timeout => {}
                    Incoming::Bytes(n) => {
                        if let Some(framing) = framing {
                            framing.push(&buffer[..n], on_event);
                        }
                    }
                    Incoming::Frame(frame) => on_event(decode_can(&frame)),
                    Incoming::Foreign(id) => on_event(RxEvent::Rejected(RxError::ForeignFrame(id))),
                }
                Ok(ready.wake)
            }
        }
    }

    /// Bytes the stream decoder threw away so far.
    pub fn discarded_bytes(&self) -> u64 {
        match self {
            Self::Port {
                framing: Some(framing),
                ..
            } => framing.discarded_bytes(),
            _ => 0,
        }
    }
}
