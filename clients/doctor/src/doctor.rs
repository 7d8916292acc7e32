//! Every check in order: the device, the CAN interface, opening the port and listening to it
//! (or, when a gateway holds it, the same questions asked of that gateway), the chassis' state,
//! the robot's gateway, the robot through zenoh when asked, and leftovers of dead processes in
//! shared memory.

use std::path::Path;
use std::time::Duration;

use scout_gateway::device::DeviceSpec;
use scout_interface::robot::{Program, RobotName};
use scout_interface::services;

use crate::check::{Check, Verdict};
use crate::gateway::{self, is_no_gateway};
use crate::port::{self, Opened};
use crate::{can, remote, usb};

/// What to check.
#[derive(Debug, Clone)]
pub struct Options {
    /// The robot (gateway) name.
    pub robot: String,
    /// The port to check, if any.
    pub port: Option<DeviceSpec>,
    /// How long to listen.
    pub window: Duration,
    /// A zenoh endpoint to read the robot's state through and measure, if asked.
    pub zenoh: Option<String>,
    /// The zenoh configuration file for it (TLS), if any.
    pub zenoh_config: Option<String>,
}

/// Whether the gateway's device names the same device as `spec`.
fn same_device(spec: &DeviceSpec, device: &str) -> bool {
    match spec {
        DeviceSpec::Serial(path) | DeviceSpec::Slcan(path) => {
            let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_owned());
            canonical(path) == canonical(Path::new(device))
        }
        DeviceSpec::Can(interface) => interface == device,
        DeviceSpec::GsUsb { .. } => spec.name() == device,
        DeviceSpec::Sim { .. } => false,
    }
}

/// Runs the checks, handing each to `report` as soon as it is made.
pub fn run(options: &Options, report: &mut dyn FnMut(&Check)) -> Vec<Check> {
    let mut out = Report {
        report,
        checks: Vec::new(),
    };
    // First: connecting to a gateway cleans up after dead processes, and this check says what
    // they left.
    out.emit(vec![leftovers()]);
    // The USB-CAN adapters: the Jetson's cases (no driver in its kernel, the adapter as can2).
    let adapters = usb::found();
    out.emit(usb::judge(
        &adapters,
        usb::module(),
        &usb::interfaces(),
        usb::Asked::of(options.port.as_ref()),
    ));
    // With no port named, the interface a driver made of each adapter is checked as --can
    // would (down, another bit rate, bus-off), each with the command that fixes it.
    if options.port.is_none() {
        for interface in adapters
            .iter()
            .filter(|adapter| adapter.driver.is_some())
            .flat_map(|adapter| &adapter.interfaces)
        {
            out.emit(can::inspect(interface));
        }
    }
    let gateway_checked = match &options.port {
        Some(spec) => check_port(spec, options, &mut out),
        None => false,
    };
    if !gateway_checked {
        check_gateway(options, &mut out);
    }
    if let Some(endpoint) = &options.zenoh {
        out.emit(remote::inspect(
            &options.robot,
            endpoint,
            options.zenoh_config.as_deref(),
            options.window,
        ));
    }
    out.checks
}

/// The checks made so far, each reported as it is made.
struct Report<'a> {
    report: &'a mut dyn FnMut(&Check),
    checks: Vec<Check>,
}

impl Report<'_> {
    fn emit(&mut self, new: Vec<Check>) {
        for check in new {
            (self.report)(&check);
            self.checks.push(check);
        }
    }
}

