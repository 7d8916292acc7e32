//! `scout record --ros2`: the chassis as ROS 2 messages (CDR, `ros2msg` schemas, the `ros2`
//! profile), in a bag directory with its `metadata.yaml`, as rosbag2's MCAP storage writes
//! them, so `ros2 bag`, rosbags and Foxglove's ROS panels take it. The messages are the ROS 2
//! bridge's own ([`scout_ros2::publish`]), made from the same states; `~/cmd_vel_sent` is each
//! motion command the gateway sent (not `/cmd_vel`: a bag played beside a running `scout ros2`
//! would drive the robot with it).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use foxglove::{Context, PartialMetadata, RawChannel, Schema};
use scout_interface::StatePayload;
use scout_interface::control::StatusPayload;
use scout_ros2::config::Ros2Config;
use scout_ros2::definitions;
use scout_ros2::msgs::{self, MessageType, PlanarTwist};
use scout_ros2::publish::{Clocks, Messages, Topic};

use crate::channels::ChannelError;
use crate::source::Transcribe;

/// What a recording's topics carry: the bridge's topics and the commands sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Recorded {
    /// One of the bridge's topics.
    Published(Topic),
    /// Each motion command the gateway sent (after the arbiter), `geometry_msgs/Twist`.
    CmdVel,
}

/// The topic of the commands sent, private to the node's name (`/scout/cmd_vel_sent` by
/// default): never `/cmd_vel`, which `scout ros2` takes commands from.
pub const CMD_VEL_SENT: &str = "~/cmd_vel_sent";

/// A command older than this before the first state is not recorded (the last one of a
/// link closed long ago would stretch the bag's start back to it).
const STALE_COMMAND: Duration = Duration::from_secs(1);

impl Recorded {
    /// Every topic a recording may have (`/tf` only where the settings publish it).
    pub fn all() -> impl Iterator<Item = Recorded> {
        Topic::ALL
            .into_iter()
            .map(Recorded::Published)
            .chain([Recorded::CmdVel])
    }

    /// Its message type.
    pub fn message(self) -> MessageType {
        match self {
            Recorded::Published(topic) => topic.message(),
            Recorded::CmdVel => msgs::TWIST,
        }
    }

    /// Its topic, resolved (absolute), or `None` when the settings switch it off.
    pub fn name(self, config: &Ros2Config) -> Option<String> {
        match self {
            Recorded::Published(topic) => topic.name(config).map(|name| config.resolve(name)),
            Recorded::CmdVel => Some(config.resolve(CMD_VEL_SENT)),
        }
    }
}

/// One message to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Message {
    /// Its topic.
    pub topic: Recorded,
    /// ns since the Unix epoch: when the gateway read (or, for `/cmd_vel`, sent) it.
    pub log_time_ns: u64,
    /// CDR, its encapsulation header first.
    pub payload: Vec<u8>,
}

/// States and statuses in, ROS 2 messages out (sans-IO: the clocks' offset given).
#[derive(Debug)]
pub struct Ros2Transcript {
    messages: Messages,
    /// CLOCK_REALTIME minus CLOCK_BOOTTIME, ns.
    realtime_offset_ns: i128,
    last_status: Option<StatusPayload>,
    last_command_ns: Option<u64>,
    first_state_ns: Option<u64>,
}

impl Ros2Transcript {
    /// Messages as `config` names them, the gateway's times shifted by `realtime_offset_ns`.
    pub fn new(config: Ros2Config, realtime_offset_ns: i128) -> Self {
        Self {
            messages: Messages::made_by(config, "recorder"),
            realtime_offset_ns,
            last_status: None,
            last_command_ns: None,
            first_state_ns: None,
        }
    }

    fn unix_ns(&self, at_ns: u64) -> u64 {
        (i128::from(at_ns) + self.realtime_offset_ns).clamp(0, i128::from(u64::MAX)) as u64
    }
}

impl Transcribe for Ros2Transcript {
    type Item = Ros2Message;

