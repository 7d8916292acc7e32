//! The bench's child processes: subscribers on each path (iceoryx2, zenoh, the port read
//! directly), a CPU hog, a request flood and a stop-endpoint flood. Each records what it saw to a file the bench reads.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use scout_clients::client::Robot;
use scout_clients::{Request, StatePayload, monotonic_ns};
use scout_protocol::link::{RxEvent, StreamFraming, Transport};

/// Connects to `name`, waiting up to 20 s for its gateway.
pub fn connect(name: &str) -> anyhow::Result<Robot> {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        match Robot::connect(name) {
            Ok(robot) => return Ok(robot),
            Err(error) if Instant::now() > deadline => return Err(error.into()),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

fn create(out: &Path) -> anyhow::Result<std::io::BufWriter<std::fs::File>> {
    let file = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
    Ok(std::io::BufWriter::new(file))
}

/// The newest frame time in a state: when the gateway read the batch it carries.
fn newest_frame_ns(state: &StatePayload) -> u64 {
    [
        state.system.received,
        state.motion.received,
        state.lights.received,
    ]
    .into_iter()
    .chain(state.motors.iter().map(|motor| motor.received))
    .filter(|received| received.valid)
    .map(|received| received.at_ns)
    .max()
    .unwrap_or(0)
}

/// iceoryx2: `SEEN READ PUBLISHED` (ns) per state, blocking on the event service.
pub fn subscribe(name: &str, out: &Path, seconds: f64) -> anyhow::Result<()> {
    let robot = connect(name)?;
    let states = robot.subscribe()?;
    let mut out = create(out)?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        if let Some(state) = states.next_timeout(Duration::from_millis(100))? {
            let seen = monotonic_ns();
            writeln!(
                out,
                "{seen} {} {}",
                newest_frame_ns(&state),
                state.published_ns
            )?;
        }
    }
    out.flush()?;
    Ok(())
}

/// zenoh: `SEEN` (ns) per state JSON, parsed, from a session in client mode.
pub fn zenoh_subscribe(name: &str, endpoint: &str, out: &Path, seconds: f64) -> anyhow::Result<()> {
    use zenoh::Wait;
    let settings = scout_clients::remote::SessionSettings {
        config_file: Some(String::new()),
        listen: Vec::new(),
        connect: vec![endpoint.to_owned()],
    };
    let session = zenoh::open(settings.config("client")?)
        .wait()
        .map_err(|error| anyhow::anyhow!("opening a zenoh session to {endpoint}: {error}"))?;
    let subscriber = session
        .declare_subscriber(scout_clients::remote::state_key(name))
        .wait()
        .map_err(|error| anyhow::anyhow!("subscribing: {error}"))?;
    let mut out = create(out)?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        let Ok(Some(sample)) = subscriber.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let state: serde_json::Value = serde_json::from_slice(&sample.payload().to_bytes())?;
        let seen = monotonic_ns();
        if state["seq"].is_u64() {
            writeln!(out, "{seen}")?;
        }
    }
    out.flush()?;
    Ok(())
}

/// The floor: the serial port read and decoded by this process, no gateway. `SEEN` (ns) per
/// read that completed at least one frame.
pub fn direct(port: &Path, out: &Path, seconds: f64) -> anyhow::Result<()> {
    let mut port =
        scout_io::Port::open_tty(port).with_context(|| format!("opening {}", port.display()))?;
    let mut framing = StreamFraming::new(Transport::Serial).context("serial framing")?;
    let mut out = create(out)?;
    let mut buffer = [0u8; 1024];
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        let scout_io::Incoming::Bytes(n) = port.read(&mut buffer, Duration::from_millis(100))?
        else {
            continue;
        };
        let mut decoded = 0;
        framing.push(&buffer[..n], |event| {
            decoded += usize::from(matches!(event, RxEvent::Message(_)));
        });
        if decoded > 0 {
            writeln!(out, "{}", monotonic_ns())?;
        }
    }
    out.flush()?;
    Ok(())
}

