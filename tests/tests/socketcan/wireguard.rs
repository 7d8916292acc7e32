//! Remote drive inside a real WireGuard tunnel, in the VM: the robot in a network namespace of
//! its own, joined to the test (the operator's machine) by a veth pair (the Wi-Fi or 4G link,
//! where netem plays the bad network), the tunnel over it; and a stranger on the robot's LAN
//! (another veth pair) without the tunnel's key, or with a key the robot does not list.

use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use scout_system_tests::{Gateway, TempDir, connect_within, free_port, robot_name, skip};

use crate::netem::Netem;
use crate::{IN_VM, LIMIT, ip, run};

/// WireGuard's port on every machine here.
const WG_PORT: &str = "51820";

/// A network namespace made with `ip netns add` (whose `exec` shows programs the namespace's
/// own `/sys`, where the gateway recognises a WireGuard interface), deleted when dropped.
#[derive(Debug)]
pub(crate) struct Namespace(String);

impl Namespace {
    fn add(name: String) -> Result<Self, String> {
        ip(&["netns", "add", &name])?;
        let namespace = Self(name);
        namespace.ip(&["link", "set", "lo", "up"])?;
        Ok(namespace)
    }

    /// The words that run a program inside it.
    pub(crate) fn through(&self) -> [&str; 4] {
        ["ip", "netns", "exec", &self.0]
    }

    /// `ip ARGS` inside it.
    fn ip(&self, args: &[&str]) -> Result<(), String> {
        ip(&[&["-n", &self.0], args].concat())
    }

    /// `program ARGS` inside it.
    fn run(&self, program: &str, args: &[&str]) -> Result<(), String> {
        let [a, b, c, d] = self.through();
        run(a, &[&[b, c, d, program], args].concat())
    }

    /// A command that runs `program` inside it.
    pub(crate) fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let [a, b, c, d] = self.through();
        let mut command = Command::new(a);
        command.args([b, c, d]).arg(program);
        command
    }
}

impl Drop for Namespace {
    fn drop(&mut self) {
        let _ = ip(&["netns", "del", &self.0]);
    }
}

/// A WireGuard key pair, the private key in a file of mode 0600.
struct Key {
    file: String,
    public: String,
}

impl Key {
    fn new(dir: &TempDir, name: &str) -> Result<Self, String> {
        let private = output(Command::new("wg").arg("genkey"), None)?;
        let file = dir.path().join(format!("{name}.key"));
        {
            use std::io::Write;
            use std::os::unix::fs::OpenOptionsExt;
            let mut out = std::fs::OpenOptions::new()
                .create(true)
                .truncate(true)
                .write(true)
                .mode(0o600)
                .open(&file)
                .map_err(|error| format!("{}: {error}", file.display()))?;
            out.write_all(private.as_bytes())
                .map_err(|error| format!("{}: {error}", file.display()))?;
        }
        let public = output(Command::new("wg").arg("pubkey"), Some(&private))?;
        Ok(Self {
            file: file.display().to_string(),
            public,
        })
    }
}

/// A program's output, trimmed, with `input` on its standard input.
fn output(command: &mut Command, input: Option<&str>) -> Result<String, String> {
    use std::io::Write;
    let mut child = command
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|error| format!("{command:?}: {error}"))?;
    if let Some(input) = input {
        let _ = child
            .stdin
            .take()
            .expect("stdin")
            .write_all(input.as_bytes());
    }
    drop(child.stdin.take());
    let output = child
        .wait_with_output()
        .map_err(|error| format!("{command:?}: {error}"))?;
    if !output.status.success() {
        return Err(format!(
            "{command:?}: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        ));
    }
    Ok(String::from_utf8_lossy(&output.stdout).trim().to_owned())
}

/// The robot, in a namespace of its own, and the tunnel from this namespace (the operator) to
/// it over a veth pair; netem goes on both ends of the pair. Addresses, for tunnel `n`: the
/// underlay 10.201.n.1 (operator) and .2 (robot), the tunnel 10.202.n.1 and .2.
pub(crate) struct Tunnel {
    n: usize,
    /// Strangers made so far.
    strangers: std::cell::Cell<usize>,
    robot: Namespace,
    robot_key: Key,
    keys: TempDir,
    /// The operator's end of the underlay and its WireGuard interface (in this namespace).
    underlay: String,
    wg: String,
}

/// How a stranger on the robot's LAN tries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Stranger {
    /// No tunnel: datagrams for the robot's tunnel address sent over the LAN.
    NoKey,
    /// A WireGuard interface of its own, with a key the robot does not list.
    WrongKey,
}