    fn handle_state(&mut self, state: &StatePayload, out: &mut Vec<Ros2Message>) {
        let first = *self.first_state_ns.get_or_insert(state.published_ns);
        let command = &state.command;
        let fresh = command.at_ns + STALE_COMMAND.as_nanos() as u64 >= first;
        if command.at_ns != 0 && fresh && self.last_command_ns != Some(command.at_ns) {
            self.last_command_ns = Some(command.at_ns);
            out.push(Ros2Message {
                topic: Recorded::CmdVel,
                log_time_ns: self.unix_ns(command.at_ns),
                payload: msgs::encode_twist(PlanarTwist {
                    linear: command.linear,
                    lateral: command.lateral,
                    angular: command.angular,
                }),
            });
        }
        let published = self.unix_ns(state.published_ns);
        let clocks = Clocks {
            monotonic_ns: state.published_ns,
            unix: Duration::from_nanos(published),
        };
        let made = self
            .messages
            .handle_state(state, self.last_status.as_ref(), clocks, &Vec::new);
        out.extend(made.into_iter().map(|message| Ros2Message {
            topic: Recorded::Published(message.topic),
            log_time_ns: published,
            payload: message.payload,
        }));
    }

    fn handle_status(&mut self, status: &StatusPayload, _out: &mut Vec<Ros2Message>) {
        // Read into the next diagnostics.
        self.last_status = Some(*status);
    }
}

/// A topic's count and times, for the bag's metadata.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Counted {
    messages: u64,
    first_ns: Option<u64>,
    last_ns: u64,
}

/// The ROS 2 channels on one Foxglove context, and what went through them.
#[derive(Debug)]
pub struct Ros2Channels {
    channels: BTreeMap<Recorded, (String, Arc<RawChannel>)>,
    counted: BTreeMap<Recorded, Counted>,
}

impl Ros2Channels {
    /// A channel for each topic `config` publishes, with its `ros2msg` schema.
    pub fn new(context: &Arc<Context>, config: &Ros2Config) -> Result<Self, ChannelError> {
        let mut channels = BTreeMap::new();
        for recorded in Recorded::all() {
            let Some(name) = recorded.name(config) else {
                continue;
            };
            let message = recorded.message();
            let schema = definitions::schema(message).unwrap_or_default();
            let channel = context
                .channel_builder(name.as_str())
                .message_encoding("cdr")
                .schema(Schema::new(message.name, "ros2msg", schema.into_bytes()))
                .metadata(
                    [("offered_qos_profiles".to_owned(), String::new())]
                        .into_iter()
                        .collect(),
                )
                .build_raw()
                .map_err(|error| ChannelError::new(&name, error))?;
            channels.insert(recorded, (name, channel));
        }
        Ok(Self {
            channels,
            counted: BTreeMap::new(),
        })
    }

    /// Writes one message (one of a topic switched off is dropped).
    pub fn write(&mut self, message: &Ros2Message) {
        let Some((_, channel)) = self.channels.get(&message.topic) else {
            return;
        };
        channel.log_with_meta(
            &message.payload,
            PartialMetadata::with_log_time(message.log_time_ns),
        );
        let counted = self.counted.entry(message.topic).or_default();
        counted.messages += 1;
        counted.first_ns.get_or_insert(message.log_time_ns);
        counted.last_ns = counted.last_ns.max(message.log_time_ns);
    }

    /// The channels (topics).
    pub fn count(&self) -> usize {
        self.channels.len()
    }

    /// Messages written, all topics.
    pub fn written(&self) -> u64 {
        self.counted.values().map(|counted| counted.messages).sum()
    }

    /// The bag's `metadata.yaml` for what was written so far into `file` (its name).
    pub fn metadata_yaml(&self, file: &str) -> String {
        let topics: Vec<BagTopic<'_>> = self
            .channels
            .iter()
            .map(|(recorded, (name, _))| BagTopic {
                name,
                message: recorded.message().name,
                count: self.counted.get(recorded).map_or(0, |c| c.messages),
            })
            .collect();
        let first = self.counted.values().filter_map(|c| c.first_ns).min();
        let last = self.counted.values().map(|c| c.last_ns).max();
        bag_metadata(file, &topics, first.zip(last))
    }
}

/// One topic of a bag's metadata.
#[derive(Debug, Clone, PartialEq)]
struct BagTopic<'a> {
    name: &'a str,
    message: &'a str,
    count: u64,
}

