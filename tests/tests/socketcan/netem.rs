//! Zenoh remote teleop over a bad network, made with netem: 100 ms delay and 10 % loss, then a
//! partition (100 % loss) and its healing; the drives queried over TCP on loopback (the old
//! path, which stutters) and put on the fast lane over UDP inside a WireGuard tunnel (which
//! drives smoothly).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use scout_system_tests::{
    GapStopReleaser, Gateway, connect_within, free_port, robot_name, try_wait_for_status,
    try_zenoh_session, wait_for_state, zenoh_query,
};
use zenoh::Wait;

use crate::{LIMIT, skip, tc};

/// netem on loopback for as long as it lives.
pub(crate) struct Loopback;

impl Loopback {
    /// No added delay, for as long as it lives; `None` (and `test` skipped, saying why) where
    /// this kernel has no netem.
    pub(crate) fn or_skip(test: &str) -> Option<Loopback> {
        Self::set(&["delay", "0ms"])
            .map_err(|reason| {
                skip(
                    test,
                    &format!("no netem here ({reason}); socketcan_tests_in_a_vm runs it in a VM"),
                );
            })
            .ok()
    }

    fn set(rule: &[&str]) -> Result<Loopback, String> {
        Self::replace(rule).map(|()| Loopback)
    }

    fn replace(rule: &[&str]) -> Result<(), String> {
        let mut args = vec!["qdisc", "replace", "dev", "lo", "root", "netem"];
        args.extend_from_slice(rule);
        tc(&args)
    }
}

/// A network whose conditions a test sets with netem rules (`delay 100ms loss 10%`).
pub(crate) trait Netem {
    /// Replaces the rule.
    fn change(&self, rule: &[&str]);
}

impl Netem for Loopback {
    fn change(&self, rule: &[&str]) {
        Self::replace(rule).expect("change netem on loopback");
    }
}

impl Drop for Loopback {
    fn drop(&mut self) {
        let _ = tc(&["qdisc", "del", "dev", "lo", "root"]);
    }
}

const LOSSY: u8 = 0;
const PARTITION: u8 = 1;
const PHASES: usize = 2;

/// What the remote teleop's commands got, per phase.
#[derive(Debug, Default)]
struct Answers {
    sent: [u64; PHASES],
    accepted: [u64; PHASES],
    refused: [BTreeMap<String, u64>; PHASES],
    retakes: u64,
}

impl Answers {
    /// Counts the answer to a command sent in `phase`; returns whether it says control was
    /// lost (so the operator takes it again).
    fn record(&mut self, phase: u8, reply: &zenoh::query::Reply) -> bool {
        let answer: serde_json::Value = reply
            .result()
            .ok()
            .and_then(|sample| {
                sample
                    .payload()
                    .try_to_string()
                    .ok()
                    .map(|t| t.into_owned())
            })
            .and_then(|text| serde_json::from_str(&text).ok())
            .unwrap_or_default();
        let phase = usize::from(phase);
        if answer["accepted"] == true {
            self.accepted[phase] += 1;
            return false;
        }
        let reason = answer["reason"].as_str().unwrap_or("no reason");
        *self.refused[phase].entry(reason_kind(reason)).or_default() += 1;
        reason.contains("take-control") || reason.contains("revoked")
    }
}

