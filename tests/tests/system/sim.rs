//! `scout-sim` driven over a real pseudo-terminal with scout-protocol's codecs, as a host would.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use scout_protocol::serial::{self, Pull, StreamDecoder};
use scout_protocol::slcan::{self, LineDecoder, Slcan};
use scout_protocol::{
    ChassisState, ControlMode, Counted, FaultClear, Message, MotionCommand, MotionFeedback, can,
};
use scout_system_tests::Sim;
use serialport::SerialPort;

fn open(path: &str) -> Box<dyn SerialPort> {
    serialport::new(path, 115_200)
        .timeout(Duration::from_millis(5))
        .open()
        .unwrap_or_else(|e| panic!("open {path}: {e}"))
}

fn forward(mode: ControlMode, linear_percent: i8) -> Message {
    Message::MotionCommand(MotionCommand {
        control_mode: mode,
        fault_clear: FaultClear::None,
        linear_percent,
        angular_percent: 0,
    })
}

/// A host on the serial link: sends `command` every 20 ms for `duration`, decoding feedback.
fn serial_host(port: &mut dyn SerialPort, command: Message, duration: Duration) -> Vec<Counted> {
    let mut decoder = StreamDecoder::new();
    let mut received = Vec::new();
    let mut buffer = [0u8; 512];
    let start = Instant::now();
    let mut count = 0u8;
    let mut next_send = start;
    while start.elapsed() < duration {
        if Instant::now() >= next_send {
            port.write_all(&serial::encode(&command, count))
                .expect("write");
            count = count.wrapping_add(1);
            next_send += Duration::from_millis(20);
        }
        if let Ok(n) = port.read(&mut buffer) {
            for byte in &buffer[..n] {
                if let Pull::Frame(counted) = decoder.push(*byte) {
                    received.push(counted);
                }
            }
        }
    }
    assert_eq!(decoder.stats().checksum_errors, 0);
    received
}

fn last_motion(received: &[Counted]) -> MotionFeedback {
    received
        .iter()
        .rev()
        .find_map(|c| match c.message {
            Message::MotionFeedback(m) => Some(m),
            _ => None,
        })
        .expect("motion feedback received")
}

#[test]
fn serial_host_drives_the_simulator() {
    let mut sim = Sim::start(&["--serial"]);
    let mut port = open(sim.port());
    let received = serial_host(
        &mut *port,
        forward(ControlMode::Serial, 10),
        Duration::from_secs(1),
    );
    assert!(
        received.len() > 100,
        "about 7 frames every 20 ms, got {}",
        received.len()
    );
    assert!((last_motion(&received).linear() - 0.15).abs() < 0.001);
    let stats = sim.stats();
    assert!(
        stats["commands"]["0x130"].as_u64().expect("count") >= 45,
        "{stats}"
    );
    assert_eq!(stats["checksum_failures"], 0);
    let intervals = &stats["motion_command_intervals"];
    assert!(
        intervals["mean_ms"].as_f64().expect("mean") > 15.0,
        "{stats}"
    );
    // The wrong control mode for serial (0x01) is ignored: the chassis slows to a stop.
    let received = serial_host(
        &mut *port,
        forward(ControlMode::Can, 10),
        Duration::from_millis(800),
    );
    assert_eq!(last_motion(&received).linear_mm_s, 0);
    assert!(
        sim.stats()["ignored"]["wrong_mode"]
            .as_u64()
            .expect("count")
            > 10
    );
}

#[test]
fn injected_estop_is_reported_on_the_wire() {
    let mut sim = Sim::start(&["--serial"]);
    let mut port = open(sim.port());
    sim.send("estop on");
    std::thread::sleep(Duration::from_millis(100));
    let received = serial_host(
        &mut *port,
        forward(ControlMode::Serial, 0),
        Duration::from_millis(300),
    );
    let status = received
        .iter()
        .rev()
        .find_map(|c| match c.message {
            Message::SystemStatus(s) => Some(s),
            _ => None,
        })
        .expect("status");
    assert_eq!(status.state, ChassisState::EStop);
    assert_eq!(status.faults.0 & 0x3C, 0x3C);
    let stats = sim.quit();
    assert!(
        stats["faults"]
            .as_array()
            .expect("faults")
            .contains(&"motor_1_comm_fault".into())
    );
}

