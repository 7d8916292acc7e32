//! `scout-gs-usb-gadget`: an emulated gs_usb USB-CAN adapter. A USB gadget (configfs, one
//! FunctionFS function, candleLight's ids) bound to a UDC (in the tests, `dummy_hcd`'s, so the
//! adapter appears on the same machine's USB bus), whose CAN side is a SocketCAN interface:
//! frames the host sends go on it, frames on it go to the host, as does an error frame (a
//! bus-off sent with `cansend` arrives as the adapter would report it).
//!
//! Needs root, and the modules `libcomposite`, `usb_f_fs` and a UDC (`dummy_hcd`). It prints
//! `ready` once bound, and on SIGINT or SIGTERM unbinds (the adapter is unplugged) and exits 0.
//! SIGUSR1 halts the IN endpoint (a stalled adapter); SIGUSR2 sends the host two transfers that
//! are no frame. Unplug and replug by writing the gadget's `UDC` file (printed at start).
//!
//! Exit codes: 0 after a signal, 1 on an error (the message says which step failed), 2 usage.

mod adapter;

use std::fs::{self, File, OpenOptions};
use std::io::{Read as _, Write as _};
use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use adapter::{Adapter, EVENT_LEN, Event, Reply};
use anyhow::{Context, bail};
use clap::Parser;
use nix::sys::signal::{SigSet, Signal};
use scout_protocol::gs_usb::{self, HostFrame};
use socketcan::{Frame as _, Socket as _, SocketOptions as _};

/// An emulated gs_usb adapter whose CAN side is a SocketCAN interface.
#[derive(Debug, Parser)]
#[command(about)]
struct Cli {
    /// The SocketCAN interface that is the adapter's bus (a vcan with the simulated chassis).
    #[arg(long, value_name = "IFACE")]
    can: String,
    /// The gadget's name in configfs and FunctionFS (unique per adapter).
    #[arg(long, default_value = "scoutgs")]
    name: String,
    /// The adapter's serial number.
    #[arg(long, default_value = "SCOUTGS0001")]
    serial: String,
    /// The UDC to bind to [default: the first in /sys/class/udc].
    #[arg(long)]
    udc: Option<String>,
    /// Put nothing the host sends on the bus and echo nothing: a bus where no node acknowledges
    /// (the chassis off, the wires loose).
    #[arg(long)]
    no_ack: bool,
}

const CONFIGFS: &str = "/sys/kernel/config";

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout-gs-usb-gadget: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Counters printed at exit.
#[derive(Debug, Default)]
struct Counts {
    to_bus: AtomicU64,
    to_host: AtomicU64,
    dropped: AtomicU64,
}