/// A remote teleop on its own thread: a drive command every 20 ms (life 500 ms) as zenoh
/// queries, answers read as they come; after its control lapsed, it takes control again, as an
/// operator still holding the stick would.
fn remote_teleop(
    session: zenoh::Session,
    name: String,
    phase: Arc<AtomicU8>,
    running: Arc<AtomicBool>,
    answers: Arc<Mutex<Answers>>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let key = |kind: &str| format!("scout/{name}/cmd/{kind}/laptop");
        let mut pending = Vec::new();
        let mut seq = 0u64;
        while running.load(Ordering::Relaxed) {
            seq += 1;
            let now_phase = phase.load(Ordering::Relaxed);
            let payload = format!(
                r#"{{"seq":{seq},"sent_ms":{},"linear":0.3,"angular":0.0,"ttl_ms":500}}"#,
                scout_clients::monotonic_ns() / 1_000_000
            );
            let replies = session
                .get(key("drive"))
                .payload(payload)
                .timeout(Duration::from_secs(15))
                .wait()
                .expect("send a drive query");
            pending.push((now_phase, replies));
            answers.lock().expect("answers").sent[usize::from(now_phase)] += 1;
            let mut retake = false;
            pending.retain(|(sent_in, replies)| match replies.try_recv() {
                Ok(Some(reply)) => {
                    retake |= answers.lock().expect("answers").record(*sent_in, &reply);
                    false
                }
                Ok(None) => true,
                Err(_) => false,
            });
            if retake {
                answers.lock().expect("answers").retakes += 1;
                let _ = session
                    .get(key("take-control"))
                    .payload(format!(
                        r#"{{"class":"teleop","sent_ms":{}}}"#,
                        scout_clients::monotonic_ns() / 1_000_000
                    ))
                    .timeout(Duration::from_secs(15))
                    .wait();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        // The answers to what was sent, as they arrive (the partition's after it heals).
        let deadline = Instant::now() + Duration::from_secs(20);
        for (sent_in, replies) in pending {
            let left = deadline.saturating_duration_since(Instant::now());
            if let Ok(Some(reply)) = replies.recv_timeout(left) {
                answers.lock().expect("answers").record(sent_in, &reply);
            }
        }
    })
}

/// A refusal's reason without its figures, to count them by kind.
fn reason_kind(reason: &str) -> String {
    reason
        .split(|c: char| c.is_ascii_digit() || c == '(')
        .next()
        .unwrap_or_default()
        .trim()
        .to_owned()
}

