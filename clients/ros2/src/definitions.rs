//! The message definitions (`.msg` text) of the types the bridge and recorder write, as a
//! recording's schemas carry them: MCAP's `ros2msg` encoding, the type's own definition then
//! each type it uses, once, after a line of `=` and `MSG: package/Type` (as rosbag2 writes).

use crate::msgs::MessageType;

/// The separator before each dependency's definition.
const SEPARATOR: &str =
    "================================================================================";

/// Every definition: `package/Type` and its fields (constants where the message has them).
/// The fields as the ROS 2 interface packages declare them (Humble to Kilted alike; Iron added
/// two BatteryState technology constants, which change neither the bytes nor the type hash).
const DEFINITIONS: [(&str, &str); 21] = [
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/TwistStamped",
        "std_msgs/Header header\ngeometry_msgs/Twist twist\n",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\n\
         geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
    (
        "sensor_msgs/BatteryState",
        "uint8 POWER_SUPPLY_STATUS_UNKNOWN = 0\n\
         uint8 POWER_SUPPLY_STATUS_CHARGING = 1\n\
         uint8 POWER_SUPPLY_STATUS_DISCHARGING = 2\n\
         uint8 POWER_SUPPLY_STATUS_NOT_CHARGING = 3\n\
         uint8 POWER_SUPPLY_STATUS_FULL = 4\n\
         uint8 POWER_SUPPLY_HEALTH_UNKNOWN = 0\n\
         uint8 POWER_SUPPLY_HEALTH_GOOD = 1\n\
         uint8 POWER_SUPPLY_HEALTH_OVERHEAT = 2\n\
         uint8 POWER_SUPPLY_HEALTH_DEAD = 3\n\
         uint8 POWER_SUPPLY_HEALTH_OVERVOLTAGE = 4\n\
         uint8 POWER_SUPPLY_HEALTH_UNSPEC_FAILURE = 5\n\
         uint8 POWER_SUPPLY_HEALTH_COLD = 6\n\
         uint8 POWER_SUPPLY_HEALTH_WATCHDOG_TIMER_EXPIRE = 7\n\
         uint8 POWER_SUPPLY_HEALTH_SAFETY_TIMER_EXPIRE = 8\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_UNKNOWN = 0\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_NIMH = 1\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_LION = 2\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_LIPO = 3\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_LIFE = 4\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_NICD = 5\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_LIMN = 6\n\
         std_msgs/Header header\nfloat32 voltage\nfloat32 temperature\nfloat32 current\n\
         float32 charge\nfloat32 capacity\nfloat32 design_capacity\nfloat32 percentage\n\
         uint8 power_supply_status\nuint8 power_supply_health\nuint8 power_supply_technology\n\
         bool present\nfloat32[] cell_voltage\nfloat32[] cell_temperature\nstring location\n\
         string serial_number\n",
    ),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
         float64[] effort\n",
    ),
    ("diagnostic_msgs/KeyValue", "string key\nstring value\n"),
    (
        "diagnostic_msgs/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\
         byte level\nstring name\nstring message\nstring hardware_id\n\
         diagnostic_msgs/KeyValue[] values\n",
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
    ),
    // ros-drivers/ackermann_msgs (ROS 2 releases): the fields, without the comments.
    (
        "ackermann_msgs/AckermannDrive",
        "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\n\
         float32 acceleration\nfloat32 jerk\n",
    ),
    (
        "ackermann_msgs/AckermannDriveStamped",
        "std_msgs/Header header\nackermann_msgs/AckermannDrive drive\n",
    ),
];

/// `package/msg/Type` without its `msg/`: how definitions name types.
fn short_name(name: &str) -> String {
    name.replacen("/msg/", "/", 1)
}

fn own(name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(defined, _)| *defined == name)
        .map(|(_, text)| *text)
}

/// The types a definition's fields use (not primitives), in order of first use.
fn uses(text: &str) -> impl Iterator<Item = &str> {
    text.lines()
        .filter(|line| !line.contains('='))
        .filter_map(|line| line.split_whitespace().next())
        .map(|kind| kind.split('[').next().unwrap_or(kind))
        .filter(|kind| kind.contains('/'))
}

/// The `ros2msg` schema text of `message`, or `None` for a type not listed here (a service).
pub fn schema(message: MessageType) -> Option<String> {
    let root = short_name(message.name);
    let mut text = own(&root)?.to_owned();
    let mut done = vec![root.clone()];
    let mut pending: Vec<String> = uses(&text).map(str::to_owned).collect();
    while let Some(next) = pending.first().cloned() {
        pending.remove(0);
        if done.contains(&next) {
            continue;
        }
        let definition = own(&next)?;
        text.push_str(&format!("{SEPARATOR}\nMSG: {next}\n{definition}"));
        pending.extend(uses(definition).map(str::to_owned));
        done.push(next);
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs;

    #[test]
    fn every_message_written_has_a_whole_schema() {
        for message in msgs::ALL {
            if message.name.contains("/srv/") {
                assert!(schema(message).is_none());
                continue;
            }
            let text = schema(message).unwrap_or_else(|| panic!("{}", message.name));
            // Every type used is defined once in it.
            let defined: Vec<&str> = text
                .lines()
                .filter_map(|line| line.strip_prefix("MSG: "))
                .collect();
            for used in uses(&text) {
                assert!(
                    defined.contains(&used),
                    "{}: {used} not defined",
                    message.name
                );
            }
            let mut unique = defined.clone();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(unique.len(), defined.len(), "{}", message.name);
        }
    }

    #[test]
    fn odometry_is_its_fields_then_its_types_in_order_of_use() {
        let text = schema(msgs::ODOMETRY).expect("listed");
        assert!(text.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
        let defined: Vec<&str> = text
            .lines()
            .filter_map(|line| line.strip_prefix("MSG: "))
            .collect();
        assert_eq!(
            defined,
            [
                "std_msgs/Header",
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/TwistWithCovariance",
                "builtin_interfaces/Time",
                "geometry_msgs/Pose",
                "geometry_msgs/Twist",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "geometry_msgs/Vector3",
            ]
        );
        assert!(text.contains(&format!("{SEPARATOR}\nMSG: std_msgs/Header\n")));
    }
}
