//! The service manager's notifications (systemd's `sd_notify` protocol, without libsystemd):
//! telling it that the program is ready or stopping, and petting its watchdog.
//!
//! The protocol: `$NOTIFY_SOCKET` names a Unix datagram socket (a path, or a name in the
//! abstract namespace when it starts with `@`); each message is one datagram of newline-separated
//! assignments (`READY=1`, `STATUS=...`, `WATCHDOG=1`, `STOPPING=1`). `$WATCHDOG_USEC` is the
//! watchdog's timeout, and `$WATCHDOG_PID`, when set, the process it watches. Without
//! `$NOTIFY_SOCKET` (not started by a service manager) everything here does nothing.

use std::ffi::OsString;
use std::os::linux::net::SocketAddrExt;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// The watchdog is petted this many times per timeout: often enough that a late iteration or a
/// slow service manager never makes it fire, rarely enough to cost nothing.
const PETS_PER_TIMEOUT: u32 = 4;

/// The service manager that started this process, as far as it asked to be told things. A
/// no-op when there is none.
#[derive(Debug)]
pub struct ServiceManager {
    target: Option<Target>,
    pet_interval: Option<Duration>,
    last_pet: Option<Duration>,
    failed_sends: u64,
}

/// Where the notifications go.
#[derive(Debug)]
struct Target {
    socket: UnixDatagram,
    address: SocketAddr,
    /// `$NOTIFY_SOCKET` as given, for messages.
    shown: String,
}

impl ServiceManager {
    /// From this process' environment (`NOTIFY_SOCKET`, `WATCHDOG_USEC`, `WATCHDOG_PID`).
    pub fn from_env() -> Self {
        Self::from_vars(|name| std::env::var_os(name), std::process::id())
    }

    /// From the variables `var` gives, for the process `pid` (this one, but for tests).
    pub fn from_vars(var: impl Fn(&str) -> Option<OsString>, pid: u32) -> Self {
        let target = var("NOTIFY_SOCKET")
            .filter(|socket| !socket.is_empty())
            .and_then(|socket| Target::open(&socket));
        let pet_interval = target
            .as_ref()
            .and_then(|_| watchdog_timeout(&var, pid))
            .map(|timeout| timeout / PETS_PER_TIMEOUT);
        Self {
            target,
            pet_interval,
            last_pet: None,
            failed_sends: 0,
        }
    }

    /// Whether a service manager listens (`$NOTIFY_SOCKET` was set and usable).
    pub fn is_present(&self) -> bool {
        self.target.is_some()
    }

    /// How often [`ServiceManager::pet`] sends, if the watchdog is on and watches this process.
    pub fn pet_interval(&self) -> Option<Duration> {
        self.pet_interval
    }

    /// Notifications that could not be sent.
    pub fn failed_sends(&self) -> u64 {
        self.failed_sends
    }

    /// The program is up (`READY=1`), with a one-line status for `systemctl status`.
    pub fn ready(&mut self, status: &str) {
        self.send(&format!("READY=1\nSTATUS={}", one_line(status)));
    }

    /// The program is shutting down (`STOPPING=1`).
    pub fn stopping(&mut self) {
        self.send("STOPPING=1");
    }

    /// Tells the watchdog that the caller's loop is alive (`WATCHDOG=1`), at most once per
    /// [`ServiceManager::pet_interval`] of `now` (any monotonic clock): call it every iteration.
    pub fn pet(&mut self, now: Duration) {
        let Some(interval) = self.pet_interval else {
            return;
        };
        if self
            .last_pet
            .is_some_and(|last| now.saturating_sub(last) < interval)
        {
            return;
        }
        self.last_pet = Some(now);
        self.send("WATCHDOG=1");
    }

    /// Sends one datagram without blocking; a failure is counted, and logged the first time.
    fn send(&mut self, message: &str) {
        let Some(target) = &self.target else {
            return;
        };
        if let Err(error) = target
            .socket
            .send_to_addr(message.as_bytes(), &target.address)
        {
            self.failed_sends += 1;
            if self.failed_sends == 1 {
                tracing::warn!(
                    "notifying the service manager at {} failed: {error} (further failures are \
                     counted, not logged)",
                    target.shown
                );
            }
        }
    }
}