#[test]
fn remote_teleop_through_delay_and_loss_then_a_partition() {
    const TEST: &str = "remote_teleop_through_delay_and_loss_then_a_partition";
    // Checks that netem works here before anything starts.
    let Some(loopback) = Loopback::or_skip(TEST) else {
        return;
    };
    let name = robot_name("netem");
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let gateway = Gateway::start_remote(&name, &endpoint, &[]);
    let state = connect_within(&name, LIMIT).subscribe().expect("state");
    // The gateway listens a moment after its services are up (long in the VM).
    let deadline = Instant::now() + LIMIT;
    let session = loop {
        match try_zenoh_session("client", &[], std::slice::from_ref(&endpoint)) {
            Ok(session) => break session,
            Err(error) => assert!(
                Instant::now() < deadline,
                "the gateway never listened: {error}"
            ),
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let deadline = Instant::now() + LIMIT;
    while zenoh_query(
        &session,
        &format!("scout/{name}/info"),
        None,
        Duration::from_secs(1),
    )
    .is_empty()
    {
        assert!(
            Instant::now() < deadline,
            "the gateway's queryable never answered"
        );
    }
    // The emulated CPU overruns a tick now and then (a stop by the gateway): released, as an
    // operator would after checking the robot. Control is then taken (again) on purpose.
    let releaser = GapStopReleaser::start(&name);
    let deadline = Instant::now() + LIMIT;
    loop {
        let taken = zenoh_query(
            &session,
            &format!("scout/{name}/cmd/take-control/laptop"),
            Some(&format!(
                r#"{{"class":"teleop","sent_ms":{}}}"#,
                scout_clients::monotonic_ns() / 1_000_000
            )),
            LIMIT,
        );
        if taken.first().is_some_and(|a| a["accepted"] == true) {
            break;
        }
        assert!(Instant::now() < deadline, "{taken:?}");
        std::thread::sleep(Duration::from_millis(200));
    }

    loopback.change(&["delay", "100ms", "loss", "10%"]);
    let phase = Arc::new(AtomicU8::new(LOSSY));
    let running = Arc::new(AtomicBool::new(true));
    let answers = Arc::new(Mutex::new(Answers::default()));
    let teleop = remote_teleop(
        session.clone(),
        name.clone(),
        Arc::clone(&phase),
        Arc::clone(&running),
        Arc::clone(&answers),
    );
    // Through 100 ms and 10 % loss, the teleop's commands reach the chassis. Only some do: one
    // lost TCP segment holds every later command up behind it, those past their life are
    // refused, the control lapses and is taken again (in the VM, 2-14 % of the commands sent
    // were accepted). So this waits for the gateway to send a non-zero command, not for the
    // simulated chassis to reach a speed, which needs a run of them.
    let deadline = Instant::now() + LIMIT;
    loop {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200))
            && sample.command.linear > 0.0
        {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no teleop command reached the chassis through 100 ms and 10 % loss within \
             {LIMIT:?}: the teleop's answers {:?}; the gateway's log:\n{}",
            answers.lock().expect("answers"),
            gateway.log()
        );
    }
    let lossy_end = Instant::now() + Duration::from_secs(5);
    let (mut samples, mut driving) = (0u32, 0u32);
    while Instant::now() < lossy_end {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200)) {
            samples += 1;
            driving += u32::from(sample.command.linear > 0.0);
        }
    }
    eprintln!("100 ms delay, 10 % loss: the command was non-zero in {driving} of {samples} states");

    // A partition: the robot stops within the commands' life, by itself.
    loopback.change(&["loss", "100%"]);
    phase.store(PARTITION, Ordering::Relaxed);
    let cut = Instant::now();
    wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);
    eprintln!(
        "partition: command zero after {} ms",
        cut.elapsed().as_millis()
    );
    std::thread::sleep(Duration::from_secs(2));
    // The teleop stops sending; once every command it sent is past its life, the network heals.
    running.store(false, Ordering::Relaxed);
    std::thread::sleep(Duration::from_millis(600));
    loopback.change(&["delay", "0ms"]);
    let healed = Instant::now();
    while healed.elapsed() < Duration::from_secs(3) {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200)) {
            assert_eq!(
                sample.command.linear, 0.0,
                "a command queued in the partition moved the robot"
            );
        }
    }
    teleop.join().expect("teleop thread");
    let answers = answers.lock().expect("answers");
    eprintln!(
        "remote teleop answers: {answers:?}; the gateway's stops released: {:?}",
        releaser.released()
    );
    assert!(answers.accepted[usize::from(LOSSY)] > 0, "{answers:?}");
    assert_eq!(
        answers.accepted[usize::from(PARTITION)],
        0,
        "a command sent in the partition was accepted after it: {answers:?}"
    );
}

/// The remote teleop of `scout drive --remote`, on its own thread: a drive put every 20 ms
/// (life 300 ms), counting the answers that said its control had ended. While `retake` holds,
/// it then takes control again, as an operator holding the stick would (the emulated CPU may
/// stall it past the teleop's age); otherwise it keeps streaming whatever the answers say, as a
/// careless client would.
fn fast_lane_teleop(
    mut controller: scout_clients::remote::RemoteController,
    running: Arc<AtomicBool>,
    retake: Arc<AtomicBool>,
    lost_control: Arc<std::sync::atomic::AtomicU64>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut next = Instant::now();
        while running.load(Ordering::Relaxed) {
            if let Err(scout_clients::remote::RemoteError::Refused { answer, .. }) =
                controller.drive(0.3, 0.0, Duration::from_millis(300))
                && answer.lost_control
            {
                lost_control.fetch_add(1, Ordering::Relaxed);
                if retake.load(Ordering::Relaxed) {
                    let _ = controller.take_control(scout_clients::Class::Teleop);
                }
            }
            next += Duration::from_millis(20);
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
        }
    })
}

