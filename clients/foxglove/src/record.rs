//! `scout record`: the transcript into an MCAP file (or, with `--ros2`, ROS 2 messages into a
//! rosbag2 bag: [`crate::ros2`]), zstd chunks, indexed, one chunk closed and synced to disk
//! every second so that a recording cut by SIGKILL or a power loss keeps all but its last
//! second (a bag's `metadata.yaml` is rewritten with it).

use std::fs::{File, OpenOptions};
use std::io::{IsTerminal, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use foxglove::{Context, McapCompression, McapWriteOptions, McapWriterHandle};
use scout_clients::failure::{Failure, FailureKind};
use tracing::{info, warn};

use crate::channels::{ChannelError, Channels, TOPICS};
use crate::ros2::{Ros2Channels, Ros2Message, Ros2Transcript};
use crate::source::{Source, SourceError, Update, realtime_offset_ns};
use crate::transcript::Timed;

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
    /// The file to write (with `ros2`: the bag's directory).
    pub output: PathBuf,
    /// ROS 2 messages, named as these settings (`scout ros2`'s) name them, in a rosbag2 bag,
    /// instead of the Foxglove channels.
    pub ros2: Option<scout_ros2::config::Ros2Config>,
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
    /// The bag's metadata could not be written.
    #[error("writing the bag's metadata {path}")]
    Metadata {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
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

/// An existing file is a usage error.
impl FailureKind for RecordError {
    fn kind(&self) -> Failure {
        match self {
            Self::Exists(_) => Failure::Usage,
            Self::Source(error) => error.kind(),
            Self::Read(error) => error.kind(),
            Self::Create { .. }
            | Self::Channel(_)
            | Self::Write { .. }
            | Self::Metadata { .. }
            | Self::Sync { .. } => Failure::Failed,
        }
    }
}

/// What was recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Messages written, all channels.
    pub messages: u64,
    /// The channels (topics) in the file.
    pub channels: usize,
    /// The MCAP file written (in a bag: the one file in its directory).
    pub file: PathBuf,
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

/// Where recorded items go: the Foxglove channels or a bag's ROS 2 channels.
trait Sink {
    /// What it writes.
    type Item;
    fn write(&mut self, item: &Self::Item);
    /// Messages written so far.
    fn written(&self) -> u64;
    /// How many channels it has.
    fn channels(&self) -> usize;
    /// After each sync of the file (and at its close): what else must be on disk.
    fn synced(&mut self) -> Result<(), RecordError> {
        Ok(())
    }
}

impl Sink for Channels {
    type Item = Timed;

    fn write(&mut self, item: &Timed) {
        Channels::write(self, item);
    }

    fn written(&self) -> u64 {
        Channels::written(self)
    }

    fn channels(&self) -> usize {
        TOPICS.len()
    }
}

/// A bag's metadata, and the file it is written to before it is renamed over it.
const METADATA: &str = "metadata.yaml";
const METADATA_PARTIAL: &str = ".metadata.yaml.partial";

/// A rosbag2 bag: its channels, and its `metadata.yaml` rewritten (whole, then renamed over)
/// at each sync, so that a bag cut short is still one rosbag2 and rosbags open.
struct Bag {
    channels: Ros2Channels,
    dir: PathBuf,
    file: String,
}

impl Sink for Bag {
    type Item = Ros2Message;

    fn write(&mut self, item: &Ros2Message) {
        self.channels.write(item);
    }

    fn written(&self) -> u64 {
        self.channels.written()
    }

    fn channels(&self) -> usize {
        self.channels.count()
    }

    fn synced(&mut self) -> Result<(), RecordError> {
        let path = self.dir.join(METADATA);
        let partial = self.dir.join(METADATA_PARTIAL);
        let metadata = |source| RecordError::Metadata {
            path: path.clone(),
            source,
        };
        let mut file = File::create(&partial).map_err(metadata)?;
        file.write_all(self.channels.metadata_yaml(&self.file).as_bytes())
            .and_then(|()| file.sync_all())
            .map_err(metadata)?;
        std::fs::rename(&partial, &path).map_err(metadata)?;
        // The rename itself on disk too.
        File::open(&self.dir)
            .and_then(|dir| dir.sync_all())
            .map_err(metadata)
    }
}

/// Records until `options.duration` passes or `stop` is set; closes the file with its summary
/// and index either way.
pub fn record(options: &RecordOptions, stop: &AtomicBool) -> Result<Summary, RecordError> {
    let output = &options.output;
    if output.exists() && !options.force {
        return Err(RecordError::Exists(output.clone()));
    }
    let Some(config) = &options.ros2 else {
        // Connect before creating the file: no gateway leaves no empty file behind.
        let source = Source::start(&options.robot)?;
        let context = Context::new();
        let writer = start_writer(&context, create_output(output, options.force)?, options, "")?;
        let channels = Channels::new(&context, &options.robot)?;
        return run(options, output, source, writer, channels, stop);
    };
    let source = Source::start_with(
        &options.robot,
        Ros2Transcript::new(config.clone(), realtime_offset_ns()),
    )?;
    // rosbag2's name for the first (here the only) file of a bag.
    let name = output
        .file_name()
        .map_or("bag".into(), |name| name.to_string_lossy().into_owned());
    let file = format!("{name}_0.mcap");
    make_bag_dir(output, &file)?;
    let path = output.join(&file);
    let context = Context::new();
    let writer = start_writer(
        &context,
        create_output(&path, options.force)?,
        options,
        "ros2",
    )?;
    let mut bag = Bag {
        channels: Ros2Channels::new(&context, config)?,
        dir: output.clone(),
        file,
    };
    bag.synced()?;
    run(options, &path, source, writer, bag, stop)
}

/// The bag's directory `dir`, made, or (`--force`) one that is empty or holds a bag emptied
/// of that bag's files (`file`, the metadata); any other directory or a file is refused, so
/// `--force` never drops a bag into, or deletes from, a directory that is not one.
fn make_bag_dir(dir: &Path, file: &str) -> Result<(), RecordError> {
    let refuse = |why: &str| RecordError::Create {
        path: dir.to_owned(),
        source: std::io::Error::other(why.to_owned()),
    };
    if dir.exists() {
        if !dir.is_dir() {
            return Err(refuse("not a directory: a ROS 2 bag is a directory"));
        }
        let entries: Vec<std::ffi::OsString> = std::fs::read_dir(dir)
            .and_then(|entries| entries.map(|entry| entry.map(|e| e.file_name())).collect())
            .map_err(|source| RecordError::Create {
                path: dir.to_owned(),
                source,
            })?;
        if !entries.is_empty() && !entries.iter().any(|entry| entry == METADATA) {
            return Err(refuse(
                "a directory with other files than a bag's: give a new or empty directory",
            ));
        }
        for name in [file, METADATA, METADATA_PARTIAL] {
            match std::fs::remove_file(dir.join(name)) {
                Err(error) if error.kind() != std::io::ErrorKind::NotFound => {
                    return Err(RecordError::Create {
                        path: dir.join(name),
                        source: error,
                    });
                }
                _ => {}
            }
        }
        return Ok(());
    }
    std::fs::create_dir_all(dir).map_err(|source| RecordError::Create {
        path: dir.to_owned(),
        source,
    })
}

/// The recording loop: `source`'s items into `sink` on `writer`'s file `path`.
fn run<S: Sink>(
    options: &RecordOptions,
    path: &Path,
    source: Source<S::Item>,
    writer: McapWriterHandle<SyncedFile>,
    mut channels: S,
    stop: &AtomicBool,
) -> Result<Summary, RecordError>
where
    S::Item: Send + 'static,
{
    let write_error = |error| RecordError::Write {
        path: path.to_owned(),
        error,
    };
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
            if let Err(error) = channels.synced() {
                break Err(error);
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
    // What else must be on disk follows what the file holds, whatever went wrong.
    let synced = channels.synced();
    outcome?;
    let mut file = closed?;
    file.flush().map_err(|source| RecordError::Sync {
        path: path.to_owned(),
        source,
    })?;
    synced?;
    let summary = Summary {
        messages: channels.written(),
        channels: channels.channels(),
        file: path.to_owned(),
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
fn create_output(path: &Path, force: bool) -> Result<File, RecordError> {
    // Without --force, a file made in the meantime is not replaced either.
    OpenOptions::new()
        .write(true)
        .create_new(!force)
        .create(force)
        .truncate(force)
        .open(path)
        .map_err(|source| match source.kind() {
            std::io::ErrorKind::AlreadyExists => RecordError::Exists(path.to_owned()),
            _ => RecordError::Create {
                path: path.to_owned(),
                source,
            },
        })
}

/// The MCAP writer on `file` (of MCAP `profile`), with the recording's metadata written.
fn start_writer(
    context: &std::sync::Arc<Context>,
    file: File,
    options: &RecordOptions,
    profile: &str,
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
                .profile(profile),
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