fn run(cli: &Cli) -> anyhow::Result<()> {
    // The signals are taken by this thread alone (sigwait below), not by the workers.
    let mut signals = SigSet::empty();
    for signal in [
        Signal::SIGINT,
        Signal::SIGTERM,
        Signal::SIGUSR1,
        Signal::SIGUSR2,
    ] {
        signals.add(signal);
    }
    signals.thread_block().context("blocking signals")?;

    let udc = match &cli.udc {
        Some(udc) => udc.clone(),
        None => first_udc()?,
    };
    let gadget = Gadget::create(cli)?;
    let ffs = PathBuf::from(format!("/dev/ffs-{}", cli.name));
    fs::create_dir_all(&ffs).with_context(|| format!("creating {}", ffs.display()))?;
    nix::mount::mount(
        Some(cli.name.as_str()),
        &ffs,
        Some("functionfs"),
        nix::mount::MsFlags::empty(),
        None::<&str>,
    )
    .with_context(|| format!("mounting FunctionFS {} (is usb_f_fs loaded?)", cli.name))?;
    let mut ep0 = OpenOptions::new()
        .read(true)
        .write(true)
        .open(ffs.join("ep0"))
        .context("opening ep0")?;
    ep0.write_all(&adapter::descriptors())
        .context("writing the descriptors to ep0")?;
    ep0.write_all(&adapter::strings())
        .context("writing the strings to ep0")?;
    let ep_in = Arc::new(Mutex::new(
        OpenOptions::new()
            .read(true)
            .write(true)
            .open(ffs.join("ep1"))
            .context("opening ep1 (IN)")?,
    ));
    let ep_out = File::open(ffs.join("ep2")).context("opening ep2 (OUT)")?;
    let bus = Arc::new(
        socketcan::CanSocket::open(&cli.can)
            .with_context(|| format!("opening CAN interface {}", cli.can))?,
    );
    bus.set_error_filter_accept_all()
        .context("accepting error frames")?;
    bus.set_read_timeout(Duration::from_millis(100))
        .context("setting the CAN read timeout")?;

    let state = Arc::new(Mutex::new(Adapter::default()));
    let counts = Arc::new(Counts::default());
    {
        let state = Arc::clone(&state);
        std::thread::spawn(move || control(ep0, &state));
    }
    {
        let (state, ep_in, bus, counts) = (
            Arc::clone(&state),
            Arc::clone(&ep_in),
            Arc::clone(&bus),
            Arc::clone(&counts),
        );
        let no_ack = cli.no_ack;
        std::thread::spawn(move || host_to_bus(ep_out, &ep_in, &bus, &state, &counts, no_ack));
    }
    {
        let (state, ep_in, bus, counts) = (
            Arc::clone(&state),
            Arc::clone(&ep_in),
            Arc::clone(&bus),
            Arc::clone(&counts),
        );
        std::thread::spawn(move || bus_to_host(&bus, &ep_in, &state, &counts));
    }

    gadget.bind(&udc)?;
    println!(
        "ready: gs_usb adapter {} (serial {}) on {udc}, bus {}; unplug: echo > {}",
        cli.name,
        cli.serial,
        cli.can,
        gadget.dir.join("UDC").display()
    );
    let _ = std::io::stdout().flush();

    loop {
        match signals.wait().context("waiting for a signal")? {
            Signal::SIGUSR1 => {
                // Reading an IN endpoint's file halts it (FunctionFS).
                let ep = ep_in
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                let _ = (&*ep).read(&mut [0; 1]);
                eprintln!("scout-gs-usb-gadget: IN endpoint halted");
            }
            Signal::SIGUSR2 => {
                let ep = ep_in
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                // A CAN FD frame, which the gateway never enabled.
                let mut bad = adapter::from_bus(0x151, &[0; 8]);
                bad[gs_usb::frame::FLAGS] = gs_usb::frame::FD;
                let _ = (&*ep).write(&[0xde, 0xad, 0xbe, 0xef, 0x01, 0x02, 0x03]);
                let _ = (&*ep).write(&bad);
                eprintln!("scout-gs-usb-gadget: sent two malformed transfers");
            }
            _ => break,
        }
    }
    let state = state
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    eprintln!(
        "scout-gs-usb-gadget: {} frames to the bus, {} to the host, {} dropped (channel \
         stopped); bit rate {:?}; requests refused {:?}",
        counts.to_bus.load(Ordering::Relaxed),
        counts.to_host.load(Ordering::Relaxed),
        counts.dropped.load(Ordering::Relaxed),
        state.bitrate(),
        state.refused
    );
    gadget.unbind();
    // Closing ep0 by exiting ends the function; the gadget's configfs entries are left for
    // `Gadget::remove` at the next start of the same name.
    Ok(())
}

/// The first UDC the kernel has.
fn first_udc() -> anyhow::Result<String> {
    let mut names: Vec<String> = fs::read_dir("/sys/class/udc")
        .context("no /sys/class/udc: load a UDC driver (modprobe dummy_hcd)")?
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
        .into_iter()
        .next()
        .context("no UDC: load a UDC driver (modprobe dummy_hcd)")
}

/// The gadget in configfs.
#[derive(Debug)]
struct Gadget {
    dir: PathBuf,
}

impl Gadget {
    fn create(cli: &Cli) -> anyhow::Result<Self> {
        let root = Path::new(CONFIGFS);
        if !root.join("usb_gadget").exists() {
            let _ = nix::mount::mount(
                Some("configfs"),
                root,
                Some("configfs"),
                nix::mount::MsFlags::empty(),
                None::<&str>,
            );
        }
        if !root.join("usb_gadget").exists() {
            bail!("no {CONFIGFS}/usb_gadget: load libcomposite (modprobe libcomposite)");
        }
        let dir = root.join("usb_gadget").join(&cli.name);
        let gadget = Self { dir };
        gadget.remove();
        let write = |path: &str, value: &str| {
            let path = gadget.dir.join(path);
            fs::write(&path, value).with_context(|| format!("writing {}", path.display()))
        };
        let mkdir = |path: &str| {
            let path = gadget.dir.join(path);
            fs::create_dir_all(&path).with_context(|| format!("creating {}", path.display()))
        };
        mkdir("")?;
        let id = gs_usb::KNOWN_ADAPTERS[0];
        write("idVendor", &format!("0x{:04x}", id.vendor))?;
        write("idProduct", &format!("0x{:04x}", id.product))?;
        write("bcdUSB", "0x0200")?;
        write("bcdDevice", "0x0000")?;
        mkdir("strings/0x409")?;
        write("strings/0x409/manufacturer", "scout tests")?;
        write(
            "strings/0x409/product",
            "candleLight USB to CAN adapter (emulated)",
        )?;
        write("strings/0x409/serialnumber", &cli.serial)?;
        mkdir("configs/c.1/strings/0x409")?;
        write("configs/c.1/strings/0x409/configuration", "gs_usb")?;
        write("configs/c.1/MaxPower", "100")?;
        let function = format!("functions/ffs.{}", cli.name);
        mkdir(&function)
            .with_context(|| "a FunctionFS function (is usb_f_fs loaded?)".to_string())?;
        symlink(
            gadget.dir.join(&function),
            gadget.dir.join(format!("configs/c.1/ffs.{}", cli.name)),
        )
        .context("linking the function into the configuration")?;
        Ok(gadget)
    }

