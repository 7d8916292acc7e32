//! Other Unix users on the robot's computer: the gateway run as a user of its own (as the
//! Debian unit runs it), clients in its group, root, and a user outside the group; each gets
//! what the rules give it, and none of them stalls or fools the gateway.

use std::process::Command;
use std::time::Duration;

use scout_system_tests::{TestUsers, robot_name, run_with_input, skip};

/// Runs `command` to its end (bounded): its exit code, standard output and error.
fn run(mut command: Command, env: &[(&str, &str)]) -> (Option<i32>, String, String) {
    command.envs(env.iter().copied());
    let output = run_with_input(command, b"", Duration::from_secs(30));
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// The status as JSON, read as `uid`.
fn status(users: &TestUsers, uid: u32, name: &str, env: &[(&str, &str)]) -> serde_json::Value {
    let mut command = users.command(uid, "scout");
    command.args(["status", "--json", "--name", name]);
    let (code, stdout, stderr) = run(command, env);
    assert_eq!(code, Some(0), "scout status as uid {uid}: {stderr}");
    serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("status JSON ({e}): {stdout}"))
}

#[test]
fn the_gateways_group_and_root_are_clients_others_only_stop_and_nobody_stalls_it() {
    let test = "the_gateways_group_and_root_are_clients_others_only_stop_and_nobody_stalls_it";
    let users = match TestUsers::ensure() {
        Ok(users) => users,
        Err(why) => return skip(test, &why),
    };
    let name = robot_name("users");
    // The shared-memory directory as the package makes /run/scout; the unit's run directory.
    let ipc = users.gateway_dir(&format!("ipc-{name}"), 0o2770);
    let run_dir = users.gateway_dir(&format!("run-{name}"), 0o700);
    let ipc_dir = ipc.path().to_string_lossy().into_owned();
    let env = [("SCOUT_IPC_DIR", ipc_dir.as_str())];
    let mut gateway = users.command(users.gateway, "scout-gateway");
    gateway
        .args(["--sim", "--no-zenoh", "--name", &name])
        .env("SCOUT_IPC_DIR", &ipc_dir)
        .env("SCOUT_RUN_DIR", run_dir.path())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    let mut gateway = scout_system_tests::Background::spawn(gateway);
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    let running = loop {
        let mut probe = users.command(users.member, "scout");
        probe.args(["status", "--json", "--name", &name]);
        let (code, stdout, stderr) = run(probe, &env);
        if code == Some(0) {
            break serde_json::from_str::<serde_json::Value>(&stdout).expect("status JSON");
        }
        assert!(!gateway.exited(), "the gateway exited: {stderr}");
        assert!(
            std::time::Instant::now() < deadline,
            "no status for the group's member: {stderr}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(running["latched"], false, "{running}");

    // Root reads the robot as a person would (`sudo scout status`, `sudo scout echo`): its
    // objects are usable by the gateway's user, so nothing stalls the control loop (before, each
    // cost a 1 s `overrun`).
    for args in [
        vec!["status", "--name", &name],
        vec!["echo", "--json", "--count", "20", "--name", &name],
        vec!["status", "--name", &name],
    ] {
        let mut command = scout_system_tests::command("scout");
        command.args(&args);
        let (code, _, stderr) = run(command, &env);
        assert_eq!(code, Some(0), "root's scout {args:?}: {stderr}");
    }
    let after_root = status(&users, users.member, &name, &env);
    assert_eq!(
        after_root["stop_total"], 0,
        "root's clients latched nothing (no overrun, no silent chassis): {after_root}"
    );

    // A user outside the group: no shared memory, told which group to join...
    let mut outside = users.command(users.outsider, "scout");
    outside.args(["status", "--name", &name]);
    let (code, _, stderr) = run(outside, &env);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("only members of the group '{}'", users.group_name)),
        "{stderr}"
    );
    // ... but the stop endpoint: it stops the robot, under its own user.
    let as_user = |uid: u32, args: &[&str]| {
        let mut command = users.command(uid, "scout");
        command.args(args).args(["--name", &name]);
        run(command, &env)
    };
    let (code, _, stderr) = as_user(users.outsider, &["estop", "--client", "guard"]);
    assert_eq!(code, Some(0), "the outsider's stop: {stderr}");
    // The member latches a stop under the same name: its own, beside the outsider's.
    let (code, _, stderr) = as_user(users.member, &["estop", "--client", "guard"]);
    assert_eq!(code, Some(0), "the member's stop: {stderr}");
    let both = status(&users, users.member, &name, &env);
    let uids: Vec<Option<u64>> = both["stops"]
        .as_array()
        .expect("stops")
        .iter()
        .map(|stop| stop["uid"].as_u64())
        .collect();
    assert_eq!(
        uids,
        [
            Some(u64::from(users.outsider)),
            Some(u64::from(users.member))
        ],
        "a stop each, by user: {both}"
    );
    // The outsider releases its own stop, never the member's of the same name.
    let (code, stdout, stderr) = as_user(
        users.outsider,
        &["release", "--owner", "guard", "--client", "guard"],
    );
    assert_eq!(code, Some(0), "its own: {stdout}{stderr}");
    let left = status(&users, users.member, &name, &env);
    assert_eq!(left["stop_total"], 1, "{left}");
    assert_eq!(left["stops"][0]["uid"], users.member, "{left}");
    let (code, stdout, stderr) = as_user(
        users.outsider,
        &["release", "--owner", "guard", "--client", "guard"],
    );
    assert_eq!(code, Some(4), "another user's stop: {stdout}{stderr}");
    assert!(
        format!("{stdout}{stderr}").contains(&format!("another user (uid {})", users.member)),
        "{stdout}{stderr}"
    );
    assert_eq!(
        status(&users, users.member, &name, &env)["stop_total"],
        1,
        "still held"
    );
    // The member releases its own; root, an operator, could have released any.
    let (code, stdout, stderr) = as_user(users.member, &["release", "--own", "--client", "guard"]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    assert_eq!(status(&users, users.member, &name, &env)["stop_total"], 0);

    gateway.signal(nix::sys::signal::Signal::SIGINT);
    assert_eq!(gateway.wait_exit(Duration::from_secs(20)), Some(0));
}
