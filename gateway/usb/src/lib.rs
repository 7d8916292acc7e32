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
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TryRecvError, TrySendError};
use std::time::Duration;

use nusb::transfer::{Bulk, ControlIn, ControlOut, ControlType, In, Out, Recipient, TransferError};
use nusb::{DeviceInfo, Endpoint, Interface, MaybeFuture as _};
use scout_protocol::CanFrame;
use scout_protocol::gs_usb::{
    self, BitTiming, BtConst, DeviceConfig, DeviceMode, HostConfig, HostFrame, KNOWN_ADAPTERS,
    Received, Request, Setup,
};

/// The chassis' CAN bit rate.
pub const BITRATE: u32 = 500_000;
/// The adapter's interface the gs_usb protocol lives on.
const INTERFACE: u8 = 0;
/// The CAN channel the chassis is on.
const CHANNEL: u8 = 0;
/// How long a control request may take: an adapter answers in a millisecond or two, and one
/// that does not answer holds the caller's loop this long per request.
const CONTROL_TIMEOUT: Duration = Duration::from_millis(100);
/// The name Linux gives a program's claim of an interface through usbfs.
const USBFS: &str = "usbfs";
/// IN transfers kept queued: frames arrive every millisecond or two at most.
const IN_TRANSFERS: usize = 8;
/// Frames read from the adapter and not yet taken by the gateway: three seconds of a v2
/// chassis' feedback. Past it, frames are dropped and counted, as the kernel's full receive
/// queue does on SocketCAN.
const QUEUE: usize = 2048;
/// Frames sent whose echo has not come back (the adapter echoes a frame once it is on the
/// bus): with this many, nothing on the bus acknowledges them. Linux's driver has as many
/// transmit contexts, and its echo ids are theirs: 0 to 9.
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
    /// Another program holds it through usbfs.
    #[error(
        "another program holds the adapter {0} through usbfs (another scout-gateway --gs-usb, \
         scout doctor --gs-usb, python-can...): stop it first"
    )]
    Busy(String),
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
        what: SetUpError,
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

/// A step of an adapter's set-up that failed.
#[derive(Debug, thiserror::Error)]
pub enum SetUpError {
    /// A control request was not taken.
    #[error("{what} failed: {error}")]
    Request {
        /// The request, in words.
        what: &'static str,
        /// What USB said.
        error: io::Error,
    },
    /// An answer did not decode.
    #[error("its {what}: {error}")]
    Answer {
        /// What it answered, in words.
        what: &'static str,
        /// Why it does not decode.
        error: gs_usb::Error,
    },
    /// Its constants allow no bit timing for 500 kbit/s.
    #[error("no bit timing for 500 kbit/s: {0}")]
    Timing(gs_usb::BitTimingError),
    /// It has no bulk endpoints to carry frames.
    #[error("its interface 0 has no bulk IN and OUT endpoints")]
    Endpoints,
    /// Its IN endpoint's packet size is not one USB has.
    #[error("its IN endpoint's packet size, {0} bytes, is not a USB one")]
    PacketSize(usize),
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
            let mut matching: Vec<Adapter> = found
                .into_iter()
                .filter(|a| a.serial() == Some(serial))
                .collect();
            if matching.len() > 1 {
                // Clones share serial numbers: which one is meant cannot be told.
                return Err(OpenError::Several(listed(&matching)));
            }
            matching.pop().ok_or_else(|| {
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
    /// A standard data frame from the bus.
    Frame(CanFrame),
    /// An extended-id or remote frame (SCOUT sends none): its raw `can_id`.
    Foreign(u32),
    /// An error frame: `linux/can/error.h`'s class bits and data, as SocketCAN gives them.
    BusError {
        /// The class bits (bus-off 0x40, controller 0x04, ...).
        class: u32,
        /// The error frame's data (byte 1: the controller's state).
        data: [u8; 8],
    },
    /// A transfer that is no frame of this channel, or an echo of nothing sent, and why.
    Malformed(gs_usb::Error),
}

/// What the IN thread hands over: an input, or the failure that ended it.
type Delivery = Result<Input, TransferError>;

/// The echo ids of frames sent and not yet echoed: bit N for id N, ids below
/// [`MAX_UNECHOED`], as Linux's driver keeps its transmit contexts. The writer sets a bit, the
/// reading thread clears it when the echo comes (so an echo never waits in the queue).
#[derive(Debug, Default)]
struct InFlight(AtomicU32);

impl InFlight {
    /// Takes a free echo id, if one is free.
    fn take(&self) -> Option<u32> {
        let busy = self.0.load(Ordering::Acquire);
        let id = (0..MAX_UNECHOED).find(|id| busy & (1 << id) == 0)?;
        self.0.fetch_or(1 << id, Ordering::AcqRel);
        Some(id)
    }

    /// Frees `id` when it was taken; `false` for an echo of nothing sent.
    fn echoed(&self, id: u32) -> bool {
        id < MAX_UNECHOED && self.0.fetch_and(!(1 << id), Ordering::AcqRel) & (1 << id) != 0
    }

    /// How many are taken.
    fn count(&self) -> u32 {
        self.0.load(Ordering::Acquire).count_ones()
    }
}

/// An open, started adapter.
pub struct GsUsbPort {
    adapter: String,
    interface: Interface,
    out: Endpoint<Bulk, Out>,
    deliveries: Receiver<Delivery>,
    wake: UnixStream,
    stop: Arc<AtomicBool>,
    in_flight: Arc<InFlight>,
    /// Frames lost before the gateway read them (see [`GsUsbPort::overflowed_frames`]).
    overflowed: Arc<AtomicU64>,
    failed: Option<TransferError>,
}

impl fmt::Debug for GsUsbPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GsUsbPort")
            .field("adapter", &self.adapter)
            .field("in_flight", &self.in_flight.count())
            .finish_non_exhaustive()
    }
}

