//! `scout teleop` on a pseudo-terminal, as a person at a keyboard, on the gateway's host and
//! through zenoh: keys drive, `e` latches the stop, `q` quits and restores the terminal.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use scout_system_tests::{Gateway, command, connect, free_port, robot_name, wait_for_status};
use serialport::{SerialPort, TTYPort};

const LIMIT: Duration = Duration::from_secs(10);

/// Reads what the program drew until `wanted` appears in it.
fn read_until(master: &mut TTYPort, screen: &mut String, wanted: &str) {
    let deadline = Instant::now() + LIMIT;
    let mut buffer = [0u8; 4096];
    while !screen.contains(wanted) {
        assert!(
            Instant::now() < deadline,
            "`{wanted}` never appeared; screen: {screen:?}"
        );
        if let Ok(n) = master.read(&mut buffer) {
            screen.push_str(&String::from_utf8_lossy(&buffer[..n]));
        }
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
    let mut screen = String::new();
    read_until(&mut master, &mut screen, "scout teleop");
    // Starting takes nothing: a running autonomy would drive on until a key is pressed.
    read_until(&mut master, &mut screen, "a movement key takes control");
    let idle = wait_for_status(&status, LIMIT, |s| s["seq"].as_u64().is_some());
    assert_eq!(idle["selected"], serde_json::Value::Null, "{idle}");
    master.write_all(b"ww").expect("keys");
    read_until(&mut master, &mut screen, "linear +0.20 m/s");
    // The state and the arbiter's status are shown (through zenoh with --remote).
    read_until(&mut master, &mut screen, "chassis  link ok");
    read_until(&mut master, &mut screen, &format!("driving {client}"));
    let driving = wait_for_status(&status, LIMIT, |s| s["selected"]["client"] == client);
    assert_eq!(driving["selected"]["class"], "teleop");
    master.write_all(b"e").expect("e-stop key");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], client);
    // Released: nothing moves until a movement key takes control again.
    master.write_all(b"r").expect("release key");
    read_until(&mut master, &mut screen, "press a movement key");
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
        let mut buffer = [0u8; 4096];
        if let Ok(n) = master.read(&mut buffer) {
            screen.push_str(&String::from_utf8_lossy(&buffer[..n]));
        }
    };
    assert_eq!(code, Some(0));
    let mut buffer = [0u8; 4096];
    while let Ok(n) = master.read(&mut buffer) {
        if n == 0 {
            break;
        }
        screen.push_str(&String::from_utf8_lossy(&buffer[..n]));
    }
    assert!(
        screen.contains("\u{1b}[?1049l"),
        "the alternate screen was left: {screen:?}"
    );
    assert!(screen.contains("\u{1b}[?25h"), "the cursor was shown again");
    drop(slave);
}