    fn bind(&self, udc: &str) -> anyhow::Result<()> {
        fs::write(self.dir.join("UDC"), udc)
            .with_context(|| format!("binding the gadget to {udc} (is it free?)"))
    }

    fn unbind(&self) {
        let _ = fs::write(self.dir.join("UDC"), "\n");
    }

    /// Removes what an earlier run of the same name left (best effort).
    fn remove(&self) {
        if !self.dir.exists() {
            return;
        }
        self.unbind();
        let name = self
            .dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned());
        if let Some(name) = name {
            let _ = fs::remove_file(self.dir.join(format!("configs/c.1/ffs.{name}")));
            let mount = format!("/dev/ffs-{name}");
            let _ = nix::mount::umount(mount.as_str());
            let _ = fs::remove_dir(self.dir.join(format!("functions/ffs.{name}")));
        }
        for dir in [
            "configs/c.1/strings/0x409",
            "configs/c.1",
            "strings/0x409",
            "",
        ] {
            let _ = fs::remove_dir(self.dir.join(dir));
        }
    }
}

fn lock(state: &Mutex<Adapter>) -> std::sync::MutexGuard<'_, Adapter> {
    state
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// ep0: the host's control requests, answered as a candleLight does.
fn control(mut ep0: File, state: &Mutex<Adapter>) {
    let mut events = [0u8; 4 * EVENT_LEN];
    loop {
        let n = match ep0.read(&mut events) {
            Ok(n) => n,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
        };
        for chunk in events[..n].chunks_exact(EVENT_LEN) {
            let event = Event::decode(chunk.try_into().expect("an event's length"));
            let Event::Setup {
                request_type,
                request,
                value,
                length,
            } = event
            else {
                continue;
            };
            let reply = lock(state).handle_setup(request_type, request, value);
            match reply {
                Reply::Send(bytes) => {
                    let _ = ep0.write(&bytes[..bytes.len().min(usize::from(length))]);
                }
                Reply::Receive(request) => {
                    let mut data = vec![0; usize::from(length)];
                    if let Ok(n) = ep0.read(&mut data)
                        && !lock(state).handle_data(request, &data[..n])
                    {
                        eprintln!("scout-gs-usb-gadget: request {request:?} with bad data");
                    }
                }
                // FunctionFS stalls a request when ep0 is used the other way.
                Reply::Stall if request_type & 0x80 != 0 => {
                    let _ = ep0.read(&mut [0; 0]);
                }
                Reply::Stall => {
                    let _ = ep0.write(&[]);
                }
            }
        }
    }
}

/// Writes one transfer to the host, retrying while the function is disabled (unplugged).
fn to_host(ep_in: &Mutex<File>, bytes: &[u8]) -> bool {
    let ep = ep_in
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    (&*ep).write(bytes).is_ok()
}

/// The OUT endpoint: frames from the host go on the bus and are echoed back.
fn host_to_bus(
    mut ep_out: File,
    ep_in: &Mutex<File>,
    bus: &socketcan::CanSocket,
    state: &Mutex<Adapter>,
    counts: &Counts,
    no_ack: bool,
) {
    let mut buffer = [0u8; 512];
    loop {
        let n = match ep_out.read(&mut buffer) {
            Ok(n) => n,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
        };
        let Ok(frame) = HostFrame::decode(&buffer[..n], false) else {
            continue;
        };
        if !lock(state).started || no_ack {
            continue;
        }
        let id = frame.can_id & 0x1fff_ffff;
        let data = &frame.data[..usize::from(frame.len.min(8))];
        if let Some(out) = socketcan::CanFrame::from_raw_id(id, data)
            && bus.write_frame(&out).is_ok()
        {
            counts.to_bus.fetch_add(1, Ordering::Relaxed);
            let (echo, len) = frame.encode();
            to_host(ep_in, &echo[..len]);
        }
    }
}

/// The bus: every frame (and error frame) on it goes to the host while the channel runs.
fn bus_to_host(
    bus: &socketcan::CanSocket,
    ep_in: &Mutex<File>,
    state: &Mutex<Adapter>,
    counts: &Counts,
) {
    loop {
        let frame = match bus.read_raw_frame() {
            Ok(frame) => frame,
            Err(_) => continue,
        };
        if !lock(state).started {
            counts.dropped.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        let len = usize::from(frame.can_dlc).min(8);
        if to_host(ep_in, &adapter::from_bus(frame.can_id, &frame.data[..len])) {
            counts.to_host.fetch_add(1, Ordering::Relaxed);
        }
    }
}
