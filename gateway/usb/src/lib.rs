//! scout-usb: a gs_usb USB-CAN adapter (candleLight, CANable, the adapter AgileX ships) as the
//! chassis port in user space, through usbfs with `nusb`: no kernel CAN driver, no `ip link`,
//! no libusb. The protocol itself is sans-IO in `scout_protocol::gs_usb`; this crate finds the
//! adapter, sets it up at 500 kbit/s and moves host frames.
//!
//! A thread of the port's own keeps the IN endpoint's transfers queued and hands what arrives
//! over a channel; a socket pair makes that readable by `poll`, so the gateway waits on the
//! adapter as it waits on a tty or a CAN socket.

use std::fmt;
use std::io::{self, Read as _, Write as _};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TryRecvError, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

use nusb::transfer::{Bulk, ControlIn, ControlOut, ControlType, In, Out, Recipient, TransferError};
use nusb::{DeviceInfo, Endpoint, Interface, MaybeFuture as _};
use scout_protocol::CanFrame;
use scout_protocol::gs_usb::{
    self, BitTiming, BtConst, DeviceConfig, DeviceMode, HostConfig, HostFrame, KNOWN_ADAPTERS,
    RX_ECHO_ID, Received, Request, Setup,
};

/// The chassis' CAN bit rate.
pub const BITRATE: u32 = 500_000;
/// The adapter's interface the gs_usb protocol lives on.
const INTERFACE: u8 = 0;
/// The CAN channel the chassis is on.
const CHANNEL: u8 = 0;
/// How long a control request may take.
const CONTROL_TIMEOUT: Duration = Duration::from_millis(500);
/// IN transfers kept queued: frames arrive every millisecond or two at most.
const IN_TRANSFERS: usize = 8;
/// Frames read from the adapter and not yet taken by the gateway: three seconds of a v2
/// chassis' feedback. Past it, frames are dropped and counted, as the kernel's full receive
/// queue does on SocketCAN.
const QUEUE: usize = 2048;
/// OUT transfers the adapter may hold before a write waits.
const OUT_TRANSFERS: usize = 4;
/// Frames sent whose echo has not come back (the adapter echoes a frame once it is on the
/// bus): past this many, nothing on the bus acknowledges them. Linux's driver stops its queue
/// at 10.
pub const MAX_UNECHOED: u32 = 10;

/// A gs_usb adapter on the USB bus.
#[derive(Debug, Clone)]
pub struct Adapter {
    info: DeviceInfo,
}

impl Adapter {
    /// Its serial number, if it reports one.
    pub fn serial(&self) -> Option<&str> {
        self.info.serial_number()
    }

    /// Where it is plugged in, as Linux names the device (`1-1.2`).
    pub fn location(&self) -> String {
        self.info
            .sysfs_path()
            .file_name()
            .map_or_else(String::new, |name| name.to_string_lossy().into_owned())
    }

    /// The product string.
    pub fn product(&self) -> Option<&str> {
        self.info.product_string()
    }

    /// Its vendor and product id.
    pub fn usb_id(&self) -> gs_usb::UsbId {
        gs_usb::UsbId {
            vendor: self.info.vendor_id(),
            product: self.info.product_id(),
        }
    }

    /// The kernel driver bound to its gs_usb interface (`gs_usb` where the module is loaded).
    pub fn driver(&self) -> Option<String> {
        let link = interface_sysfs(self.info.sysfs_path()).join("driver");
        std::fs::read_link(link)
            .ok()
            .and_then(|target| target.file_name().map(|n| n.to_string_lossy().into_owned()))
    }

    /// The CAN interfaces the kernel driver made of it (`can2`), if one is bound.
    pub fn net_interfaces(&self) -> Vec<String> {
        let dir = interface_sysfs(self.info.sysfs_path()).join("net");
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .map(|entries| {
                entries
                    .filter_map(Result::ok)
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default();
        names.sort();
        names
    }
}

impl Adapter {
    /// Which adapter: ids, place and serial number.
    pub fn identity(&self) -> String {
        let id = self.usb_id();
        format!(
            "{:04x}:{:04x} at {} (serial {})",
            id.vendor,
            id.product,
            self.location(),
            self.serial().unwrap_or("none")
        )
    }
}

/// The adapter and who holds it: `1d50:606f at 1-1.2 (serial X, kernel driver gs_usb: can2)`.
impl fmt::Display for Adapter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let identity = self.identity();
        f.write_str(identity.strip_suffix(')').unwrap_or(&identity))?;
        match self.driver() {
            Some(driver) => write!(f, ", kernel driver {driver}")?,
            None => f.write_str(", no kernel driver")?,
        }
        let nets = self.net_interfaces();
        if !nets.is_empty() {
            write!(f, ": {}", nets.join(", "))?;
        }
        f.write_str(")")
    }
}

