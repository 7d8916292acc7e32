//! The simulator's driver loop: the one place that touches the port and the clock. It feeds the
//! chassis model, plays the slcan adapter, and carries out the link-level fault injections.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use anyhow::Context;
use scout_protocol::slcan::{self, Bitrate, Slcan};
use scout_protocol::v2::MessageV2;
use scout_protocol::{CanFrame, Counted, Message, can, serial};
use serialport::{SerialPort, TTYPort};
use tracing::{info, warn};

use crate::chassis::{Chassis, Feedback, Injection, SimParams};
use crate::replay::Replay;
use crate::script::{HELP, SimCommand};
use scout_io::{Incoming, Port};
use scout_protocol::Transport;
use scout_protocol::link::{RxEvent, StreamFraming, decode_can, decode_can_v2};
pub use scout_protocol::version::Protocol;

/// How the simulator is reached and what it simulates.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// The transport it speaks.
    pub transport: Transport,
    /// The firmware's protocol.
    pub protocol: Protocol,
    /// For [`Transport::Can`]: the SocketCAN interface.
    pub can_interface: Option<String>,
    /// A symbolic link kept pointing at the pseudo-terminal (stable across `unplug`).
    pub link: Option<PathBuf>,
    /// The chassis model's parameters.
    pub params: SimParams,
    /// Seed of the garbage generator.
    pub seed: u64,
    /// A file to record the wire in, with CLOCK_BOOTTIME times (see [`Trace`]).
    pub trace: Option<PathBuf>,
    /// SCHED_FIFO priority of the simulator's loop (0: normal), so that what it measures is
    /// the gateway's timing, not its own scheduling.
    pub realtime_priority: u8,
    /// A gateway's black box to replay in place of the model's feedback.
    pub replay: Option<Replay>,
}

/// The wire as the chassis saw it, one line an event, times in CLOCK_BOOTTIME ns (shared by
/// every process on the host), flushed every feedback period, for benchmarks: `F NS` a feedback batch written, `C NS LINEAR
/// ANGULAR` a motion command read (m/s, rad/s), `A NS LINEAR` the chassis' actual speed when it
/// changes.
struct Trace {
    out: std::io::BufWriter<std::fs::File>,
    actual: f64,
}

impl Trace {
    fn create(path: &Path) -> anyhow::Result<Self> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("creating the trace file {}", path.display()))?;
        Ok(Self {
            out: std::io::BufWriter::new(file),
            actual: f64::NAN,
        })
    }

    fn now_ns() -> u64 {
        nix::time::clock_gettime(nix::time::ClockId::CLOCK_BOOTTIME)
            .map_or(0, |time| std::time::Duration::from(time).as_nanos() as u64)
    }

    fn line(&mut self, args: std::fmt::Arguments<'_>) {
        if let Err(error) = self.out.write_fmt(args) {
            warn!("writing the trace failed: {error}");
        }
    }
}

/// Counts of the link side, beside the model's statistics.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
struct LinkStats {
    frames_sent: u64,
    bytes_dropped: u64,
    garbage_bytes: u64,
    corrupted_frames: u64,
    unplugs: u64,
    /// CAN frames the socket refused (a full queue, an interface down).
    write_errors: u64,
}

/// The open port and, for a pseudo-terminal, what keeps it alive.
#[derive(Debug)]
struct Endpoint {
    port: Port,
    /// The pty's slave side, held open so that the master never sees a hang-up between clients.
    _slave: Option<TTYPort>,
}

/// The slcan adapter's state, when the simulator plays one.
#[derive(Debug, Clone, Copy, Default)]
struct Adapter {
    bitrate: Option<Bitrate>,
    open: bool,
    timestamps: bool,
}

impl Adapter {
    /// Whether chassis frames reach the host: channel open at the SCOUT's bit rate.
    fn hears_chassis(&self) -> bool {
        self.open && self.bitrate == Some(Bitrate::SCOUT)
    }