/// Burns one core for `seconds`.
pub fn hog(seconds: f64) {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut x = 0u64;
    while Instant::now() < end {
        for i in 0..10_000u64 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(i));
        }
    }
}

/// Control requests at `hz` for `seconds`, each waiting for its answer.
pub fn flood(name: &str, hz: f64, seconds: f64) -> anyhow::Result<()> {
    let robot = connect(name)?;
    let mut controller = robot.controller(&format!("flood-{}", std::process::id()), None)?;
    let requests = [
        Request::Resume,
        Request::Heartbeat {
            period: Duration::ZERO,
        },
        Request::Relinquish,
    ];
    let period = Duration::from_secs_f64(1.0 / hz);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut next = Instant::now();
    let mut i = 0;
    while Instant::now() < end {
        let _ = controller.request(&requests[i % requests.len()]);
        i += 1;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    Ok(())
}

/// Makes `count` one-page anonymous mappings that the kernel cannot merge (their protections
/// alternate), never touched: no memory, but as many lines in `/proc/PID/maps`. Stops early,
/// saying so, when the kernel's `vm.max_map_count` is reached.
#[allow(unsafe_code)]
fn many_mappings(count: usize) -> usize {
    use nix::sys::mman::{MapFlags, ProtFlags, mmap_anonymous};
    let page = std::num::NonZeroUsize::new(4096).expect("non-zero");
    for made in 0..count {
        let prot = if made % 2 == 0 {
            ProtFlags::PROT_READ
        } else {
            ProtFlags::PROT_READ | ProtFlags::PROT_WRITE
        };
        // SAFETY: a fresh private anonymous mapping at an address the kernel chooses touches no
        // memory this process uses; it is never read, written or unmapped (the process exits).
        if unsafe { mmap_anonymous(None, page, prot, MapFlags::MAP_PRIVATE) }.is_err() {
            eprintln!("datagram-flood: {made} mappings made, the kernel refused more");
            return made;
        }
    }
    count
}

/// Release datagrams (or `garbage`) on `name`'s stop endpoint for `seconds`, as fast as its
/// queue takes them, from an unbound socket (no answers), after making `mappings` memory
/// mappings. Prints `ready MAPPINGS` once mapped, then `sent N` at the end.
pub fn datagram_flood(
    name: &str,
    seconds: f64,
    mappings: usize,
    garbage: bool,
) -> anyhow::Result<()> {
    use std::os::linux::net::SocketAddrExt;
    use std::os::unix::net::{SocketAddr, UnixDatagram};

    use scout_clients::ReleaseTarget;
    use scout_clients::interface::stop_socket::{self, Ask, StopRequest};

    let made = many_mappings(mappings);
    let gateway = SocketAddr::from_abstract_name(stop_socket::address(name).as_bytes())?;
    let socket = UnixDatagram::unbound()?;
    socket.set_nonblocking(true)?;
    println!("ready {made}");
    std::io::stdout().flush()?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut sent = 0u64;
    while Instant::now() < end {
        let datagram = if garbage {
            let mut bytes = [0u8; 64];
            for (i, byte) in bytes.iter_mut().enumerate() {
                *byte = (sent as u8).wrapping_mul(31).wrapping_add(i as u8);
            }
            bytes.to_vec()
        } else {
            StopRequest {
                seq: sent,
                name: Some(format!("flood-{}", std::process::id())),
                ask: Ask::Release {
                    target: ReleaseTarget::Own,
                    through: u64::MAX,
                },
            }
            .emit()
            .to_vec()
        };
        match socket.send_to_addr(&datagram, &gateway) {
            Ok(_) => sent += 1,
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_micros(50));
            }
            Err(error) => return Err(error).context("sending to the stop endpoint"),
        }
    }
    println!("sent {sent}");
    Ok(())
}
