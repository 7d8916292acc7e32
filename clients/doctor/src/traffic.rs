//! What a port said while the doctor listened, and the verdicts on it: whether frames arrive,
//! which protocol their ids speak, checksums and rejects, another host commanding the chassis,
//! and the chassis' own state from its last 0x151. Sans-IO: events and their times come in.

use std::collections::BTreeMap;
use std::time::Duration;

use scout_protocol::Severity;
use scout_protocol::link::RxEvent;
use scout_protocol::model::{Model, Names, Sign};
use scout_protocol::v2::{ControlModeV2, MessageV2, RcStateV2, SwitchPosition, SystemStateV2};
use scout_protocol::version::{Detection, Protocol, ProtocolDetector, protocol_of_feedback_id};
use scout_protocol::{ChassisState, ControlMode, Direction, Message, SystemStatus, Transport};

use crate::check::Check;

/// Below this the battery is worth a warning (the chassis faults at 22 V), V.
pub const LOW_BATTERY: f64 = 23.0;

/// The tally of one listening window.
#[derive(Debug, Clone, Default)]
pub struct Traffic {
    /// Valid frames by CAN id.
    pub frames: BTreeMap<u16, u64>,
    /// Rejected input by CAN id, where it had one.
    pub rejected_ids: BTreeMap<u16, u64>,
    /// Frames rejected for their checksum.
    pub checksum_errors: u64,
    /// Other rejected input.
    pub rejected: u64,
    /// Extended, remote or error CAN frames.
    pub foreign: u64,
    /// Motion or light commands another host sent (the chassis' ids for host commands).
    pub other_host_commands: u64,
    /// Bytes the stream decoder discarded (a tty), set by the caller at the end.
    pub discarded_bytes: u64,
    /// The last system status.
    pub last_status: Option<SystemStatus>,
    /// Valid protocol v2 frames by CAN id.
    pub frames_v2: BTreeMap<u16, u64>,
    /// The last v2 system state (0x211).
    pub last_system_v2: Option<SystemStateV2>,
    /// The last v2 RC state (0x241).
    pub last_rc_v2: Option<RcStateV2>,
    /// What the frames said of the chassis' model that no SCOUT sends, each once, in order.
    pub signs: Vec<Sign>,
    version: ProtocolDetector,
}

impl Traffic {
    /// An empty tally.
    pub fn new() -> Self {
        Self::default()
    }

    /// One event, received at `now` (any monotonic origin).
    pub fn handle(&mut self, event: &RxEvent, now: Duration) {
        match event {
            RxEvent::Message(counted) => {
                let id = counted.message.kind().can_id();
                self.version.observe(id, now);
                *self.frames.entry(id).or_default() += 1;
                if counted.message.kind().direction() == Direction::Command {
                    self.other_host_commands += 1;
                }
                if let Message::SystemStatus(status) = counted.message {
                    self.last_status = Some(status);
                }
            }
            RxEvent::V2(message) => {
                let id = message.can_id();
                self.version.observe(id, now);
                *self.frames_v2.entry(id).or_default() += 1;
                if message.is_command() {
                    self.other_host_commands += 1;
                }
                match message {
                    MessageV2::SystemState(state) => self.last_system_v2 = Some(*state),
                    MessageV2::RcState(rc) => self.last_rc_v2 = Some(*rc),
                    _ => {}
                }
                self.sign(Sign::of_v2_message(message));
            }
            RxEvent::Rejected(error) => {
                if let Some(id) = error.can_id() {
                    self.version.observe(id, now);
                    *self.rejected_ids.entry(id).or_default() += 1;
                    self.sign(Sign::of_v2_id(id));
                }
                if error.is_checksum() {
                    self.checksum_errors += 1;
                } else if matches!(error, scout_protocol::link::RxError::ForeignFrame(_)) {
                    self.foreign += 1;
                } else {
                    self.rejected += 1;
                }
            }
            RxEvent::Slcan(_) => {}
        }
    }

    fn sign(&mut self, sign: Option<Sign>) {
        if let Some(sign) = sign
            && !self.signs.contains(&sign)
        {
            self.signs.push(sign);
        }
    }