#[test]
fn slcan_host_sets_up_the_adapter_and_drives() {
    let sim = Sim::start(&["--slcan"]);
    let mut port = open(sim.port());
    let mut lines = LineDecoder::new();
    let mut buffer = [0u8; 1024];
    let mut read_messages = |port: &mut Box<dyn SerialPort>, for_time: Duration| {
        let mut messages = Vec::new();
        let start = Instant::now();
        while start.elapsed() < for_time {
            if let Ok(n) = port.read(&mut buffer) {
                messages.extend(buffer[..n].iter().filter_map(|b| lines.push(*b)));
            }
        }
        messages
    };
    // Before the channel is open, the adapter refuses to transmit and forwards nothing.
    port.write_all(b"O\r").expect("write");
    assert_eq!(
        read_messages(&mut port, Duration::from_millis(100)),
        [Ok(Slcan::Nack)]
    );
    port.write_all(b"S6\rO\r").expect("write");
    let answers = read_messages(&mut port, Duration::from_millis(100));
    assert_eq!(answers[..2], [Ok(Slcan::Ack), Ok(Slcan::Ack)]);
    let mut count = 0u8;
    let start = Instant::now();
    let mut frames = Vec::new();
    while start.elapsed() < Duration::from_secs(1) {
        let frame = can::encode(&forward(ControlMode::Can, 10), count);
        count = count.wrapping_add(1);
        port.write_all(
            slcan::encode(&Slcan::Frame {
                frame,
                timestamp: None,
            })
            .as_bytes(),
        )
        .expect("write");
        for message in read_messages(&mut port, Duration::from_millis(20)) {
            if let Ok(Slcan::Frame { frame, .. }) = message {
                frames.push(can::decode(&frame).expect("valid feedback frame"));
            }
        }
    }
    assert!(frames.len() > 100, "{}", frames.len());
    assert!((last_motion(&frames).linear() - 0.15).abs() < 0.001);
    let stats = sim.quit();
    // The host above sends one command per 20 ms read window (a little slower than 50 Hz).
    assert!(
        stats["commands"]["0x130"].as_u64().expect("count") >= 30,
        "{stats}"
    );
    assert_eq!(stats["checksum_failures"], 0);
    assert_eq!(stats["transport"], "slcan");
}

#[test]
fn corrupted_and_garbage_output_is_rejected_by_the_codec_and_counted() {
    let mut sim = Sim::start(&["--serial"]);
    let mut port = open(sim.port());
    std::thread::sleep(Duration::from_millis(100));
    sim.send("corrupt 5");
    sim.send("garbage 200");
    let mut decoder = StreamDecoder::new();
    let mut buffer = [0u8; 512];
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(500) {
        if let Ok(n) = port.read(&mut buffer) {
            decoder.push_all(&buffer[..n]).for_each(drop);
        }
    }
    let stats = decoder.stats();
    assert_eq!(stats.checksum_errors, 5, "{stats:?}");
    assert!(stats.frames > 100, "frames keep coming: {stats:?}");
    assert!(stats.discarded_bytes >= 100, "{stats:?}");
    let sim_stats = sim.quit();
    assert_eq!(sim_stats["link"]["corrupted_frames"], 5);
    assert_eq!(sim_stats["link"]["garbage_bytes"], 200);
}

