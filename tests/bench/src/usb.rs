//! `scout-bench usb`: a gs_usb adapter emulated on USB (`scout-gs-usb-gadget` on `dummy_hcd`)
//! in front of the simulated chassis' CAN bus, the gateway reaching it three ways in one run:
//! the bus itself (SocketCAN on vcan, no USB), the kernel's gs_usb driver on the adapter
//! (`--can canN`), and the gateway's own user-space transport (`--gs-usb`). Needs root and a
//! kernel with vcan, dummy_hcd, libcomposite, usb_f_fs and gs_usb: the project's VM has them
//! (`tests/vm/run -- target/release/scout-bench usb`).

use std::io::{BufRead as _, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};

use crate::procs::command;
use crate::run::Rig;

/// The bus, the emulated adapter and the kernel's interface for it; torn down when dropped.
pub struct Set {
    bus: String,
    gadget: Child,
    serial: String,
    kernel_interface: String,
}

fn run(program: &str, args: &[&str]) -> anyhow::Result<()> {
    let output = Command::new(program)
        .args(args)
        .output()
        .with_context(|| format!("running {program}"))?;
    ensure!(
        output.status.success(),
        "`{program} {}` failed: {}",
        args.join(" "),
        String::from_utf8_lossy(&output.stderr).trim()
    );
    Ok(())
}

impl Set {
    /// Loads the modules, makes the bus and plugs the adapter in, bound to the kernel's driver
    /// and brought up at 500 kbit/s.
    pub fn set_up() -> anyhow::Result<Set> {
        for module in [
            &["vcan"][..],
            &["dummy_hcd"],
            &["libcomposite"],
            &["usb_f_fs"],
            &["gs_usb"],
        ] {
            run("modprobe", module).context(
                "scout-bench usb needs root and these modules: run it in the project's VM \
                 (tests/vm/run -- target/release/scout-bench usb)",
            )?;
        }
        let bus = format!("benchcan{}", std::process::id() % 10_000);
        run("ip", &["link", "add", &bus, "type", "vcan"])?;
        run("ip", &["link", "set", &bus, "up"])?;
        let serial = format!("BENCH{}", std::process::id());
        let mut gadget = command("scout-gs-usb-gadget")?
            .args(["--can", &bus, "--name", "benchgs", "--serial", &serial])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .context("starting scout-gs-usb-gadget")?;
        let mut line = String::new();
        BufReader::new(gadget.stdout.take().context("the gadget's output")?)
            .read_line(&mut line)?;
        ensure!(
            line.starts_with("ready"),
            "the emulated adapter did not start: {line:?}"
        );
        let mut set = Set {
            bus,
            gadget,
            serial,
            kernel_interface: String::new(),
        };
        set.kernel_interface = set.wait_interface()?;
        run(
            "ip",
            &[
                "link",
                "set",
                &set.kernel_interface,
                "type",
                "can",
                "bitrate",
                "500000",
            ],
        )?;
        run("ip", &["link", "set", &set.kernel_interface, "up"])?;
        Ok(set)
    }

    /// The CAN interface the kernel's driver made of the adapter.
    fn wait_interface(&self) -> anyhow::Result<String> {
        let deadline = Instant::now() + Duration::from_secs(30);
        while Instant::now() < deadline {
            for entry in std::fs::read_dir("/sys/bus/usb/devices")?.filter_map(Result::ok) {
                let path = entry.path();
                let serial = std::fs::read_to_string(path.join("serial")).unwrap_or_default();
                if serial.trim() != self.serial {
                    continue;
                }
                let name = entry.file_name().to_string_lossy().into_owned();
                if let Some(net) = std::fs::read_dir(path.join(format!("{name}:1.0/net")))
                    .ok()
                    .and_then(|mut e| e.next())
                    .and_then(Result::ok)
                {
                    return Ok(net.file_name().to_string_lossy().into_owned());
                }
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        bail!("the kernel's gs_usb driver made no CAN interface of the emulated adapter in 30 s")
    }

    /// The three ways, in the order they run (the user-space transport last: it takes the
    /// adapter from the kernel's driver).
    pub fn rigs(&self) -> [Rig; 3] {
        [
            Rig::Can {
                key: "can_vcan",
                label: "SocketCAN, vcan (no USB)",
                bus: self.bus.clone(),
                port: vec!["--can".into(), self.bus.clone()],
            },
            Rig::Can {
                key: "can_gs_usb_kernel",
                label: "gs_usb adapter, kernel driver (--can)",
                bus: self.bus.clone(),
                port: vec!["--can".into(), self.kernel_interface.clone()],
            },
            Rig::Can {
                key: "gs_usb_user_space",
                label: "gs_usb adapter, user space (--gs-usb)",
                bus: self.bus.clone(),
                port: vec![
                    "--gs-usb".into(),
                    self.serial.clone(),
                    "--gs-usb-detach".into(),
                ],
            },
        ]
    }
}

impl Drop for Set {
    fn drop(&mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.gadget.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let _ = self.gadget.wait();
        let _ = run("ip", &["link", "del", &self.bus]);
    }
}