    /// The adapter's answer to a set-up command from the host.
    fn answer(&mut self, command: Slcan) -> Option<Slcan> {
        const OK: Option<Slcan> = Some(Slcan::Ack);
        const ERROR: Option<Slcan> = Some(Slcan::Nack);
        match command {
            Slcan::SetBitrate(_) if self.open => ERROR,
            Slcan::SetBitrate(rate) => {
                self.bitrate = Some(rate);
                OK
            }
            Slcan::Open if self.bitrate.is_none() || self.open => ERROR,
            Slcan::Open => {
                self.open = true;
                OK
            }
            Slcan::Close => {
                self.open = false;
                OK
            }
            Slcan::Timestamps(on) => {
                self.timestamps = on;
                OK
            }
            Slcan::Ack | Slcan::Nack | Slcan::TransmitAck { .. } => None,
            _ => ERROR,
        }
    }
}

/// A pseudo-random byte source for `garbage` (xorshift; reproducible from the seed).
#[derive(Debug, Clone, Copy)]
struct Garbage(u64);

impl Garbage {
    fn next_byte(&mut self) -> u8 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 24) as u8
    }
}

/// The running simulator.
struct Simulator<'a> {
    options: SimOptions,
    start: Instant,
    chassis: Chassis,
    framing: Option<StreamFraming>,
    adapter: Adapter,
    endpoint: Option<Endpoint>,
    unplugged_until: Option<Duration>,
    silent_until: Duration,
    corrupt_remaining: u32,
    garbage: Garbage,
    stats: LinkStats,
    /// `stats.write_errors` when the last failure streak was reported.
    write_errors_reported: u64,
    trace: Option<Trace>,
    out: &'a mut dyn Write,
    /// The black box being replayed, and when it began (when the host first spoke).
    replay: Option<(Replay, Option<Duration>)>,
    /// Whether anything came from the host yet (a replay waits for it).
    host_heard: bool,
}

/// Runs the simulator until `stop` is set or a `quit` command arrives; prints the port line first
/// and the statistics JSON line last on `out`.
pub fn run(
    options: SimOptions,
    commands: &Receiver<SimCommand>,
    stop: &AtomicBool,
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    scout_io::raise_priority(options.realtime_priority, "simulator loop");
    let chassis = Chassis::new(options.params.clone(), options.transport);
    let chassis = match (options.protocol, options.transport) {
        (Protocol::V1, _) => chassis,
        (Protocol::V2, Transport::Slcan | Transport::Can | Transport::GsUsb) => {
            chassis.with_protocol_v2()
        }
        (Protocol::V2, Transport::Serial | Transport::Sim) => anyhow::bail!(
            "protocol v2 is CAN only (the vendor SDK implements no v2 over RS232): use --slcan or --can"
        ),
    };
    let mut simulator = Simulator {
        start: Instant::now(),
        chassis,
        framing: StreamFraming::new(options.transport),
        adapter: Adapter::default(),
        endpoint: None,
        unplugged_until: None,
        silent_until: Duration::ZERO,
        corrupt_remaining: 0,
        garbage: Garbage(options.seed | 1),
        stats: LinkStats::default(),
        write_errors_reported: 0,
        trace: options.trace.as_deref().map(Trace::create).transpose()?,
        out,
        replay: options.replay.clone().map(|replay| (replay, None)),
        host_heard: false,
        options,
    };
    simulator.plug_in()?;
    let result = simulator.run_loop(commands, stop);
    simulator.print_stats()?;
    if let Some(link) = &simulator.options.link {
        let _ = std::fs::remove_file(link);
    }
    result
}