    /// Which model the frames suggest: a SCOUT's (or a chassis that sends the same), or another
    /// the gateway refuses to drive as a SCOUT.
    fn model_check(&self) -> Check {
        let Some(first) = self.signs.first() else {
            return Check::pass(
                "model",
                "nothing a SCOUT does not send (a Tracer or a Bunker sends the same)",
            );
        };
        let sent: Vec<&str> = self.signs.iter().map(|sign| sign.short()).collect();
        let detail = format!(
            "the chassis sends {}: it looks like {}",
            sent.join(", "),
            first.suggests()
        );
        // The models that send all of it; else those the gateway would drive all the same (a
        // parking brake is judged on a Hunter alone: 0x211 byte 6 is reserved elsewhere).
        let models = |fits: fn(Model, Sign) -> bool| -> Vec<&str> {
            Model::ALL
                .into_iter()
                .filter(|model| self.signs.iter().all(|sign| fits(*model, *sign)))
                .map(Model::name)
                .collect()
        };
        let sending = models(Model::sends);
        let models = match sending.is_empty() {
            true => models(Model::may_send),
            false => sending,
        };
        if !models.is_empty() {
            return Check::warn(
                "model",
                detail,
                format!(
                    "start the gateway with the model it is, --model {}: as another model it \
                     refuses to drive it",
                    models.join(" or --model ")
                ),
            );
        }
        Check::fail(
            "model",
            detail,
            format!(
                "the gateway drives these models only ({Names}) and refuses to drive this \
                 chassis: driven with their command it would move otherwise than asked \
                 (docs/chassis.md)"
            ),
        )
    }

    fn valid_frames(&self) -> u64 {
        self.frames.values().sum::<u64>() + self.frames_v2.values().sum::<u64>()
    }