impl Tunnel {
    /// A tunnel of its own, or why this kernel or machine cannot make one. In CI's VM (which
    /// has wireguard-tools) it must: there, a failure panics.
    pub(crate) fn new(test: &str) -> Result<Tunnel, String> {
        Self::create().inspect_err(|reason| {
            assert!(
                std::env::var_os(IN_VM).is_none() || std::env::var_os("SCOUT_REQUIRE_VM").is_none(),
                "{test}: no WireGuard tunnel in the VM: {reason}"
            );
        })
    }

    /// [`Tunnel::new`], or `None` with `test` skipped, saying why.
    pub(crate) fn or_skip(test: &str) -> Option<Tunnel> {
        Self::new(test)
            .map_err(|reason| {
                skip(
                    test,
                    &format!(
                        "no WireGuard tunnel here ({reason}); socketcan_tests_in_a_vm runs it \
                         in a VM (with wireguard-tools installed)"
                    ),
                );
            })
            .ok()
    }

    fn create() -> Result<Tunnel, String> {
        // The operator's end lives in this process' namespace: only the VM's is the test's own.
        if std::env::var_os(IN_VM).is_none() {
            return Err("outside the VM the operator's end would be this machine's network".into());
        }
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let tag = format!("{}x{n}", std::process::id() % 10_000);
        let keys = TempDir::new(&format!("wg-{tag}"));
        let robot_key = Key::new(&keys, "robot")?;
        let operator_key = Key::new(&keys, "operator")?;
        let robot = Namespace::add(format!("scout-robot-{tag}"))?;
        let (underlay, wg) = (format!("wgu{tag}"), format!("wgo{tag}"));
        let tunnel = Tunnel {
            n,
            strangers: std::cell::Cell::new(0),
            robot,
            robot_key,
            keys,
            underlay: underlay.clone(),
            wg: wg.clone(),
        };
        let net = |subnet: u8, host: u8| format!("10.{subnet}.{n}.{host}");
        // The underlay: the operator's end here, the robot's (`lan0`) in its namespace.
        ip(&[
            "link",
            "add",
            &underlay,
            "type",
            "veth",
            "peer",
            "name",
            "lan0",
            "netns",
            &tunnel.robot.0,
        ])?;
        ip(&[
            "addr",
            "add",
            &format!("{}/24", net(201, 1)),
            "dev",
            &underlay,
        ])?;
        ip(&["link", "set", &underlay, "up"])?;
        (tunnel.robot).ip(&["addr", "add", &format!("{}/24", net(201, 2)), "dev", "lan0"])?;
        tunnel.robot.ip(&["link", "set", "lan0", "up"])?;
        // The tunnel: the robot's `wg0` admits the operator's key alone.
        tunnel
            .robot
            .ip(&["link", "add", "wg0", "type", "wireguard"])?;
        tunnel.robot.run(
            "wg",
            &[
                "set",
                "wg0",
                "private-key",
                &tunnel.robot_key.file,
                "listen-port",
                WG_PORT,
                "peer",
                &operator_key.public,
                "allowed-ips",
                &format!("{}/32", net(202, 1)),
            ],
        )?;
        (tunnel.robot).ip(&["addr", "add", &format!("{}/24", net(202, 2)), "dev", "wg0"])?;
        tunnel.robot.ip(&["link", "set", "wg0", "up"])?;
        ip(&["link", "add", &wg, "type", "wireguard"])?;
        run(
            "wg",
            &[
                "set",
                &wg,
                "private-key",
                &operator_key.file,
                "peer",
                &tunnel.robot_key.public,
                "endpoint",
                &format!("{}:{WG_PORT}", net(201, 2)),
                "allowed-ips",
                &format!("{}/32", net(202, 2)),
            ],
        )?;
        ip(&["addr", "add", &format!("{}/24", net(202, 1)), "dev", &wg])?;
        ip(&["link", "set", &wg, "up"])?;
        tunnel.set_netem(&["delay", "0ms"])?;
        Ok(tunnel)
    }

    /// The robot's address on the tunnel.
    pub(crate) fn robot_address(&self) -> String {
        format!("10.202.{}.2", self.n)
    }

    /// What the gateway listens on: UDP on the tunnel's address, bound to the tunnel.
    pub(crate) fn listen(&self, port: u16) -> String {
        format!("udp/{}:{port}#iface=wg0", self.robot_address())
    }

    /// What the operator connects to.
    pub(crate) fn connect(&self, port: u16) -> String {
        format!("udp/{}:{port}", self.robot_address())
    }

    /// The robot's namespace.
    pub(crate) fn robot(&self) -> &Namespace {
        &self.robot
    }

