//! The gateway under a service manager, played by this test on a socket of its own: READY=1
//! once it serves, WATCHDOG=1 from its control loop, silence while it is stuck, and after the
//! kill that a watchdog timeout ends in, a new gateway that starts latched (`gateway_start`).

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_system_tests::{Gateway, robot_name, scout};

const LIMIT: Duration = Duration::from_secs(10);
/// The watchdog timeout the gateway is given: petted every 50 ms.
const WATCHDOG_USEC: &str = "200000";

/// The service manager's end of `NOTIFY_SOCKET`, in a directory of its own (removed when
/// dropped) that also holds the gateway's run directory.
struct ServiceManager {
    socket: UnixDatagram,
    dir: PathBuf,
}

impl ServiceManager {
    fn new(test: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("scout-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        let socket = UnixDatagram::bind(dir.join("notify")).expect("bind the notify socket");
        Self { socket, dir }
    }

    fn path(&self, name: &str) -> String {
        self.dir.join(name).to_str().expect("utf-8").to_owned()
    }

    /// A gateway of robot `name` under this manager, with the watchdog on.
    fn start(&self, name: &str) -> Gateway {
        Gateway::start_with_env(
            &["--sim", "--name", name],
            &[
                ("NOTIFY_SOCKET", &self.path("notify")),
                ("WATCHDOG_USEC", WATCHDOG_USEC),
                ("SCOUT_RUN_DIR", &self.path("run")),
            ],
        )
    }

    /// The next message, if one comes within `timeout`.
    fn next(&self, timeout: Duration) -> Option<String> {
        if timeout.is_zero() {
            return None;
        }
        self.socket
            .set_read_timeout(Some(timeout))
            .expect("read timeout");
        let mut buffer = [0; 4096];
        match self.socket.recv(&mut buffer) {
            Ok(length) => Some(String::from_utf8_lossy(&buffer[..length]).into_owned()),
            Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => None,
            Err(error) if error.kind() == std::io::ErrorKind::TimedOut => None,
            Err(error) => panic!("receiving a notification: {error}"),
        }
    }

    /// Waits at most [`LIMIT`] for a message with the line `line`; returns it.
    fn expect(&self, line: &str, gateway: &Gateway) -> String {
        let deadline = Instant::now() + LIMIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.next(left) {
                Some(message) if message.lines().any(|l| l == line) => return message,
                Some(_) => {}
                None => panic!("no {line} within {LIMIT:?}:\n{}", gateway.log()),
            }
        }
    }

    /// The messages that arrive during `time` (waiting on the socket, not sleeping).
    fn during(&self, time: Duration) -> Vec<String> {
        let end = Instant::now() + time;
        let mut messages = Vec::new();
        while let Some(message) = self.next(end.saturating_duration_since(Instant::now())) {
            messages.push(message);
        }
        messages
    }
}

impl Drop for ServiceManager {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Waits at most [`LIMIT`] until process `pid` is stopped (state `T` in /proc).
fn wait_stopped(gateway: &Gateway) {
    let stat = format!("/proc/{}/stat", gateway.pid());
    let deadline = Instant::now() + LIMIT;
    loop {
        let text = std::fs::read_to_string(&stat).expect("the gateway's /proc stat");
        // pid (comm) STATE ...: comm may hold spaces, the state follows its closing parenthesis.
        let state = text
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.trim().chars().next());
        if state == Some('T') {
            return;
        }
        assert!(Instant::now() < deadline, "not stopped: {text}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn running_marker(manager: &ServiceManager, name: &str) -> bool {
    Path::new(&manager.path("run"))
        .join(format!("robot-{name}.running"))
        .exists()
}

#[test]
fn a_stuck_gateway_goes_silent_and_its_successor_starts_latched() {
    let name = robot_name("watchdog");
    let manager = ServiceManager::new("watchdog");
    let mut first = manager.start(&name);

    // Ready first, naming the robot and the transport; then the watchdog, every 50 ms, not at
    // every 20 ms tick.
    let ready = manager.expect("READY=1", &first);
    let status = format!("STATUS=robot '{name}', sim on ");
    assert!(
        ready.lines().any(|line| line.starts_with(&status)),
        "{ready}"
    );
    manager.expect("WATCHDOG=1", &first);
    let second = manager.during(Duration::from_secs(1));
    let pets = second.iter().filter(|m| m.as_str() == "WATCHDOG=1").count();
    assert!((10..=25).contains(&pets), "{pets} pets in 1 s: {second:?}");
    assert!(running_marker(&manager, &name));

    // Stuck: no pet, for five times the watchdog's timeout.
    first.signal(Signal::SIGSTOP);
    wait_stopped(&first);
    // Whatever it sent before it stopped.
    while manager.next(Duration::from_millis(1)).is_some() {}
    let silent = manager.during(Duration::from_secs(1));
    assert!(silent.is_empty(), "a stopped gateway notified {silent:?}");

    // The watchdog's end: SIGABRT waits for SIGCONT on a stopped process, SIGKILL does not.
    first.signal(Signal::SIGKILL);
    assert_eq!(first.wait_exit(LIMIT), None, "killed by a signal");
    assert!(
        running_marker(&manager, &name),
        "the killed gateway's marker is gone"
    );

    // The restart: ready again, and latched until someone checks the robot.
    let mut restarted = manager.start(&name);
    manager.expect("READY=1", &restarted);
    let (code, stdout, stderr) = scout(&["status", "--name", &name, "--json"]);
    assert_eq!(code, Some(0), "{stderr}\n{}", restarted.log());
    let status: serde_json::Value = serde_json::from_str(&stdout).expect("status JSON");
    assert_eq!(status["latched"], true, "{status}");
    let stops = status["stops"].as_array().expect("stops");
    assert!(
        stops
            .iter()
            .any(|stop| stop["cause"] == "gateway_start" && stop["owner"] == "gateway"),
        "{status}"
    );
    assert!(
        restarted.log().contains("exited uncleanly"),
        "{}",
        restarted.log()
    );

    // A clean stop says so, and leaves no marker: the next start is clean.
    restarted.signal(Signal::SIGTERM);
    manager.expect("STOPPING=1", &restarted);
    assert_eq!(restarted.wait_exit(LIMIT), Some(0), "{}", restarted.log());
    assert!(!running_marker(&manager, &name));
}
