//! Helpers for the multi-process system tests: build and find the real binaries, run them with
//! a deadline, and read their output.

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// The directory holding the workspace's binaries for the profile these tests were built with.
fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test-exe>
    exe.parent()
        .and_then(|deps| deps.parent())
        .expect("target/<profile>")
        .to_path_buf()
}

/// The binaries and examples the system tests run.
const ARTIFACTS: [&str; 10] = [
    "scout",
    "scout-ros2",
    "scout-foxglove",
    "scout-web",
    "scout-doctor",
    "scout-gateway",
    "scout-sim",
    "scout-bench",
    "examples/square",
    "examples/logger",
];

/// Makes sure the binaries exist. `cargo test --workspace` (the README's test command) builds
/// them itself, with the same features as the tests, before any test runs: the gateway and
/// clients packages have integration tests, and examples are always built. Run on its own
/// (`cargo test -p scout-system-tests`), this builds whatever is missing, once per test process;
/// it cannot tell an out-of-date binary, so after changing the gateway run the workspace tests.
fn ensure_built() {
    static BUILT: OnceLock<()> = OnceLock::new();
    BUILT.get_or_init(|| {
        if ARTIFACTS
            .iter()
            .all(|artifact| bin_dir().join(artifact).exists())
        {
            return;
        }
        assert!(
            std::env::var_os("SCOUT_IN_VM").is_none(),
            "a binary the system tests run is missing inside the VM: build them on the host first"
        );
        let mut command = cargo();
        command.args(["build", "--quiet", "--workspace", "--bins", "--examples"]);
        if bin_dir().ends_with("release") {
            command.arg("--release");
        }
        let status = command
            .status()
            .expect("run cargo build for the system tests");
        assert!(
            status.success(),
            "cargo build --workspace --bins --examples failed"
        );
    });
}

/// A `cargo` command as the one running the tests, without what cargo set for this test
/// process: a build script that reads such a variable (ring's reads `CARGO_MANIFEST_DIR`) would
/// run again, and everything above it would build again, here and in the next workspace build.
pub fn cargo() -> Command {
    let mut command = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    for (name, _) in std::env::vars_os() {
        let name = name.to_string_lossy().into_owned();
        let set_for_this_test = name.starts_with("CARGO_PKG_")
            || name.starts_with("CARGO_BIN_")
            || [
                "CARGO_MANIFEST_DIR",
                "CARGO_MANIFEST_PATH",
                "CARGO_CRATE_NAME",
                "CARGO_PRIMARY_PACKAGE",
                "CARGO_TARGET_TMPDIR",
                "CARGO_RUSTC_CURRENT_DIR",
            ]
            .contains(&name.as_str());
        if set_for_this_test {
            command.env_remove(name);
        }
    }
    command
}

/// The path of workspace binary `name`, built if needed.
pub fn bin(name: &str) -> PathBuf {
    ensure_built();
    let path = bin_dir().join(name);
    assert!(path.exists(), "{} was not built", path.display());
    path
}

/// The directory of the workspace's binaries, built if needed: for a program that runs them
/// by name from there (a script, the Python tests).
pub fn built_bin_dir() -> PathBuf {
    ensure_built();
    bin_dir()
}

/// A command for the example `name` of the workspace.
pub fn example(name: &str) -> Command {
    ensure_built();
    let path = bin_dir().join("examples").join(name);
    assert!(path.exists(), "{} was not built", path.display());
    let mut command = Command::new(path);
    command.env_remove("RUST_BACKTRACE");
    command
}

/// A command for workspace binary `name`. Not under this process' service manager, if any: a
/// test that wants one sets `NOTIFY_SOCKET` itself.
pub fn command(name: &str) -> Command {
    command_for(bin(name))
}

/// A command for `program` with a workspace binary's environment (see [`command`]).
fn command_for(program: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut command = Command::new(program);
    workspace_env(&mut command);
    command
}

/// A workspace binary's environment: warnings logged, no backtraces, no service manager.
fn workspace_env(command: &mut Command) {
    command
        .env("RUST_LOG", "warn")
        .env_remove("RUST_BACKTRACE")
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID");
}

/// Reads a child's pipe to the end on a thread of its own, so that the child never blocks on a
/// full pipe.
fn drain(mut pipe: impl std::io::Read + Send + 'static) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = pipe.read_to_end(&mut bytes);
        bytes
    })
}

/// Runs `command` with `stdin` as its input and waits at most `limit` for it.
pub fn run_with_input(mut command: Command, stdin: &[u8], limit: Duration) -> Output {
    use std::io::Write;
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut input = child.stdin.take().expect("stdin");
    let bytes = stdin.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = input.write_all(&bytes);
    });
    let output = wait_output(child, limit);
    let _ = writer.join();
    output
}

/// Waits at most `limit` for `child` to exit (killing it past that), reading what is left of
/// its piped output.
pub fn wait_output(mut child: std::process::Child, limit: Duration) -> Output {
    let stdout = child.stdout.take().map(drain);
    let stderr = child.stderr.take().map(drain);
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("process {} did not finish within {limit:?}", child.id());
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let read = |pipe: Option<std::thread::JoinHandle<Vec<u8>>>| {
        pipe.map_or_else(Vec::new, |reader| reader.join().expect("pipe reader"))
    };
    Output {
        status,
        stdout: read(stdout),
        stderr: read(stderr),
    }
}

/// A running `scout-sim`, killed when dropped.
#[derive(Debug)]
pub struct Sim {
    child: std::process::Child,
    stdin: std::process::ChildStdin,
    lines: std::sync::mpsc::Receiver<String>,
    port: String,
}