    /// A stranger on the robot's LAN: a namespace of its own on a veth pair to the robot (the
    /// `m`th stranger 10.(203+m).n.1, the robot .2 there), which sends to the robot's tunnel
    /// address as `how` says.
    pub(crate) fn stranger(&self, how: Stranger) -> Namespace {
        let (n, m) = (self.n, self.strangers.get());
        self.strangers.set(m + 1);
        let stranger = Namespace::add(format!(
            "scout-stranger-{}x{n}x{m}",
            std::process::id() % 10_000
        ))
        .expect("a stranger's namespace");
        let lan = format!("10.{}.{n}", 203 + m);
        let (robot_lan, robot_end) = (format!("{lan}.2"), format!("lan{}", m + 1));
        let setup = || -> Result<(), String> {
            ip(&[
                "link",
                "add",
                "lan0",
                "netns",
                &stranger.0,
                "type",
                "veth",
                "peer",
                "name",
                &robot_end,
                "netns",
                &self.robot.0,
            ])?;
            stranger.ip(&["addr", "add", &format!("{lan}.1/24"), "dev", "lan0"])?;
            stranger.ip(&["link", "set", "lan0", "up"])?;
            (self.robot).ip(&["addr", "add", &format!("{robot_lan}/24"), "dev", &robot_end])?;
            self.robot.ip(&["link", "set", &robot_end, "up"])?;
            let tunnel_net = format!("10.202.{n}.0/24");
            match how {
                Stranger::NoKey => stranger.ip(&["route", "add", &tunnel_net, "via", &robot_lan]),
                Stranger::WrongKey => {
                    let key = Key::new(&self.keys, &format!("stranger{m}"))?;
                    stranger.ip(&["link", "add", "wg0", "type", "wireguard"])?;
                    stranger.run(
                        "wg",
                        &[
                            "set",
                            "wg0",
                            "private-key",
                            &key.file,
                            "peer",
                            &self.robot_key.public,
                            "endpoint",
                            &format!("{robot_lan}:{WG_PORT}"),
                            "allowed-ips",
                            &tunnel_net,
                        ],
                    )?;
                    let address = format!("10.202.{n}.{}/24", 3 + m);
                    stranger.ip(&["addr", "add", &address, "dev", "wg0"])?;
                    stranger.ip(&["link", "set", "wg0", "up"])
                }
            }
        };
        setup().expect("a stranger on the robot's LAN");
        stranger
    }
}