/// The sysfs directory of the adapter's gs_usb interface (`.../1-1.2:1.0`).
fn interface_sysfs(device: &Path) -> PathBuf {
    let name = device
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    device.join(format!("{name}:1.{INTERFACE}"))
}

/// Every gs_usb adapter plugged in (those with an id Linux's driver knows).
pub fn adapters() -> io::Result<Vec<Adapter>> {
    let mut found: Vec<Adapter> = nusb::list_devices()
        .wait()
        .map_err(io::Error::from)?
        .filter(|info| {
            KNOWN_ADAPTERS.contains(&gs_usb::UsbId {
                vendor: info.vendor_id(),
                product: info.product_id(),
            })
        })
        .map(|info| Adapter { info })
        .collect();
    found.sort_by_key(Adapter::location);
    Ok(found)
}

/// Why an adapter could not be opened; each says what to do.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// None plugged in (or none with the serial number asked).
    #[error("{0}")]
    NotFound(String),
    /// Several, and no serial number to choose.
    #[error(
        "several gs_usb adapters are plugged in ({0}): choose one with --gs-usb SERIAL \
         (`scout doctor` lists them)"
    )]
    Several(String),
    /// A kernel driver holds it and detaching was not asked for.
    #[error(
        "the kernel's {driver} driver holds the adapter {adapter}: use --can {interface}, or \
         --gs-usb-detach to take the adapter from the driver"
    )]
    Bound {
        /// The adapter.
        adapter: String,
        /// The driver's name.
        driver: String,
        /// Its CAN interface (or `canN` when unknown).
        interface: String,
    },
    /// The adapter answered its set-up wrongly or not at all.
    #[error("setting up the adapter {adapter}: {what}")]
    SetUp {
        /// The adapter.
        adapter: String,
        /// What went wrong.
        what: String,
    },
    /// The OS refused (permissions, busy, gone).
    #[error("opening the adapter {adapter}: {error}{hint}")]
    Io {
        /// The adapter.
        adapter: String,
        /// The OS's error.
        error: io::Error,
        /// What to do about it.
        hint: &'static str,
    },
}

impl OpenError {
    fn io(adapter: &Adapter, error: impl Into<io::Error>) -> Self {
        let error = error.into();
        let hint = match error.kind() {
            io::ErrorKind::PermissionDenied => {
                " (the gateway's user needs the device: install 60-scout-gs-usb.rules in /etc/udev/rules.d, as the package does, or run as root)"
            }
            io::ErrorKind::ResourceBusy => " (another program has it open)",
            _ => "",
        };
        Self::Io {
            adapter: adapter.identity(),
            error,
            hint,
        }
    }
}

/// Chooses the adapter: the one with `serial`, else the only one.
pub fn choose(found: Vec<Adapter>, serial: Option<&str>) -> Result<Adapter, OpenError> {
    let listed = |found: &[Adapter]| {
        found
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    };
    match serial {
        Some(serial) => {
            let all = listed(&found);
            found
                .into_iter()
                .find(|a| a.serial() == Some(serial))
                .ok_or_else(|| {
                    OpenError::NotFound(if all.is_empty() {
                        format!("no gs_usb adapter with serial number {serial}: none is plugged in")
                    } else {
                        format!("no gs_usb adapter with serial number {serial} (found: {all})")
                    })
                })
        }
        None => match found.len() {
            0 => Err(OpenError::NotFound(
                "no gs_usb adapter is plugged in (candleLight ids, e.g. 1d50:606f): check the \
                 cable and `lsusb`"
                    .into(),
            )),
            1 => Ok(found.into_iter().next().expect("one")),
            _ => Err(OpenError::Several(listed(&found))),
        },
    }
}