#[test]
fn unplug_comes_back_on_the_link_path() {
    let dir = std::env::temp_dir().join(format!("scout-sim-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let link = dir.join("chassis");
    let link_arg = link.to_str().expect("utf-8 path");
    let mut sim = Sim::start(&["--serial", "--link", link_arg]);
    let port = open(link_arg);
    drop(port);
    sim.send("unplug 300");
    std::thread::sleep(Duration::from_millis(100));
    assert!(!link.exists(), "the link disappears while unplugged");
    let path = sim.next_port_line();
    assert_eq!(
        std::fs::read_link(&link).expect("link back").to_str(),
        Some(path.as_str())
    );
    let mut port = open(link_arg);
    let received = serial_host(
        &mut *port,
        forward(ControlMode::Serial, 0),
        Duration::from_millis(200),
    );
    assert!(!received.is_empty());
    assert_eq!(sim.quit()["link"]["unplugs"], 1);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn script_file_injects_faults_on_schedule() {
    let dir = std::env::temp_dir().join(format!("scout-sim-script-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let script = dir.join("faults.txt");
    std::fs::write(
        &script,
        "# a scripted fault\nwait 100\nbattery 21.9\nprotect overcurrent\n",
    )
    .expect("write script");
    let mut sim = Sim::start(&["--serial", "--script", script.to_str().expect("utf-8")]);
    let first = sim.stats();
    assert!(
        first["faults"].as_array().expect("faults").is_empty(),
        "{first}"
    );
    std::thread::sleep(Duration::from_millis(300));
    let faults = sim.quit()["faults"].clone();
    for expected in ["battery_undervoltage_fault", "motor_overcurrent_protection"] {
        assert!(
            faults
                .as_array()
                .expect("faults")
                .contains(&expected.into()),
            "{faults}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// A host on the slcan link to a v2 chassis: opens the adapter, sends `setup` frames once, then
/// `command` every 20 ms for `duration`; the v2 frames it received.
fn v2_host(
    port: &mut Box<dyn SerialPort>,
    setup: &[scout_protocol::v2::MessageV2],
    command: scout_protocol::v2::MessageV2,
    duration: Duration,
) -> Vec<scout_protocol::v2::MessageV2> {
    let line = |message: &scout_protocol::v2::MessageV2| {
        slcan::encode(&Slcan::Frame {
            frame: message.encode(),
            timestamp: None,
        })
    };
    port.write_all(b"S6\rO\r").expect("write");
    for message in setup {
        port.write_all(line(message).as_bytes()).expect("write");
    }
    let mut lines = LineDecoder::new();
    let mut buffer = [0u8; 1024];
    let mut received = Vec::new();
    let start = Instant::now();
    let mut next = Instant::now();
    while start.elapsed() < duration {
        if Instant::now() >= next {
            port.write_all(line(&command).as_bytes()).expect("write");
            next += Duration::from_millis(20);
        }
        if let Ok(n) = port.read(&mut buffer) {
            for decoded in buffer[..n].iter().filter_map(|b| lines.push(*b)) {
                if let Ok(Slcan::Frame { frame, .. }) = decoded {
                    received.push(scout_protocol::v2::decode(&frame).expect("a v2 frame"));
                }
            }
        }
    }
    received
}

#[test]
fn a_v2_chassis_drives_only_after_0x421_and_reports_in_v2() {
    use scout_protocol::v2::{ControlModeV2, MessageV2, MotionV2};
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout-mini"]);
    let mut port = open(sim.port());
    let go = MessageV2::MotionCommand(MotionV2::from_si(2.0, 0.0));

    // Without 0x421: standby, nothing moves, and the chassis says so in 0x211.
    let frames = v2_host(&mut port, &[], go, Duration::from_millis(500));
    let standby = frames.iter().rev().find_map(|f| match f {
        MessageV2::SystemState(state) => Some(*state),
        _ => None,
    });
    assert_eq!(
        standby.map(|s| s.control_mode),
        Some(ControlModeV2::Standby),
        "{frames:?}"
    );
    assert!(frames.iter().any(|f| f.can_id() == 0x311), "odometers");
    assert_eq!(sim.stats()["actual"]["linear"], 0.0);

    // 0x421 [01], then the same stream: it moves, up to the MINI's 3 m/s (2 m/s asked).
    let frames = v2_host(
        &mut port,
        &[MessageV2::ControlMode(ControlModeV2::Can)],
        go,
        Duration::from_millis(1500),
    );
    let last_motion = frames.iter().rev().find_map(|f| match f {
        MessageV2::MotionState(motion) => Some(*motion),
        _ => None,
    });
    assert!(
        last_motion.is_some_and(|m| m.linear() > 1.0),
        "accelerating toward 2 m/s: {last_motion:?}"
    );
    let stats = sim.quit();
    assert_eq!(stats["control_mode"], "can");
    assert!(stats["ignored"]["standby"].as_u64() >= Some(10), "{stats}");
    assert_eq!(stats["commands"]["0x421"], 1);
}

#[test]
fn a_v2_chassis_is_refused_on_serial() {
    let output = scout_system_tests::run_with_input(
        scout_system_tests::command("scout-sim"),
        b"",
        Duration::from_secs(10),
    );
    assert_eq!(
        output.status.code(),
        Some(2),
        "no transport is a usage error"
    );
    let mut sim = scout_system_tests::command("scout-sim");
    sim.args(["--serial", "--protocol", "v2"]);
    let output = scout_system_tests::run_with_input(sim, b"", Duration::from_secs(10));
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("CAN only"), "{stderr}");
}