    fn ids(ids: &BTreeMap<u16, u64>) -> String {
        ids.iter()
            .map(|(id, count)| format!("0x{id:03X} x{count}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The verdicts after listening for `window` on `transport`, at `now`.
    pub fn checks(&self, transport: Transport, window: Duration, now: Duration) -> Vec<Check> {
        let anything = self.valid_frames()
            + self.checksum_errors
            + self.rejected
            + self.foreign
            + self.discarded_bytes;
        if anything == 0 {
            return vec![Check::fail(
                "traffic",
                format!("nothing received in {window:.1?}"),
                format!("nothing arrives: {}", Self::what_to_check(transport)),
            )];
        }
        let v2_ids = self.v2_ids();
        let mut checks = vec![
            self.traffic_check(transport, window, &v2_ids),
            self.protocol_check(now, &v2_ids),
            self.model_check(),
            self.errors_check(),
            self.other_host_check(),
        ];
        match (&self.last_status, &self.last_system_v2) {
            (None, Some(state)) => {
                checks.extend(chassis_checks_v2(state, self.last_rc_v2.as_ref()));
            }
            (status, _) => checks.extend(chassis_checks(status.as_ref())),
        }
        checks
    }

    /// What to check on `transport` when nothing arrives.
    fn what_to_check(transport: Transport) -> &'static str {
        match transport {
            Transport::Serial => {
                "is the chassis on, the cable on its RS232 port (TX/RX crossed, GND), and the port \
                 at 115200 8N1?"
            }
            Transport::Slcan | Transport::Can | Transport::GsUsb => {
                "is the chassis on, CAN_H/CAN_L wired (and terminated: 120 ohm at each end), the \
                 bus at 500 kbit/s?"
            }
            Transport::Sim => "is the simulator running?",
        }
    }

    /// The ids of protocol v2 seen, rejected (by v1) or decoded.
    fn v2_ids(&self) -> BTreeMap<u16, u64> {
        let mut v2_ids: BTreeMap<u16, u64> = self
            .rejected_ids
            .iter()
            .filter(|(id, _)| protocol_of_feedback_id(**id) == Some(Protocol::V2))
            .map(|(id, count)| (*id, *count))
            .collect();
        for (id, count) in &self.frames_v2 {
            *v2_ids.entry(*id).or_default() += count;
        }
        v2_ids
    }

    /// Whether valid frames arrive, and at what rate.
    fn traffic_check(
        &self,
        transport: Transport,
        window: Duration,
        v2_ids: &BTreeMap<u16, u64>,
    ) -> Check {
        let valid = self.valid_frames();
        if valid == 0 && v2_ids.is_empty() {
            let what = format!(
                "no valid frame in {window:.1?}: {} rejected, {} checksum errors, {} bytes \
                 discarded, {} foreign frames{}",
                self.rejected,
                self.checksum_errors,
                self.discarded_bytes,
                self.foreign,
                if self.rejected_ids.is_empty() {
                    String::new()
                } else {
                    format!("; ids {}", Self::ids(&self.rejected_ids))
                }
            );
            let fix = match transport {
                Transport::Serial => {
                    "bytes arrive but no SCOUT frame: the wrong baud rate (the chassis speaks \
                     115200 8N1), another device on this port, or a CAN adapter (use --slcan)"
                }
                Transport::Slcan => {
                    "lines arrive but no SCOUT frame: the adapter's bitrate (500k), or not an \
                     slcan adapter (a plain RS232 link is --serial)"
                }
                Transport::Can | Transport::GsUsb | Transport::Sim => {
                    "frames arrive but none of SCOUT v1: another device on the bus, or the \
                     wrong bitrate"
                }
            };
            Check::fail("traffic", what, fix)
        } else {
            let rate = valid as f64 / window.as_secs_f64().max(1e-3);
            let mut ids = self.frames.clone();
            ids.extend(self.frames_v2.iter().map(|(id, count)| (*id, *count)));
            Check::pass(
                "traffic",
                format!(
                    "{valid} frames in {window:.1?} ({rate:.0}/s): {}",
                    Self::ids(&ids)
                ),
            )
        }
    }

    /// Which protocol the feedback proves.
    fn protocol_check(&self, now: Duration, v2_ids: &BTreeMap<u16, u64>) -> Check {
        match self.version.detection(now) {
            Detection::Found(Protocol::V1) => Check::pass(
                "protocol",
                format!(
                    "v1 ({} seen): scout-gateway --protocol v1 or auto",
                    self.version.ids(Protocol::V1)
                ),
            ),
            Detection::Found(Protocol::V2) => Check::pass(
                "protocol",
                format!(
                    "v2, a SCOUT 2.0 or MINI ({} seen): scout-gateway --protocol v2 or auto (it \
                     takes the command mode, 0x421, when a client drives)",
                    self.version.ids(Protocol::V2)
                ),
            ),
            Detection::Both => Check::fail(
                "protocol",
                format!(
                    "feedback of both protocols: v1 {}, v2 {}",
                    self.version.ids(Protocol::V1),
                    self.version.ids(Protocol::V2)
                ),
                "two chassis, or another node using their ids, on one bus: take the other \
                 node off (scout-gateway refuses such a bus)",
            ),
            Detection::Listening if !v2_ids.is_empty() => Check::fail(
                "protocol",
                format!("protocol v2 ids ({}) only briefly", Self::ids(v2_ids)),
                "listen longer (--window), the chassis' feedback comes every 20 ms",
            ),
            Detection::Listening => Check::fail(
                "protocol",
                "no feedback that tells the protocol (v1's 0x151, v2's 0x211/0x221)",
                "a chassis sends its feedback every 20 ms: check the ids above, the wiring and \
                 the bitrate",
            ),
        }
    }

    /// Checksum errors, rejected and foreign frames.
    fn errors_check(&self) -> Check {
        let valid = self.valid_frames();
        let bad = self.checksum_errors + self.rejected + self.foreign;
        let total = valid + bad;
        if bad == 0 {
            return Check::pass("errors", "no checksum errors or rejected frames");
        }
        let detail = format!(
            "{} checksum errors, {} rejected, {} foreign of {total} frames{}",
            self.checksum_errors,
            self.rejected,
            self.foreign,
            if self.rejected_ids.is_empty() {
                String::new()
            } else {
                format!("; rejected ids {}", Self::ids(&self.rejected_ids))
            }
        );
        let fix = "noise or another device: check the wiring and its shield, the \
                       termination (CAN), and what else is on the bus";
        if bad * 20 > total {
            Check::fail("errors", detail, fix)
        } else {
            Check::warn("errors", detail, fix)
        }
    }

    /// Commands from another host on the link.
    fn other_host_check(&self) -> Check {
        if self.other_host_commands > 0 {
            Check::fail(
                "other-host",
                format!(
                    "{} motion or light commands from another host (0x130/0x140)",
                    self.other_host_commands
                ),
                "another program commands this chassis: stop it (two commanders fight, and \
                 the gateway cannot arbitrate what it does not send)",
            )
        } else {
            Check::pass("other-host", "no other host sends commands")
        }
    }
}

/// The check of a battery at `volts`.
fn battery_check(volts: f64) -> Check {
    if volts < LOW_BATTERY {
        Check::warn(
            "chassis.battery",
            format!("{volts:.1} V"),
            "charge the battery (the chassis faults at 22 V)",
        )
    } else {
        Check::pass("chassis.battery", format!("{volts:.1} V"))
    }
}

/// A protocol v2 chassis' own state from its 0x211 (and 0x241, when the RC transmitter is on):
/// e-stop, who controls it and what the host must do (0x421), the RC's switches, errors,
/// battery (protocol-v2-notes 5).
pub fn chassis_checks_v2(state: &SystemStateV2, rc: Option<&RcStateV2>) -> Vec<Check> {
    let mut checks = Vec::new();
    checks.push(match state.state {
        ChassisState::Normal => Check::pass("chassis.estop", "state normal"),
        ChassisState::EStop => Check::fail(
            "chassis.estop",
            "the chassis reports its e-stop",
            "release the e-stop buttons on the chassis; on SCOUT V2.5 and newer the RC's SWA down \
             is a wireless e-stop too (put it up); then `scout release` for the gateway's stop",
        ),
        ChassisState::Exception | ChassisState::Unknown(_) => Check::fail(
            "chassis.estop",
            format!("the chassis reports state {}", state.state.name()),
            "a system exception (seen after the RC and the host fought over the chassis with an \
             e-stop between): power-cycle the chassis",
        ),
    });
    checks.push(match state.control_mode {
        ControlModeV2::Can => {
            Check::pass("chassis.control", "CAN command mode: the host may drive")
        }
        ControlModeV2::Standby => Check::pass(
            "chassis.control",
            "standby, as after power-on: a v2 chassis obeys nothing but the control-mode frame \
             until the host sends 0x421 [01]; scout-gateway sends it when a client takes control \
             and drives (by hand: `cansend can0 421#01`)",
        ),
        ControlModeV2::Rc => Check::warn(
            "chassis.control",
            "control mode rc: the RC transmitter holds the chassis",
            "give control to the host: SWB up (command mode; middle is manual RC), or switch the \
             RC off, then 0x421 [01] again; the gateway never fights the RC",
        ),
        ControlModeV2::Uart | ControlModeV2::Unknown(_) => Check::warn(
            "chassis.control",
            format!(
                "control mode {} (raw {}; firmware before late 2023 numbered 0 as RC)",
                state.control_mode.name(),
                state.control_mode.raw()
            ),
            "the host takes CAN control with 0x421 [01]",
        ),
    });
    checks.push(match rc {
        None => Check::skip("chassis.rc", "no RC frame (0x241): the transmitter is off"),
        Some(rc) if rc.swa == SwitchPosition::Down => Check::fail(
            "chassis.rc",
            "SWA is down: a wireless e-stop on SCOUT V2.5 and newer",
            "put SWA up",
        ),
        Some(rc) if rc.swb != SwitchPosition::Up => Check::warn(
            "chassis.rc",
            format!("SWB is {}: the RC drives (manual)", rc.swb.name()),
            "put SWB up to give the chassis to the host (command mode)",
        ),
        Some(_) => Check::pass("chassis.rc", "SWA up, SWB up (command mode)"),
    });
    let named: Vec<&str> = state.errors.names().collect();
    let unknown = state.errors.unknown();
    checks.push(match (named.is_empty(), unknown) {
        (true, 0) => Check::pass("chassis.faults", "no error bits"),
        (false, _) => Check::fail(
            "chassis.faults",
            format!(
                "error bits 0x{:04X}: {}{}",
                state.errors.0,
                named.join(", "),
                if unknown == 0 {
                    String::new()
                } else {
                    format!(" and unknown bits 0x{unknown:04X}")
                }
            ),
            "remove the cause (the motors' cables, the battery, the RC link), then clear with \
             0x441 [00]",
        ),
        (true, unknown) => Check::warn(
            "chassis.faults",
            format!(
                "error bits 0x{unknown:04X} that no source names for a SCOUT (a Bunker Mini \
                 reports 0x0080 in e-stop)"
            ),
            "read them with the e-stop and RC checks above; the documents disagree on these bits",
        ),
    });
    checks.push(battery_check(state.battery_voltage()));
    checks
}

/// The chassis' own state from its 0x151: e-stop, who controls it, faults, battery.
pub fn chassis_checks(status: Option<&SystemStatus>) -> Vec<Check> {
    let Some(status) = status else {
        return [
            "chassis.estop",
            "chassis.control",
            "chassis.faults",
            "chassis.battery",
        ]
        .into_iter()
        .map(|name| Check::skip(name, "no 0x151 system status received"))
        .collect();
    };
    let mut checks = Vec::new();
    checks.push(match status.state {
        ChassisState::Normal => Check::pass("chassis.estop", "state normal"),
        ChassisState::EStop => Check::fail(
            "chassis.estop",
            "the chassis reports its e-stop",
            "release the e-stop button on the chassis (turn it), or the RC's stop switch; then \
             `scout release` for the gateway's stop",
        ),
        ChassisState::Exception | ChassisState::Unknown(_) => Check::fail(
            "chassis.estop",
            format!("the chassis reports state {}", status.state.name()),
            "a system exception: see chassis.faults; power-cycle the chassis if it persists",
        ),
    });
    checks.push(match status.control_mode {
        ControlMode::Can | ControlMode::Serial => Check::pass(
            "chassis.control",
            format!(
                "command mode {}: the host may drive",
                status.control_mode.name()
            ),
        ),
        ControlMode::Rc | ControlMode::Unknown(_) => Check::warn(
            "chassis.control",
            format!(
                "control mode {}: the RC transmitter holds the chassis",
                status.control_mode.name()
            ),
            "give control to the host: the RC's mode switch to command mode (or switch the RC \
             off); the gateway never fights the RC",
        ),
    });
    let faults: Vec<_> = status.faults.iter().collect();
    checks.push(if faults.is_empty() {
        Check::pass("chassis.faults", "no fault bits")
    } else {
        let names = faults
            .iter()
            .map(|f| f.name())
            .collect::<Vec<_>>()
            .join(", ");
        let latched = faults.iter().any(|f| f.severity() == Severity::Protection);
        Check::fail(
            "chassis.faults",
            format!("fault bits 0x{:04X}: {names}", status.faults.0),
            if latched {
                "a latched protection: remove the cause (let drivers cool, lighten the load), \
                 then `scout clear-fault all`"
            } else {
                "the chassis reports it while the cause lasts: check the motors' cables and the \
                 battery; `scout clear-fault` for latched ones"
            },
        )
    });
    checks.push(battery_check(status.battery_voltage()));
    checks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::Verdict;
    use scout_protocol::link::RxError;
    use scout_protocol::{Counted, FaultBits};

    fn verdicts(checks: &[Check]) -> Vec<(&'static str, Verdict)> {
        checks.iter().map(|c| (c.name, c.verdict)).collect()
    }

    fn status(state: ChassisState, mode: ControlMode, faults: u16, decivolts: u16) -> RxEvent {
        RxEvent::Message(Counted {
            message: Message::SystemStatus(SystemStatus {
                state,
                control_mode: mode,
                battery_decivolts: decivolts,
                faults: FaultBits(faults),
            }),
            count: 0,
        })
    }

    const MS: Duration = Duration::from_millis(1);
    const WINDOW: Duration = Duration::from_secs(1);

    #[test]
    fn a_healthy_chassis_passes_everything() {
        let mut traffic = Traffic::new();
        for i in 0..50 {
            traffic.handle(
                &status(ChassisState::Normal, ControlMode::Can, 0, 250),
                i * 20 * MS,
            );
        }
        let checks = traffic.checks(Transport::Can, WINDOW, WINDOW);
        assert!(
            checks.iter().all(|c| c.verdict == Verdict::Pass),
            "{checks:#?}"
        );
        assert!(
            checks[0].detail.contains("0x151 x50"),
            "{}",
            checks[0].detail
        );
    }

    #[test]
    fn silence_fails_with_what_to_check_and_stops_there() {
        let checks = Traffic::new().checks(Transport::Serial, WINDOW, WINDOW);
        assert_eq!(verdicts(&checks), [("traffic", Verdict::Fail)]);
        assert!(
            checks[0]
                .fix
                .as_deref()
                .is_some_and(|f| f.contains("115200"))
        );
    }

    #[test]
    fn garbage_fails_as_the_wrong_baud_rate() {
        let mut traffic = Traffic::new();
        traffic.discarded_bytes = 300;
        let checks = traffic.checks(Transport::Serial, WINDOW, WINDOW);
        assert_eq!(checks[0].verdict, Verdict::Fail);
        assert!(
            checks[0].fix.as_deref().is_some_and(|f| f.contains("baud")),
            "{checks:#?}"
        );
    }

    #[test]
    fn v2_ids_without_0x151_are_protocol_v2_with_how_to_start_the_gateway() {
        let mut traffic = Traffic::new();
        for i in 0..60 {
            let error = RxError::Can(scout_protocol::can::CanError::UnknownId { id: 0x211 });
            traffic.handle(&RxEvent::Rejected(error), i * 20 * MS);
        }
        let checks = traffic.checks(Transport::Slcan, WINDOW, 1200 * MS);
        let protocol = checks
            .iter()
            .find(|c| c.name == "protocol")
            .expect("protocol");
        assert_eq!(protocol.verdict, Verdict::Pass);
        assert!(protocol.detail.contains("0x211"), "{protocol:?}");
        assert!(protocol.detail.contains("--protocol v2"), "{protocol:?}");
    }

    #[test]
    fn a_chassis_that_steers_or_moves_sideways_is_named() {
        let find = |traffic: &Traffic| {
            let checks = traffic.checks(Transport::Can, WINDOW, WINDOW);
            checks
                .into_iter()
                .find(|c| c.name == "model")
                .expect("model")
        };
        let motion = |lateral_mm_s, steering_mrad| {
            RxEvent::V2(MessageV2::MotionState(scout_protocol::v2::MotionV2 {
                lateral_mm_s,
                steering_mrad,
                ..Default::default()
            }))
        };
        let mut traffic = Traffic::new();
        traffic.handle(&motion(0, 0), Duration::ZERO);
        assert_eq!(find(&traffic).verdict, Verdict::Pass);
        // Sideways: an OMNI, or a Ranger.
        traffic.handle(&motion(120, 0), 20 * MS);
        let check = find(&traffic);
        assert_eq!(check.verdict, Verdict::Warn, "{check:?}");
        assert!(
            check
                .fix
                .as_deref()
                .is_some_and(|fix| fix.contains("--model scout-mini-omni")),
            "{check:?}"
        );
        // A motion mode: a Ranger, named as the model to give.
        let mode = scout_protocol::v2::MotionModeStateV2::new(
            scout_protocol::v2::MotionModeV2::DualAckermann,
            false,
        );
        traffic.handle(&RxEvent::V2(MessageV2::MotionModeState(mode)), 40 * MS);
        traffic.handle(&RxEvent::V2(MessageV2::MotionModeState(mode)), 60 * MS);
        let check = find(&traffic);
        assert_eq!(check.verdict, Verdict::Warn, "{check:?}");
        assert!(
            check
                .detail
                .contains("a sideways speed (0x221), a motion mode (0x291)"),
            "{check:?}"
        );
        let fix = check.fix.as_deref().unwrap_or_default();
        assert!(
            fix.contains("--model ranger-mini-2 or --model ranger-mini-3") && !fix.contains("omni"),
            "{check:?}"
        );
        // A parking brake reported locked: a Hunter 2.0, not a Hunter SE.
        let mut traffic = Traffic::new();
        let braked = SystemStateV2 {
            state: ChassisState::Normal,
            control_mode: ControlModeV2::Standby,
            battery_decivolts: 259,
            errors: scout_protocol::v2::ErrorBitsV2(0),
            reserved: 1,
            count: 0,
        };
        traffic.handle(&RxEvent::V2(MessageV2::SystemState(braked)), Duration::ZERO);
        let check = find(&traffic);
        assert_eq!(check.verdict, Verdict::Warn, "{check:?}");
        assert!(check.detail.contains("a Hunter 2.0"), "{check:?}");
        let fix = check.fix.as_deref().unwrap_or_default();
        assert!(
            fix.contains("--model hunter2:") && !fix.contains("hunter-se"),
            "{check:?}"
        );
    }

    #[test]
    fn feedback_of_both_protocols_fails_with_the_ids_of_each() {
        let mut traffic = Traffic::new();
        traffic.handle(
            &status(ChassisState::Normal, ControlMode::Can, 0, 250),
            Duration::ZERO,
        );
        let error = RxError::Can(scout_protocol::can::CanError::UnknownId { id: 0x221 });
        traffic.handle(&RxEvent::Rejected(error), 100 * MS);
        let checks = traffic.checks(Transport::Can, WINDOW, 1200 * MS);
        let protocol = checks
            .iter()
            .find(|c| c.name == "protocol")
            .expect("protocol");
        assert_eq!(protocol.verdict, Verdict::Fail);
        assert!(
            protocol.detail.contains("0x151") && protocol.detail.contains("0x221"),
            "{protocol:?}"
        );
    }

    #[test]
    fn the_chassis_estop_rc_faults_and_a_low_battery_are_named_with_their_fixes() {
        let mut traffic = Traffic::new();
        traffic.handle(
            &status(ChassisState::EStop, ControlMode::Rc, 0x0040, 225),
            Duration::ZERO,
        );
        let checks = traffic.checks(Transport::Serial, WINDOW, WINDOW);
        let find = |name| checks.iter().find(|c| c.name == name).expect(name);
        assert_eq!(find("chassis.estop").verdict, Verdict::Fail);
        assert_eq!(find("chassis.control").verdict, Verdict::Warn);
        assert!(
            find("chassis.control")
                .fix
                .as_deref()
                .is_some_and(|f| f.contains("RC"))
        );
        let faults = find("chassis.faults");
        assert_eq!(faults.verdict, Verdict::Fail);
        assert!(
            faults
                .fix
                .as_deref()
                .is_some_and(|f| f.contains("clear-fault")),
            "{faults:?}"
        );
        assert_eq!(find("chassis.battery").verdict, Verdict::Warn);
    }

    #[test]
    fn a_v2_chassis_in_standby_with_the_rc_in_manual_says_what_to_do() {
        use scout_protocol::v2::ErrorBitsV2;
        let mut traffic = Traffic::new();
        let state = SystemStateV2 {
            state: ChassisState::Normal,
            control_mode: ControlModeV2::Standby,
            battery_decivolts: 259,
            errors: ErrorBitsV2(0x0080),
            reserved: 0,
            count: 0,
        };
        let rc = RcStateV2 {
            swa: SwitchPosition::Up,
            swb: SwitchPosition::Middle,
            swc: SwitchPosition::Up,
            swd: SwitchPosition::Up,
            right_horizontal: 0,
            right_vertical: 0,
            left_vertical: 0,
            left_horizontal: 0,
            knob: 0,
            reserved: 0,
            count: 0,
        };
        for i in 0..60 {
            traffic.handle(&RxEvent::V2(MessageV2::SystemState(state)), i * 20 * MS);
            traffic.handle(&RxEvent::V2(MessageV2::RcState(rc)), i * 20 * MS);
        }
        let checks = traffic.checks(Transport::Can, WINDOW, 1200 * MS);
        let find = |name| checks.iter().find(|c| c.name == name).expect(name);
        assert_eq!(find("traffic").verdict, Verdict::Pass, "{checks:#?}");
        assert!(find("traffic").detail.contains("0x211 x60"), "{checks:#?}");
        assert_eq!(find("protocol").verdict, Verdict::Pass);
        let control = find("chassis.control");
        assert_eq!(
            control.verdict,
            Verdict::Pass,
            "standby is how a v2 chassis starts"
        );
        assert!(control.detail.contains("421#01"), "{control:?}");
        assert_eq!(find("chassis.rc").verdict, Verdict::Warn);
        assert!(
            find("chassis.rc")
                .fix
                .as_deref()
                .is_some_and(|f| f.contains("SWB up"))
        );
        assert_eq!(
            find("chassis.faults").verdict,
            Verdict::Warn,
            "0x0080 is unknown"
        );
        assert_eq!(find("chassis.battery").verdict, Verdict::Pass);
        assert_eq!(
            find("errors").verdict,
            Verdict::Pass,
            "v2 frames are valid, not rejected"
        );
    }

    #[test]
    fn another_host_sending_0x130_fails() {
        let mut traffic = Traffic::new();
        traffic.handle(
            &status(ChassisState::Normal, ControlMode::Can, 0, 250),
            Duration::ZERO,
        );
        traffic.handle(
            &RxEvent::Message(Counted {
                message: Message::MotionCommand(scout_protocol::MotionCommand::stop(
                    ControlMode::Can,
                )),
                count: 0,
            }),
            MS,
        );
        let checks = traffic.checks(Transport::Can, WINDOW, WINDOW);
        let other = checks
            .iter()
            .find(|c| c.name == "other-host")
            .expect("other-host");
        assert_eq!(other.verdict, Verdict::Fail);
    }
}
