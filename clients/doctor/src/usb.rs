//! gs_usb USB-CAN adapters on the USB bus, and what a Jetson owner needs to know about them: a
//! driver missing from the kernel, an adapter with none bound, the adapter named `can2` because
//! the computer's own controllers took `can0` and `can1`. The verdicts are sans-IO ([`judge`]).

use scout_gateway::device::DeviceSpec;

use crate::check::Check;

/// An adapter as seen on the bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seen {
    /// Ids, place and serial number, as people read them.
    pub identity: String,
    /// Its serial number.
    pub serial: Option<String>,
    /// The kernel driver bound to its interface.
    pub driver: Option<String>,
    /// The CAN interfaces that driver made of it.
    pub interfaces: Vec<String>,
}

/// Whether the running kernel has the gs_usb driver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Module {
    /// Loaded (or built in).
    Loaded,
    /// Present as a module, not loaded.
    Available,
    /// Not in this kernel (JetPack 6's, for one).
    Missing,
}

/// What the user asked to check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Asked<'a> {
    /// `--gs-usb [SERIAL]`.
    GsUsb(Option<&'a str>),
    /// `--can IFACE`.
    Can(&'a str),
    /// No port: the adapters are reported only if there are some.
    Nothing,
}

impl<'a> Asked<'a> {
    /// What `spec` asks.
    pub fn of(spec: Option<&'a DeviceSpec>) -> Self {
        match spec {
            Some(DeviceSpec::GsUsb { serial, .. }) => Self::GsUsb(serial.as_deref()),
            Some(DeviceSpec::Can(interface)) => Self::Can(interface),
            Some(DeviceSpec::Serial(_) | DeviceSpec::Slcan(_) | DeviceSpec::Sim { .. }) | None => {
                Self::Nothing
            }
        }
    }
}

/// The checks, from what is on the bus (`found`), the kernel's `module`, and the CAN interfaces
/// the system has (`interfaces`, for `can0`/`can1` taken by other controllers).
pub fn judge(
    found: &[Seen],
    module: Module,
    interfaces: &[String],
    asked: Asked<'_>,
) -> Vec<Check> {
    const NAME: &str = "usb.adapter";
    if found.is_empty() {
        return match asked {
            Asked::GsUsb(_) => vec![Check::fail(
                NAME,
                "no gs_usb USB-CAN adapter is plugged in",
                "plug it in (`lsusb` lists it: candleLight's id is 1d50:606f)",
            )],
            Asked::Can(_) | Asked::Nothing => Vec::new(),
        };
    }
    let mut checks = Vec::new();
    if let Asked::GsUsb(None) = asked
        && found.len() > 1
    {
        checks.push(Check::fail(
            NAME,
            format!("{} gs_usb adapters are plugged in", found.len()),
            format!(
                "name one by its serial number: {}",
                found
                    .iter()
                    .map(|a| format!("--gs-usb {}", a.serial.as_deref().unwrap_or("?")))
                    .collect::<Vec<_>>()
                    .join(" or ")
            ),
        ));
    }
    let own_controllers: Vec<&String> = interfaces
        .iter()
        .filter(|name| name.starts_with("can"))
        .filter(|name| !found.iter().any(|a| a.interfaces.contains(name)))
        .collect();
    for adapter in found {
        let serial = adapter.serial.as_deref().unwrap_or("?");
        let check = match (&adapter.driver, adapter.interfaces.first()) {
            (None, _) => {
                let (what, fix) = match module {
                    Module::Missing => (
                        "this kernel has no gs_usb driver (as JetPack 6's)",
                        format!(
                            "no kernel rebuild needed: scout-gateway --gs-usb {serial} drives \
                             it in user space"
                        ),
                    ),
                    Module::Available => (
                        "the gs_usb module is not loaded",
                        format!(
                            "scout-gateway --gs-usb {serial} drives it in user space; or \
                             `sudo modprobe gs_usb` makes it a CAN interface for --can"
                        ),
                    ),
                    Module::Loaded => (
                        "no driver is bound to it",
                        format!("scout-gateway --gs-usb {serial} drives it in user space"),
                    ),
                };
                match asked {
                    Asked::GsUsb(_) => Check::pass(
                        NAME,
                        format!("{}: no kernel driver, free for --gs-usb", adapter.identity),
                    ),
                    Asked::Can(_) | Asked::Nothing => {
                        Check::warn(NAME, format!("{}: {what}", adapter.identity), fix)
                    }
                }
            }
            // A program in user space (a gateway on --gs-usb, most often) holds it.
            (Some(driver), _) if driver == "usbfs" => {
                let detail = format!(
                    "{}: held through usbfs by a program in user space (a scout-gateway \
                     --gs-usb?)",
                    adapter.identity
                );
                match asked {
                    Asked::GsUsb(_) => Check::warn(
                        NAME,
                        detail,
                        "`scout doctor` alone checks the robot through its gateway; stop the \
                         other program to check the adapter here",
                    ),
                    Asked::Can(_) | Asked::Nothing => Check::pass(NAME, detail),
                }
            }
            (Some(driver), interface) => {
                let interface = interface.map_or("no interface", String::as_str);
                let named = if own_controllers.is_empty() || interface == "no interface" {
                    String::new()
                } else {
                    format!(
                        "; {} {} the computer's own CAN controller{}, not the adapter",
                        own_controllers
                            .iter()
                            .map(|s| s.as_str())
                            .collect::<Vec<_>>()
                            .join(" and "),
                        if own_controllers.len() == 1 {
                            "is"
                        } else {
                            "are"
                        },
                        if own_controllers.len() == 1 { "" } else { "s" }
                    )
                };
                let detail = format!(
                    "{}: the kernel's {driver} driver made it {interface}{named}",
                    adapter.identity
                );
                match asked {
                    Asked::GsUsb(_) => Check::warn(
                        NAME,
                        detail,
                        format!(
                            "use --can {interface} (its driver works), or --gs-usb-detach to \
                             take it from the driver"
                        ),
                    ),
                    Asked::Can(checked) if checked != interface => Check::warn(
                        NAME,
                        detail,
                        format!("the adapter is {interface}: scout doctor --can {interface}"),
                    ),
                    Asked::Can(_) | Asked::Nothing => Check::pass(NAME, detail),
                }
            }
        };
        checks.push(check);
    }
    checks
}

/// The adapters plugged in now.
pub fn found() -> Vec<Seen> {
    scout_gateway::device::gs_usb_adapters()
        .unwrap_or_default()
        .iter()
        .map(|adapter| Seen {
            identity: adapter.identity(),
            serial: adapter.serial().map(str::to_owned),
            driver: adapter.driver(),
            interfaces: adapter.net_interfaces(),
        })
        .collect()
}

/// Whether the running kernel has gs_usb: `/sys/module`, else its `modules.builtin` and
/// `modules.dep`.
pub fn module() -> Module {
    if std::path::Path::new("/sys/module/gs_usb").exists() {
        return Module::Loaded;
    }
    let release = std::fs::read_to_string("/proc/sys/kernel/osrelease").unwrap_or_default();
    let dir = std::path::Path::new("/lib/modules").join(release.trim());
    let lists = |file: &str| {
        std::fs::read_to_string(dir.join(file))
            .is_ok_and(|text| text.lines().any(|line| line.contains("/gs_usb.ko")))
    };
    if lists("modules.builtin") {
        Module::Loaded
    } else if lists("modules.dep") {
        Module::Available
    } else {
        Module::Missing
    }
}

/// The network interfaces the system has.
pub fn interfaces() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir("/sys/class/net")
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::Verdict;

    fn adapter(serial: &str, driver: Option<&str>, interfaces: &[&str]) -> Seen {
        Seen {
            identity: format!("1d50:606f at 1-2 (serial {serial})"),
            serial: Some(serial.into()),
            driver: driver.map(str::to_owned),
            interfaces: interfaces.iter().map(|s| (*s).to_owned()).collect(),
        }
    }

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn a_jetson_without_the_driver_is_offered_the_user_space_transport() {
        let checks = judge(
            &[adapter("A1", None, &[])],
            Module::Missing,
            &names(&["can0", "can1", "lo"]),
            Asked::Nothing,
        );
        assert_eq!(checks.len(), 1);
        assert_eq!(checks[0].verdict, Verdict::Warn);
        assert!(
            checks[0].detail.contains("no gs_usb driver"),
            "{:?}",
            checks[0]
        );
        assert!(
            checks[0]
                .fix
                .as_deref()
                .unwrap_or("")
                .contains("--gs-usb A1"),
            "{:?}",
            checks[0]
        );
        let asked = judge(
            &[adapter("A1", None, &[])],
            Module::Missing,
            &[],
            Asked::GsUsb(None),
        );
        assert_eq!(asked[0].verdict, Verdict::Pass);
    }

    #[test]
    fn an_adapter_named_can2_is_told_from_the_computers_own_controllers() {
        let checks = judge(
            &[adapter("A1", Some("gs_usb"), &["can2"])],
            Module::Loaded,
            &names(&["can0", "can1", "can2", "eth0"]),
            Asked::Can("can0"),
        );
        assert_eq!(checks[0].verdict, Verdict::Warn);
        assert!(
            checks[0]
                .detail
                .contains("made it can2; can0 and can1 are the computer's own CAN controllers"),
            "{:?}",
            checks[0]
        );
        assert!(
            checks[0]
                .fix
                .as_deref()
                .unwrap_or("")
                .contains("--can can2"),
            "{:?}",
            checks[0]
        );
        let right = judge(
            &[adapter("A1", Some("gs_usb"), &["can2"])],
            Module::Loaded,
            &names(&["can0", "can1", "can2"]),
            Asked::Can("can2"),
        );
        assert_eq!(right[0].verdict, Verdict::Pass);
    }

    #[test]
    fn several_adapters_without_a_serial_number_fail_naming_each() {
        let checks = judge(
            &[adapter("A1", None, &[]), adapter("B2", None, &[])],
            Module::Available,
            &[],
            Asked::GsUsb(None),
        );
        assert_eq!(checks[0].verdict, Verdict::Fail);
        let fix = checks[0].fix.as_deref().unwrap_or("");
        assert!(
            fix.contains("--gs-usb A1") && fix.contains("--gs-usb B2"),
            "{fix}"
        );
    }

    #[test]
    fn a_bound_adapter_asked_for_in_user_space_names_its_interface_and_the_detach() {
        let checks = judge(
            &[adapter("A1", Some("gs_usb"), &["can0"])],
            Module::Loaded,
            &names(&["can0"]),
            Asked::GsUsb(Some("A1")),
        );
        assert_eq!(checks[0].verdict, Verdict::Warn);
        let fix = checks[0].fix.as_deref().unwrap_or("");
        assert!(
            fix.contains("--can can0") && fix.contains("--gs-usb-detach"),
            "{fix}"
        );
    }

    #[test]
    fn an_adapter_a_gateway_holds_in_user_space_is_no_kernel_driver() {
        let held = adapter("A1", Some("usbfs"), &[]);
        let checks = judge(
            std::slice::from_ref(&held),
            Module::Loaded,
            &[],
            Asked::Nothing,
        );
        assert_eq!(checks[0].verdict, Verdict::Pass);
        assert!(checks[0].detail.contains("usbfs"), "{:?}", checks[0]);
        let asked = judge(&[held], Module::Loaded, &[], Asked::GsUsb(Some("A1")));
        assert_eq!(asked[0].verdict, Verdict::Warn);
        assert!(
            !asked[0]
                .fix
                .as_deref()
                .unwrap_or("")
                .contains("--gs-usb-detach")
        );
    }

    #[test]
    fn nothing_plugged_in_fails_only_when_asked_for() {
        assert_eq!(
            judge(&[], Module::Missing, &[], Asked::GsUsb(None))[0].verdict,
            Verdict::Fail
        );
        assert!(judge(&[], Module::Missing, &[], Asked::Nothing).is_empty());
        assert!(judge(&[], Module::Loaded, &[], Asked::Can("can0")).is_empty());
    }
}
