//! `scout record`: the transcript into an MCAP file, zstd chunks, indexed, one chunk closed and
//! synced to disk every second so that a recording cut by SIGKILL or a power loss keeps all
//! but its last second.

use std::fs::{File, OpenOptions};
use std::io::{IsTerminal, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use foxglove::{Context, McapCompression, McapWriteOptions, McapWriterHandle};
use scout_clients::failure::Failure;
use tracing::{info, warn};

use crate::channels::{ChannelError, Channels};
use crate::source::{Source, SourceError, Update};

/// How often the current chunk is closed, written and synced.
pub const SYNC_EVERY: Duration = Duration::from_secs(1);
/// How often the progress line is redrawn.
const PROGRESS_EVERY: Duration = Duration::from_millis(500);
/// The largest chunk before compression (a second of the channels is about 70 kB).
const CHUNK_SIZE: u64 = 1 << 20;

/// What to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The robot.
    pub robot: String,
    /// The file to write.
    pub output: PathBuf,
    /// Stop after this long (else at Ctrl-C or SIGTERM).
    pub duration: Option<Duration>,
    /// Replace an existing file.
    pub force: bool,
    /// Draw a progress line on standard error (when it is a terminal).
    pub progress: bool,
}

/// Why a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The output exists and `--force` was not given.
    #[error("{0} exists: choose another name, or --force to replace it")]
    Exists(PathBuf),
    /// The output could not be created.
    #[error("creating {path}")]
    Create {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The gateway could not be read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// A channel could not be made.
    #[error(transparent)]
    Channel(#[from] ChannelError),
    /// Writing the file failed.
    #[error("writing {path}: {error}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        error: foxglove::FoxgloveError,
    },
    /// Reading the gateway failed during the recording.
    #[error("reading the gateway")]
    Read(#[source] scout_clients::client::ClientError),
    /// The closed file could not be synced to disk.
    #[error("syncing {path} to disk")]
    Sync {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

impl RecordError {
    /// What kind of failure this is: an existing file is a usage error.
    pub fn kind(&self) -> Failure {
        match self {
            Self::Exists(_) => Failure::Usage,
            Self::Source(error) => error.kind(),
            Self::Read(error) => error.kind(),
            Self::Create { .. } | Self::Channel(_) | Self::Write { .. } | Self::Sync { .. } => {
                Failure::Failed
            }
        }
    }
}

/// What was recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Messages written, all channels.
    pub messages: u64,
    /// How long it recorded.
    pub duration: Duration,
    /// The file's size.
    pub bytes: u64,
    /// States the reader lost (it fell behind the gateway).
    pub missed_states: u64,
}

/// The file under the MCAP writer: `flush` (a closed chunk) also syncs it to disk.
#[derive(Debug)]
struct SyncedFile(File);

impl Write for SyncedFile {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.write(bytes)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.sync_data()
    }
}

impl Seek for SyncedFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.0.seek(to)
    }
}

fn size(path: &Path) -> u64 {
    std::fs::metadata(path).map_or(0, |metadata| metadata.len())
}

