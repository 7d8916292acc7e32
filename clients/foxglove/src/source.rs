//! Reading a gateway for the recorder and the live view: an ordinary iceoryx2 subscriber of the
//! state and the status (no work in the gateway's loop), on a thread of its own that turns them
//! into transcript entries, so a slow disk or a flush never makes it miss a state.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use scout_clients::client::{ClientError, Robot};
use scout_clients::failure::{Failure, FailureKind};
use scout_clients::monotonic_ns;
use tracing::warn;

use scout_interface::StatePayload;
use scout_interface::control::StatusPayload;

use crate::transcript::{Timed, Transcript};

/// How long the reader waits for a state before it looks at the status again.
const WAIT: Duration = Duration::from_millis(50);
/// No state for this long: the gateway is said to be silent.
const SILENT_AFTER: Duration = Duration::from_secs(2);

/// What turns the states and statuses read into what is written: the transcript (Foxglove's
/// channels) or ROS 2 messages.
pub trait Transcribe: Send + 'static {
    /// One thing to write.
    type Item: Send + 'static;
    /// What to write for a state.
    fn handle_state(&mut self, state: &StatePayload, out: &mut Vec<Self::Item>);
    /// What to write for a status.
    fn handle_status(&mut self, status: &StatusPayload, out: &mut Vec<Self::Item>);
}

impl Transcribe for Transcript {
    type Item = Timed;

    fn handle_state(&mut self, state: &StatePayload, out: &mut Vec<Timed>) {
        Transcript::handle_state(self, state, out);
    }

    fn handle_status(&mut self, status: &StatusPayload, out: &mut Vec<Timed>) {
        Transcript::handle_status(self, status, out);
    }
}

/// What the reader thread sends.
#[derive(Debug)]
pub enum Update<I = Timed> {
    /// Entries to write, in order.
    Entries(Vec<I>),
    /// No state came for this long (sent once per silence).
    Silent(Duration),
    /// States flow again after a silence.
    Flowing,
    /// States the subscriber's buffer lost (a gap in `seq`): the reader fell behind.
    Missed(u64),
    /// Reading failed; the reader stopped.
    Failed(ClientError),
}

/// CLOCK_REALTIME minus CLOCK_BOOTTIME now, ns.
pub fn realtime_offset_ns() -> i128 {
    let monotonic = i128::from(monotonic_ns());
    let realtime = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |since| since.as_nanos() as i128);
    realtime - monotonic
}

/// Why reading could not start.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The gateway could not be reached.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The reader thread could not be started.
    #[error("starting the reader thread")]
    Thread(#[source] std::io::Error),
}

/// .
impl FailureKind for SourceError {
    fn kind(&self) -> Failure {
        match self {
            Self::Client(error) => error.kind(),
            Self::Thread(_) => Failure::Failed,
        }
    }
}

/// A reader thread for one robot.
#[derive(Debug)]
pub struct Source<I = Timed> {
    updates: Receiver<Update<I>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Source {
    /// Connects to robot `name` (fails at once when no gateway of that name runs) and starts
    /// reading into the transcript.
    pub fn start(name: &str) -> Result<Self, SourceError> {
        Source::start_with(name, Transcript::new(monotonic_ns(), realtime_offset_ns()))
    }
}

impl<I: Send + 'static> Source<I> {
    /// [`Source::start`], turning what it reads into `transcriber`'s items.
    pub fn start_with<T: Transcribe<Item = I>>(
        name: &str,
        transcriber: T,
    ) -> Result<Self, SourceError> {
        let robot = Robot::connect(name)?;
        let states = robot.subscribe()?;
        let status = robot.status()?;
        let (sender, updates) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let thread_stop = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("scout-reader".into())
            .spawn(move || {
                // The robot's node outlives its ports.
                let _robot = robot;
                read(&states, &status, transcriber, &sender, &thread_stop);
            })
            .map_err(SourceError::Thread)?;
        Ok(Self {
            updates,
            stop,
            thread: Some(thread),
        })
    }

    /// The next update, waiting at most `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<Update<I>> {
        self.updates.recv_timeout(timeout).ok()
    }

    /// Stops reading and hands over what was read and not yet taken, so that nothing read is
    /// lost at the end of a recording.
    pub fn finish(mut self) -> Vec<Update<I>> {
        self.stop_reading();
        self.updates.try_iter().collect()
    }
}

impl<I> Source<I> {
    fn stop_reading(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl<I> Drop for Source<I> {
    fn drop(&mut self) {
        self.stop_reading();
    }
}

fn read<T: Transcribe>(
    states: &scout_clients::client::StateSubscriber,
    status: &scout_clients::control::StatusReader,
    mut transcript: T,
    sender: &Sender<Update<T::Item>>,
    stop: &AtomicBool,
) {
    let mut last_seq: Option<u64> = None;
    let mut last_state = std::time::Instant::now();
    let mut silent = false;
    while !stop.load(Ordering::Relaxed) {
        let mut entries = Vec::new();
        let mut missed = 0;
        let result = (|| -> Result<(), ClientError> {
            if let Some(state) = states.next_timeout(WAIT)? {
                let mut next = Some(state);
                while let Some(state) = next {
                    if let Some(last) = last_seq {
                        missed += state.seq.saturating_sub(last + 1);
                    }
                    last_seq = Some(state.seq);
                    transcript.handle_state(&state, &mut entries);
                    next = states.try_next()?;
                }
                last_state = std::time::Instant::now();
            }
            while let Some(status) = status.try_next()? {
                transcript.handle_status(&status, &mut entries);
            }
            Ok(())
        })();
        if let Err(error) = result {
            let _ = sender.send(Update::Failed(error));
            return;
        }
        let since = last_state.elapsed();
        let mut updates = Vec::new();
        if missed > 0 {
            warn!("{missed} states lost: the recorder fell behind the gateway");
            updates.push(Update::Missed(missed));
        }
        if !entries.is_empty() {
            updates.push(Update::Entries(entries));
        }
        if since >= SILENT_AFTER && !silent {
            silent = true;
            updates.push(Update::Silent(since));
        } else if since < SILENT_AFTER && silent {
            silent = false;
            updates.push(Update::Flowing);
        }
        for update in updates {
            if sender.send(update).is_err() {
                return;
            }
        }
    }
}
