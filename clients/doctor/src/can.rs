//! A SocketCAN interface as the kernel describes it (`ip -json -details -statistics link show`):
//! up, at 500 kbit/s, error-active, its error counters, automatic restart after bus-off. The
//! verdicts are made from the JSON alone (sans-IO); [`inspect`] runs `ip`.

use std::process::Command;

use serde_json::Value;

use crate::check::Check;

/// The chassis' CAN bitrate.
pub const SCOUT_BITRATE: u64 = 500_000;

/// The fix for a missing or misconfigured interface.
fn set_up(interface: &str) -> String {
    format!(
        "sudo ip link set {interface} down; sudo ip link set {interface} type can bitrate 500000 \
         restart-ms 100; sudo ip link set {interface} up"
    )
}

/// Runs `ip` for `interface` and judges what it says.
pub fn inspect(interface: &str) -> Vec<Check> {
    let output = Command::new("ip")
        .args([
            "-json",
            "-details",
            "-statistics",
            "link",
            "show",
            "dev",
            interface,
        ])
        .output();
    match output {
        Err(error) => vec![Check::skip(
            "can.interface",
            format!("cannot run `ip` ({error}): install iproute2 to check the interface"),
        )],
        Ok(output) if !output.status.success() => vec![Check::fail(
            "can.interface",
            format!(
                "no interface {interface}: {}",
                String::from_utf8_lossy(&output.stderr).trim()
            ),
            format!(
                "plug the CAN adapter in and load its driver (`ip link show` lists interfaces; \
                 gs_usb for most USB adapters), then: {}",
                set_up(interface)
            ),
        )],
        Ok(output) => judge(interface, &String::from_utf8_lossy(&output.stdout)),
    }
}