/// How long a test waits for a line from a child process.
pub const LINE_TIMEOUT: Duration = Duration::from_secs(10);

/// The lines a child writes to `pipe`, read on a thread of their own as they come.
pub fn line_reader(pipe: impl std::io::Read + Send + 'static) -> std::sync::mpsc::Receiver<String> {
    let (sender, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(pipe).lines() {
            let Ok(line) = line else { return };
            if sender.send(line).is_err() {
                return;
            }
        }
    });
    lines
}

/// A peer process (the Python peers of the ROS 2 tests) that answers each JSON command on its
/// standard input with one JSON line, after a first `{"ready": true}`; killed when dropped.
#[derive(Debug)]
pub struct JsonPeer {
    child: std::process::Child,
    stdin: std::process::ChildStdin,
    lines: std::sync::mpsc::Receiver<String>,
    /// What it is, for the messages.
    what: String,
    /// How long an answer may take.
    limit: Duration,
}

impl JsonPeer {
    /// Starts `command` (its standard error is the test's) and waits for its `ready`.
    pub fn start(mut command: Command, what: &str, limit: Duration) -> JsonPeer {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap_or_else(|error| panic!("spawn {what}: {error}"));
        let stdin = child.stdin.take().expect("stdin");
        let lines = line_reader(child.stdout.take().expect("stdout"));
        let mut peer = JsonPeer {
            child,
            stdin,
            lines,
            what: what.to_owned(),
            limit,
        };
        assert_eq!(peer.answer()["ready"], true, "{what} is not ready");
        peer
    }

    /// Its next line, as JSON.
    pub fn answer(&mut self) -> serde_json::Value {
        let line = self
            .lines
            .recv_timeout(self.limit)
            .unwrap_or_else(|_| panic!("{} answered nothing within {:?}", self.what, self.limit));
        serde_json::from_str(&line).unwrap_or_else(|_| panic!("{}: not JSON: {line}", self.what))
    }

    /// Sends `command` and returns its answer, which must not be an error.
    pub fn ask(&mut self, command: serde_json::Value) -> serde_json::Value {
        use std::io::Write;
        writeln!(self.stdin, "{command}")
            .and_then(|()| self.stdin.flush())
            .unwrap_or_else(|error| panic!("writing to {}: {error}", self.what));
        let answer = self.answer();
        assert!(answer.get("error").is_none(), "{command}: {answer}");
        answer
    }
}

impl Drop for JsonPeer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Sim {
    /// Starts `scout-sim` with `args` (e.g. `--serial`) and waits for its port line.
    pub fn start(args: &[&str]) -> Sim {
        let mut child = command("scout-sim")
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("spawn scout-sim");
        let stdin = child.stdin.take().expect("stdin");
        let lines = line_reader(child.stdout.take().expect("stdout"));
        let mut sim = Sim {
            child,
            stdin,
            lines,
            port: String::new(),
        };
        sim.port = sim.next_port_line();
        sim
    }

    /// Waits for the next `TRANSPORT PATH` line and returns the path.
    pub fn next_port_line(&mut self) -> String {
        let line = self.next_line(|line| !line.starts_with('{'));
        line.split_once(' ')
            .map(|(_, path)| path.to_owned())
            .expect("`TRANSPORT PATH` line")
    }

    /// The path of the simulator's port.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// Sends one fault-injection command.
    pub fn send(&mut self, command: &str) {
        use std::io::Write;
        writeln!(self.stdin, "{command}").expect("write to scout-sim");
        self.stdin.flush().expect("flush scout-sim stdin");
    }

    /// The statistics, or, when the simulator does not answer in time, what its process is
    /// doing (its state and where in the kernel it waits), for a failure message.
    pub fn stats_or_state(&mut self) -> String {
        use std::io::Write;
        // Never panics (it runs while a failing test unwinds): a closed stdin shows as silence.
        let _ = writeln!(self.stdin, "stats").and_then(|()| self.stdin.flush());
        let deadline = Instant::now() + LINE_TIMEOUT;
        while let Ok(line) = self
            .lines
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            if line.starts_with('{') {
                return line;
            }
        }
        let pid = self.child.id();
        let read = |file: &str| {
            std::fs::read_to_string(format!("/proc/{pid}/{file}"))
                .unwrap_or_else(|error| format!("({error})"))
        };
        let state = read("status")
            .lines()
            .filter(|line| line.starts_with("State:"))
            .collect::<String>();
        format!(
            "no answer to `stats` within {LINE_TIMEOUT:?}: {state}, waiting in {}, kernel stack:\n{}",
            read("wchan"),
            read("stack")
        )
    }

    /// Waits until the simulator has sent feedback on its port (its `link.frames_sent`), so
    /// that a listener started now hears the chassis at once; panics after [`LINE_TIMEOUT`].
    pub fn wait_sending(&mut self) {
        let deadline = Instant::now() + LINE_TIMEOUT;
        loop {
            let stats = self.stats();
            if stats["link"]["frames_sent"]
                .as_u64()
                .is_some_and(|sent| sent > 0)
            {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "scout-sim sent no feedback within {LINE_TIMEOUT:?}: {stats}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Asks for the statistics and returns them.
    pub fn stats(&mut self) -> serde_json::Value {
        self.send("stats");
        let line = self.next_line(|line| line.starts_with('{'));
        serde_json::from_str(&line).expect("statistics JSON")
    }

    fn next_line(&mut self, wanted: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + LINE_TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if wanted(&line) => return line,
                Ok(_) => {}
                Err(_) => panic!("scout-sim printed no expected line within {LINE_TIMEOUT:?}"),
            }
        }
    }

    /// Asks the simulator to quit and returns its final statistics.
    pub fn quit(mut self) -> serde_json::Value {
        self.send("quit");
        let line = self.next_line(|line| line.starts_with('{'));
        serde_json::from_str(&line).expect("statistics JSON")
    }
}