impl GsUsbPort {
    /// Opens the adapter with `serial` (or the only one), sets 500 kbit/s and starts its
    /// channel. A kernel driver bound to it is detached only when `detach` says so (and not
    /// bound back when the port closes: a link that flaps never hands the adapter to the
    /// driver, and to whatever brings its interface up, in between).
    ///
    /// It runs on the caller's thread: an adapter that does not answer fails at its first
    /// control request (0.1 s); one that answers slowly holds the caller up to 0.1 s for each
    /// of the six (a healthy one answers in a millisecond or two).
    pub fn open(serial: Option<&str>, detach: bool) -> Result<Self, OpenError> {
        let found = adapters()
            .map_err(|error| OpenError::NotFound(format!("listing USB devices failed: {error}")))?;
        let adapter = choose(found, serial)?;
        Self::open_adapter(&adapter, detach)
    }

    /// Opens `adapter` (see [`GsUsbPort::open`]).
    pub fn open_adapter(adapter: &Adapter, detach: bool) -> Result<Self, OpenError> {
        let name = adapter.identity();
        let driver = adapter.driver();
        match driver.as_deref() {
            None => {}
            // usbfs is another program in user space, never taken from it.
            Some(USBFS) => return Err(OpenError::Busy(name)),
            Some(driver) if detach => tracing::warn!(
                "detaching the kernel's {driver} driver from the adapter {adapter} \
                 (--gs-usb-detach)"
            ),
            Some(driver) => {
                return Err(OpenError::Bound {
                    adapter: name,
                    driver: driver.to_owned(),
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
        if driver.is_some() {
            device
                .detach_kernel_driver(INTERFACE)
                .map_err(|e| OpenError::io(adapter, e))?;
        }
        let interface = device
            .claim_interface(INTERFACE)
            .wait()
            .map_err(|e| OpenError::io(adapter, e))?;
        let set_up = |what: SetUpError| OpenError::SetUp {
            adapter: name.clone(),
            what,
        };
        // Whether it answers at all, before anything that could wait longer.
        let timing = timing_for(&interface).map_err(set_up)?;
        let (in_address, out_address) =
            bulk_endpoints(&interface).ok_or_else(|| set_up(SetUpError::Endpoints))?;
        let mut input = interface
            .endpoint::<Bulk, In>(in_address)
            .map_err(|e| OpenError::io(adapter, e))?;
        let mut out = interface
            .endpoint::<Bulk, Out>(out_address)
            .map_err(|e| OpenError::io(adapter, e))?;
        let size = transfer_size(input.max_packet_size())
            .ok_or_else(|| set_up(SetUpError::PacketSize(input.max_packet_size())))?;
        // A halt left by an earlier owner (or a stall before an unplug) is cleared.
        let _ = input.clear_halt().wait();
        let _ = out.clear_halt().wait();
        let (wake, signal) = UnixStream::pair().map_err(|e| OpenError::io(adapter, e))?;
        wake.set_nonblocking(true)
            .and_then(|()| signal.set_nonblocking(true))
            .map_err(|e| OpenError::io(adapter, e))?;
        let (sender, deliveries) = mpsc::sync_channel(QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let in_flight = Arc::new(InFlight::default());
        let overflowed = Arc::new(AtomicU64::new(0));
        let reader = Reader {
            stop: Arc::clone(&stop),
            in_flight: Arc::clone(&in_flight),
            overflowed: Arc::clone(&overflowed),
            sender,
            signal,
            size,
        };
        // Not joined when the port closes: it ends by itself within one wait.
        std::thread::Builder::new()
            .name("gs_usb in".into())
            .spawn(move || reader.run(input))
            .map_err(|e| OpenError::io(adapter, e))?;
        let port = Self {
            adapter: name.clone(),
            interface,
            out,
            deliveries,
            wake,
            stop,
            in_flight,
            overflowed,
            failed: None,
        };
        // Started last: a failure before leaves the channel as it was, one after is undone
        // by the port's drop.
        start_channel(&port.interface, &timing).map_err(set_up)?;
        tracing::info!(
            "gs_usb adapter {}: 500 kbit/s, channel started",
            port.adapter
        );
        Ok(port)
    }

    /// Frames lost before the gateway read them: those the adapter said it lost (one per
    /// frame flagged with its overflow bit: it does not say how many), and frames and errors
    /// dropped here, the queue full.
    pub fn overflowed_frames(&self) -> u64 {
        self.overflowed.load(Ordering::Relaxed)
    }

    /// Reads one input, waiting at most `timeout` (zero: only what already arrived).
    /// `Ok(None)`: nothing in time. The port's descriptor stays readable while inputs wait.
    pub fn read(&mut self, timeout: Duration) -> io::Result<Option<Input>> {
        let delivery = match self.deliveries.try_recv() {
            Ok(delivery) => delivery,
            Err(TryRecvError::Disconnected) => return Err(self.reader_gone()),
            Err(TryRecvError::Empty) => {
                // Level-triggered: the wake-up bytes are drained only once the queue is
                // empty, then the queue is looked at again (an input and its byte may have
                // come in between).
                self.drain_wake();
                let next = if timeout.is_zero() {
                    self.deliveries.try_recv().map_err(|e| match e {
                        TryRecvError::Empty => RecvTimeoutError::Timeout,
                        TryRecvError::Disconnected => RecvTimeoutError::Disconnected,
                    })
                } else {
                    self.deliveries.recv_timeout(timeout)
                };
                match next {
                    Ok(delivery) => delivery,
                    Err(RecvTimeoutError::Timeout) => return Ok(None),
                    Err(RecvTimeoutError::Disconnected) => return Err(self.reader_gone()),
                }
            }
        };
        match delivery {
            Ok(input) => Ok(Some(input)),
            Err(error) => {
                self.failed = Some(error);
                Err(transfer_error("reading from", &self.adapter, error))
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

    /// Sends one frame without waiting: the transfer is queued, and completed ones are
    /// reaped. A frame needs one of the ten echo ids; with all ten on their way (the adapter
    /// does not take frames, or nothing on the bus acknowledges them) it is an
    /// [`Unacknowledged`] error, as a full transmit queue is on SocketCAN.
    pub fn write(&mut self, frame: &CanFrame) -> io::Result<()> {
        while self.out.pending() > 0 {
            let Some(done) = self.out.wait_next_complete(Duration::ZERO) else {
                break;
            };
            done.status
                .map_err(|error| transfer_error("writing to", &self.adapter, error))?;
        }
        let echo = self.in_flight.take().ok_or_else(|| {
            io::Error::other(Unacknowledged {
                frames: MAX_UNECHOED,
                untaken: self.out.pending() as u32,
            })
        })?;
        let (bytes, len) = HostFrame::transmit(frame, CHANNEL, echo).encode();
        self.out.submit(bytes[..len].to_vec().into());
        Ok(())
    }
}

impl Drop for GsUsbPort {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Frames not yet taken never reach the bus after the reset (nor at the next start).
        self.out.cancel_all();
        while self.out.pending() > 0
            && self
                .out
                .wait_next_complete(Duration::from_millis(20))
                .is_some()
        {}
        // The channel is reset so the adapter stops sending (the kernel driver does the same
        // when the interface goes down); an adapter that is gone does not answer.
        let _ = control_out(
            &self.interface,
            Request::Mode,
            &DeviceMode::STOPPED.encode(),
        );
    }
}

impl AsRawFd for GsUsbPort {
    /// Readable while inputs wait (or the reading failed).
    fn as_raw_fd(&self) -> RawFd {
        self.wake.as_raw_fd()
    }
}

/// The adapter has not echoed this many frames: they are not on the bus (the adapter does not
/// take them, or no other node acknowledges them, or the adapter is bus-off). A link fault, as
/// a full CAN transmit queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unacknowledged {
    /// Frames sent and not echoed.
    pub frames: u32,
    /// Of those, the frames the adapter has not even taken from the host.
    pub untaken: u32,
}

impl fmt::Display for Unacknowledged {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.untaken > 0 {
            write!(
                f,
                "the adapter put none of the last {} frames on the bus and has not taken {} of \
                 them: it does not keep up (stalled, or its USB link is failing)",
                self.frames, self.untaken
            )
        } else {
            write!(
                f,
                "the adapter put none of the last {} frames on the bus: nothing acknowledges \
                 them (is the chassis on, the bus wired and terminated?)",
                self.frames
            )
        }
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

/// The size of an IN transfer for `max_packet` (one host frame, 20 or 24 bytes, fits in it),
/// or `None` for a packet size no USB endpoint has.
fn transfer_size(max_packet: usize) -> Option<usize> {
    (max_packet.is_power_of_two() && (8..=1024).contains(&max_packet))
        .then(|| max_packet * gs_usb::frame::LEN_TIMESTAMPED.div_ceil(max_packet))
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

/// The first half of the set-up Linux's driver does: byte order, the device's configuration,
/// the channel's constants; the bit timing for 500 kbit/s from them.
fn timing_for(interface: &Interface) -> Result<BitTiming, SetUpError> {
    control_out(interface, Request::HostFormat, &HostConfig::encode()).map_err(|error| {
        SetUpError::Request {
            what: "the host format request",
            error,
        }
    })?;
    let config =
        DeviceConfig::decode(&control_in(interface, Request::DeviceConfig)?).map_err(|error| {
            SetUpError::Answer {
                what: "device configuration",
                error,
            }
        })?;
    let constants =
        BtConst::decode(&control_in(interface, Request::BtConst)?).map_err(|error| {
            SetUpError::Answer {
                what: "bit-timing constants",
                error,
            }
        })?;
    let timing = BitTiming::for_bitrate(&constants, BITRATE).map_err(SetUpError::Timing)?;
    tracing::debug!(
        "gs_usb: {} channels, firmware {}, hardware {}, {} Hz clock, {timing:?}",
        config.channels,
        config.software_version,
        config.hardware_version,
        constants.clock_hz
    );
    Ok(timing)
}

/// The second half: the channel reset (an earlier owner may have left it started), the bit
/// timing, then start.
fn start_channel(interface: &Interface, timing: &BitTiming) -> Result<(), SetUpError> {
    let step = |what: &'static str| move |error| SetUpError::Request { what, error };
    control_out(interface, Request::Mode, &DeviceMode::STOPPED.encode())
        .map_err(step("resetting the channel"))?;
    control_out(interface, Request::BitTiming, &timing.encode())
        .map_err(step("setting 500 kbit/s"))?;
    let start = DeviceMode {
        start: true,
        flags: 0,
    };
    control_out(interface, Request::Mode, &start.encode()).map_err(step("starting the channel"))
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

fn control_in(interface: &Interface, request: Request) -> Result<Vec<u8>, SetUpError> {
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
        .map_err(|error| SetUpError::Request {
            what: match request {
                Request::BtConst => "the bit-timing constants request",
                Request::DeviceConfig => "the device configuration request",
                Request::HostFormat | Request::BitTiming | Request::Mode => "a control request",
            },
            error: io::Error::from(error),
        })
}

/// What one transfer from the adapter says, for the gateway (`None`: an echo, accounted
/// here). Every transfer is read without timestamps (the mode never asks for them; bytes after
/// the frame are ignored).
fn classify(bytes: &[u8], in_flight: &InFlight, overflowed: &AtomicU64) -> Option<Input> {
    let frame = match HostFrame::decode(bytes, false) {
        Ok(frame) => frame,
        Err(error) => return Some(Input::Malformed(error)),
    };
    if frame.channel != CHANNEL {
        return Some(Input::Malformed(gs_usb::Error::Channel(frame.channel)));
    }
    if frame.overflow() {
        overflowed.fetch_add(1, Ordering::Relaxed);
    }
    match frame.received() {
        Received::Echo(id) if in_flight.echoed(id) => None,
        Received::Echo(id) => Some(Input::Malformed(gs_usb::Error::UnknownEcho(id))),
        Received::Frame(frame) => Some(Input::Frame(frame)),
        Received::Foreign(can_id) => Some(Input::Foreign(can_id)),
        Received::BusError { class, data } => Some(Input::BusError { class, data }),
    }
}

/// The IN endpoint's thread: keeps transfers queued and hands every input over, until `stop`
/// or a transfer fails (unplugged, stalled).
struct Reader {
    stop: Arc<AtomicBool>,
    in_flight: Arc<InFlight>,
    overflowed: Arc<AtomicU64>,
    sender: SyncSender<Delivery>,
    signal: UnixStream,
    size: usize,
}

impl Reader {
    fn run(self, mut input: Endpoint<Bulk, In>) {
        while !self.stop.load(Ordering::Relaxed) {
            while input.pending() < IN_TRANSFERS {
                let buffer = input.allocate(self.size);
                input.submit(buffer);
            }
            let Some(done) = input.wait_next_complete(Duration::from_millis(20)) else {
                continue;
            };
            let delivery = match done.status {
                Ok(()) => {
                    let bytes = &done.buffer[..done.actual_len.min(done.buffer.len())];
                    match classify(bytes, &self.in_flight, &self.overflowed) {
                        Some(input) => Ok(input),
                        None => {
                            input.submit(done.buffer);
                            continue;
                        }
                    }
                }
                Err(TransferError::Cancelled) if self.stop.load(Ordering::Relaxed) => break,
                Err(error) => Err(error),
            };
            let failed = delivery.is_err();
            match self.sender.try_send(delivery) {
                Ok(()) => {}
                // A failure is handed over whatever it waits for: it ends the port (and a
                // port that closes drops the receiver, which ends the wait).
                Err(TrySendError::Full(delivery)) if failed => {
                    if self.sender.send(delivery).is_err() {
                        break;
                    }
                }
                Err(TrySendError::Full(_)) => {
                    self.overflowed.fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => break,
            }
            let _ = (&self.signal).write(&[1]);
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::gs_usb::RX_ECHO_ID;

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

    fn from_bus(can_id: u32, data: &[u8]) -> Vec<u8> {
        let frame = HostFrame {
            echo_id: RX_ECHO_ID,
            can_id,
            len: data.len() as u8,
            channel: CHANNEL,
            flags: 0,
            data: {
                let mut padded = [0; 8];
                padded[..data.len()].copy_from_slice(data);
                padded
            },
            timestamp_us: None,
        };
        let (bytes, len) = frame.encode();
        bytes[..len].to_vec()
    }

    #[test]
    fn echo_ids_are_ten_contexts_and_an_echo_of_nothing_is_refused() {
        let in_flight = InFlight::default();
        let ids: Vec<u32> = (0..MAX_UNECHOED).map_while(|_| in_flight.take()).collect();
        assert_eq!(ids, (0..MAX_UNECHOED).collect::<Vec<_>>());
        assert_eq!(
            in_flight.take(),
            None,
            "all ten on their way: nothing acknowledges"
        );
        assert!(in_flight.echoed(3));
        assert!(!in_flight.echoed(3), "an echo comes once");
        assert!(!in_flight.echoed(MAX_UNECHOED), "an id never given");
        assert_eq!(in_flight.take(), Some(3));
        assert_eq!(in_flight.count(), MAX_UNECHOED);
    }

    #[test]
    fn transfers_are_classified_echoes_accounted_garbage_refused() {
        let in_flight = InFlight::default();
        let overflowed = AtomicU64::new(0);
        let classify = |bytes: &[u8]| classify(bytes, &in_flight, &overflowed);
        let data = [0, 0, 0, 0, 0, 0, 0, 3];
        let Some(Input::Frame(frame)) = classify(&from_bus(0x151, &data)) else {
            panic!("a frame from the bus")
        };
        assert_eq!((frame.id(), frame.data()), (0x151, &data[..]));
        // The echo of a frame sent is taken here; one of nothing sent is refused.
        let id = in_flight.take().expect("an id");
        let (echo, len) = HostFrame::transmit(&frame, CHANNEL, id).encode();
        assert_eq!(classify(&echo[..len]), None);
        assert_eq!(
            classify(&echo[..len]),
            Some(Input::Malformed(gs_usb::Error::UnknownEcho(id)))
        );
        // Another channel, short transfers, bus-off, an overflow flag.
        let mut other = from_bus(0x151, &data);
        other[gs_usb::frame::CHANNEL] = 1;
        assert_eq!(
            classify(&other),
            Some(Input::Malformed(gs_usb::Error::Channel(1)))
        );
        assert!(matches!(classify(&[0xde, 0xad]), Some(Input::Malformed(_))));
        assert!(matches!(classify(&[]), Some(Input::Malformed(_))));
        assert_eq!(
            classify(&from_bus(0x2000_0040, &[0; 8])),
            Some(Input::BusError {
                class: 0x40,
                data: [0; 8]
            })
        );
        let mut flagged = from_bus(0x151, &data);
        flagged[gs_usb::frame::FLAGS] = gs_usb::frame::OVERFLOW;
        assert!(matches!(classify(&flagged), Some(Input::Frame(_))));
        assert_eq!(overflowed.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn transfer_sizes_hold_a_frame_and_refuse_packet_sizes_usb_has_not() {
        assert_eq!(transfer_size(64), Some(64));
        assert_eq!(transfer_size(512), Some(512));
        assert_eq!(transfer_size(8), Some(24));
        assert_eq!(transfer_size(16), Some(32));
        for bad in [0, 7, 48, 2048] {
            assert_eq!(transfer_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn unacknowledged_frames_are_a_bus_fault_that_says_what_to_check() {
        let error = Unacknowledged {
            frames: MAX_UNECHOED,
            untaken: 0,
        };
        assert!(error.to_string().contains("is the chassis on"), "{error}");
        let stalled = Unacknowledged {
            frames: MAX_UNECHOED,
            untaken: 4,
        };
        assert!(
            stalled.to_string().contains("does not keep up"),
            "{stalled}"
        );
    }
}