impl Simulator<'_> {
    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    fn run_loop(
        &mut self,
        commands: &Receiver<SimCommand>,
        stop: &AtomicBool,
    ) -> anyhow::Result<()> {
        let mut buffer = [0u8; 1024];
        while !stop.load(Ordering::Relaxed) {
            while let Ok(command) = commands.try_recv() {
                if !self.apply(command)? {
                    return Ok(());
                }
            }
            if self
                .unplugged_until
                .is_some_and(|until| self.now() >= until)
                && let Err(error) = self.plug_in()
            {
                // The interface went away (a USB adapter unplugged): wait for it to come back.
                warn!("{error:#}; trying again in 1 s");
                self.unplugged_until = Some(self.now() + Duration::from_secs(1));
            }
            let now = self.now();
            match self.chassis.poll_feedback(now) {
                // A replay speaks instead of the model (which still hears the commands).
                _ if self.replay.is_some() => self.send_replayed(now)?,
                Some(Feedback::V1(batch)) => self.send_feedback(&batch, now)?,
                Some(Feedback::V2(frames)) => self.send_feedback_v2(&frames, now)?,
                None => {}
            }
            let wait = self
                .chassis
                .next_feedback_at()
                .saturating_sub(self.now())
                .min(Duration::from_millis(5));
            let Some(endpoint) = self.endpoint.as_mut() else {
                std::thread::sleep(wait.max(Duration::from_millis(1)));
                continue;
            };
            match endpoint.port.read(&mut buffer, wait) {
                Ok(Incoming::Timeout) => {}
                Ok(Incoming::Bytes(n)) => self.receive_bytes(&buffer[..n])?,
                Ok(Incoming::Frame(frame)) => self.receive(self.decoder()(&frame))?,
                Ok(Incoming::Foreign(_) | Incoming::BusError(_) | Incoming::Malformed(_)) => {
                    self.chassis.handle_rejected(self.now())
                }
                Err(error) => {
                    warn!("port read failed: {error}; unplugging for 1 s");
                    self.unplug(Duration::from_secs(1));
                }
            }
        }
        Ok(())
    }

    /// Carries out one command; `false` to quit.
    fn apply(&mut self, command: SimCommand) -> anyhow::Result<bool> {
        let now = self.now();
        match command {
            SimCommand::Inject(injection) => {
                self.chassis.inject(now, injection);
                info!("{}", describe(injection));
            }
            SimCommand::Garbage(count) => {
                let bytes: Vec<u8> = (0..count).map(|_| self.garbage.next_byte()).collect();
                self.stats.garbage_bytes += count as u64;
                self.write_bytes(&bytes)?;
                info!("wrote {count} garbage bytes");
            }
            SimCommand::Frame(frame) => {
                let mut bytes = Vec::new();
                self.put_frame(&frame, None, &mut bytes);
                self.write_bytes(&bytes)?;
                info!("sent frame 0x{:03X} {:02X?}", frame.id(), frame.data());
            }
            SimCommand::Corrupt(count) => {
                self.corrupt_remaining = count;
                info!("corrupting the checksum of the next {count} feedback frames");
            }
            SimCommand::Silence(duration) => {
                self.silent_until = now + duration;
                info!("silent for {} ms", duration.as_millis());
            }
            SimCommand::Unplug(duration) => self.unplug(duration),
            SimCommand::Stats => self.print_stats()?,
            SimCommand::Wait(_) => {}
            SimCommand::Help => eprintln!("{HELP}"),
            SimCommand::Quit => {
                info!("quit");
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn unplug(&mut self, duration: Duration) {
        self.endpoint = None;
        self.unplugged_until = Some(self.now() + duration);
        self.stats.unplugs += 1;
        if let Some(link) = &self.options.link {
            let _ = std::fs::remove_file(link);
        }
        info!("unplugged; back in {} ms", duration.as_millis());
    }

    /// Opens the port (a new pseudo-terminal, or the CAN interface) and announces it.
    fn plug_in(&mut self) -> anyhow::Result<()> {
        self.unplugged_until = None;
        self.adapter = Adapter::default();
        if let Some(framing) = self.framing.as_mut() {
            framing.reset();
        }
        let (endpoint, announced) = match self.options.transport {
            Transport::Can => {
                let interface = self
                    .options
                    .can_interface
                    .clone()
                    .context("--can needs an interface")?;
                let port = Port::open_can(&interface)
                    .with_context(|| format!("opening SocketCAN interface {interface}"))?;
                (Endpoint { port, _slave: None }, interface)
            }
            Transport::Sim | Transport::GsUsb => anyhow::bail!(
                "scout-sim speaks serial, slcan or SocketCAN (the in-process chassis is \
                 scout-gateway --sim; a gs_usb adapter is emulated by scout-gs-usb-gadget, on \
                 a CAN interface the simulator is on)"
            ),
            Transport::Serial | Transport::Slcan => {
                let (master, slave) =
                    TTYPort::pair().context("creating a pseudo-terminal (is /dev/ptmx there?)")?;
                let path = slave.name().context("the pseudo-terminal has no name")?;
                if let Some(link) = &self.options.link {
                    link_to(link, Path::new(&path))?;
                }
                (
                    Endpoint {
                        port: Port::Tty(master),
                        _slave: Some(slave),
                    },
                    path,
                )
            }
        };
        self.endpoint = Some(endpoint);
        writeln!(self.out, "{} {announced}", self.options.transport)?;
        self.out.flush()?;
        info!("{} chassis on {announced}", self.options.transport);
        Ok(())
    }

    /// How a frame from the host is read: by a v2 chassis with v2's meaning of the ids both
    /// protocols use (0x141 sets a Ranger's mode).
    fn decoder(&self) -> fn(&CanFrame) -> RxEvent {
        match self.options.protocol {
            Protocol::V1 => decode_can,
            Protocol::V2 => decode_can_v2,
        }
    }

    fn receive_bytes(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let mut events = Vec::new();
        let decode = self.decoder();
        if let Some(framing) = self.framing.as_mut() {
            framing.push_with(bytes, decode, |event| events.push(event));
        }
        events.into_iter().try_for_each(|event| self.receive(event))
    }

    fn receive(&mut self, event: RxEvent) -> anyhow::Result<()> {
        self.host_heard = true;
        let now = self.now();
        let slcan = self.options.transport == Transport::Slcan;
        match event {
            RxEvent::Slcan(command) => {
                if let Some(answer) = self.adapter.answer(command) {
                    self.write_bytes(slcan::encode(&answer).as_bytes())?;
                }
                return Ok(());
            }
            _ if slcan && !self.adapter.open => {
                // A closed adapter refuses to transmit.
                return self.write_bytes(slcan::encode(&Slcan::Nack).as_bytes());
            }
            RxEvent::Message(counted) => {
                if let (Some(trace), Message::MotionCommand(command)) =
                    (self.trace.as_mut(), &counted.message)
                {
                    let params = &self.options.params;
                    let (linear, angular) = (
                        command.linear(params.max_linear),
                        command.angular(params.max_angular),
                    );
                    trace.line(format_args!("C {} {linear} {angular}\n", Trace::now_ns()));
                }
                if !slcan || self.adapter.hears_chassis() {
                    self.chassis.handle_message(now, counted);
                }
            }
            RxEvent::V2(message) => {
                if let (Some(trace), MessageV2::MotionCommand(command)) =
                    (self.trace.as_mut(), &message)
                {
                    let (linear, angular) = (command.linear(), command.angular());
                    trace.line(format_args!("C {} {linear} {angular}\n", Trace::now_ns()));
                }
                if !slcan || self.adapter.hears_chassis() {
                    self.chassis.handle_v2(now, message);
                }
            }
            RxEvent::Rejected(error) if error.is_checksum() => {
                self.chassis.handle_checksum_error(now)
            }
            RxEvent::Rejected(_) => self.chassis.handle_rejected(now),
        }
        if slcan {
            self.write_bytes(slcan::encode(&Slcan::TransmitAck { extended: false }).as_bytes())?;
        }
        Ok(())
    }

    /// Whether feedback goes out at `now` (not silenced, plugged in, heard through the adapter):
    /// the trace time of the write, stamped before it (a reader may wake before a later stamp
    /// would be taken), and the slcan timestamp if the adapter adds them.
    fn feedback_slot(&self, now: Duration) -> Option<(u64, Option<u16>)> {
        let heard = match self.options.transport {
            Transport::Slcan => self.adapter.hears_chassis(),
            Transport::Serial | Transport::Can | Transport::GsUsb | Transport::Sim => true,
        };
        if now < self.silent_until || self.endpoint.is_none() || !heard {
            return None;
        }
        let timestamp = self
            .adapter
            .timestamps
            .then_some((now.as_millis() % 60_000) as u16);
        Some((Trace::now_ns(), timestamp))
    }

    /// One period's v2 frames. `corrupt` sends a frame one byte short (v2 has no checksum to
    /// damage: a wrong length is what a receiver can catch).
    fn send_feedback_v2(&mut self, frames: &[MessageV2], now: Duration) -> anyhow::Result<()> {
        let Some((written_ns, timestamp)) = self.feedback_slot(now) else {
            return Ok(());
        };
        let mut bytes = Vec::new();
        for message in frames {
            let mut frame = message.encode();
            if self.corrupt_remaining > 0 {
                self.corrupt_remaining -= 1;
                self.stats.corrupted_frames += 1;
                let data = frame.data();
                frame = CanFrame::new(frame.id(), &data[..data.len().saturating_sub(1)])
                    .context("shortening a feedback frame")?;
            }
            self.stats.frames_sent += 1;
            self.put_frame(&frame, timestamp, &mut bytes);
        }
        self.write_bytes(&bytes)?;
        self.trace_feedback(written_ns);
        Ok(())
    }

    /// Sends `frame` on SocketCAN now, or appends its slcan line to `bytes`.
    fn put_frame(&mut self, frame: &CanFrame, timestamp: Option<u16>, bytes: &mut Vec<u8>) {
        let Some(endpoint) = self.endpoint.as_mut() else {
            return;
        };
        if self.options.transport != Transport::Can {
            bytes.extend_from_slice(
                slcan::encode(&Slcan::Frame {
                    frame: *frame,
                    timestamp,
                })
                .as_bytes(),
            );
            return;
        }
        match endpoint.port.write_frame(frame) {
            Ok(()) if self.stats.write_errors > self.write_errors_reported => {
                info!(
                    "CAN writes go through again after {} failures",
                    self.stats.write_errors - self.write_errors_reported
                );
                self.write_errors_reported = self.stats.write_errors;
            }
            Ok(()) => {}
            Err(error) => {
                if self.stats.write_errors == self.write_errors_reported {
                    warn!("CAN write failed: {error} (counting until one goes through)");
                }
                self.stats.write_errors += 1;
            }
        }
    }

    /// The trace's lines after a feedback batch was written at `written_ns`.
    fn trace_feedback(&mut self, written_ns: u64) {
        let actual = self.chassis.actual().linear;
        let Some(trace) = self.trace.as_mut() else {
            return;
        };
        trace.line(format_args!("F {written_ns}\n"));
        if actual != trace.actual {
            trace.actual = actual;
            trace.line(format_args!("A {} {actual}\n", Trace::now_ns()));
        }
        // Readable while the simulator runs, at most one period behind.
        if let Err(error) = trace.out.flush() {
            warn!("writing the trace failed: {error}");
        }
    }

    fn send_feedback(&mut self, batch: &[Counted], now: Duration) -> anyhow::Result<()> {
        let Some((written_ns, timestamp)) = self.feedback_slot(now) else {
            return Ok(());
        };
        let mut bytes = Vec::with_capacity(batch.len() * 32);
        for counted in batch {
            let corrupt = self.corrupt_remaining > 0;
            if corrupt {
                self.corrupt_remaining -= 1;
                self.stats.corrupted_frames += 1;
            }
            self.stats.frames_sent += 1;
            let checksum_damage = if corrupt { 0x5A } else { 0 };
            match self.options.transport {
                Transport::Serial => {
                    let mut frame = serial::encode(&counted.message, counted.count);
                    frame[serial::FRAME_LEN - 1] ^= checksum_damage;
                    bytes.extend_from_slice(&frame);
                }
                Transport::Slcan | Transport::Can | Transport::GsUsb | Transport::Sim => {
                    let frame = can::encode(&counted.message, counted.count);
                    let mut data = [0u8; 8];
                    data.copy_from_slice(frame.data());
                    data[can::CHECKSUM] ^= checksum_damage;
                    let frame =
                        CanFrame::new(frame.id(), &data).context("re-encoding a feedback frame")?;
                    self.put_frame(&frame, timestamp, &mut bytes);
                }
            }
        }
        self.write_bytes(&bytes)?;
        self.trace_feedback(written_ns);
        Ok(())
    }

    /// The replayed frames due now, from when the host first spoke (a gateway's first command
    /// or an adapter's set-up); silence after the last.
    fn send_replayed(&mut self, now: Duration) -> anyhow::Result<()> {
        if !self.host_heard {
            return Ok(());
        }
        let Some((written_ns, timestamp)) = self.feedback_slot(now) else {
            return Ok(());
        };
        let Some((replay, started)) = self.replay.as_mut() else {
            return Ok(());
        };
        let started = *started.get_or_insert(now);
        let due: Vec<CanFrame> = replay
            .due(now.saturating_sub(started))
            .iter()
            .map(|(_, frame)| *frame)
            .collect();
        let finished = replay.finished();
        if due.is_empty() {
            return Ok(());
        }
        let mut bytes = Vec::new();
        for frame in &due {
            self.stats.frames_sent += 1;
            match self.options.transport {
                Transport::Serial => match can::decode(frame) {
                    Ok(counted) => {
                        bytes.extend_from_slice(&serial::encode(&counted.message, counted.count))
                    }
                    Err(error) => warn!("frame 0x{:03X} cannot go on RS232: {error}", frame.id()),
                },
                Transport::Slcan | Transport::Can | Transport::GsUsb | Transport::Sim => {
                    self.put_frame(frame, timestamp, &mut bytes);
                }
            }
        }
        self.write_bytes(&bytes)?;
        self.trace_feedback(written_ns);
        if finished {
            info!("replay done: the chassis falls silent");
        }
        Ok(())
    }

    /// Writes to the tty without waiting for a reader: what does not fit is lost, as on a wire.
    fn write_bytes(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let Some(endpoint) = self.endpoint.as_mut() else {
            return Ok(());
        };
        if bytes.is_empty() || matches!(endpoint.port, Port::Can(_)) {
            return Ok(());
        }
        match endpoint.port.write_bytes(bytes, Duration::from_millis(1)) {
            Ok(written) => self.stats.bytes_dropped += (bytes.len() - written) as u64,
            Err(error) => {
                warn!("port write failed: {error}");
                self.stats.bytes_dropped += bytes.len() as u64;
            }
        }
        Ok(())
    }

    fn print_stats(&mut self) -> anyhow::Result<()> {
        let mut json = serde_json::to_value(self.chassis.stats())?;
        if let serde_json::Value::Object(object) = &mut json {
            object.insert("time_s".into(), self.now().as_secs_f64().into());
            object.insert("transport".into(), self.options.transport.name().into());
            object.insert("link".into(), serde_json::to_value(self.stats)?);
        }
        writeln!(self.out, "{json}")?;
        self.out.flush()?;
        Ok(())
    }
}

/// Points the symbolic link `link` at `target`, replacing an old link.
fn link_to(link: &Path, target: &Path) -> anyhow::Result<()> {
    if link.symlink_metadata().is_ok() {
        std::fs::remove_file(link).with_context(|| format!("replacing {}", link.display()))?;
    }
    std::os::unix::fs::symlink(target, link)
        .with_context(|| format!("linking {} to {}", link.display(), target.display()))
}

fn describe(injection: Injection) -> String {
    match injection {
        Injection::EStop(true) => "emergency stop pressed".into(),
        Injection::EStop(false) => "emergency stop released".into(),
        Injection::Rc(on) => format!("RC transmitter {}", if on { "on" } else { "off" }),
        Injection::Protect(protection) => format!("{protection:?} protection latched"),
        Injection::Warn(warning, on) => {
            format!(
                "{warning:?} warning {}",
                if on { "forced on" } else { "automatic" }
            )
        }
        Injection::MotorCommFault(motor, on) => format!(
            "motor {} communication fault {}",
            motor.number(),
            if on { "on" } else { "off" }
        ),
        Injection::Battery(volts) => format!("battery at {volts:.1} V"),
        Injection::Charger(amps) => format!("charger at {amps:.1} A"),
        Injection::PinMotor(motor, value, to) => {
            format!("motor {} {value:?} pinned at {to}", motor.number())
        }
        Injection::UnpinMotor(motor) => format!("motor {} values automatic", motor.number()),
        Injection::Standby => "v2 firmware fell back to standby (v1: nothing)".into(),
    }
}