/// What dead processes left in shared memory (removed by this check).
fn leftovers() -> Check {
    match services::remove_dead_nodes() {
        Ok(removed) if removed.is_empty() => {
            Check::pass("iceoryx2", "no resources left by dead processes")
        }
        Ok(removed) => {
            let gateways: Vec<String> = removed
                .iter()
                .filter_map(|node| RobotName::of_node(node, Program::Gateway))
                .map(String::from)
                .collect();
            let what = if gateways.is_empty() {
                String::new()
            } else {
                format!(
                    ", among them the gateway of robot {} (it was killed or crashed: its next \
                     start latches gateway_start until someone checks the robot and releases it)",
                    gateways.join(", ")
                )
            };
            Check::warn(
                "iceoryx2",
                format!(
                    "removed the shared-memory resources of {} dead processes ({}){what}",
                    removed.len(),
                    removed
                        .iter()
                        .map(|name| if name.is_empty() {
                            "unnamed"
                        } else {
                            name.as_str()
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                "nothing more to do; a gateway or client killed (SIGKILL, power loss) leaves them",
            )
        }
        Err(error) => Check::warn(
            "iceoryx2",
            error.to_string(),
            "the shared-memory directory must be usable by this user (SCOUT_IPC_DIR, or the group of /run/scout)",
        ),
    }
}

/// The port itself: the device, then what it carries, or, when a gateway holds it, the
/// gateway through which it is checked. Whether the gateway was checked so.
fn check_port(spec: &DeviceSpec, options: &Options, out: &mut Report<'_>) -> bool {
    let robot = &options.robot;
    let device = match spec {
        DeviceSpec::Serial(path) | DeviceSpec::Slcan(path) => port::tty_checks(path),
        DeviceSpec::Can(interface) => can::inspect(interface),
        DeviceSpec::GsUsb { .. } | DeviceSpec::Sim { .. } => Vec::new(),
    };
    let usable = !device.iter().any(|check| {
        check.verdict == Verdict::Fail
            && matches!(check.name, "device" | "can.interface" | "can.up")
    });
    out.emit(device);
    if usable {
        let mut opened = Vec::new();
        match port::listen(spec, options.window, &mut opened) {
            Opened::Listened(tally) => {
                out.emit(opened);
                out.emit(tally.checks(spec.transport(), options.window, options.window));
            }
            Opened::Failed => out.emit(opened),
            Opened::Held(holder) => {
                let pid =
                    holder.map_or_else(|| "pid unknown".to_owned(), |pid| format!("pid {pid}"));
                match gateway::inspect(robot, options.window) {
                    Ok(found) if same_device(spec, &found.device) => {
                        out.emit(vec![Check::pass(
                            "port",
                            format!(
                                "held by the gateway of robot {robot} ({pid}): checked \
                                     through it"
                            ),
                        )]);
                        out.emit(found.checks);
                        return true;
                    }
                    Ok(_) | Err(_) => out.emit(vec![Check::fail(
                        "port",
                        format!(
                            "{} is held by another scout-gateway ({pid}), not robot \
                                 {robot}'s",
                            spec.name()
                        ),
                        "stop that gateway (`systemctl stop scout-gateway` or kill the \
                             pid), or run `scout doctor --name` with its robot name",
                    )]),
                }
            }
        }
    }
    false
}

/// The gateway of the robot, or why there is none.
fn check_gateway(options: &Options, out: &mut Report<'_>) {
    let robot = &options.robot;
    match gateway::inspect(robot, options.window) {
        Ok(found) => out.emit(found.checks),
        Err(error) if is_no_gateway(&error) => {
            let check = match &options.port {
                Some(spec) => Check::warn(
                    "gateway",
                    format!("no gateway serves robot {robot}: the port was checked directly"),
                    format!(
                        "when the checks pass: scout-gateway --{} {} --name {robot}",
                        match spec {
                            DeviceSpec::Serial(_) => "serial",
                            DeviceSpec::Slcan(_) => "slcan",
                            DeviceSpec::Can(_) => "can",
                            DeviceSpec::GsUsb { .. } => "gs-usb",
                            DeviceSpec::Sim { .. } => "sim",
                        },
                        spec.name()
                    ),
                ),
                None => Check::fail(
                    "gateway",
                    format!("no gateway serves robot {robot}"),
                    format!(
                        "start one (scout-gateway --serial DEV --name {robot}, or --sim), or \
                         give the port (--serial, --slcan, --can) to check it directly"
                    ),
                ),
            };
            out.emit(vec![check]);
        }
        Err(error) => out.emit(vec![Check::fail(
            "gateway",
            format!("reading the gateway of robot {robot}: {error}"),
            "see the error; `scout status` says more",
        )]),
    }
}