/// What one read of the adapter got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// A host frame, understood.
    Frame(Received),
    /// Bytes that are no host frame, and why.
    Malformed(gs_usb::Error),
}

/// What the IN thread hands over.
type Delivery = Result<HostFrameOrGarbage, TransferError>;

#[derive(Debug)]
enum HostFrameOrGarbage {
    Frame(HostFrame),
    Garbage(gs_usb::Error),
}

/// An open, started adapter.
pub struct GsUsbPort {
    adapter: String,
    interface: Interface,
    out: Endpoint<Bulk, Out>,
    deliveries: Receiver<Delivery>,
    wake: UnixStream,
    stop: Arc<AtomicBool>,
    reader: Option<JoinHandle<()>>,
    next_echo: u32,
    unechoed: u32,
    overflowed: u64,
    /// Frames the reading thread dropped, the queue full.
    dropped: Arc<AtomicU64>,
    failed: Option<TransferError>,
}

impl fmt::Debug for GsUsbPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GsUsbPort")
            .field("adapter", &self.adapter)
            .field("unechoed", &self.unechoed)
            .finish_non_exhaustive()
    }
}

impl GsUsbPort {
    /// Opens the adapter with `serial` (or the only one), sets 500 kbit/s and starts its
    /// channel. A kernel driver bound to it is detached only when `detach` says so.
    pub fn open(serial: Option<&str>, detach: bool) -> Result<Self, OpenError> {
        let found = adapters()
            .map_err(|error| OpenError::NotFound(format!("listing USB devices failed: {error}")))?;
        let adapter = choose(found, serial)?;
        Self::open_adapter(&adapter, detach)
    }

