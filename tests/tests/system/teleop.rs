//! `scout teleop` on a pseudo-terminal, as a person at a keyboard, on the gateway's host and
//! through zenoh: keys drive, `e` latches the stop, `q` quits and restores the terminal.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use scout_system_tests::{Gateway, command, connect, free_port, robot_name, wait_for_status};
use serialport::{SerialPort, TTYPort};

const LIMIT: Duration = Duration::from_secs(10);

/// What the program drew, read off the pseudo-terminal by a thread of its own from the start
/// (a terminal nobody reads fills up, and the program would block drawing: a person's terminal
/// is always read).
struct Screen {
    text: String,
    chunks: std::sync::mpsc::Receiver<String>,
}

impl Screen {
    fn reading(mut master: TTYPort) -> Screen {
        let (sender, chunks) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut buffer = [0u8; 4096];
            loop {
                match master.read(&mut buffer) {
                    Ok(0) => return,
                    Ok(n) => {
                        let chunk = String::from_utf8_lossy(&buffer[..n]).into_owned();
                        if sender.send(chunk).is_err() {
                            return;
                        }
                    }
                    Err(error) if error.kind() == std::io::ErrorKind::TimedOut => {}
                    Err(_) => return,
                }
            }
        });
        Screen {
            text: String::new(),
            chunks,
        }
    }

    /// Waits until `wanted` appears in what was drawn.
    fn until(&mut self, wanted: &str) {
        let deadline = Instant::now() + LIMIT;
        while !self.text.contains(wanted) {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.chunks.recv_timeout(left) {
                Ok(chunk) => self.text.push_str(&chunk),
                Err(_) => panic!("`{wanted}` never appeared; screen: {:?}", self.text),
            }
        }
    }

    /// Everything drawn until the program closed the terminal (or `LIMIT`).
    fn read_to_the_end(&mut self) -> &str {
        let deadline = Instant::now() + LIMIT;
        while let Ok(chunk) = self
            .chunks
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            self.text.push_str(&chunk);
        }
        &self.text
    }
}

#[test]
fn keyboard_teleop_drives_stops_and_restores_the_terminal() {
    let name = robot_name("teleop");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    keyboard_teleop(&name, &[], "keyboard");
}

/// `scout teleop --remote` over UDP: drives on the fast lane, state and status through zenoh,
/// the e-stop and the release through the remote commands, as on this host.
#[test]
fn keyboard_teleop_through_zenoh_drives_stops_and_restores_the_terminal() {
    let name = robot_name("teleop-remote");
    let endpoint = format!("udp/127.0.0.1:{}", free_port());
    let _gateway = Gateway::start_remote(&name, &endpoint, &[]);
    keyboard_teleop(&name, &["--remote", &endpoint], "remote:keyboard");
}

/// Runs `scout teleop` on a pseudo-terminal with `extra` arguments, as client `keyboard`
/// (`client` as the gateway names it): keys drive, `e` stops, `r` releases, a movement key
/// takes control again, `q` quits and restores the terminal.
fn keyboard_teleop(name: &str, extra: &[&str], client: &str) {
    let robot = connect(name);
    let status = robot.status().expect("status");
    let (mut master, slave) = TTYPort::pair().expect("a pseudo-terminal");
    master
        .set_timeout(Duration::from_millis(50))
        .expect("timeout");
    let tty = slave.name().expect("pty path");
    let open = || {
        std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&tty)
            .expect("open the pty")
    };
    let mut teleop = command("scout")
        .args(["teleop", "--name", name, "--client", "keyboard"])
        .args(extra)
        .stdin(open())
        .stdout(open())
        .stderr(open())
        .spawn()
        .expect("spawn scout teleop");
    let mut screen = Screen::reading(master.try_clone_native().expect("the pty, to read"));
    screen.until("scout teleop");
    // Starting takes nothing: a running autonomy would drive on until a key is pressed.
    screen.until("a movement key takes control");
    let idle = wait_for_status(&status, LIMIT, |s| s["seq"].as_u64().is_some());
    assert_eq!(idle["selected"], serde_json::Value::Null, "{idle}");
    master.write_all(b"ww").expect("keys");
    screen.until("linear +0.20 m/s");
    // The state and the arbiter's status are shown (through zenoh with --remote).
    screen.until("chassis  link ok");
    screen.until(&format!("driving {client}"));
    let driving = wait_for_status(&status, LIMIT, |s| s["selected"]["client"] == client);
    assert_eq!(driving["selected"]["class"], "teleop");
    master.write_all(b"e").expect("e-stop key");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], client);
    // Released: nothing moves until a movement key takes control again.
    master.write_all(b"r").expect("release key");
    screen.until("press a movement key");
    wait_for_status(&status, LIMIT, |s| {
        s["latched"] == false && s["selected"].is_null()
    });
    master.write_all(b"w").expect("a movement key");
    let again = wait_for_status(&status, LIMIT, |s| s["selected"]["client"] == client);
    assert_eq!(again["selected"]["class"], "teleop");
    master.write_all(b"q").expect("quit key");
    let deadline = Instant::now() + LIMIT;
    let code = loop {
        if let Some(status) = teleop.try_wait().expect("try_wait") {
            break status.code();
        }
        assert!(Instant::now() < deadline, "teleop did not quit");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(code, Some(0));
    drop(slave);
    let screen = screen.read_to_the_end();
    assert!(
        screen.contains("\u{1b}[?1049l"),
        "the alternate screen was left: {screen:?}"
    );
    assert!(screen.contains("\u{1b}[?25h"), "the cursor was shown again");
}
