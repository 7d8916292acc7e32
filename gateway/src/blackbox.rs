//! The black box of the bus: the last minutes of every frame the gateway read and wrote, kept
//! on a thread of its own and written to disk (candump's log format, with both clocks) when a
//! stop latches, when a client asks (`scout blackbox save`), and when the gateway fails (its
//! loop ends with an error, or it panics). The
//! control loop only hands each frame over a bounded channel: it never waits on the black box
//! or the disk.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use scout_protocol::CanFrame;
use tracing::{info, warn};

use crate::config::BlackBoxConfig;

/// A save waits this long after its cause, so that the file shows what followed (the stop on
/// the wire, the chassis coming to rest); causes within it share one file.
pub const SAVE_AFTER: Duration = Duration::from_secs(2);
/// Frames in flight between the control loop and the black box's thread.
const CHANNEL: usize = 8192;

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
        let mut line = format!(
            "({}.{:06}) {} {:03X}#",
            self.wall.as_secs(),
            self.wall.subsec_micros(),
            self.direction.name(),
            self.frame.id()
        );
        for byte in self.frame.data() {
            let _ = write!(line, "{byte:02X}");
        }
        let _ = write!(
            line,
            " boot={}.{:06}",
            self.boot.as_secs(),
            self.boot.subsec_micros()
        );
        line
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

    /// The file: a header of `#` lines (`header`, one per line), then a line per frame.
    pub fn render(&self, header: &[String]) -> String {
        let mut text = String::with_capacity(64 * (self.frames.len() + header.len()));
        for line in header {
            let _ = writeln!(text, "# {line}");
        }
        for frame in &self.frames {
            text.push_str(&frame.line());
            text.push('\n');
        }
        text
    }
}

enum Message {
    Frame(Recorded),
    /// A wake-up: reasons to save wait in [`Recorder::reasons`].
    Save,
}

/// The black box's thread and the control loop's end of its channel.
#[derive(Debug)]
pub struct Recorder {
    sender: Option<SyncSender<Message>>,
    /// Why to save, waiting for the thread (a lock held only to push or take: a save is
    /// never lost to a full channel, and never waits for room in it).
    reasons: Arc<Mutex<Vec<String>>>,
    /// Frames the channel had no room for (the thread fell behind), counted and said.
    lost: Arc<AtomicU64>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Recorder {
    /// Starts the black box of `robot` as `config` says, or none when it is off.
    pub fn start(config: &BlackBoxConfig, robot: &str) -> anyhow::Result<Option<Self>> {
        if config.minutes <= 0.0 {
            info!("black box off ([blackbox] minutes = 0)");
            return Ok(None);
        }
        let dir = config.dir();
        let (sender, receiver) = std::sync::mpsc::sync_channel(CHANNEL);
        let lost = Arc::new(AtomicU64::new(0));
        let reasons = Arc::new(Mutex::new(Vec::new()));
        let keeper = Keeper {
            reasons: Arc::clone(&reasons),
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
            && let Err(TrySendError::Full(_)) = sender.try_send(Message::Frame(recorded))
        {
            self.lost.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Asks for the black box on disk, `why`, [`SAVE_AFTER`] from now. Never waits on the
    /// thread: the reason waits in a list, and a wake-up that finds the channel full is not
    /// needed (the thread looks at the list after every frame).
    pub fn save(&self, why: String) {
        self.reasons
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(why);
        if let Some(sender) = &self.sender {
            let _ = sender.try_send(Message::Save);
        }
    }
}

impl Drop for Recorder {
    /// Ends the thread once a pending save is written.
    fn drop(&mut self) {
        drop(self.sender.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The thread's side: the ring, and where and how many files to keep.
struct Keeper {
    reasons: Arc<Mutex<Vec<String>>>,
    ring: Ring,
    dir: PathBuf,
    keep: usize,
    robot: String,
    lost: Arc<AtomicU64>,
}

impl Keeper {
    fn run(mut self, receiver: &Receiver<Message>) {
        let mut pending: Option<(Instant, Vec<String>)> = None;
        loop {
            let wait = pending
                .as_ref()
                .map_or(Duration::from_secs(3600), |(at, _)| {
                    at.saturating_duration_since(Instant::now())
                });
            let received = receiver.recv_timeout(wait);
            if let Ok(Message::Frame(frame)) = received {
                self.ring.push(frame);
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
                    None => pending = Some((Instant::now() + SAVE_AFTER, asked)),
                }
            }
            if let Err(RecvTimeoutError::Disconnected) = received {
                if let Some((_, reasons)) = pending.take() {
                    self.write(&reasons);
                }
                return;
            }
            if pending
                .as_ref()
                .is_some_and(|(at, _)| Instant::now() >= *at)
                && let Some((_, reasons)) = pending.take()
            {
                self.write(&reasons);
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
        match write_file(&self.dir, &path, &self.ring.render(&header)) {
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

/// Writes `text` to `path` through a file beside it, synced, so that a crash leaves no half.
fn write_file(dir: &Path, path: &Path, text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    std::fs::create_dir_all(dir)?;
    let partial = path.with_extension("log.partial");
    let mut file = std::fs::File::create(&partial)?;
    file.write_all(text.as_bytes())?;
    file.sync_all()?;
    std::fs::rename(&partial, path)?;
    Ok(())
}

/// Removes the oldest of the robot's black boxes beyond `keep` (their names sort by time).
fn prune(dir: &Path, robot: &str, keep: usize) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!("{robot}-");
    let mut files: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|entry| entry.path())
        .filter(|path| {
            path.file_name()
                .and_then(|name| name.to_str())
                .is_some_and(|name| name.starts_with(&prefix) && name.ends_with(".log"))
        })
        .collect();
    files.sort();
    let excess = files.len().saturating_sub(keep);
    for old in &files[..excess] {
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
        let text = small.render(&["saved for: a test".into()]);
        assert!(text.starts_with("# saved for: a test\n("), "{text}");
        assert_eq!(text.lines().count(), 11);
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
        for old in ["r1-2000-01-01T00-00-00Z.log", "r1-2000-01-02T00-00-00Z.log"] {
            std::fs::create_dir_all(&dir).expect("dir");
            std::fs::write(dir.join(old), "old").expect("an old box");
        }
        std::fs::write(dir.join("other-2000-01-01T00-00-00Z.log"), "").expect("another robot's");
        let config = BlackBoxConfig {
            dir: Some(dir.clone()),
            keep: 2,
            ..BlackBoxConfig::default()
        };
        let recorder = Recorder::start(&config, "r1").expect("start").expect("on");
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
            names[0], "other-2000-01-01T00-00-00Z.log",
            "another robot's kept"
        );
        assert_eq!(
            names[1], "r1-2000-01-02T00-00-00Z.log",
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