impl Drop for Sim {
    /// Kills the simulator; when a test fails with it still running, first prints what it
    /// says of its link (or why it does not answer), which the test's own message lacks.
    fn drop(&mut self) {
        if std::thread::panicking() {
            match self.child.try_wait() {
                Ok(None) => eprintln!("scout-sim at the failure: {}", self.stats_or_state()),
                exited => eprintln!("scout-sim had ended before the failure: {exited:?}"),
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Reports a skipped test on the real stderr (not captured by the test harness), so the reason
/// shows in every run's output.
pub fn skip(test: &str, reason: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: {reason}");
}

/// A unique name for one test's robot, so that tests never share iceoryx2 services or locks.
pub fn robot_name(test: &str) -> String {
    format!("{test}-{}", std::process::id())
}

/// A directory of one test's own (a gateway's `SCOUT_RUN_DIR`), removed when dropped.
#[derive(Debug)]
pub struct TempDir(PathBuf);

/// A shared-memory directory of one test's own (`SCOUT_IPC_DIR`): what the processes started
/// with it leave in shared memory is seen by them alone, not cleaned up by the other tests'
/// clients running beside them. Removed when dropped.
#[derive(Debug)]
pub struct IpcDomain {
    dir: TempDir,
}

impl IpcDomain {
    /// A new domain for `test`: a directory only this user may enter.
    pub fn new(test: &str) -> Self {
        let dir = TempDir::new(&format!("ipc-{test}"));
        std::fs::set_permissions(
            dir.path(),
            std::os::unix::fs::PermissionsExt::from_mode(0o700),
        )
        .expect("make the shared-memory directory private");
        Self { dir }
    }

    /// The environment a process needs to use it.
    pub fn env(&self) -> (&'static str, &std::path::Path) {
        ("SCOUT_IPC_DIR", self.dir.path())
    }
}

impl TempDir {
    /// Creates an empty directory named after `name` (a [`robot_name`]) in the system's
    /// temporary directory.
    pub fn new(name: &str) -> TempDir {
        let path = std::env::temp_dir().join(format!("scout-test-{name}"));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).expect("create a temporary directory");
        TempDir(path)
    }

    /// Its path.
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A running `scout-gateway`, killed when dropped. Its stderr is collected for failure messages.
#[derive(Debug)]
pub struct Gateway {
    child: std::process::Child,
    log: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Gateway {
    /// Starts `scout-gateway` with `args`; without zenoh unless `args` set it up (parallel tests
    /// would all want the default port).
    pub fn start(args: &[&str]) -> Gateway {
        Self::start_with_env(args, &[])
    }

    /// [`Gateway::start`] with its lock files (and the `robot-NAME.running` marker of an unclean
    /// exit) in `run_dir` (`SCOUT_RUN_DIR`) instead of the user's run directory.
    pub fn start_in(run_dir: &std::path::Path, args: &[&str]) -> Gateway {
        let run_dir = run_dir.to_string_lossy();
        Self::start_with_env(args, &[("SCOUT_RUN_DIR", run_dir.as_ref())])
    }

    /// Starts `scout-gateway` on the simulated chassis as robot `name`, its zenoh listening on
    /// `endpoint` with remote e-stop, teleop and release on, and `extra` arguments.
    pub fn start_remote(name: &str, endpoint: &str, extra: &[&str]) -> Gateway {
        let args = [
            "--sim",
            "--name",
            name,
            "--zenoh-listen",
            endpoint,
            "--remote-commands",
            "estop,teleop,release",
        ];
        Self::start(&[&args[..], extra].concat())
    }

    /// Starts `scout-gateway` with `args` and the environment variables `env` set.
    pub fn start_with_env(args: &[&str], env: &[(&str, &str)]) -> Gateway {
        Self::start_through(&[], args, env)
    }

    /// [`Gateway::start_with_env`] through `wrapper`, a program that runs the one it is given
    /// in its own place (`ip netns exec NS`, `nsenter ...`): signals reach the gateway.
    pub fn start_through(wrapper: &[&str], args: &[&str], env: &[(&str, &str)]) -> Gateway {
        let zenoh = args
            .iter()
            .any(|a| a.starts_with("--zenoh") || *a == "--remote-commands");
        let mut command = match wrapper.split_first() {
            None => command("scout-gateway"),
            Some((program, rest)) => {
                let mut wrapped = command_for(program);
                wrapped.args(rest).arg(bin("scout-gateway"));
                wrapped
            }
        };
        // `SCOUT_TEST_GATEWAY_LOG=info,scout_bridge=debug` to see more of what it did.
        let log = std::env::var("SCOUT_TEST_GATEWAY_LOG").unwrap_or_else(|_| "info".into());
        let mut child = command
            .env("RUST_LOG", log)
            .envs(env.iter().copied())
            .args(args)
            .args(if zenoh { None } else { Some("--no-zenoh") })
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn scout-gateway");
        let stderr = child.stderr.take().expect("stderr");
        let log = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        let sink = std::sync::Arc::clone(&log);
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(stderr).lines() {
                let Ok(line) = line else { return };
                if let Ok(mut log) = sink.lock() {
                    log.push_str(&line);
                    log.push('\n');
                }
            }
        });
        Gateway { child, log }
    }

    /// Everything it logged so far.
    pub fn log(&self) -> String {
        self.log.lock().map(|log| log.clone()).unwrap_or_default()
    }

    /// Its process id.
    pub fn pid(&self) -> nix::unistd::Pid {
        nix::unistd::Pid::from_raw(self.child.id() as i32)
    }

    /// Sends `signal` to it.
    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        nix::sys::signal::kill(self.pid(), signal).expect("signal the gateway");
    }

    /// Waits at most `limit` for it to exit and returns its exit code.
    pub fn wait_exit(&mut self, limit: Duration) -> Option<i32> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                return status.code();
            }
            assert!(
                Instant::now() < deadline,
                "gateway still running after {limit:?}:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Whether it still runs.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Connects to robot `name`, retrying until its gateway is up (at most `LINE_TIMEOUT`).
pub fn connect(name: &str) -> scout_clients::client::Robot {
    connect_within(name, LINE_TIMEOUT)
}

/// Connects to robot `name`, retrying until its gateway is up (at most `limit`).
pub fn connect_within(name: &str, limit: Duration) -> scout_clients::client::Robot {
    let deadline = Instant::now() + limit;
    loop {
        match scout_clients::client::Robot::connect(name) {
            Ok(robot) => return robot,
            Err(error) => {
                assert!(
                    Instant::now() < deadline,
                    "no gateway '{name}' after {limit:?}: {error}"
                );
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    }
}

/// Polls `next` until it gives a JSON value that satisfies `wanted`, at most `limit`: that
/// value, or the last one seen (`Null` if none).
fn try_wait_for(
    limit: Duration,
    mut next: impl FnMut() -> Option<serde_json::Value>,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> Result<serde_json::Value, serde_json::Value> {
    let deadline = Instant::now() + limit;
    let mut last = serde_json::Value::Null;
    while Instant::now() < deadline {
        if let Some(value) = next() {
            if wanted(&value) {
                return Ok(value);
            }
            last = value;
        }
    }
    Err(last)
}

/// As [`try_wait_for`], panicking at the deadline.
fn wait_for(
    what: &str,
    limit: Duration,
    next: impl FnMut() -> Option<serde_json::Value>,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    try_wait_for(limit, next, wanted)
        .unwrap_or_else(|last| panic!("no wanted {what} within {limit:?}; last: {last}"))
}

/// Waits for a state that satisfies `wanted`, at most `limit`; returns it as JSON.
pub fn wait_for_state(
    subscriber: &scout_clients::client::StateSubscriber,
    limit: Duration,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    wait_for("state", limit, || state_now(subscriber), wanted)
}

/// As [`wait_for_state`], but the last state seen (`Null` if none) at the deadline instead of a
/// panic: for a test that says more of what went wrong.
pub fn try_wait_for_state(
    subscriber: &scout_clients::client::StateSubscriber,
    limit: Duration,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> Result<serde_json::Value, serde_json::Value> {
    try_wait_for(limit, || state_now(subscriber), wanted)
}

/// The next state as JSON, if one came within 200 ms.
fn state_now(subscriber: &scout_clients::client::StateSubscriber) -> Option<serde_json::Value> {
    let state = subscriber
        .next_timeout(Duration::from_millis(200))
        .expect("receive state")?;
    Some(scout_clients::interface::json::state_json(
        &state,
        scout_clients::monotonic_ns(),
    ))
}

/// The arbiter's newest status as JSON, if one came within `wait`.
pub fn status_now(
    reader: &scout_clients::control::StatusReader,
    wait: Duration,
) -> Option<serde_json::Value> {
    let status = reader.latest(wait).expect("read status")?;
    Some(scout_clients::interface::json::status_json(
        &status,
        scout_clients::monotonic_ns(),
    ))
}

/// Waits for an arbiter status that satisfies `wanted`, at most `limit`; returns it as JSON.
pub fn wait_for_status(
    reader: &scout_clients::control::StatusReader,
    limit: Duration,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let next = || status_now(reader, Duration::from_millis(50));
    wait_for("status", limit, next, wanted)
}

/// As [`wait_for_status`], but the last status seen (`Null` if none) at the deadline instead
/// of a panic: for a test that acts again, as a person would, when nothing came.
pub fn try_wait_for_status(
    reader: &scout_clients::control::StatusReader,
    limit: Duration,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> Result<serde_json::Value, serde_json::Value> {
    try_wait_for(
        limit,
        || status_now(reader, Duration::from_millis(50)),
        wanted,
    )
}

/// A `scout` process in the background (a driver, a router), killed when dropped.
#[derive(Debug)]
pub struct Background {
    child: std::process::Child,
}

/// A client process driving at 50 Hz in the background (`scout drive`).
pub type Driver = Background;

impl Background {
    /// Whether it has exited.
    pub fn exited(&mut self) -> bool {
        self.child.try_wait().is_ok_and(|status| status.is_some())
    }

    /// Starts `scout drive` for robot `name` with `args` (e.g. `--linear 0.5 --class autonomy`).
    pub fn start(name: &str, args: &[&str]) -> Background {
        let mut all = vec!["drive", "--name", name];
        all.extend_from_slice(args);
        Self::scout(&all)
    }

    /// Starts `scout ARGS`.
    pub fn scout(args: &[&str]) -> Background {
        let mut scout = command("scout");
        scout
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        Self::spawn(scout)
    }

    /// Starts `command`.
    pub fn spawn(mut command: Command) -> Background {
        let child = command.spawn().expect("spawn a background process");
        Background { child }
    }

    /// Takes over a child already started (to read its output first).
    pub fn from_child(child: std::process::Child) -> Background {
        Background { child }
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends `signal` to it.
    pub fn signal(&self, signal: nix::sys::signal::Signal) {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        nix::sys::signal::kill(pid, signal).expect("signal the process");
    }

    /// Waits at most `limit` for it to exit and returns its exit code.
    pub fn wait_exit(&mut self, limit: Duration) -> Option<i32> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                return status.code();
            }
            assert!(Instant::now() < deadline, "still running after {limit:?}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `scout ARGS` to completion (bounded) and returns its exit code and output.
pub fn scout(args: &[&str]) -> (Option<i32>, String, String) {
    let mut scout = command("scout");
    scout.args(args);
    let output = run_with_input(scout, b"", Duration::from_secs(20));
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// The zenoh endpoint of `port` on 127.0.0.1.
pub fn tcp(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// A TCP port on 127.0.0.1 that was free a moment ago.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free port on 127.0.0.1")
}

/// A zenoh session of this test process in `mode` (`router`, `peer`, `client`), multicast
/// scouting off, listening on / connecting to loopback endpoints only. A gateway started a
/// moment ago may not listen yet (its iceoryx2 services come first): connecting is tried
/// again for up to 30 s.
pub fn zenoh_session(mode: &str, listen: &[String], connect: &[String]) -> zenoh::Session {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        match try_zenoh_session(mode, listen, connect) {
            Ok(session) => return session,
            Err(_) if Instant::now() < deadline && !connect.is_empty() => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(error) => panic!("open a zenoh session: {error}"),
        }
    }
}

/// A client session with `settings`, retried until the gateway listens (at most `limit`).
pub fn open_within(
    settings: &scout_clients::remote::SessionSettings,
    limit: Duration,
) -> zenoh::Session {
    let deadline = Instant::now() + limit;
    loop {
        match settings.open("client") {
            Ok(session) => return session,
            Err(error) => assert!(
                Instant::now() < deadline,
                "no zenoh session within {limit:?}: {error}"
            ),
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// [`zenoh_session`], or why it could not open (nobody listening on `connect` yet).
pub fn try_zenoh_session(
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> zenoh::Result<zenoh::Session> {
    use zenoh::Wait;
    let settings = scout_clients::remote::SessionSettings {
        config_file: Some(String::new()),
        listen: listen.to_vec(),
        connect: connect.to_vec(),
    };
    let config = settings.config(mode).expect("zenoh config");
    zenoh::open(config).wait()
}

/// Sends `payload` as a zenoh query to `key` and returns the replies' JSON (empty when none
/// came within `timeout`, as when access control drops the query).
pub fn zenoh_query(
    session: &zenoh::Session,
    key: &str,
    payload: Option<&str>,
    timeout: Duration,
) -> Vec<serde_json::Value> {
    use zenoh::Wait;
    let mut get = session.get(key).timeout(timeout);
    if let Some(payload) = payload {
        get = get.payload(payload.to_owned());
    }
    let replies = get.wait().expect("send a zenoh query");
    let mut answers = Vec::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(sample) = reply.result() {
            let text = sample
                .payload()
                .try_to_string()
                .expect("UTF-8 reply")
                .into_owned();
            answers.push(serde_json::from_str(&text).expect("JSON reply"));
        }
    }
    answers
}

/// The simulator's ground truth stays at rest for `time` (it is polled, not slept on).
pub fn chassis_stays_still(sim: &mut Sim, time: Duration) {
    let end = Instant::now() + time;
    while Instant::now() < end {
        let stats = sim.stats();
        assert_eq!(stats["actual"]["linear"], 0.0, "the chassis moves: {stats}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The simulator's ground truth comes to rest within `limit` (polled).
pub fn comes_to_rest(sim: &mut Sim, limit: Duration) {
    let deadline = Instant::now() + limit;
    while sim.stats()["actual"]["linear"].as_f64() != Some(0.0) {
        assert!(Instant::now() < deadline, "the chassis never stopped");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits at most `limit` until the simulator's ground truth moves forward (it is polled).
pub fn moving(sim: &mut Sim, limit: Duration) {
    let deadline = Instant::now() + limit;
    while sim.stats()["actual"]["linear"].as_f64() < Some(0.2) {
        assert!(Instant::now() < deadline, "the chassis never moved");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Starts `scout drive --name NAME` with `args` and waits at most `limit` until the simulator's
/// ground truth moves. Where the drive is refused or loses control first (the emulated CPU of
/// the VM stalls the gateway past its 400 ms wire-gap limit now and then, and it latches an
/// `overrun`, as it must), the stops are released and the drive started again, up to 5 times:
/// the tests using it are about what comes after.
pub fn drive_until_moving(sim: &mut Sim, name: &str, args: &[&str], limit: Duration) -> Driver {
    for _ in 0..5 {
        let mut driver = Driver::start(name, args);
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline && !driver.exited() {
            if sim.stats()["actual"]["linear"].as_f64() >= Some(0.2) {
                return driver;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        release_all(name);
    }
    panic!("the chassis never moved");
}

/// `scout doctor ARGS --json` (ARGS giving `--listen` too), run to its end: the exit code and
/// the checks, one JSON object each.
pub fn doctor(args: &[&str]) -> (Option<i32>, Vec<serde_json::Value>) {
    doctor_in(None, args)
}

/// [`doctor`] in the shared-memory directory of `domain` (see [`IpcDomain`]).
pub fn doctor_in(
    domain: Option<&IpcDomain>,
    args: &[&str],
) -> (Option<i32>, Vec<serde_json::Value>) {
    let mut doctor = command("scout");
    if let Some(domain) = domain {
        let (key, dir) = domain.env();
        doctor.env(key, dir);
    }
    doctor.arg("doctor").args(args).arg("--json");
    let output = run_with_input(doctor, b"", Duration::from_secs(120));
    let checks = String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|_| panic!("not JSON: {line}")))
        .collect();
    (output.status.code(), checks)
}

/// The check called `name` among `checks` (the last of that name).
pub fn doctor_check<'a>(checks: &'a [serde_json::Value], name: &str) -> &'a serde_json::Value {
    checks
        .iter()
        .rev()
        .find(|c| c["check"] == name)
        .unwrap_or_else(|| panic!("no check {name} in {checks:#?}"))
}

/// `scout release`: every stop, as an operator. A gateway that did not answer within the
/// client's second (exit 3: a host stall, as the VM's emulated CPU has now and then) is asked
/// again, and so is one that refused because of an `overrun` stop (exit 4: the same stall seen
/// in the chassis' reports, latched as it must be, its cause not yet over), up to 5 times.
pub fn release_all(name: &str) {
    for _ in 0..5 {
        let (code, _, stderr) = scout(&["release", "--name", name]);
        let stalled = (code == Some(3) && stderr.contains("no answer"))
            || (code == Some(4) && stderr.contains("overrun"));
        if stalled {
            std::thread::sleep(Duration::from_millis(500));
            continue;
        }
        assert_eq!(code, Some(0), "{stderr}");
        return;
    }
    panic!("gateway {name} refused or did not answer `scout release` 5 times (host stalls)");
}

/// A private network namespace with only `lo` (up, multicast on), for processes that speak DDS:
/// DDS discovers peers by multicast on every interface, and test traffic must stay inside
/// namespaces a test made itself. A `sleep` holds it; [`NetNs::command`] runs a program in it.
/// Abstract Unix sockets are per namespace too: a gateway's stop endpoint outside is not seen
/// inside (clients there use its iceoryx2 services, which are shared memory).
#[derive(Debug)]
pub struct NetNs {
    holder: std::process::Child,
}

impl NetNs {
    /// Makes one, or says why it cannot (not root, no `unshare`/`ip`/`nsenter`).
    pub fn create() -> Result<NetNs, String> {
        let mut holder = Command::new("unshare")
            .args([
                "-n",
                "sh",
                "-c",
                "ip link set lo up && ip link set lo multicast on && echo ready && exec sleep 3600",
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|error| format!("cannot run unshare: {error}"))?;
        let lines = line_reader(holder.stdout.take().expect("stdout"));
        match lines.recv_timeout(Duration::from_secs(10)) {
            Ok(line) if line == "ready" => {}
            Ok(_) | Err(_) => {
                let _ = holder.kill();
                let output = holder.wait_with_output().ok();
                let stderr = output
                    .map(|o| String::from_utf8_lossy(&o.stderr).trim().to_owned())
                    .unwrap_or_default();
                return Err(format!(
                    "cannot make a network namespace (`unshare -n`, needs root): {stderr}"
                ));
            }
        }
        let namespace = NetNs { holder };
        if !Command::new("nsenter")
            .arg(namespace.net())
            .arg("true")
            .status()
            .is_ok_and(|status| status.success())
        {
            return Err("cannot enter the network namespace with nsenter".into());
        }
        Ok(namespace)
    }

    fn net(&self) -> String {
        format!("--net=/proc/{}/ns/net", self.holder.id())
    }

    /// A command that runs `program` inside the namespace (nsenter enters it and executes the
    /// program in its own place: signals reach the program).
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut command = Command::new("nsenter");
        command.arg(self.net()).arg("--").arg(program);
        command
    }

    /// [`NetNs::command`] for a workspace binary, with its environment.
    pub fn binary(&self, name: &str) -> Command {
        let mut command = self.command(bin(name));
        workspace_env(&mut command);
        command
    }
}

impl Drop for NetNs {
    fn drop(&mut self) {
        let _ = self.holder.kill();
        let _ = self.holder.wait();
    }
}
/// Test certificates, made fresh for each run: a CA, the gateway, an operator the access control
/// allows, and an intruder it does not (signed by the same CA, so TLS alone would let it in).
#[derive(Debug)]
pub struct Pki {
    dir: std::path::PathBuf,
}

impl Pki {
    pub fn new(test: &str) -> Pki {
        use rcgen::{
            BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer,
            KeyPair, KeyUsagePurpose,
        };
        let dir = std::env::temp_dir().join(format!("scout-pki-{test}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let ca_key = KeyPair::generate().expect("CA key");
        let mut ca = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        ca.distinguished_name
            .push(DnType::CommonName, "scout test CA");
        ca.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        let ca_cert = ca.self_signed(&ca_key).expect("CA certificate");
        std::fs::write(dir.join("ca.pem"), ca_cert.pem()).expect("write CA");
        let issuer = Issuer::new(ca, ca_key);
        for name in ["gateway", "operator", "intruder"] {
            let key = KeyPair::generate().expect("key");
            let mut params =
                CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()])
                    .expect("params");
            params.distinguished_name.push(DnType::CommonName, name);
            params.extended_key_usages = vec![
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ];
            let cert = params.signed_by(&key, &issuer).expect("certificate");
            std::fs::write(dir.join(format!("{name}.pem")), cert.pem()).expect("write certificate");
            std::fs::write(dir.join(format!("{name}.key")), key.serialize_pem())
                .expect("write key");
        }
        Pki { dir }
    }

    pub fn path(&self, file: &str) -> String {
        self.dir.join(file).display().to_string()
    }

    /// A zenoh configuration: TLS with mutual authentication as `who`; `extra` is appended.
    pub fn config(&self, who: &str, mode: &str, endpoints: &str, extra: &str) -> String {
        let path = self.dir.join(format!("{who}-{mode}.json5"));
        let text = format!(
            r#"{{
  mode: "{mode}",
  {endpoints},
  scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }},
  transport: {{ link: {{ tls: {{
    root_ca_certificate: "{ca}",
    listen_certificate: "{cert}", listen_private_key: "{key}",
    connect_certificate: "{cert}", connect_private_key: "{key}",
    enable_mtls: true,
  }} }} }},
  {extra}
}}"#,
            ca = self.path("ca.pem"),
            cert = self.path(&format!("{who}.pem")),
            key = self.path(&format!("{who}.key")),
        );
        std::fs::write(&path, text).expect("write zenoh config");
        path.display().to_string()
    }
}

impl Drop for Pki {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Releases the stops the gateway latches for its own gaps (a tick overrun, a silent
/// simulator: the VM's emulated CPU stalls now and then), as an operator would after checking
/// the robot, for as long as it lives; the other owners' stops it leaves alone. Tests of a link,
/// not of the host's speed, run one; a release restarts nothing, so the rules they check hold.
#[derive(Debug)]
pub struct GapStopReleaser {
    running: std::sync::Arc<std::sync::atomic::AtomicBool>,
    released: std::sync::Arc<Mutex<Vec<String>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl GapStopReleaser {
    /// Watches the status of gateway `name` on a thread of its own.
    pub fn start(name: &str) -> Self {
        use std::sync::atomic::{AtomicBool, Ordering};
        let running = std::sync::Arc::new(AtomicBool::new(true));
        let released = std::sync::Arc::new(Mutex::new(Vec::new()));
        let thread = {
            let (name, running, released) = (
                name.to_owned(),
                std::sync::Arc::clone(&running),
                std::sync::Arc::clone(&released),
            );
            std::thread::spawn(move || {
                let robot = connect_within(&name, Duration::from_secs(30));
                let status = robot.status().expect("status");
                while running.load(Ordering::Relaxed) {
                    let Some(now) = status_now(&status, Duration::from_millis(100)) else {
                        continue;
                    };
                    let gaps: Vec<String> = now["stops"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .filter(|stop| stop["owner"] == "gateway")
                        .map(|stop| format!("{} ({})", stop["reason"], stop["cause"]))
                        .collect();
                    if gaps.is_empty() {
                        std::thread::sleep(Duration::from_millis(100));
                        continue;
                    }
                    // Refused while its cause persists: asked again at the next status.
                    let (code, _, stderr) =
                        scout(&["release", "--name", &name, "--owner", "gateway"]);
                    if code == Some(0) {
                        eprintln!("released the gateway's stops {gaps:?}");
                        released.lock().expect("released").extend(gaps);
                    } else {
                        eprintln!("releasing the gateway's stops {gaps:?}: {stderr}");
                        std::thread::sleep(Duration::from_millis(200));
                    }
                }
            })
        };
        Self {
            running,
            released,
            thread: Some(thread),
        }
    }

    /// The gateway's stops released so far.
    pub fn released(&self) -> Vec<String> {
        self.released.lock().expect("released").clone()
    }
}

impl Drop for GapStopReleaser {
    fn drop(&mut self) {
        self.running
            .store(false, std::sync::atomic::Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The Unix users of the multi-user tests, made once and kept (the names are the tests' own):
/// the gateway's user, a member of the clients' group, and an outsider; and that group. Their
/// commands run the workspace's binaries from a directory every user can enter.
#[derive(Debug)]
pub struct TestUsers {
    /// The gateway's user (a member of the group, as the Debian package makes it).
    pub gateway: u32,
    /// A client: a member of the group.
    pub member: u32,
    /// A user outside the group.
    pub outsider: u32,
    /// The clients' group.
    pub group: u32,
    /// The group's name.
    pub group_name: &'static str,
    bin_dir: PathBuf,
}

impl TestUsers {
    /// The users and the group, made if missing; `Err(why not)` where they cannot be (not root,
    /// no `useradd` or `setpriv`).
    pub fn ensure() -> Result<TestUsers, String> {
        if !nix::unistd::geteuid().is_root() {
            return Err("not root: it makes Unix users and runs processes as them".into());
        }
        for tool in ["useradd", "groupadd", "usermod", "setpriv"] {
            let found = Command::new("sh")
                .args(["-c", &format!("command -v {tool}")])
                .output()
                .is_ok_and(|o| o.status.success());
            if !found {
                return Err(format!("{tool} missing (Debian's passwd and util-linux)"));
            }
        }
        static MADE: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _made = MADE.lock().unwrap_or_else(|e| e.into_inner());
        let group_name = "scout-test";
        let run = |program: &str, args: &[&str]| {
            let output = Command::new(program)
                .args(args)
                .output()
                .map_err(|e| format!("{program}: {e}"))?;
            if output.status.success() {
                Ok(())
            } else {
                Err(format!(
                    "{program} {}: {}",
                    args.join(" "),
                    String::from_utf8_lossy(&output.stderr).trim()
                ))
            }
        };
        if nix::unistd::Group::from_name(group_name)
            .ok()
            .flatten()
            .is_none()
        {
            run("groupadd", &["--system", group_name])?;
        }
        let user = |name: &str, member: bool| -> Result<u32, String> {
            if nix::unistd::User::from_name(name).ok().flatten().is_none() {
                run(
                    "useradd",
                    &[
                        "--system",
                        "--no-create-home",
                        "--shell",
                        "/usr/sbin/nologin",
                        name,
                    ],
                )?;
            }
            if member {
                run("usermod", &["-aG", group_name, name])?;
            }
            nix::unistd::User::from_name(name)
                .ok()
                .flatten()
                .map(|user| user.uid.as_raw())
                .ok_or_else(|| format!("user {name} not found after useradd"))
        };
        let users = TestUsers {
            gateway: user("scout-test-gw", true)?,
            member: user("scout-test-member", true)?,
            outsider: user("scout-test-outsider", false)?,
            group: nix::unistd::Group::from_name(group_name)
                .ok()
                .flatten()
                .map(|group| group.gid.as_raw())
                .ok_or("the group vanished")?,
            group_name,
            bin_dir: Self::shared_bin_dir()?,
        };
        Ok(users)
    }

    /// The workspace's binaries where every user can run them: where they are built if every
    /// directory above lets others in, else a copy of those the tests run.
    fn shared_bin_dir() -> Result<PathBuf, String> {
        let built = built_bin_dir();
        let open = built.ancestors().all(|dir| {
            std::fs::metadata(dir).is_ok_and(|m| {
                std::os::unix::fs::PermissionsExt::mode(&m.permissions()) & 0o001 != 0
            })
        });
        if open {
            return Ok(built);
        }
        let copy =
            std::env::temp_dir().join(format!("scout-test-users-bin-{}", std::process::id()));
        std::fs::create_dir_all(&copy).map_err(|e| e.to_string())?;
        for name in ["scout", "scout-gateway"] {
            std::fs::copy(built.join(name), copy.join(name)).map_err(|e| e.to_string())?;
        }
        std::fs::set_permissions(&copy, std::os::unix::fs::PermissionsExt::from_mode(0o755))
            .map_err(|e| e.to_string())?;
        Ok(copy)
    }

    /// A command running workspace binary `name` as user `uid`, with that user's groups.
    pub fn command(&self, uid: u32, name: &str) -> Command {
        let user = nix::unistd::User::from_uid(nix::unistd::Uid::from_raw(uid))
            .ok()
            .flatten()
            .expect("a test user");
        let mut command = Command::new("setpriv");
        command
            .args([
                "--reuid",
                &uid.to_string(),
                "--regid",
                &user.gid.as_raw().to_string(),
            ])
            .arg("--init-groups")
            .arg("--")
            .arg(self.bin_dir.join(name))
            .env("RUST_LOG", "warn")
            .env_remove("RUST_BACKTRACE")
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .env_remove("WATCHDOG_PID");
        command
    }

    /// A directory of the gateway's user with `mode` (and the clients' group), removed when
    /// dropped: a shared-memory directory as the package makes `/run/scout` (0o2770), or a
    /// run directory (0o700).
    pub fn gateway_dir(&self, tag: &str, mode: u32) -> TempDir {
        let dir = TempDir::new(tag);
        std::os::unix::fs::chown(dir.path(), Some(self.gateway), Some(self.group))
            .expect("chown the directory to the gateway's user");
        std::fs::set_permissions(
            dir.path(),
            std::os::unix::fs::PermissionsExt::from_mode(mode),
        )
        .expect("chmod the directory");
        dir
    }
}

/// The shipped configurations for remote drive inside a tunnel (config/zenoh-wireguard-*.json5)
/// made a test's own: the gateway's with a users file of its own (alice and bob), and an
/// operator's per user, connecting to `endpoint`.
#[derive(Debug)]
pub struct ShippedUsers {
    dir: TempDir,
    operator: String,
    /// The gateway's zenoh configuration file.
    pub gateway: String,
}

impl ShippedUsers {
    /// The users, with passwords `alice-secret` and `bob-secret`.
    pub const USERS: &'static str = "alice:alice-secret\nbob:bob-secret\n";

    pub fn new(test: &str, endpoint: &str) -> ShippedUsers {
        let dir = TempDir::new(&format!("{test}-users"));
        let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
        let read = |file: &str| std::fs::read_to_string(shipped.join(file)).expect("example");
        let users = dir.path().join("zenoh-users.txt");
        std::fs::write(&users, Self::USERS).expect("write the users");
        let gateway = read("zenoh-wireguard-gateway.json5");
        assert!(gateway.contains("/etc/scout/zenoh-users.txt"), "{gateway}");
        let gateway = gateway.replace("/etc/scout/zenoh-users.txt", &users.display().to_string());
        let file = dir.path().join("gateway.json5");
        std::fs::write(&file, gateway).expect("write the gateway's config");
        let operator = read("zenoh-wireguard-operator.json5");
        assert!(operator.contains("udp/10.8.0.1:7448"), "{operator}");
        ShippedUsers {
            operator: operator.replace("udp/10.8.0.1:7448", endpoint),
            gateway: file.display().to_string(),
            dir,
        }
    }

    /// An operator's configuration file as `user` with `password`, or with no credentials.
    pub fn operator(&self, user: Option<(&str, &str)>) -> String {
        let file = self
            .dir
            .path()
            .join(format!("operator-{}.json5", free_port()));
        let text = match user {
            Some((user, password)) => (self.operator)
                .replace(r#"user: "alice""#, &format!(r#"user: "{user}""#))
                .replace(r#""change-me""#, &format!(r#""{password}""#)),
            None => {
                (self.operator).replace(r#"usrpwd: { user: "alice", password: "change-me" },"#, "")
            }
        };
        std::fs::write(&file, text).expect("write an operator's config");
        file.display().to_string()
    }
}