    /// Opens `adapter` (see [`GsUsbPort::open`]).
    pub fn open_adapter(adapter: &Adapter, detach: bool) -> Result<Self, OpenError> {
        let name = adapter.identity();
        if let Some(driver) = adapter.driver() {
            if detach {
                tracing::warn!(
                    "detaching the kernel's {driver} driver from the adapter {adapter} \
                     (--gs-usb-detach)"
                );
            } else {
                return Err(OpenError::Bound {
                    adapter: name,
                    driver,
                    interface: adapter
                        .net_interfaces()
                        .into_iter()
                        .next()
                        .unwrap_or_else(|| "canN".into()),
                });
            }
        }
        let device = adapter
            .info
            .open()
            .wait()
            .map_err(|e| OpenError::io(adapter, e))?;
        let interface = if detach {
            device.detach_and_claim_interface(INTERFACE).wait()
        } else {
            device.claim_interface(INTERFACE).wait()
        }
        .map_err(|e| OpenError::io(adapter, e))?;
        let set_up = |what: String| OpenError::SetUp {
            adapter: name.clone(),
            what,
        };
        let (in_address, out_address) = bulk_endpoints(&interface)
            .ok_or_else(|| set_up("its interface 0 has no bulk IN and OUT endpoints".into()))?;
        set_up_channel(&interface).map_err(set_up)?;
        let mut input = interface
            .endpoint::<Bulk, In>(in_address)
            .map_err(|e| OpenError::io(adapter, e))?;
        let mut out = interface
            .endpoint::<Bulk, Out>(out_address)
            .map_err(|e| OpenError::io(adapter, e))?;
        // A halt left by an earlier owner (or a stall before an unplug) is cleared.
        let _ = input.clear_halt().wait();
        let _ = out.clear_halt().wait();
        let (wake, signal) = UnixStream::pair().map_err(|e| OpenError::io(adapter, e))?;
        wake.set_nonblocking(true)
            .and_then(|()| signal.set_nonblocking(true))
            .map_err(|e| OpenError::io(adapter, e))?;
        let (sender, deliveries) = mpsc::sync_channel(QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let dropped = Arc::new(AtomicU64::new(0));
        let reader = {
            let (stop, dropped) = (Arc::clone(&stop), Arc::clone(&dropped));
            std::thread::Builder::new()
                .name("gs_usb in".into())
                .spawn(move || read_in(input, &sender, &signal, &stop, &dropped))
                .map_err(|e| OpenError::io(adapter, e))?
        };
        tracing::info!("gs_usb adapter {name}: 500 kbit/s, channel started");
        Ok(Self {
            adapter: name,
            interface,
            out,
            deliveries,
            wake,
            stop,
            reader: Some(reader),
            next_echo: 0,
            unechoed: 0,
            overflowed: 0,
            dropped,
            failed: None,
        })
    }

    /// Frames lost before the gateway read them: those the adapter said it lost (one per
    /// frame flagged with its overflow bit: it does not say how many), and those dropped here
    /// with the queue full.
    pub fn overflowed_frames(&self) -> u64 {
        self.overflowed + self.dropped.load(Ordering::Relaxed)
    }

    /// Reads one input, waiting at most `timeout` (zero: only what already arrived). Echoes of
    /// sent frames are consumed here. `Ok(None)`: nothing in time.
    pub fn read(&mut self, timeout: Duration) -> io::Result<Option<Input>> {
        self.drain_wake();
        loop {
            let delivery = if timeout.is_zero() {
                match self.deliveries.try_recv() {
                    Ok(delivery) => delivery,
                    Err(TryRecvError::Empty) => return Ok(None),
                    Err(TryRecvError::Disconnected) => return Err(self.reader_gone()),
                }
            } else {
                match self.deliveries.recv_timeout(timeout) {
                    Ok(delivery) => delivery,
                    Err(RecvTimeoutError::Timeout) => return Ok(None),
                    Err(RecvTimeoutError::Disconnected) => return Err(self.reader_gone()),
                }
            };
            match delivery {
                Err(error) => {
                    self.failed = Some(error);
                    return Err(transfer_error("reading from", &self.adapter, error));
                }
                Ok(HostFrameOrGarbage::Garbage(error)) => return Ok(Some(Input::Malformed(error))),
                Ok(HostFrameOrGarbage::Frame(frame)) => {
                    if frame.overflow() {
                        self.overflowed += 1;
                    }
                    match frame.received() {
                        Received::Echo(_) => self.unechoed = self.unechoed.saturating_sub(1),
                        received => return Ok(Some(Input::Frame(received))),
                    }
                }
            }
        }
    }

    fn reader_gone(&self) -> io::Error {
        match self.failed {
            Some(error) => transfer_error("reading from", &self.adapter, error),
            None => io::Error::new(
                io::ErrorKind::BrokenPipe,
                format!("the adapter {}'s reading thread ended", self.adapter),
            ),
        }
    }

    fn drain_wake(&mut self) {
        let mut sink = [0u8; 64];
        while matches!(self.wake.read(&mut sink), Ok(n) if n > 0) {}
    }

    /// Sends one frame, waiting at most `timeout` for the adapter to take it. Too many frames
    /// not echoed (nothing on the bus acknowledges them) is an [`Unacknowledged`] error.
    pub fn write(&mut self, frame: &CanFrame, timeout: Duration) -> io::Result<()> {
        if self.unechoed >= MAX_UNECHOED {
            return Err(io::Error::other(Unacknowledged {
                frames: self.unechoed,
            }));
        }
        while self.out.pending() > 0 {
            let wait = if self.out.pending() >= OUT_TRANSFERS {
                timeout
            } else {
                Duration::ZERO
            };
            let Some(done) = self.out.wait_next_complete(wait) else {
                if self.out.pending() >= OUT_TRANSFERS {
                    return Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        format!(
                            "the adapter {} took no frame in {timeout:?}: it does not read its \
                             OUT endpoint",
                            self.adapter
                        ),
                    ));
                }
                break;
            };
            done.status
                .map_err(|error| transfer_error("writing to", &self.adapter, error))?;
        }
        // Echo ids cycle below RX_ECHO_ID, which marks frames from the bus.
        let echo = self.next_echo;
        self.next_echo = (self.next_echo + 1) % RX_ECHO_ID;
        let (bytes, len) = HostFrame::transmit(frame, CHANNEL, echo).encode();
        self.out.submit(bytes[..len].to_vec().into());
        self.unechoed += 1;
        Ok(())
    }
}