/// The fast lane through 100 ms and 10 % loss, a partition and its healing, over plain UDP
/// inside a real WireGuard tunnel (netem on its underlay; the link the guide recommends), or
/// over loopback where no tunnel can be made (outside CI's VM: it says so).
#[test]
fn fast_lane_teleop_inside_wireguard_drives_through_loss_a_partition_stops_healing_restarts_nothing()
 {
    const TEST: &str = "fast_lane_teleop_inside_wireguard_drives_through_loss_a_partition_stops_healing_restarts_nothing";
    let Some(loopback) = Loopback::or_skip(TEST) else {
        return;
    };
    let tunnel = crate::wireguard::Tunnel::new(TEST)
        .inspect_err(|reason| eprintln!("{TEST}: over loopback: no WireGuard tunnel ({reason})"))
        .ok();
    let name = robot_name("netem-fast");
    let port = free_port();
    let (network, through, listen, endpoint): (&dyn Netem, _, _, _) = match &tunnel {
        Some(tunnel) => (
            tunnel,
            tunnel.robot().through().to_vec(),
            tunnel.listen(port),
            tunnel.connect(port),
        ),
        None => {
            let endpoint = format!("udp/127.0.0.1:{port}");
            (&loopback, Vec::new(), endpoint.clone(), endpoint)
        }
    };
    // The emulated CPU stalls the processes for up to a quarter second: a teleop's default
    // life (250 ms) would end its control at every stall. The arbiter's longest (500 ms)
    // tests what the link does, not what the emulation does.
    let config = std::env::temp_dir().join(format!("{name}.toml"));
    std::fs::write(&config, "[arbiter]\nteleop_max_age_ms = 500\n").expect("write the config");
    let config = config.to_string_lossy().into_owned();
    let args = [
        "--sim",
        "--name",
        &name,
        "--zenoh-listen",
        &listen,
        "--remote-commands",
        "estop,teleop,release",
        "--config",
        &config,
    ];
    let gateway = Gateway::start_through(&through, &args, &[]);
    let robot = connect_within(&name, LIMIT);
    let state = robot.subscribe().expect("state");
    let status = robot.status().expect("status");
    let settings = scout_clients::remote::SessionSettings {
        connect: vec![endpoint.clone()],
        ..Default::default()
    };
    // Every session opens before the loss (a handshake over UDP would not survive it); the
    // gateway listens a moment after its services are up (long in the VM).
    let deadline = Instant::now() + LIMIT;
    let session = loop {
        if let Ok(session) = try_zenoh_session("client", &[], std::slice::from_ref(&endpoint))
            && !zenoh_query(&session, &format!("scout/{name}/info"), None, LIMIT).is_empty()
        {
            break session;
        }
        assert!(
            Instant::now() < deadline,
            "the gateway never answered: {}",
            gateway.log()
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    let connect = |peer: &str| {
        scout_clients::remote::RemoteController::connect(&settings, &name, peer)
            .expect("connect a remote controller")
    };
    let (mut controller, mut officer) = (connect("laptop"), connect("officer"));
    let releaser = GapStopReleaser::start(&name);
    // Over plain UDP a take-control or its answer can be lost: the teleop asks again rather
    // than wait the default 5 s (CI saw one lost retake cost a quarter of the lossy phase).
    controller.set_answer_timeout(Duration::from_secs(1));
    // Control is taken through the loss, as an operator on that link would: the gateway then
    // ages the drives against a delivery through the same delay. (Learned before the delay, it
    // would take every drive for 100 ms old, and a stall of the emulated CPU would end the
    // control.)
    network.change(&["delay", "100ms", "loss", "10%"]);
    let deadline = Instant::now() + LIMIT;
    while let Err(error) = controller.take_control(scout_clients::Class::Teleop) {
        assert!(
            Instant::now() < deadline,
            "no take-control through 100 ms and 10 % loss: {error}"
        );
    }
    // Streaming at once: a gap longer than the teleop's age would end its control.
    let running = Arc::new(AtomicBool::new(true));
    let lost_control = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let retake = Arc::new(AtomicBool::new(true));
    let teleop = fast_lane_teleop(
        controller,
        Arc::clone(&running),
        Arc::clone(&retake),
        Arc::clone(&lost_control),
    );
    // Through 100 ms and 10 % loss the chassis reaches the commanded speed and keeps it: a
    // lost drive is replaced by the next, nothing waits behind it.
    let info = || {
        let info = zenoh_query(&session, &format!("scout/{name}/info"), None, LIMIT);
        info.first()
            .map(|info| format!("counters {}, links {}", info["counters"], info["links"]))
            .unwrap_or_default()
    };
    let deadline = Instant::now() + LIMIT;
    loop {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200))
            && sample.motion.linear() > 0.25
        {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the fast lane never drove the chassis through 100 ms and 10 % loss: {}; the \
             gateway's log:\n{}",
            info(),
            gateway.log()
        );
    }
    let lossy_end = Instant::now() + Duration::from_secs(5);
    let (mut samples, mut at_speed) = (0u32, 0u32);
    while Instant::now() < lossy_end {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200)) {
            samples += 1;
            at_speed += u32::from((sample.motion.linear() - 0.3).abs() < 0.05);
        }
    }
    // The chassis keeps near the commanded speed: over TCP (a query per drive) it was there in
    // a few states in ten. How smoothly exactly is a figure of the host's speed as much as of
    // the link's (the emulated CPU stalls the processes, worse on a busy host): measured by the
    // benchmark (BENCHMARKS.md); asserted here only as "most of the time".
    eprintln!(
        "fast lane, 100 ms delay, 10 % loss: at speed in {at_speed} of {samples} states, \
         control lapsed {} times, the gateway's stops released {:?}; {}",
        lost_control.load(Ordering::Relaxed),
        releaser.released(),
        info()
    );
    assert!(
        samples > 0 && 2 * at_speed > samples,
        "the chassis was at the commanded speed in only {at_speed} of {samples} states; the \
         gateway's log:\n{}",
        gateway.log()
    );

    // A partition: the robot stops by itself, although the teleop goes on streaming (and from
    // now on never takes control again).
    retake.store(false, Ordering::Relaxed);
    network.change(&["loss", "100%"]);
    let cut = Instant::now();
    wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);
    eprintln!(
        "fast lane, partition: command zero after {} ms",
        cut.elapsed().as_millis()
    );
    std::thread::sleep(Duration::from_secs(2));
    // Healing, the teleop still streaming: its control ended in the partition, so nothing
    // moves, and its answers say so.
    let before_healing = lost_control.load(Ordering::Relaxed);
    network.change(&["delay", "0ms"]);
    let healed = Instant::now();
    while healed.elapsed() < Duration::from_secs(3) {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(200)) {
            assert_eq!(
                sample.command.linear, 0.0,
                "the streaming teleop moved the robot after the partition healed"
            );
        }
    }
    let deadline = Instant::now() + LIMIT;
    while lost_control.load(Ordering::Relaxed) == before_healing {
        assert!(
            Instant::now() < deadline,
            "no answer after the healing told the teleop its control ended"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    running.store(false, Ordering::Relaxed);
    teleop.join().expect("teleop thread");

    // The stop gets through the loss: put three times and queried, it latches once. An officer
    // who sees no answer presses again (the same stop: it latches once all the same).
    network.change(&["delay", "100ms", "loss", "10%"]);
    let officers = |s: &serde_json::Value| {
        s["stops"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|stop| stop["owner"] == "remote:officer")
            .count()
    };
    let asked = Instant::now();
    let mut answers = Vec::new();
    let latched = loop {
        answers.push(officer.stop("through loss"));
        if let Ok(latched) =
            try_wait_for_status(&status, Duration::from_secs(3), |s| officers(s) > 0)
        {
            break latched;
        }
        assert!(
            asked.elapsed() < LIMIT,
            "the officer's stop never latched through 100 ms and 10 % loss: answers {answers:?}; \
             {}; the gateway's log:\n{}",
            info(),
            gateway.log()
        );
    };
    eprintln!(
        "fast lane, e-stop through 100 ms and 10 % loss: latched seen after {} ms, answers \
         {answers:?}",
        asked.elapsed().as_millis()
    );
    assert_eq!(latched["latched"], true, "{latched}");
    assert_eq!(officers(&latched), 1, "{latched}");
}