fn megabytes(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// Records until `options.duration` passes or `stop` is set; closes the file with its summary
/// and index either way.
pub fn record(options: &RecordOptions, stop: &AtomicBool) -> Result<Summary, RecordError> {
    let path = &options.output;
    if path.exists() && !options.force {
        return Err(RecordError::Exists(path.clone()));
    }
    // Connect before creating the file: no gateway leaves no empty file behind.
    let source = Source::start(&options.robot)?;
    let context = Context::new();
    let writer = start_writer(&context, create_output(options)?, options)?;
    let write_error = |error| RecordError::Write {
        path: path.clone(),
        error,
    };
    let mut channels = Channels::new(&context, &options.robot)?;
    info!("recording robot {} to {}", options.robot, path.display());

    let started = Instant::now();
    let mut last_sync = Instant::now();
    let mut last_progress: Option<Instant> = None;
    let mut missed_states = 0;
    let mut silent: Option<Duration> = None;
    let progress = options.progress && std::io::stderr().is_terminal();
    let outcome = loop {
        if stop.load(Ordering::Relaxed)
            || options
                .duration
                .is_some_and(|duration| started.elapsed() >= duration)
        {
            break Ok(());
        }
        if let Some(update) = source.next(Duration::from_millis(100)) {
            match update {
                Update::Entries(entries) => {
                    for entry in &entries {
                        channels.write(entry);
                    }
                }
                Update::Missed(count) => missed_states += count,
                Update::Silent(since) => {
                    warn!(
                        "no state from the gateway of {} for {since:.1?}: is it running? \
                         (recording goes on)",
                        options.robot
                    );
                    silent = Some(since);
                }
                Update::Flowing => silent = None,
                Update::Failed(error) => break Err(RecordError::Read(error)),
            }
        }
        if last_sync.elapsed() >= SYNC_EVERY {
            if let Err(error) = writer.flush() {
                break Err(write_error(error));
            }
            last_sync = Instant::now();
        }
        if progress && last_progress.is_none_or(|at| at.elapsed() >= PROGRESS_EVERY) {
            eprint!(
                "\r\x1b[Krecording {} to {}: {:.1} s, {} messages, {:.2} MB{}",
                options.robot,
                path.display(),
                started.elapsed().as_secs_f64(),
                channels.written(),
                megabytes(size(path)),
                if silent.is_some() {
                    " (no state: is the gateway running?)"
                } else {
                    ""
                },
            );
            last_progress = Some(Instant::now());
        }
    };
    // What the reader read before it stopped goes into the file too.
    for update in source.finish() {
        match update {
            Update::Entries(entries) => entries.iter().for_each(|entry| channels.write(entry)),
            Update::Missed(count) => missed_states += count,
            Update::Silent(_) | Update::Flowing | Update::Failed(_) => {}
        }
    }
    let closed = writer.close().map_err(write_error);
    if progress {
        eprintln!();
    }
    outcome?;
    let mut file = closed?;
    file.flush().map_err(|source| RecordError::Sync {
        path: path.clone(),
        source,
    })?;
    let summary = Summary {
        messages: channels.written(),
        duration: started.elapsed(),
        bytes: size(path),
        missed_states,
    };
    info!(
        "wrote {}: {} messages in {:.1} s, {:.2} MB",
        path.display(),
        summary.messages,
        summary.duration.as_secs_f64(),
        megabytes(summary.bytes)
    );
    Ok(summary)
}

/// The output file: created, or replaced with `--force`; an existing file (even one made since
/// the check) is not replaced without it.
fn create_output(options: &RecordOptions) -> Result<File, RecordError> {
    // Without --force, a file made in the meantime is not replaced either.
    OpenOptions::new()
        .write(true)
        .create_new(!options.force)
        .create(options.force)
        .truncate(options.force)
        .open(&options.output)
        .map_err(|source| match source.kind() {
            std::io::ErrorKind::AlreadyExists => RecordError::Exists(options.output.clone()),
            _ => RecordError::Create {
                path: options.output.clone(),
                source,
            },
        })
}

/// The MCAP writer on `file`, with the recording's metadata written.
fn start_writer(
    context: &std::sync::Arc<Context>,
    file: File,
    options: &RecordOptions,
) -> Result<McapWriterHandle<SyncedFile>, RecordError> {
    let write_error = |error| RecordError::Write {
        path: options.output.clone(),
        error,
    };
    let writer = context
        .mcap_writer_with_options(
            McapWriteOptions::new()
                .compression(Some(McapCompression::Zstd))
                .chunk_size(Some(CHUNK_SIZE))
                .profile(""),
        )
        .create(SyncedFile(file))
        .map_err(write_error)?;
    let metadata = [
        ("robot".to_owned(), options.robot.clone()),
        (
            "recorder".to_owned(),
            format!("scout-foxglove {}", env!("CARGO_PKG_VERSION")),
        ),
        (
            "log_time".to_owned(),
            "the gateway's CLOCK_BOOTTIME receive (state) or send (command) time, shifted to \
             Unix time when the recording started"
                .to_owned(),
        ),
    ]
    .into_iter()
    .collect();
    writer
        .write_metadata("scout", metadata)
        .map_err(write_error)?;
    Ok(writer)
}