impl Drop for GsUsbPort {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // The channel is reset so the adapter stops sending (the kernel driver does the same
        // when the interface goes down); an adapter that is gone does not answer.
        let _ = control_out(
            &self.interface,
            Request::Mode,
            &DeviceMode::STOPPED.encode(),
        );
        if let Some(reader) = self.reader.take() {
            // Emptied while it ends: a thread waiting to hand over a failure is let go.
            while !reader.is_finished() {
                while self.deliveries.try_recv().is_ok() {}
                std::thread::sleep(Duration::from_millis(5));
            }
            let _ = reader.join();
        }
    }
}

impl AsRawFd for GsUsbPort {
    /// Readable when the adapter delivered something (or its reading failed).
    fn as_raw_fd(&self) -> RawFd {
        self.wake.as_raw_fd()
    }
}

/// The adapter has not echoed this many frames: they are not on the bus (no other node
/// acknowledges them, or the adapter is bus-off). A link fault, as a full CAN transmit queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unacknowledged {
    /// Frames sent and not echoed.
    pub frames: u32,
}

impl fmt::Display for Unacknowledged {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the adapter put none of the last {} frames on the bus: nothing acknowledges them \
             (is the chassis on, the bus wired and terminated?)",
            self.frames
        )
    }
}

impl std::error::Error for Unacknowledged {}

fn transfer_error(doing: &str, adapter: &str, error: TransferError) -> io::Error {
    let kind = match error {
        TransferError::Disconnected => io::ErrorKind::NotConnected,
        _ => io::ErrorKind::Other,
    };
    let hint = match error {
        TransferError::Disconnected => ": it was unplugged or reset",
        TransferError::Stall => ": the adapter stalled its endpoint",
        TransferError::Fault => ": unplugged, reset or failing",
        _ => "",
    };
    io::Error::new(
        kind,
        format!("{doing} the adapter {adapter}: {error}{hint}"),
    )
}

/// The interface's bulk IN and OUT endpoint addresses.
fn bulk_endpoints(interface: &Interface) -> Option<(u8, u8)> {
    let descriptor = interface.descriptor()?;
    let mut input = None;
    let mut output = None;
    for endpoint in descriptor.endpoints() {
        if endpoint.transfer_type() != nusb::descriptors::TransferType::Bulk {
            continue;
        }
        match endpoint.direction() {
            nusb::transfer::Direction::In => input = input.or(Some(endpoint.address())),
            nusb::transfer::Direction::Out => output = output.or(Some(endpoint.address())),
        }
    }
    Some((input?, output?))
}

/// The set-up Linux's driver does: byte order, the device's configuration, the channel's
/// constants, the bit timing for 500 kbit/s, then start.
fn set_up_channel(interface: &Interface) -> Result<(), String> {
    control_out(interface, Request::HostFormat, &HostConfig::encode())
        .map_err(|e| format!("the host format request failed: {e}"))?;
    let config = DeviceConfig::decode(&control_in(interface, Request::DeviceConfig)?)
        .map_err(|e| format!("its device configuration: {e}"))?;
    if config.channels == 0 {
        return Err("it reports no CAN channel".into());
    }
    let constants = BtConst::decode(&control_in(interface, Request::BtConst)?)
        .map_err(|e| format!("its bit-timing constants: {e}"))?;
    let timing = BitTiming::for_bitrate(&constants, BITRATE)
        .map_err(|e| format!("no bit timing for 500 kbit/s: {e}"))?;
    tracing::debug!(
        "gs_usb: firmware {}, hardware {}, {} Hz clock, {timing:?}",
        config.software_version,
        config.hardware_version,
        constants.clock_hz
    );
    // A channel left started by an earlier owner is reset before it is set.
    control_out(interface, Request::Mode, &DeviceMode::STOPPED.encode())
        .map_err(|e| format!("resetting the channel failed: {e}"))?;
    control_out(interface, Request::BitTiming, &timing.encode())
        .map_err(|e| format!("setting 500 kbit/s failed: {e}"))?;
    let start = DeviceMode {
        start: true,
        flags: 0,
    };
    control_out(interface, Request::Mode, &start.encode())
        .map_err(|e| format!("starting the channel failed: {e}"))
}

