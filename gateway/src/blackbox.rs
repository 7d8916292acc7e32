//! The black box of the bus: the last minutes of every frame the gateway read and wrote, kept
//! on a thread of its own and written to disk (candump's log format, with both clocks) when a
//! stop latches, when a client asks (`scout blackbox save`), and when the gateway fails (its
//! loop ends with an error, or it panics). The
//! control loop only hands each frame over a bounded channel: it never waits on the black box
//! or the disk.

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::Context;
use scout_protocol::CanFrame;
use tracing::{info, warn};

use crate::config::BlackBoxConfig;

/// A save waits this long after its cause, so that the file shows what followed (the stop on
/// the wire, the chassis coming to rest); causes within it share one file.
pub const SAVE_AFTER: Duration = Duration::from_secs(2);
/// The buffer a save writes through: the one allocation of a save, whatever the ring holds.
const WRITE_BUFFER: usize = 64 * 1024;
/// Frames in flight between the control loop and the black box's thread.
const CHANNEL: usize = 8192;
/// The thread wakes this often to take what came: the control loop never has a sleeper to
/// wake (sending then takes no lock).
const POLL: Duration = Duration::from_millis(20);

/// Which way a frame went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Read from the chassis.
    Rx,
    /// Written to the chassis.
    Tx,
}

impl Direction {
    /// The interface column of the log: `rx` or `tx`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Rx => "rx",
            Self::Tx => "tx",
        }
    }
}

/// One frame as the black box keeps it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Recorded {
    /// CLOCK_BOOTTIME when it went by.
    pub boot: Duration,
    /// The wall clock then, since the Unix epoch.
    pub wall: Duration,
    /// Read or written.
    pub direction: Direction,
    /// The frame.
    pub frame: CanFrame,
}

impl Recorded {
    /// The candump log line: `(WALL) rx|tx ID#DATA boot=BOOT`, seconds with microseconds
    /// (candump and canplayer read the first three fields; `scout decode` reads it all).
    pub fn line(&self) -> String {
        let mut line = Vec::with_capacity(64);
        let _ = self.write_line(&mut line);
        line.pop(); // its newline
        String::from_utf8_lossy(&line).into_owned()
    }

    /// Writes [`Recorded::line`] and its newline to `out`, allocating nothing.
    pub fn write_line(&self, out: &mut impl Write) -> std::io::Result<()> {
        write!(
            out,
            "({}.{:06}) {} {:03X}#",
            self.wall.as_secs(),
            self.wall.subsec_micros(),
            self.direction.name(),
            self.frame.id()
        )?;
        for byte in self.frame.data() {
            write!(out, "{byte:02X}")?;
        }
        writeln!(
            out,
            " boot={}.{:06}",
            self.boot.as_secs(),
            self.boot.subsec_micros()
        )
    }
}

/// The last `span` of frames, at most `max_frames` of them (sans-IO: the times come with the
/// frames).
#[derive(Debug, Clone)]
pub struct Ring {
    span: Duration,
    max_frames: usize,
    frames: VecDeque<Recorded>,
}

impl Ring {
    /// An empty ring.
    pub fn new(span: Duration, max_frames: usize) -> Self {
        Self {
            span,
            max_frames,
            frames: VecDeque::new(),
        }
    }

    /// Keeps `frame`, forgetting what is older than the span or beyond the count.
    pub fn push(&mut self, frame: Recorded) {
        self.frames.push_back(frame);
        while self.frames.len() > self.max_frames
            || self
                .frames
                .front()
                .is_some_and(|first| frame.boot.saturating_sub(first.boot) > self.span)
        {
            self.frames.pop_front();
        }
    }

    /// The frames kept, oldest first.
    pub fn frames(&self) -> impl Iterator<Item = &Recorded> {
        self.frames.iter()
    }

    /// Writes the file to `out`: a header of `#` lines (`header`, one per line), then a line per
    /// frame, as they go (the file is never whole in memory: a multi-MB text built and freed
    /// every save would only leave the allocator's heap fragmented).
    pub fn write_to(&self, out: &mut impl Write, header: &[String]) -> std::io::Result<()> {
        for line in header {
            writeln!(out, "# {line}")?;
        }
        for frame in &self.frames {
            frame.write_line(out)?;
        }
        Ok(())
    }
}