impl Target {
    /// A non-blocking socket for `$NOTIFY_SOCKET`, or `None` (logged) if it cannot be used.
    fn open(socket: &std::ffi::OsStr) -> Option<Self> {
        let shown = socket.to_string_lossy().into_owned();
        let bytes = socket.as_bytes();
        let address = match bytes.first() {
            Some(b'@') => SocketAddr::from_abstract_name(&bytes[1..]),
            Some(b'/') => SocketAddr::from_pathname(socket),
            _ => {
                tracing::warn!(
                    "NOTIFY_SOCKET={shown}: only a path or an @abstract name is supported; \
                     the service manager will not be notified"
                );
                return None;
            }
        };
        let socket = address.and_then(|address| {
            let socket = UnixDatagram::unbound()?;
            socket.set_nonblocking(true)?;
            Ok((socket, address))
        });
        match socket {
            Ok((socket, address)) => Some(Self {
                socket,
                address,
                shown,
            }),
            Err(error) => {
                tracing::warn!(
                    "NOTIFY_SOCKET={shown}: {error}; the service manager will not be notified"
                );
                None
            }
        }
    }
}

/// `$WATCHDOG_USEC` if the watchdog is on and watches `pid` (`$WATCHDOG_PID` unset, or `pid`).
fn watchdog_timeout(var: &impl Fn(&str) -> Option<OsString>, pid: u32) -> Option<Duration> {
    let usec = var("WATCHDOG_USEC")?;
    let timeout = match usec.to_str().and_then(|usec| usec.parse::<u64>().ok()) {
        Some(usec) if usec > 0 => Duration::from_micros(usec),
        _ => {
            tracing::warn!("WATCHDOG_USEC={usec:?} is not a timeout: the watchdog is not petted");
            return None;
        }
    };
    if let Some(watched) = var("WATCHDOG_PID")
        && watched.to_str().and_then(|p| p.parse::<u32>().ok()) != Some(pid)
    {
        tracing::debug!("WATCHDOG_PID={watched:?}: the watchdog watches another process");
        return None;
    }
    Some(timeout)
}

