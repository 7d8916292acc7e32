//! The channels a recording and the live view carry, on one Foxglove context: their topics,
//! schemas and encodings, and how each transcript entry is written to them.

use std::sync::Arc;

use foxglove::messages::log::Level;
use foxglove::messages::{FrameTransform, Log, Pose, PoseInFrame, Quaternion, Timestamp, Vector3};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use serde_json::{Value, json};

use crate::schema;
use crate::transcript::{Entry, Timed};

/// The chassis state, JSON (`scout.State`).
pub const STATE_TOPIC: &str = "/scout/state";
/// Each motion command as sent, JSON (`scout.Command`).
pub const COMMAND_TOPIC: &str = "/scout/command";
/// The arbiter's status, JSON (`scout.Status`).
pub const STATUS_TOPIC: &str = "/scout/status";
/// The arbiter's events, `foxglove.Log`.
pub const EVENTS_TOPIC: &str = "/scout/events";
/// The odometry pose, `foxglove.PoseInFrame` in `odom`.
pub const POSE_TOPIC: &str = "/scout/pose";
/// `odom` to `base_link`, `foxglove.FrameTransform`.
pub const TF_TOPIC: &str = "/tf";
/// Every topic, in the order they are advertised.
pub const TOPICS: [&str; 6] = [
    STATE_TOPIC,
    COMMAND_TOPIC,
    STATUS_TOPIC,
    EVENTS_TOPIC,
    POSE_TOPIC,
    TF_TOPIC,
];

/// The fixed frame of the odometry.
pub const ODOM_FRAME: &str = "odom";
/// The robot's frame.
pub const BASE_FRAME: &str = "base_link";

/// What could not be set up.
#[derive(Debug, thiserror::Error)]
#[error("creating the Foxglove channel {topic}: {error}")]
pub struct ChannelError {
    topic: String,
    error: foxglove::FoxgloveError,
}

impl ChannelError {
    /// `topic`'s channel could not be made.
    pub fn new(topic: &str, error: foxglove::FoxgloveError) -> Self {
        Self {
            topic: topic.to_owned(),
            error,
        }
    }
}

/// The channels, made on one context (a recording's or the live server's).
#[derive(Debug)]
pub struct Channels {
    state: Arc<RawChannel>,
    command: Arc<RawChannel>,
    status: Arc<RawChannel>,
    events: Channel<Log>,
    pose: Channel<PoseInFrame>,
    tf: Channel<FrameTransform>,
    robot: String,
    /// Messages written, all channels.
    written: u64,
}

fn json_channel(
    context: &Arc<Context>,
    topic: &'static str,
    schema: Value,
) -> Result<Arc<RawChannel>, ChannelError> {
    let name = schema["title"].as_str().unwrap_or(topic).to_owned();
    context
        .channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(
            name,
            "jsonschema",
            schema.to_string().into_bytes(),
        ))
        .build_raw()
        .map_err(|error| ChannelError::new(topic, error))
}

fn timestamp(unix_ns: u64) -> Timestamp {
    let sec = u32::try_from(unix_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (unix_ns % 1_000_000_000) as u32)
}

/// A stop latching and control being revoked are warnings; the rest (releases, takeovers,
/// resumes) is information.
fn event_level(text: &str) -> Level {
    if text.starts_with("STOP #") || text.starts_with("control revoked") {
        Level::Warning
    } else {
        Level::Info
    }
}

impl Channels {
    /// Advertises every channel on `context` for robot `robot`.
    pub fn new(context: &Arc<Context>, robot: &str) -> Result<Self, ChannelError> {
        Ok(Self {
            state: json_channel(context, STATE_TOPIC, schema::state())?,
            command: json_channel(context, COMMAND_TOPIC, schema::command())?,
            status: json_channel(context, STATUS_TOPIC, schema::status())?,
            events: context.channel_builder(EVENTS_TOPIC).build(),
            pose: context.channel_builder(POSE_TOPIC).build(),
            tf: context.channel_builder(TF_TOPIC).build(),
            robot: robot.to_owned(),
            written: 0,
        })
    }

    /// Messages written so far, all channels together.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Writes one entry to its channels, with its time as the log time.
    pub fn write(&mut self, timed: &Timed) {
        let time = PartialMetadata::with_log_time(timed.time_ns);
        let stamp = Some(timestamp(timed.time_ns));
        match &timed.entry {
            Entry::State(state) => self.state.log_with_meta(state.to_string().as_bytes(), time),
            Entry::Command { linear, angular } => {
                let command = json!({ "linear": linear, "angular": angular });
                self.command
                    .log_with_meta(command.to_string().as_bytes(), time);
            }
            Entry::Status(status) => self
                .status
                .log_with_meta(status.to_string().as_bytes(), time),
            Entry::Event(text) => {
                let log = Log {
                    timestamp: stamp,
                    level: event_level(text) as i32,
                    message: text.clone(),
                    name: format!("scout-gateway {}", self.robot),
                    file: String::new(),
                    line: 0,
                };
                self.events.log_with_meta(&log, time);
            }
            Entry::Pose { x, y, yaw } => {
                let translation = Some(Vector3 {
                    x: *x,
                    y: *y,
                    z: 0.0,
                });
                let rotation = Some(Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: (yaw / 2.0).sin(),
                    w: (yaw / 2.0).cos(),
                });
                self.pose.log_with_meta(
                    &PoseInFrame {
                        timestamp: stamp,
                        frame_id: ODOM_FRAME.to_owned(),
                        pose: Some(Pose {
                            position: translation,
                            orientation: rotation,
                        }),
                    },
                    time,
                );
                self.tf.log_with_meta(
                    &FrameTransform {
                        timestamp: stamp,
                        parent_frame_id: ODOM_FRAME.to_owned(),
                        child_frame_id: BASE_FRAME.to_owned(),
                        translation,
                        rotation,
                    },
                    time,
                );
                self.written += 1;
            }
        }
        self.written += 1;
    }
}