impl Tunnel {
    /// netem on both ends of the underlay: each datagram meets `rule` once, either way.
    fn set_netem(&self, rule: &[&str]) -> Result<(), String> {
        fn args<'a>(dev: &'a str, rule: &[&'a str]) -> Vec<&'a str> {
            [&["qdisc", "replace", "dev", dev, "root", "netem"], rule].concat()
        }
        crate::tc(&args(&self.underlay, rule))?;
        self.robot.run("tc", &args("lan0", rule))
    }
}

impl Netem for Tunnel {
    fn change(&self, rule: &[&str]) {
        self.set_netem(rule)
            .expect("change netem on the tunnel's underlay");
    }
}

impl Drop for Tunnel {
    fn drop(&mut self) {
        let _ = ip(&["link", "del", &self.wg]);
        let _ = ip(&["link", "del", &self.underlay]);
    }
}

/// `scout ARGS` run through `namespace` (or here), its exit code and output.
fn scout_in(namespace: Option<&Namespace>, args: &[&str]) -> std::process::Child {
    let scout = scout_system_tests::bin("scout");
    let mut command = match namespace {
        Some(namespace) => namespace.command(scout),
        None => Command::new(scout),
    };
    command
        .args(args)
        .env("RUST_LOG", "warn")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run scout")
}

/// Waits for a gateway's zenoh to listen (it logs so), saying what it logged if it does not.
fn wait_listening(gateway: &Gateway) {
    let deadline = Instant::now() + LIMIT;
    while !gateway.log().contains("zenoh: publishing") {
        assert!(
            Instant::now() < deadline,
            "the gateway's zenoh never came up:\n{}",
            gateway.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Through a real WireGuard tunnel, with the shipped configurations (the gateway bound to the
/// tunnel, users and access control): alice, on the machine whose key the robot lists, drives.
/// A stranger on the robot's LAN who holds alice's password reaches nothing, without a key or
/// with a key the robot does not list; bob, on alice's machine (the tunnel admits it), cannot
/// drive as alice; the chassis never moves for any of them. And why the binding: a listener on
/// the tunnel's address but not bound to it (e-stops only, which the gateway allows there) is
/// reached from the LAN without any key.
#[test]
fn through_wireguard_only_a_listed_key_with_the_users_password_drives() {
    const TEST: &str = "through_wireguard_only_a_listed_key_with_the_users_password_drives";
    let Some(tunnel) = Tunnel::or_skip(TEST) else {
        return;
    };
    let name = robot_name("wg-impostors");
    let port = free_port();
    let endpoint = tunnel.connect(port);
    let configs = scout_system_tests::ShippedUsers::new(&name, &endpoint);
    let through = tunnel.robot().through();
    let gateway = Gateway::start_through(
        &through,
        &[
            "--sim",
            "--name",
            &name,
            "--zenoh-config",
            &configs.gateway,
            "--zenoh-listen",
            &tunnel.listen(port),
            "--remote-commands",
            "estop,teleop,release",
        ],
        &[],
    );
    let unbound_name = robot_name("wg-unbound");
    let unbound_endpoint = format!("udp/{}:{}", tunnel.robot_address(), free_port());
    let unbound = Gateway::start_through(
        &through,
        &[
            "--sim",
            "--name",
            &unbound_name,
            "--zenoh-listen",
            &unbound_endpoint,
            "--remote-commands",
            "estop",
        ],
        &[],
    );
    let robot = connect_within(&name, LIMIT);
    let state = robot.subscribe().expect("state");
    wait_listening(&gateway);
    wait_listening(&unbound);
    // The emulated CPU may overrun a tick as the gateway starts (a stop): released first.
    scout_system_tests::release_all(&name);

    // Alice, through the tunnel, drives.
    let alice = configs.operator(Some(("alice", "alice-secret")));
    let drive = |config: &str| {
        [
            "drive",
            "--remote",
            &endpoint,
            "--name",
            &name,
            "--client",
            "alice",
            "--zenoh-config",
            config,
            "--linear",
            "0.3",
            "--duration",
            "3",
        ]
        .map(str::to_owned)
    };
    let args = drive(&alice);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let child = scout_in(None, &args);
    if let Err(last) = scout_system_tests::try_wait_for_state(&state, LIMIT, |s| {
        s["command"]["linear"].as_f64() > Some(0.0)
    }) {
        let output = scout_system_tests::wait_output(child, LIMIT);
        panic!(
            "alice's drive through the tunnel never reached the chassis (last state {last}); \
             scout drive: {:?}: {}{}; the gateway's log:\n{}",
            output.status.code(),
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr),
            gateway.log()
        )
    }
    // Her drive ends by itself (0), or with its control ended (4) when the emulated CPU stalls
    // a process past the teleop's age; never unanswered.
    let output = scout_system_tests::wait_output(child, LIMIT);
    assert!(
        matches!(output.status.code(), Some(0 | 4)),
        "alice through the tunnel: {:?}: {}",
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
    scout_system_tests::wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);

    // The impostors, at once: each waits out its own timeouts.
    let no_key = tunnel.stranger(Stranger::NoKey);
    let wrong_key = tunnel.stranger(Stranger::WrongKey);
    let bob = configs.operator(Some(("bob", "bob-secret")));
    let tries = [
        ("a stranger without a key", Some(&no_key), drive(&alice)),
        (
            "a stranger with a key the robot does not list",
            Some(&wrong_key),
            drive(&alice),
        ),
        ("bob as alice, through the tunnel", None, drive(&bob)),
    ];
    let children: Vec<_> = (tries.iter())
        .map(|(who, namespace, args)| {
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            (*who, scout_in(*namespace, &args))
        })
        .collect();
    // Meanwhile the chassis is never commanded to move.
    let watch_until = Instant::now() + Duration::from_secs(5);
    while Instant::now() < watch_until {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200)) {
            assert_eq!(sample.command.linear, 0.0, "an impostor moved the robot");
        }
    }
    for (who, child) in children {
        let output = scout_system_tests::wait_output(child, LIMIT);
        let stderr = String::from_utf8_lossy(&output.stderr);
        eprintln!("{who}: {:?}: {}", output.status.code(), stderr.trim());
        assert_ne!(output.status.code(), Some(0), "{who} drove: {stderr}");
    }
    let status = robot.status().expect("status");
    let now = scout_system_tests::wait_for_status(&status, LIMIT, |_| true);
    assert_ne!(now["selected"]["client"], "remote:alice", "{now}");

    // The same address, not bound to the tunnel: the stranger without a key reaches it.
    let unbound_status = connect_within(&unbound_name, LIMIT)
        .status()
        .expect("status");
    let estop = [
        "estop",
        "--remote",
        &unbound_endpoint,
        "--name",
        &unbound_name,
        "--reason",
        "from the LAN",
    ];
    let output = scout_system_tests::wait_output(scout_in(Some(&no_key), &estop), LIMIT);
    assert_eq!(
        output.status.code(),
        Some(0),
        "a keyless e-stop to the unbound listener: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    scout_system_tests::wait_for_status(&unbound_status, LIMIT, |s| s["latched"] == true);
}
