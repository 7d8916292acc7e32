//! The black box end to end: a gateway on the simulated chassis saves the last minutes of the
//! bus when a stop latches and when asked; `scout decode` reads every line of it; `scout-sim
//! --replay` plays the chassis' side of it to another gateway, which sees the incident again.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use scout_clients::Class;
use scout_system_tests::{Gateway, Sim, TempDir, connect, robot_name, scout, wait_for_state};

const LIMIT: Duration = Duration::from_secs(15);

/// The robot's black boxes in `dir`, oldest first.
fn boxes(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|entry| entry.path())
                .filter(|path| path.extension().is_some_and(|ext| ext == "log"))
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}

/// Waits for the `count`th black box in `dir`.
fn wait_for_box(dir: &Path, count: usize) -> PathBuf {
    let deadline = Instant::now() + LIMIT;
    loop {
        let files = boxes(dir);
        if files.len() >= count {
            return files[count - 1].clone();
        }
        assert!(
            Instant::now() < deadline,
            "no black box #{count} in {}",
            dir.display()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_stop_saves_the_black_box_decode_reads_it_and_the_sim_replays_it() {
    let name = robot_name("blackbox");
    let dir = TempDir::new(&name);
    let boxes_dir = dir.path().join("boxes");
    let config = dir.path().join("gateway.toml");
    std::fs::write(
        &config,
        format!(
            "[blackbox]\nminutes = 1\nmin_interval_s = 1\ndir = \"{}\"\n",
            boxes_dir.display()
        ),
    )
    .expect("the gateway's configuration");
    let config = config.to_string_lossy().into_owned();
    let sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let gateway = Gateway::start(&["--serial", &port, "--name", &name, "--config", &config]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    wait_for_state(&states, LIMIT, |s| s["link"]["state"] == "ok");

    // Drive for a second, then the e-stop: a stop latched saves the black box.
    let mut teleop = robot
        .controller("driver", Some(Class::Teleop))
        .expect("a controller");
    teleop.take_control().expect("take control");
    let until = Instant::now() + Duration::from_secs(1);
    while Instant::now() < until {
        teleop.drive(0.4, 0.0).expect("drive");
        std::thread::sleep(Duration::from_millis(20));
    }
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", "black box test"]);
    assert_eq!(code, Some(0), "{stderr}");
    let saved = wait_for_box(&boxes_dir, 1);
    let text = std::fs::read_to_string(&saved).expect("the black box");
    assert!(
        text.lines()
            .any(|l| l.starts_with("# saved for: stop #") && l.contains("black box test")),
        "{}",
        &text[..text.len().min(800)]
    );
    let rx = text.lines().filter(|l| l.contains(") rx ")).count();
    let tx: Vec<&str> = text.lines().filter(|l| l.contains(") tx 130#")).collect();
    assert!(rx > 300 && tx.len() > 40, "{rx} rx, {} tx", tx.len());
    assert!(
        tx.iter().any(|l| !l.contains("130#0200000000")),
        "a drive on the wire"
    );
    assert!(
        tx.last().is_some_and(|l| l.contains("130#0200000000")),
        "the stop's zero on the wire: {:?}",
        tx.last()
    );
    assert!(
        gateway.log().contains("black box saved to"),
        "{}",
        gateway.log()
    );

    // `scout decode FILE` (as the box's header says) reads every frame line; `scout blackbox
    // save` saves another.
    let path = saved.to_string_lossy().into_owned();
    let mut decode = scout_system_tests::command("scout");
    decode
        .args(["decode", "--json", &path])
        .stdin(std::process::Stdio::null());
    let output = decode.output().expect("scout decode");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        output.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let decoded = String::from_utf8_lossy(&output.stdout);
    assert_eq!(
        decoded.lines().count(),
        rx + text.lines().filter(|l| l.contains(") tx ")).count()
    );
    assert!(
        decoded.contains("\"motion_command\""),
        "{}",
        &decoded[..decoded.len().min(400)]
    );
    let (code, _, stderr) = scout(&["blackbox", "save", "--name", &name]);
    assert_eq!(code, Some(0), "{stderr}");
    let asked = wait_for_box(&boxes_dir, 2);
    let asked_text = std::fs::read_to_string(&asked).expect("the second box");
    assert!(
        asked_text.contains("# saved for: asked by operator"),
        "{}",
        &asked_text[..400]
    );
    drop(gateway);
    drop(sim);

    // The chassis' side replayed to a new gateway: it sees the chassis drive again, with
    // nobody commanding it (and says so: a runaway), then fall silent.
    let replay_name = robot_name("blackbox-replay");
    let mut replayed = Sim::start(&["--serial", "--replay", &path]);
    let port = replayed.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &replay_name]);
    let states = connect(&replay_name).subscribe().expect("state");
    let moving = wait_for_state(&states, LIMIT, |s| {
        s["motion"]["linear"].as_f64() > Some(0.3)
    });
    assert_eq!(
        moving["command"]["linear"], 0.0,
        "nobody drives it: {moving}"
    );
    wait_for_state(&states, LIMIT, |s| s["link"]["state"] == "silent");
    let stats = replayed.stats();
    assert!(
        stats["link"]["frames_sent"].as_u64() >= Some(rx as u64),
        "{stats}"
    );
}