/// The black box's thread and the control loop's end of its channel.
#[derive(Debug)]
pub struct Recorder {
    sender: Option<SyncSender<Recorded>>,
    /// Why to save, for the thread to take (the control loop only ever `try_lock`s it).
    reasons: Arc<Mutex<Vec<String>>>,
    /// Reasons the control loop could not hand over yet (the thread held the lock).
    unsent: Vec<String>,
    /// Frames the channel had no room for (the thread fell behind), counted and said.
    lost: Arc<AtomicU64>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Recorder {
    /// Starts the black box of `robot` as `config` says, or none when it is off.
    pub fn start(config: &BlackBoxConfig, robot: &str) -> anyhow::Result<Option<Self>> {
        if !config.enabled() {
            info!("black box off ([blackbox] minutes = 0)");
            return Ok(None);
        }
        let dir = config
            .dir()
            .context("the black box's directory ([blackbox] dir)")?;
        let (sender, receiver) = std::sync::mpsc::sync_channel(CHANNEL);
        let lost = Arc::new(AtomicU64::new(0));
        let reasons = Arc::new(Mutex::new(Vec::new()));
        let keeper = Keeper {
            reasons: Arc::clone(&reasons),
            min_interval: Duration::from_secs_f64(config.min_interval_s),
            ring: Ring::new(
                Duration::from_secs_f64(config.minutes * 60.0),
                config.max_frames,
            ),
            dir: dir.clone(),
            keep: config.keep,
            robot: robot.to_owned(),
            lost: Arc::clone(&lost),
        };
        let thread = std::thread::Builder::new()
            .name("black box".into())
            .spawn(move || keeper.run(&receiver))?;
        // A panic anywhere asks for a save; the unwinding drops the recorder, whose thread
        // then writes before the process ends.
        let on_panic = Arc::clone(&reasons);
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if let Ok(mut reasons) = on_panic.lock() {
                reasons.push(format!("the gateway panicked: {info}"));
            }
            previous(info);
        }));
        info!(
            "black box: the last {} min of frames (at most {}), saved to {} on a stop, a failure \
             or `scout blackbox save`",
            config.minutes,
            config.max_frames,
            dir.display()
        );
        Ok(Some(Self {
            sender: Some(sender),
            reasons,
            unsent: Vec::new(),
            lost,
            thread: Some(thread),
        }))
    }

    /// Hands a frame over; never waits (a full channel loses the frame, counted).
    pub fn record(&self, direction: Direction, frame: CanFrame, boot: Duration) {
        let wall = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap_or_default();
        let recorded = Recorded {
            boot,
            wall,
            direction,
            frame,
        };
        if let Some(sender) = &self.sender
            && let Err(TrySendError::Full(_)) = sender.try_send(recorded)
        {
            self.lost.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Asks for the black box on disk, `why`, [`SAVE_AFTER`] from now (or `[blackbox]
    /// min_interval_s` after the last file: a burst of stops, a flapping link, a client asking
    /// again and again, neither rewrites the ring every few seconds nor pushes the incident's
    /// own file out; later causes share the next file, which still holds the minutes before). Never waits on the thread: a reason the
    /// lock is busy for waits here for [`Recorder::hand_over`].
    pub fn save(&mut self, why: String) {
        self.unsent.push(why);
        self.hand_over();
    }

    /// Hands waiting reasons to the thread if its lock is free (called every iteration).
    pub fn hand_over(&mut self) {
        if self.unsent.is_empty() {
            return;
        }
        if let Ok(mut reasons) = self.reasons.try_lock() {
            reasons.append(&mut self.unsent);
        }
    }
}

impl Drop for Recorder {
    /// Ends the thread once a pending save is written.
    fn drop(&mut self) {
        if !self.unsent.is_empty() {
            self.reasons
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .append(&mut self.unsent);
        }
        drop(self.sender.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The thread's side: the ring, and where and how many files to keep.
struct Keeper {
    reasons: Arc<Mutex<Vec<String>>>,
    min_interval: Duration,
    ring: Ring,
    dir: PathBuf,
    keep: usize,
    robot: String,
    lost: Arc<AtomicU64>,
}

impl Keeper {
    fn run(mut self, receiver: &Receiver<Recorded>) {
        let mut pending: Option<(Instant, Vec<String>)> = None;
        let mut last_file: Option<Instant> = None;
        loop {
            std::thread::sleep(POLL);
            let mut gone = false;
            loop {
                match receiver.try_recv() {
                    Ok(frame) => self.ring.push(frame),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => {
                        gone = true;
                        break;
                    }
                }
            }
            let asked = std::mem::take(
                &mut *self
                    .reasons
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner),
            );
            if !asked.is_empty() {
                match pending.as_mut() {
                    Some((_, reasons)) => reasons.extend(asked),
                    None => {
                        let soonest = Instant::now() + SAVE_AFTER;
                        let allowed = last_file.map_or(soonest, |at| at + self.min_interval);
                        pending = Some((soonest.max(allowed), asked));
                    }
                }
            }
            let due = pending
                .as_ref()
                .is_some_and(|(at, _)| gone || Instant::now() >= *at);
            if due && let Some((_, reasons)) = pending.take() {
                self.write(&reasons);
                last_file = Some(Instant::now());
            }
            if gone {
                return;
            }
        }
    }

    fn write(&self, reasons: &[String]) {
        let now = SystemTime::now();
        let stamp = humantime::format_rfc3339_millis(now)
            .to_string()
            .replace(':', "-");
        let mut header = vec![
            format!("scout-gateway black box of '{}', saved {stamp}", self.robot),
            "candump log: (wall clock, s) rx|tx CAN-ID#DATA boot=CLOCK_BOOTTIME s".to_owned(),
            "read it with `scout decode FILE`; replay the rx side with `scout-sim --replay FILE`"
                .to_owned(),
        ];
        header.extend(reasons.iter().map(|why| format!("saved for: {why}")));
        let lost = self.lost.load(Ordering::Relaxed);
        if lost > 0 {
            header.push(format!(
                "frames lost before the black box (it fell behind): {lost}"
            ));
        }
        let path = self.dir.join(format!("{}-{stamp}.log", self.robot));
        match write_file(&self.dir, &path, |out| self.ring.write_to(out, &header)) {
            Ok(()) => info!(
                "black box saved to {} ({} frames; {})",
                path.display(),
                self.ring.frames.len(),
                reasons.join("; ")
            ),
            Err(error) => warn!(
                "the black box could not be saved to {}: {error:#} (check [blackbox] dir)",
                path.display()
            ),
        }
        prune(&self.dir, &self.robot, self.keep);
    }
}

/// Writes what `contents` writes to `path` (through a buffer of [`WRITE_BUFFER`] bytes) by way
/// of a file beside it, synced, so that a crash leaves no half.
fn write_file(
    dir: &Path,
    path: &Path,
    contents: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> std::io::Result<()>,
) -> anyhow::Result<()> {
    crate::run_dir::private(dir)?;
    let partial = path.with_extension("log.partial");
    // Anything left there (a crash's leftover, a planted link) goes; the file is made anew.
    let _ = std::fs::remove_file(&partial);
    let file = crate::run_dir::create_new(&partial)?;
    let mut out = std::io::BufWriter::with_capacity(WRITE_BUFFER, &file);
    contents(&mut out)?;
    out.flush()?;
    drop(out);
    file.sync_all()?;
    std::fs::rename(&partial, path)?;
    Ok(())
}

/// Whether `name` is a black box of `robot`: `ROBOT-YYYY-MM-DDTHH-MM-SS.mmmZ.log` exactly (so
/// robot `scout` never takes robot `scout-2`'s files for its own).
fn is_box_of(name: &str, robot: &str) -> bool {
    let Some(stamp) = name
        .strip_prefix(robot)
        .and_then(|rest| rest.strip_prefix('-'))
    else {
        return false;
    };
    let bytes = stamp.as_bytes();
    bytes.len() == "2026-11-27T21-55-12.345Z.log".len()
        && stamp.ends_with("Z.log")
        && bytes[4] == b'-'
        && bytes[10] == b'T'
        && bytes[..4].iter().all(u8::is_ascii_digit)
}

/// Removes the oldest of the robot's black boxes beyond `keep`, oldest by modification time
/// (a stepped wall clock does not reorder them).
fn prune(dir: &Path, robot: &str, keep: usize) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut files: Vec<(SystemTime, PathBuf)> = entries
        .filter_map(Result::ok)
        .filter(|entry| {
            entry
                .file_name()
                .to_str()
                .is_some_and(|name| is_box_of(name, robot))
        })
        .filter_map(|entry| Some((entry.metadata().ok()?.modified().ok()?, entry.path())))
        .collect();
    files.sort();
    let excess = files.len().saturating_sub(keep);
    for (_, old) in &files[..excess] {
        if let Err(error) = std::fs::remove_file(old) {
            warn!("removing the old black box {}: {error}", old.display());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(boot_ms: u64, direction: Direction) -> Recorded {
        Recorded {
            boot: Duration::from_millis(boot_ms),
            wall: Duration::from_millis(1_764_280_000_000 + boot_ms),
            direction,
            frame: CanFrame::new(0x151, &[0, 1, 0xF5, 0, 0, 0, 7, 0x5A]).expect("a frame"),
        }
    }

    #[test]
    fn a_line_is_candump_log_with_both_clocks() {
        let line = frame(1_234, Direction::Rx).line();
        assert_eq!(
            line,
            "(1764280001.234000) rx 151#0001F5000000075A boot=1.234000"
        );
        let record = scout_protocol::candump::parse(&line).expect("candump reads it");
        assert_eq!(record.interface, Some("rx"));
        assert_eq!(record.frame, frame(0, Direction::Rx).frame);
    }

    #[test]
    fn the_ring_keeps_its_span_and_its_count() {
        let mut ring = Ring::new(Duration::from_secs(1), 100);
        for ms in (0..3_000).step_by(20) {
            ring.push(frame(ms, Direction::Tx));
        }
        let kept: Vec<u64> = ring.frames().map(|f| f.boot.as_millis() as u64).collect();
        assert_eq!(kept.first(), Some(&1_980), "the last second: {kept:?}");
        assert_eq!(kept.last(), Some(&2_980));
        let mut small = Ring::new(Duration::from_secs(60), 10);
        for ms in 0..50 {
            small.push(frame(ms, Direction::Rx));
        }
        assert_eq!(small.frames().count(), 10);
        let mut text = Vec::new();
        small
            .write_to(&mut text, &["saved for: a test".into()])
            .expect("written");
        let text = String::from_utf8(text).expect("text");
        assert!(text.starts_with("# saved for: a test\n("), "{text}");
        assert_eq!(text.lines().count(), 11);
        assert_eq!(
            text.lines().nth(1),
            Some(small.frames().next().expect("a frame").line().as_str())
        );
    }

    #[test]
    fn a_box_is_its_robots_by_the_whole_name() {
        assert!(is_box_of("scout-2026-11-27T21-55-12.345Z.log", "scout"));
        assert!(!is_box_of("scout-2-2026-11-27T21-55-12.345Z.log", "scout"));
        assert!(is_box_of("scout-2-2026-11-27T21-55-12.345Z.log", "scout-2"));
        assert!(!is_box_of(
            "scout-2026-11-27T21-55-12.345Z.log.partial",
            "scout"
        ));
        assert!(!is_box_of("notes.log", "scout"));
    }

    #[test]
    fn a_panic_saves_the_black_box_as_the_recorder_unwinds() {
        let dir = std::env::temp_dir().join(format!("scout-blackbox-panic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let config = BlackBoxConfig {
            dir: Some(dir.clone()),
            ..BlackBoxConfig::default()
        };
        let recorder = Recorder::start(&config, "r2").expect("start").expect("on");
        recorder.record(Direction::Tx, frame(0, Direction::Tx).frame, Duration::ZERO);
        let unwound = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
            let _recorder = recorder;
            panic!("a test's own panic");
        }));
        assert!(unwound.is_err());
        let files: Vec<_> = std::fs::read_dir(&dir).expect("a box").collect();
        assert_eq!(files.len(), 1);
        let path = files[0].as_ref().expect("entry").path();
        let saved = std::fs::read_to_string(path).expect("read");
        assert!(
            saved.contains("# saved for: the gateway panicked: "),
            "{saved}"
        );
        assert!(saved.contains("a test's own panic"), "{saved}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_save_writes_the_file_after_its_delay_and_old_ones_go() {
        let dir = std::env::temp_dir().join(format!("scout-blackbox-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for old in [
            "r1-2000-01-01T00-00-00.000Z.log",
            "r1-2000-01-02T00-00-00.000Z.log",
        ] {
            std::fs::create_dir_all(&dir).expect("dir");
            std::fs::write(dir.join(old), "old").expect("an old box");
            std::thread::sleep(Duration::from_millis(20));
        }
        std::fs::write(dir.join("r1-2-2000-01-01T00-00-00.000Z.log"), "").expect("robot r1-2's");
        let config = BlackBoxConfig {
            dir: Some(dir.clone()),
            keep: 2,
            ..BlackBoxConfig::default()
        };
        let mut recorder = Recorder::start(&config, "r1").expect("start").expect("on");
        for ms in 0..100 {
            recorder.record(
                Direction::Rx,
                frame(ms, Direction::Rx).frame,
                Duration::from_millis(ms),
            );
        }
        recorder.save("stop #1 by test".into());
        drop(recorder);
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .expect("dir")
            .map(|entry| {
                entry
                    .expect("entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        assert_eq!(names.len(), 3, "{names:?}");
        assert_eq!(
            names[0], "r1-2-2000-01-01T00-00-00.000Z.log",
            "robot r1-2's kept"
        );
        assert_eq!(
            names[1], "r1-2000-01-02T00-00-00.000Z.log",
            "the oldest of r1 went"
        );
        let saved = std::fs::read_to_string(dir.join(&names[2])).expect("the box");
        assert!(saved.contains("# saved for: stop #1 by test\n"), "{saved}");
        assert_eq!(
            saved.lines().filter(|l| l.contains(" rx 151#")).count(),
            100
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