/// rosbag2's `metadata.yaml` (version 5: what Humble writes and every later rosbag2 and rosbags
/// read) for one MCAP file, its topics and `span` (first and last log time, ns since the epoch).
fn bag_metadata(file: &str, topics: &[BagTopic<'_>], span: Option<(u64, u64)>) -> String {
    let (start, duration) = span.map_or((0, 0), |(first, last)| (first, last - first));
    let total: u64 = topics.iter().map(|topic| topic.count).sum();
    // The file's name double-quoted (a bag's name may hold YAML's own characters).
    let file = format!("\"{}\"", file.replace('\\', "\\\\").replace('"', "\\\""));
    let mut yaml = format!(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  \
         duration:\n    nanoseconds: {duration}\n  starting_time:\n    \
         nanoseconds_since_epoch: {start}\n  message_count: {total}\n  \
         topics_with_message_count:\n"
    );
    for topic in topics {
        yaml.push_str(&format!(
            "    - topic_metadata:\n        name: {}\n        type: {}\n        \
             serialization_format: cdr\n        offered_qos_profiles: \"\"\n      \
             message_count: {}\n",
            topic.name, topic.message, topic.count
        ));
    }
    yaml.push_str(&format!(
        "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    \
         - {file}\n  files:\n    - path: {file}\n      starting_time:\n        \
         nanoseconds_since_epoch: {start}\n      duration:\n        nanoseconds: {duration}\n      \
         message_count: {total}\n"
    ));
    yaml
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_metadata_names_each_topic_its_type_and_count() {
        let topics = [
            BagTopic {
                name: "/odom",
                message: "nav_msgs/msg/Odometry",
                count: 50,
            },
            BagTopic {
                name: "/cmd_vel",
                message: "geometry_msgs/msg/Twist",
                count: 0,
            },
        ];
        let yaml = bag_metadata("run_0.mcap", &topics, Some((1_000, 3_500)));
        assert!(yaml.starts_with("rosbag2_bagfile_information:\n  version: 5\n"));
        for expected in [
            "  storage_identifier: mcap\n",
            "    nanoseconds: 2500\n",
            "    nanoseconds_since_epoch: 1000\n",
            "  message_count: 50\n",
            "        name: /odom\n        type: nav_msgs/msg/Odometry\n        serialization_format: cdr\n",
            "        name: /cmd_vel\n        type: geometry_msgs/msg/Twist\n",
            "  relative_file_paths:\n    - \"run_0.mcap\"\n",
        ] {
            assert!(yaml.contains(expected), "{expected:?} in\n{yaml}");
        }
        // A name YAML would misread goes quoted.
        assert!(
            bag_metadata("run: \"2\"_0.mcap", &topics, None)
                .contains("    - \"run: \\\"2\\\"_0.mcap\"\n")
        );
        // Nothing written yet: a bag of no messages, readable all the same.
        assert!(bag_metadata("x_0.mcap", &topics, None).contains("  message_count: 50\n"));
    }

    #[test]
    fn commands_are_recorded_once_each_and_a_stale_first_one_not_at_all() {
        let mut transcript = Ros2Transcript::new(Ros2Config::default(), 0);
        let mut state = StatePayload {
            published_ns: 3_600_000_000_000,
            ..StatePayload::default()
        };
        // The command of a link closed an hour ago.
        state.command.at_ns = 1_000_000_000;
        state.command.linear = 0.5;
        let commands = |transcript: &mut Ros2Transcript, state: &StatePayload| {
            let mut out = Vec::new();
            transcript.handle_state(state, &mut out);
            out.iter()
                .filter(|message| message.topic == Recorded::CmdVel)
                .map(|message| message.log_time_ns)
                .collect::<Vec<_>>()
        };
        assert!(commands(&mut transcript, &state).is_empty());
        state.published_ns += 20_000_000;
        state.command.at_ns = state.published_ns - 5_000_000;
        assert_eq!(commands(&mut transcript, &state), [state.command.at_ns]);
        // The same command in the next state: not again.
        state.published_ns += 20_000_000;
        assert!(commands(&mut transcript, &state).is_empty());
    }

    #[test]
    fn topics_resolve_in_the_namespace_and_tf_follows_the_setting() {
        let mut config = Ros2Config::default();
        let names: Vec<Option<String>> = Recorded::all()
            .map(|recorded| recorded.name(&config))
            .collect();
        assert!(names.contains(&Some("/odom".into())), "{names:?}");
        assert!(names.contains(&Some("/tf".into())));
        assert!(
            names.contains(&Some("/scout/cmd_vel_sent".into())),
            "{names:?}"
        );
        config.namespace = "/robot1".into();
        config.publish_tf = false;
        assert_eq!(
            Recorded::Published(Topic::Odom).name(&config),
            Some("/robot1/odom".into())
        );
        assert_eq!(Recorded::Published(Topic::Tf).name(&config), None);
    }
}