fn control_out(interface: &Interface, request: Request, data: &[u8]) -> io::Result<()> {
    let setup = Setup::new(request, CHANNEL, interface.interface_number());
    interface
        .control_out(
            ControlOut {
                control_type: ControlType::Vendor,
                recipient: Recipient::Interface,
                request: setup.request,
                value: setup.value,
                index: setup.index,
                data,
            },
            CONTROL_TIMEOUT,
        )
        .wait()
        .map_err(io::Error::from)
}

fn control_in(interface: &Interface, request: Request) -> Result<Vec<u8>, String> {
    let setup = Setup::new(request, CHANNEL, interface.interface_number());
    interface
        .control_in(
            ControlIn {
                control_type: ControlType::Vendor,
                recipient: Recipient::Interface,
                request: setup.request,
                value: setup.value,
                index: setup.index,
                length: setup.length,
            },
            CONTROL_TIMEOUT,
        )
        .wait()
        .map_err(|e| format!("request {request:?} failed: {e}"))
}

/// The IN endpoint's thread: keeps transfers queued and hands every completed one over, until
/// `stop` or a transfer fails (unplugged, stalled).
fn read_in(
    mut input: Endpoint<Bulk, In>,
    sender: &SyncSender<Delivery>,
    signal: &UnixStream,
    stop: &AtomicBool,
    dropped: &AtomicU64,
) {
    let size = input.max_packet_size().max(64);
    let mut signal = signal;
    while !stop.load(Ordering::Relaxed) {
        while input.pending() < IN_TRANSFERS {
            let buffer = input.allocate(size);
            input.submit(buffer);
        }
        let Some(done) = input.wait_next_complete(Duration::from_millis(50)) else {
            continue;
        };
        let delivery = match done.status {
            Ok(()) => {
                let bytes = &done.buffer[..done.actual_len.min(done.buffer.len())];
                let timestamped = bytes.len() >= gs_usb::frame::LEN_TIMESTAMPED;
                Ok(match HostFrame::decode(bytes, timestamped) {
                    Ok(frame) => HostFrameOrGarbage::Frame(frame),
                    Err(error) => HostFrameOrGarbage::Garbage(error),
                })
            }
            Err(TransferError::Cancelled) if stop.load(Ordering::Relaxed) => break,
            Err(error) => Err(error),
        };
        let failed = delivery.is_err();
        match sender.try_send(delivery) {
            Ok(()) => {}
            // A failure is handed over whatever it waits for: it ends the port.
            Err(TrySendError::Full(delivery)) if failed => {
                if sender.send(delivery).is_err() {
                    break;
                }
            }
            Err(TrySendError::Full(_)) => {
                dropped.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Disconnected(_)) => break,
        }
        let _ = signal.write(&[1]);
        if failed {
            break;
        }
        input.submit(done.buffer);
    }
    input.cancel_all();
    while input.pending() > 0
        && input
            .wait_next_complete(Duration::from_millis(100))
            .is_some()
    {}
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packaged udev rule gives the gateway's group every adapter id the transport looks
    /// for, and no other.
    #[test]
    fn the_udev_rule_lists_the_known_adapters() {
        let rules = include_str!("../../../tests/release/debian/60-scout-gs-usb.rules");
        let mut listed: Vec<(u16, u16)> = rules
            .lines()
            .filter(|line| line.starts_with("SUBSYSTEM"))
            .map(|line| {
                let field = |name: &str| {
                    let start = line.find(&format!("{name}}}==\"")).expect(name) + name.len() + 4;
                    u16::from_str_radix(&line[start..start + 4], 16).expect("a hex id")
                };
                (field("ATTR{idVendor"), field("ATTR{idProduct"))
            })
            .collect();
        let mut known: Vec<(u16, u16)> = KNOWN_ADAPTERS
            .iter()
            .map(|a| (a.vendor, a.product))
            .collect();
        listed.sort_unstable();
        known.sort_unstable();
        assert_eq!(listed, known);
        assert!(rules.contains("GROUP=\"scout\""));
    }

    #[test]
    fn unacknowledged_frames_are_a_bus_fault_that_says_what_to_check() {
        let error = Unacknowledged {
            frames: MAX_UNECHOED,
        };
        assert!(error.to_string().contains("is the chassis on"), "{error}");
    }
}