/// The verdicts on `ip -json -details -statistics link show dev INTERFACE` output.
pub fn judge(interface: &str, json: &str) -> Vec<Check> {
    let parsed: Value = match serde_json::from_str(json) {
        Ok(value) => value,
        Err(error) => {
            return vec![Check::skip(
                "can.interface",
                format!("cannot read `ip -json` output ({error})"),
            )];
        }
    };
    let Some(link) = parsed.get(0) else {
        return vec![Check::fail(
            "can.interface",
            format!("no interface {interface}"),
            set_up(interface),
        )];
    };
    let mut checks = Vec::new();
    let kind = link["linkinfo"]["info_kind"].as_str().unwrap_or("");
    match kind {
        "can" | "vcan" => checks.push(Check::pass(
            "can.interface",
            format!("{interface} is a {kind} interface"),
        )),
        other => {
            checks.push(Check::fail(
                "can.interface",
                format!("{interface} is not a CAN interface (kind `{other}`)"),
                "name the CAN interface (`ip -details link show type can`)",
            ));
            return checks;
        }
    }
    let flags: Vec<&str> = link["flags"]
        .as_array()
        .map(|flags| flags.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    checks.push(if flags.contains(&"UP") {
        Check::pass("can.up", format!("{interface} is up"))
    } else {
        Check::fail("can.up", format!("{interface} is down"), set_up(interface))
    });
    if kind == "vcan" {
        checks.push(Check::skip(
            "can.bitrate",
            "a virtual CAN interface has no bitrate, state or restart",
        ));
        return checks;
    }
    let data = &link["linkinfo"]["info_data"];
    checks.push(match data["bittiming"]["bitrate"].as_u64() {
        Some(SCOUT_BITRATE) => Check::pass("can.bitrate", "500000 bit/s"),
        Some(other) => Check::fail(
            "can.bitrate",
            format!("{other} bit/s; the chassis speaks 500000"),
            set_up(interface),
        ),
        None => Check::fail("can.bitrate", "no bitrate set", set_up(interface)),
    });
    let state = data["state"].as_str().unwrap_or("unknown");
    let tx = data["berr_counter"]["tx"].as_u64().unwrap_or(0);
    let rx = data["berr_counter"]["rx"].as_u64().unwrap_or(0);
    let counters = format!("error counters tx {tx}, rx {rx}");
    checks.push(match state {
        "ERROR-ACTIVE" => Check::pass("can.state", format!("error-active, {counters}")),
        "ERROR-WARNING" => Check::warn(
            "can.state",
            format!("error-warning, {counters}"),
            "errors on the bus: check the wiring, the 120 ohm terminations and the bitrate",
        ),
        "ERROR-PASSIVE" => Check::fail(
            "can.state",
            format!("error-passive, {counters}"),
            "the controller sees many errors: nobody acknowledges (the chassis off or not \
             wired), or the bitrate or terminations are wrong",
        ),
        "BUS-OFF" => Check::fail(
            "can.state",
            format!("bus-off, {counters}"),
            format!(
                "the controller left the bus: fix the cause (wiring, bitrate), then `sudo ip \
                 link set {interface} type can restart` (or restart-ms for automatic recovery)"
            ),
        ),
        other => Check::warn(
            "can.state",
            format!("state {other}, {counters}"),
            "an adapter that does not report its state: watch the error counters",
        ),
    });
    checks.push(match data["restart_ms"].as_u64() {
        Some(0) | None => Check::warn(
            "can.restart",
            "restart-ms 0: after a bus-off the interface stays off until restarted by hand",
            set_up(interface),
        ),
        Some(ms) => Check::pass("can.restart", format!("restart-ms {ms}")),
    });
    checks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::Verdict;

    fn can_link(flags: &str, bitrate: u64, state: &str, restart_ms: u64) -> String {
        format!(
            r#"[{{"ifindex":3,"ifname":"can0","flags":[{flags}],"mtu":16,"operstate":"UP",
            "linkinfo":{{"info_kind":"can","info_data":{{"ctrlmode":[],"state":"{state}",
            "berr_counter":{{"tx":12,"rx":0}},"restart_ms":{restart_ms},
            "bittiming":{{"bitrate":{bitrate},"sample_point":"0.875"}}}}}}}}]"#
        )
    }

    fn verdict(checks: &[Check], name: &str) -> Verdict {
        checks
            .iter()
            .find(|c| c.name == name)
            .map_or(Verdict::Skip, |c| c.verdict)
    }

    #[test]
    fn a_good_interface_passes() {
        let checks = judge(
            "can0",
            &can_link(r#""NOARP","UP","LOWER_UP""#, 500_000, "ERROR-ACTIVE", 100),
        );
        assert!(
            checks.iter().all(|c| c.verdict == Verdict::Pass),
            "{checks:#?}"
        );
    }

    #[test]
    fn down_wrong_bitrate_bus_off_and_no_restart_each_fail_or_warn_with_the_commands() {
        let checks = judge("can0", &can_link(r#""NOARP""#, 250_000, "BUS-OFF", 0));
        assert_eq!(verdict(&checks, "can.up"), Verdict::Fail);
        assert_eq!(verdict(&checks, "can.bitrate"), Verdict::Fail);
        assert_eq!(verdict(&checks, "can.state"), Verdict::Fail);
        assert_eq!(verdict(&checks, "can.restart"), Verdict::Warn);
        let bitrate = checks
            .iter()
            .find(|c| c.name == "can.bitrate")
            .expect("bitrate");
        assert!(bitrate.detail.contains("250000"));
        assert!(
            bitrate
                .fix
                .as_deref()
                .is_some_and(|f| f.contains("bitrate 500000 restart-ms 100"))
        );
        let state = checks
            .iter()
            .find(|c| c.name == "can.state")
            .expect("state");
        assert!(state.detail.contains("tx 12"), "{state:?}");
    }

    #[test]
    fn vcan_has_no_bitrate_and_other_kinds_are_not_can() {
        let vcan = r#"[{"ifname":"vcan0","flags":["NOARP","UP","LOWER_UP"],"linkinfo":{"info_kind":"vcan"}}]"#;
        let checks = judge("vcan0", vcan);
        assert_eq!(verdict(&checks, "can.up"), Verdict::Pass);
        assert_eq!(verdict(&checks, "can.bitrate"), Verdict::Skip);
        let ethernet = r#"[{"ifname":"eth0","flags":["UP"]}]"#;
        assert_eq!(
            verdict(&judge("eth0", ethernet), "can.interface"),
            Verdict::Fail
        );
        assert_eq!(verdict(&judge("x", "[]"), "can.interface"), Verdict::Fail);
        assert_eq!(
            verdict(&judge("x", "not json"), "can.interface"),
            Verdict::Skip
        );
    }
}