/// `text` with line breaks turned into spaces: one assignment cannot span lines.
fn one_line(text: &str) -> String {
    text.replace(['\n', '\r'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;
    use std::path::PathBuf;

    /// A service manager's end: a socket bound in a directory of its own, removed when dropped.
    struct Listener {
        socket: UnixDatagram,
        dir: Option<PathBuf>,
        address: String,
    }

    impl Listener {
        fn at_path(test: &str) -> Self {
            let dir =
                std::env::temp_dir().join(format!("scout-notify-{test}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("temp dir");
            let path = dir.join("notify");
            let socket = UnixDatagram::bind(&path).expect("bind the notify socket");
            Self::new(socket, Some(dir), path.to_str().expect("utf-8").to_owned())
        }

        fn abstract_name(test: &str) -> Self {
            let name = format!("scout-notify-{test}-{}", std::process::id());
            let address = SocketAddr::from_abstract_name(name.as_bytes()).expect("address");
            let socket = UnixDatagram::bind_addr(&address).expect("bind the abstract socket");
            Self::new(socket, None, format!("@{name}"))
        }

        fn new(socket: UnixDatagram, dir: Option<PathBuf>, address: String) -> Self {
            socket
                .set_read_timeout(Some(Duration::from_secs(5)))
                .expect("timeout");
            Self {
                socket,
                dir,
                address,
            }
        }

        /// The next message; fails the test if none comes within 5 s.
        fn next(&self) -> String {
            let mut buffer = [0; 4096];
            let length = self.socket.recv(&mut buffer).expect("a notification");
            String::from_utf8(buffer[..length].to_vec()).expect("utf-8")
        }

        /// Every message waiting now.
        fn waiting(&self) -> Vec<String> {
            self.socket.set_nonblocking(true).expect("non-blocking");
            let mut messages = Vec::new();
            let mut buffer = [0; 4096];
            while let Ok(length) = self.socket.recv(&mut buffer) {
                messages.push(String::from_utf8(buffer[..length].to_vec()).expect("utf-8"));
            }
            self.socket.set_nonblocking(false).expect("blocking");
            messages
        }

        fn manager(&self, vars: &[(&str, &str)]) -> ServiceManager {
            let mut all: HashMap<String, OsString> = vars
                .iter()
                .map(|(name, value)| (name.to_string(), OsString::from(value)))
                .collect();
            all.insert("NOTIFY_SOCKET".into(), self.address.clone().into());
            ServiceManager::from_vars(|name| all.get(name).cloned(), std::process::id())
        }
    }

    impl Drop for Listener {
        fn drop(&mut self) {
            if let Some(dir) = &self.dir {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
    }

    const START: Duration = Duration::from_secs(1000);

    #[test]
    fn the_messages_arrive() {
        let listener = Listener::at_path("messages");
        let mut manager = listener.manager(&[("WATCHDOG_USEC", "2000000")]);
        assert!(manager.is_present());
        assert_eq!(manager.pet_interval(), Some(Duration::from_millis(500)));
        manager.ready("robot 'scout', sim\non sim");
        assert_eq!(listener.next(), "READY=1\nSTATUS=robot 'scout', sim on sim");
        manager.pet(START);
        assert_eq!(listener.next(), "WATCHDOG=1");
        manager.stopping();
        assert_eq!(listener.next(), "STOPPING=1");
        assert_eq!(manager.failed_sends(), 0);
    }

    #[test]
    fn the_watchdog_is_petted_at_most_every_quarter_of_its_timeout() {
        let listener = Listener::at_path("rate");
        let mut manager = listener.manager(&[("WATCHDOG_USEC", "200000")]);
        // Every 20 ms tick for 1 s of virtual time: a pet at the first tick 50 ms or more after
        // the last one.
        let mut pets = 0;
        for tick in 0..50 {
            manager.pet(START + Duration::from_millis(20) * tick);
            pets += listener.waiting().len();
        }
        // At 0, 60, 120, ... 960 ms.
        assert_eq!(pets, 17);
        // The last pet was at 960 ms: due again at 1010 ms, not a microsecond before.
        manager.pet(START + Duration::from_micros(1_009_999));
        assert!(listener.waiting().is_empty());
        manager.pet(START + Duration::from_millis(1010));
        assert_eq!(listener.waiting(), ["WATCHDOG=1"]);
        manager.pet(START + Duration::from_millis(1010));
        assert!(listener.waiting().is_empty());
    }

    #[test]
    fn abstract_addresses_work() {
        let listener = Listener::abstract_name("abstract");
        let mut manager = listener.manager(&[("WATCHDOG_USEC", "1000000")]);
        manager.ready("up");
        assert_eq!(listener.next(), "READY=1\nSTATUS=up");
        manager.pet(START);
        assert_eq!(listener.next(), "WATCHDOG=1");
    }

    #[test]
    fn the_watchdog_of_another_process_is_not_ours() {
        let listener = Listener::at_path("other-pid");
        let other = (std::process::id() + 1).to_string();
        let mut manager =
            listener.manager(&[("WATCHDOG_USEC", "200000"), ("WATCHDOG_PID", &other)]);
        assert_eq!(manager.pet_interval(), None);
        manager.pet(START);
        manager.ready("up");
        // Only READY=1: no WATCHDOG=1 before it.
        assert_eq!(listener.waiting(), ["READY=1\nSTATUS=up"]);
        let ours = std::process::id().to_string();
        let mut manager = listener.manager(&[("WATCHDOG_USEC", "200000"), ("WATCHDOG_PID", &ours)]);
        manager.pet(START);
        assert_eq!(listener.next(), "WATCHDOG=1");
    }

    #[test]
    fn a_malformed_timeout_turns_the_watchdog_off() {
        let listener = Listener::at_path("malformed");
        for usec in ["", "0", "-5", "2s"] {
            let manager = listener.manager(&[("WATCHDOG_USEC", usec)]);
            assert_eq!(manager.pet_interval(), None, "{usec:?}");
            assert!(manager.is_present());
        }
    }

    #[test]
    fn without_notify_socket_nothing_happens() {
        let mut manager = ServiceManager::from_vars(
            |name| (name == "WATCHDOG_USEC").then(|| "200000".into()),
            std::process::id(),
        );
        assert!(!manager.is_present());
        assert_eq!(manager.pet_interval(), None);
        manager.ready("up");
        manager.pet(START);
        manager.stopping();
        assert_eq!(manager.failed_sends(), 0);
        let empty = ServiceManager::from_vars(|_| Some(OsString::new()), std::process::id());
        assert!(!empty.is_present());
        let relative = ServiceManager::from_vars(
            |name| (name == "NOTIFY_SOCKET").then(|| "run/notify".into()),
            std::process::id(),
        );
        assert!(!relative.is_present());
    }

    #[test]
    fn a_failed_send_is_counted_and_never_blocks() {
        // Nobody at the address.
        let dir = std::env::temp_dir().join(format!("scout-notify-gone-{}", std::process::id()));
        let missing = dir.join("notify").into_os_string();
        let mut manager = ServiceManager::from_vars(
            |name| (name == "NOTIFY_SOCKET").then(|| missing.clone()),
            std::process::id(),
        );
        assert!(manager.is_present());
        manager.ready("up");
        manager.stopping();
        assert_eq!(manager.failed_sends(), 2);
        // A service manager that does not read: its queue fills, and sending fails at once
        // rather than waits.
        let listener = Listener::at_path("full");
        let mut manager = listener.manager(&[("WATCHDOG_USEC", "4")]);
        let (done, finished) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for micros in 0..10_000 {
                manager.pet(START + Duration::from_micros(micros));
            }
            let _ = done.send(manager.failed_sends());
        });
        let failed = finished
            .recv_timeout(Duration::from_secs(10))
            .expect("petting a full socket blocked");
        assert!(failed > 0, "a full queue refused nothing");
        assert!(!listener.waiting().is_empty());
    }
}
