//! The ROS 2 messages the bridge publishes and receives, with their type names and RIHS01 type
//! hashes (REP 2016; checked against rosbags' `hash_rihs01` by the tests), written as CDR.

use scout_protocol::model::{Model, Steering};

use crate::cdr::{CdrError, Reader, Writer};

/// A ROS 2 message type as rmw_zenoh names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageType {
    /// `package/msg/Name`.
    pub name: &'static str,
    /// `package::msg::dds_::Name_`, the name in keys and liveliness tokens.
    pub dds_name: &'static str,
    /// `RIHS01_<sha256>` (Jazzy and later).
    pub hash: &'static str,
}

pub const ODOMETRY: MessageType = MessageType {
    name: "nav_msgs/msg/Odometry",
    dds_name: "nav_msgs::msg::dds_::Odometry_",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
pub const TWIST: MessageType = MessageType {
    name: "geometry_msgs/msg/Twist",
    dds_name: "geometry_msgs::msg::dds_::Twist_",
    hash: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
};
pub const TWIST_STAMPED: MessageType = MessageType {
    name: "geometry_msgs/msg/TwistStamped",
    dds_name: "geometry_msgs::msg::dds_::TwistStamped_",
    hash: "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
};
/// ros-drivers/ackermann_msgs: what a car-like robot's planners publish (its hash as rosbags
/// computes it from the fields).
pub const ACKERMANN_DRIVE_STAMPED: MessageType = MessageType {
    name: "ackermann_msgs/msg/AckermannDriveStamped",
    dds_name: "ackermann_msgs::msg::dds_::AckermannDriveStamped_",
    hash: "RIHS01_48ca7612a08d3bb72744fd98b71b7cf2ea24c6ad50fa4e1aa0bbad963c90d8cf",
};
pub const TF_MESSAGE: MessageType = MessageType {
    name: "tf2_msgs/msg/TFMessage",
    dds_name: "tf2_msgs::msg::dds_::TFMessage_",
    hash: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
};
pub const BATTERY_STATE: MessageType = MessageType {
    name: "sensor_msgs/msg/BatteryState",
    dds_name: "sensor_msgs::msg::dds_::BatteryState_",
    hash: "RIHS01_4bee5dfce981c98faa6828b868307a0a73f992ed0789f374ee96c8f840e69741",
};
pub const JOINT_STATE: MessageType = MessageType {
    name: "sensor_msgs/msg/JointState",
    dds_name: "sensor_msgs::msg::dds_::JointState_",
    hash: "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
};
pub const DIAGNOSTIC_ARRAY: MessageType = MessageType {
    name: "diagnostic_msgs/msg/DiagnosticArray",
    dds_name: "diagnostic_msgs::msg::dds_::DiagnosticArray_",
    hash: "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
};

/// A service: `std_srvs/srv/Trigger` (the e-stop and release services). Its hash is the
/// service type's (request, response and event messages), as rmw_zenoh keys services.
pub const TRIGGER: MessageType = MessageType {
    name: "std_srvs/srv/Trigger",
    dds_name: "std_srvs::srv::dds_::Trigger_",
    hash: "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
};

/// Every type the bridge speaks, for the hash test.
pub const ALL: [MessageType; 9] = [
    ODOMETRY,
    TWIST,
    TWIST_STAMPED,
    ACKERMANN_DRIVE_STAMPED,
    TF_MESSAGE,
    BATTERY_STATE,
    JOINT_STATE,
    DIAGNOSTIC_ARRAY,
    TRIGGER,
];

/// `builtin_interfaces/Time` and `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq)]
pub struct Header<'a> {
    /// Since the Unix epoch.
    pub stamp: std::time::Duration,
    pub frame_id: &'a str,
}

impl Header<'_> {
    fn write(&self, w: &mut Writer) {
        w.i32(self.stamp.as_secs() as i32)
            .u32(self.stamp.subsec_nanos())
            .string(self.frame_id);
    }
}

/// A planar pose and twist: what a skid-steer robot's odometry has.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry<'a> {
    pub header: Header<'a>,
    pub child_frame_id: &'a str,
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
    pub linear: f64,
    /// m/s leftward (0 but on a chassis that moves sideways).
    pub lateral: f64,
    pub angular: f64,
    /// Row-major 6x6 diagonal (x, y, z, roll, pitch, yaw).
    pub pose_covariance: [f64; 6],
    pub twist_covariance: [f64; 6],
}

/// The quaternion (x, y, z, w) of a rotation by `yaw` about z.
pub fn yaw_quaternion(yaw: f64) -> [f64; 4] {
    [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()]
}

fn covariance(w: &mut Writer, diagonal: &[f64; 6]) {
    for (row, value) in diagonal.iter().enumerate() {
        for column in 0..6 {
            w.f64(if row == column { *value } else { 0.0 });
        }
    }
}

impl Odometry<'_> {
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        self.header.write(&mut w);
        w.string(self.child_frame_id);
        w.f64s(&[self.x, self.y, 0.0])
            .f64s(&yaw_quaternion(self.yaw));
        covariance(&mut w, &self.pose_covariance);
        w.f64s(&[self.linear, self.lateral, 0.0, 0.0, 0.0, self.angular]);
        covariance(&mut w, &self.twist_covariance);
        w.finish()
    }
}

/// `tf2_msgs/TFMessage` with one planar transform.
#[derive(Debug, Clone, PartialEq)]
pub struct Transform<'a> {
    pub header: Header<'a>,
    pub child_frame_id: &'a str,
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
}

impl Transform<'_> {
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.sequence(1);
        self.header.write(&mut w);
        w.string(self.child_frame_id);
        w.f64s(&[self.x, self.y, 0.0])
            .f64s(&yaw_quaternion(self.yaw));
        w.finish()
    }
}

/// `sensor_msgs/BatteryState`: the voltage the chassis reports; the rest unknown (NaN) as the
/// message defines.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery<'a> {
    pub header: Header<'a>,
    pub voltage: f32,
    /// deg C; NaN when unknown.
    pub temperature: f32,
    /// A, negative while discharging; NaN when unknown.
    pub current: f32,
    /// Ah; NaN when unknown.
    pub design_capacity: f32,
    /// 0..1; NaN when unknown.
    pub percentage: f32,
    /// POWER_SUPPLY_STATUS_* (0 unknown, 1 charging, 2 discharging, 3 not charging, 4 full).
    pub status: u8,
    /// POWER_SUPPLY_HEALTH_* (0 unknown, 1 good, 3 dead, 4 overvoltage...).
    pub health: u8,
    pub present: bool,
}

impl Battery<'_> {
    /// POWER_SUPPLY_TECHNOLOGY_LIPO would be a guess: the chassis does not say.
    const TECHNOLOGY_UNKNOWN: u8 = 0;

    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        self.header.write(&mut w);
        w.f32(self.voltage)
            .f32(self.temperature)
            .f32(self.current)
            .f32(f32::NAN) // charge
            .f32(f32::NAN) // capacity
            .f32(self.design_capacity)
            .f32(self.percentage)
            .u8(self.status)
            .u8(self.health)
            .u8(Self::TECHNOLOGY_UNKNOWN)
            .bool(self.present)
            .sequence(0) // cell_voltage
            .sequence(0) // cell_temperature
            .string("") // location
            .string(""); // serial_number
        w.finish()
    }
}

/// `sensor_msgs/JointState`: the wheels whose motors report, or the steering joints (their
/// positions alone: velocity and effort empty, as the message allows).
#[derive(Debug, Clone, PartialEq)]
pub struct Joints<'a> {
    pub header: Header<'a>,
    pub names: Vec<&'a str>,
    /// rad.
    pub position: Vec<f64>,
    /// rad/s.
    pub velocity: Vec<f64>,
    /// Motor current, A (the chassis gives no torque).
    pub effort: Vec<f64>,
}

impl Joints<'_> {
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        self.header.write(&mut w);
        w.sequence(self.names.len());
        for name in &self.names {
            w.string(name);
        }
        for values in [&self.position, &self.velocity, &self.effort] {
            w.sequence(values.len()).f64s(values);
        }
        w.finish()
    }
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// OK 0, WARN 1, ERROR 2, STALE 3.
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<(String, String)>,
}

/// `diagnostic_msgs/DiagnosticArray`.
pub fn encode_diagnostics(header: &Header<'_>, statuses: &[Status]) -> Vec<u8> {
    let mut w = Writer::new();
    header.write(&mut w);
    w.sequence(statuses.len());
    for status in statuses {
        w.u8(status.level)
            .string(&status.name)
            .string(&status.message)
            .string(&status.hardware_id)
            .sequence(status.values.len());
        for (key, value) in &status.values {
            w.string(key).string(value);
        }
    }
    w.finish()
}

/// A `std_srvs/Trigger` response: whether it worked, and what happened.
pub fn encode_trigger_response(success: bool, message: &str) -> Vec<u8> {
    let mut w = Writer::new();
    w.bool(success).string(message);
    w.finish()
}

/// Reads a `std_srvs/Trigger` request: no fields, so the one placeholder byte that CDR gives an
/// empty structure (`structure_needs_at_least_one_member`).
pub fn decode_trigger_request(bytes: &[u8]) -> Result<(), CdrError> {
    let mut r = Reader::new(bytes)?;
    r.u8()?;
    r.finish()
}

/// The planar part of a `geometry_msgs/Twist`: linear x (m/s), linear y (m/s, leftward: a
/// chassis that moves sideways), angular z (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarTwist {
    pub linear: f64,
    pub lateral: f64,
    pub angular: f64,
}

/// What a topic that drives carries, decoded: a twist, or an Ackermann drive (made a twist
/// with the chassis' wheelbase, which the decoder does not know).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    Twist(PlanarTwist),
    Ackermann(AckermannDrive),
}

/// The part of an `ackermann_msgs/AckermannDrive` the bridge takes: the speed (m/s, forward)
/// and the steering angle (rad, positive to the left: the message's "virtual angle", a
/// bicycle's front wheel). Its `steering_angle_velocity`, `acceleration` and `jerk` are not
/// used: the gateway's own limits and ramps apply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AckermannDrive {
    pub speed: f64,
    pub steering_angle: f64,
}

impl AckermannDrive {
    /// The body velocity it asks of a chassis with `steering`: the speed, and the yaw rate of
    /// a bicycle at that steering angle, `speed * tan(angle) / wheelbase` (the inverse of the
    /// gateway's steering from a yaw rate).
    pub fn twist(&self, steering: &Steering) -> PlanarTwist {
        PlanarTwist {
            linear: self.speed,
            lateral: 0.0,
            angular: steering.yaw_rate(self.speed, self.steering_angle),
        }
    }

    /// [`AckermannDrive::twist`] for a chassis of `model` (`None`: not known yet), or why it
    /// makes none: a chassis that does not steer its front wheels, or an angle no wheel takes
    /// (a quarter turn or more: `tan` wraps, degrees sent as radians would turn the other way).
    pub fn twist_for(&self, model: Option<Model>) -> Result<PlanarTwist, NoTwist> {
        let steering = model.and_then(Model::steering).ok_or(NoTwist::NotSteered)?;
        if self.steering_angle.abs() >= core::f64::consts::FRAC_PI_2 {
            return Err(NoTwist::NotAWheelAngle);
        }
        Ok(self.twist(&steering))
    }
}

/// Why an Ackermann drive makes no twist ([`AckermannDrive::twist_for`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoTwist {
    /// The chassis does not steer its front wheels (or its model is not known yet).
    NotSteered,
    /// A steering angle of a quarter turn or more.
    NotAWheelAngle,
}

/// Reads an `ackermann_msgs/AckermannDriveStamped`.
pub fn decode_ackermann(bytes: &[u8]) -> Result<AckermannDrive, CdrError> {
    let mut r = Reader::new(bytes)?;
    r.i32()?;
    r.u32()?;
    r.skip_string()?;
    let steering_angle = r.f32()?;
    r.f32()?;
    let speed = r.f32()?;
    r.f32()?;
    r.f32()?;
    r.finish()?;
    Ok(AckermannDrive {
        speed: f64::from(speed),
        steering_angle: f64::from(steering_angle),
    })
}

/// Writes a planar `Twist` (what a recording's `/cmd_vel` carries).
pub fn encode_twist(twist: PlanarTwist) -> Vec<u8> {
    let mut w = Writer::new();
    w.f64s(&[twist.linear, twist.lateral, 0.0, 0.0, 0.0, twist.angular]);
    w.finish()
}

/// Reads a `Twist` (or, with `stamped`, a `TwistStamped`).
pub fn decode_twist(bytes: &[u8], stamped: bool) -> Result<PlanarTwist, CdrError> {
    let mut r = Reader::new(bytes)?;
    if stamped {
        r.i32()?;
        r.u32()?;
        r.skip_string()?;
    }
    let linear = r.f64()?;
    let lateral = r.f64()?;
    r.f64()?;
    r.f64()?;
    r.f64()?;
    let angular = r.f64()?;
    r.finish()?;
    Ok(PlanarTwist {
        linear,
        lateral,
        angular,
    })
}

#[cfg(test)]
mod tests {
    //! Golden vectors: rosbags' `serialize_cdr` (ROS 2 Jazzy type store) of the same messages,
    //! generated once and kept here; the system test compares against rosbags live.
    use super::*;
    use std::time::Duration;

    const ODOMETRY: &str = "0001000005000000fa000000050000006f646f6d000000000a000000626173655f6c696e6b00000000000000000000000000f83f000000000000d0bf000000000000000000000000000000000000000000000000f0054b74e8aede3f507d5b062815ec3f7b14ae47e17a843f0000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000007b14ae47e17a843f0000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000009a9999999999a93f333333333333d33f00000000000000000000000000000000000000000000000000000000000000009a9999999999b9bf7b14ae47e17a943f0000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000080842e410000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000007b14ae47e17aa43f";
    const TF: &str = "000100000100000005000000fa000000050000006f646f6d000000000a000000626173655f6c696e6b000000000000000000f83f000000000000d0bf000000000000000000000000000000000000000000000000f0054b74e8aede3f507d5b062815ec3f";
    const BATTERY: &str = "0001000005000000fa0000000a000000626173655f6c696e6b0000000000cc410000c07f0000c07f0000c07f0000c07f0000c07fcdcc4c3f02010001000000000000000001000000000000000100000000";
    const JOINTS: &str = "0001000005000000fa0000000a000000626173655f6c696e6b000000040000001200000066726f6e745f72696768745f776865656c0000001100000066726f6e745f6c6566745f776865656c0000000010000000726561725f6c6566745f776865656c0011000000726561725f72696768745f776865656c0000000004000000000000009a9999999999b93f9a9999999999c93f333333333333d33f9a9999999999d93f0400000000000000000000000000f03f000000000000f0bf000000000000f0bf000000000000f03f04000000000000009a9999999999e93f9a9999999999e9bf9a9999999999e9bf9a9999999999e93f";
    const DIAGNOSTICS: &str = "0001000005000000fa000000010000000000000002000000000000000c00000073636f75743a206c696e6b00030000006f6b00000600000073636f7574000000010000000a00000072785f6672616d657300000003000000313200020f00000073636f75743a20636861737369730000060000006573746f700000000600000073636f757400000000000000";
    const TWIST: &str = "00010000333333333333d33f00000000000000000000000000000000000000000000000000000000000000009a9999999999c93f";
    const TRIGGER_RESPONSE: &str = "00010000010000000800000073746f7070656400";
    const TWIST_STAMPED: &str = "0001000005000000fa0000000a000000626173655f6c696e6b000000000000000000e0bf0000000000000000000000000000000000000000000000000000000000000000000000000000d03f";
    /// rosbags' AckermannDriveStamped: stamp (1, 2), "base_link", steering 0.25, speed 0.5.
    const ACKERMANN: &str = "0001000001000000020000000a000000626173655f6c696e6b0000000000803e000000000000003f0000000000000000";

    fn hex(text: &str) -> Vec<u8> {
        (0..text.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&text[i..i + 2], 16).expect("hex"))
            .collect()
    }

    fn header(frame_id: &str) -> Header<'_> {
        Header {
            stamp: Duration::new(5, 250),
            frame_id,
        }
    }

    #[test]
    fn odometry_and_tf_match_rosbags() {
        let odometry = Odometry {
            header: header("odom"),
            child_frame_id: "base_link",
            x: 1.5,
            y: -0.25,
            yaw: 1.0,
            linear: 0.3,
            lateral: 0.0,
            angular: -0.1,
            pose_covariance: [0.01, 0.01, 1e6, 1e6, 1e6, 0.05],
            twist_covariance: [0.02, 1e6, 1e6, 1e6, 1e6, 0.04],
        };
        assert_eq!(odometry.encode(), hex(ODOMETRY));
        let transform = Transform {
            header: header("odom"),
            child_frame_id: "base_link",
            x: 1.5,
            y: -0.25,
            yaw: 1.0,
        };
        assert_eq!(transform.encode(), hex(TF));
    }

    #[test]
    fn battery_joints_and_diagnostics_match_rosbags() {
        let battery = Battery {
            header: header("base_link"),
            voltage: 25.5,
            temperature: f32::NAN,
            current: f32::NAN,
            design_capacity: f32::NAN,
            percentage: 0.8,
            status: 2,
            health: 1,
            present: true,
        };
        assert_eq!(battery.encode(), hex(BATTERY));
        let joints = Joints {
            header: header("base_link"),
            names: vec![
                "front_right_wheel",
                "front_left_wheel",
                "rear_left_wheel",
                "rear_right_wheel",
            ],
            position: vec![0.1, 0.2, 0.3, 0.4],
            velocity: vec![1.0, -1.0, -1.0, 1.0],
            effort: vec![0.8, -0.8, -0.8, 0.8],
        };
        assert_eq!(joints.encode(), hex(JOINTS));
        let statuses = [
            Status {
                level: 0,
                name: "scout: link".into(),
                message: "ok".into(),
                hardware_id: "scout".into(),
                values: vec![("rx_frames".into(), "12".into())],
            },
            Status {
                level: 2,
                name: "scout: chassis".into(),
                message: "estop".into(),
                hardware_id: "scout".into(),
                values: Vec::new(),
            },
        ];
        assert_eq!(encode_diagnostics(&header(""), &statuses), hex(DIAGNOSTICS));
    }

    #[test]
    fn the_trigger_response_matches_rosbags() {
        assert_eq!(
            encode_trigger_response(true, "stopped"),
            hex(TRIGGER_RESPONSE)
        );
    }

    #[test]
    fn twists_from_rosbags_decode() {
        assert_eq!(
            decode_twist(&hex(TWIST), false),
            Ok(PlanarTwist {
                linear: 0.3,
                lateral: 0.0,
                angular: 0.2
            })
        );
        assert_eq!(
            decode_twist(&hex(TWIST_STAMPED), true),
            Ok(PlanarTwist {
                linear: -0.5,
                lateral: 0.0,
                angular: 0.25
            })
        );
        assert!(decode_twist(&hex(TWIST)[..20], false).is_err());
        assert_eq!(
            decode_twist(&[0, 1, 0], false),
            Err(crate::cdr::CdrError::Truncated(3))
        );
        let mut long = hex(TWIST);
        long.extend([0; 64]);
        assert_eq!(
            decode_twist(&long, false),
            Err(crate::cdr::CdrError::Trailing(64))
        );
    }

    #[test]
    fn an_ackermann_drive_from_rosbags_decodes_and_is_a_bicycles_twist() {
        let drive = decode_ackermann(&hex(ACKERMANN)).expect("decodes");
        assert_eq!(
            drive,
            AckermannDrive {
                speed: 0.5,
                steering_angle: 0.25
            }
        );
        assert!(decode_ackermann(&hex(ACKERMANN)[..30]).is_err());
        assert!(decode_ackermann(&hex(TWIST)).is_err());
        // The Hunter 2.0's 0.650 m wheelbase: 0.5 m/s at 0.25 rad turns at 0.196 rad/s.
        let hunter = scout_protocol::model::Model::Hunter2
            .steering()
            .expect("steered");
        let twist = drive.twist(&hunter);
        assert_eq!((twist.linear, twist.lateral), (0.5, 0.0));
        assert!((twist.angular - 0.5 * 0.25_f64.tan() / 0.650).abs() < 1e-12);
        // Backing up with the wheels to the left turns clockwise, as a car does.
        let back = AckermannDrive {
            speed: -0.5,
            steering_angle: 0.25,
        };
        assert!(back.twist(&hunter).angular < 0.0);
        // For a model: the Hunter's twist; a skid-steer, an unknown model or an angle of a
        // quarter turn refused.
        use scout_protocol::model::Model;
        assert_eq!(drive.twist_for(Some(Model::Hunter2)), Ok(twist));
        assert_eq!(
            drive.twist_for(Some(Model::Scout2)),
            Err(NoTwist::NotSteered)
        );
        assert_eq!(drive.twist_for(None), Err(NoTwist::NotSteered));
        let degrees = AckermannDrive {
            speed: 0.5,
            steering_angle: 30.0,
        };
        assert_eq!(
            degrees.twist_for(Some(Model::Hunter2)),
            Err(NoTwist::NotAWheelAngle)
        );
        // The DDS reader's decoder reads the same.
        #[cfg(feature = "dds")]
        assert_eq!(
            crate::dds_wire::decode_ackermann(&hex(ACKERMANN)),
            Ok(drive)
        );
    }

    #[test]
    fn a_twist_written_is_rosbags_own() {
        let twist = PlanarTwist {
            linear: 0.3,
            lateral: 0.0,
            angular: 0.2,
        };
        assert_eq!(encode_twist(twist), hex(TWIST));
    }

    #[test]
    fn dds_names_follow_the_type_names() {
        for message in ALL {
            let [package, kind, name] = message.name.split('/').collect::<Vec<_>>()[..] else {
                panic!("{}", message.name)
            };
            assert_eq!(
                message.dds_name,
                format!("{package}::{kind}::dds_::{name}_")
            );
            assert_eq!(message.hash.len(), "RIHS01_".len() + 64);
        }
    }

    proptest::proptest! {
        /// Any bytes from the network: a twist or an error, never a panic.
        #[test]
        fn any_bytes_decode_or_fail_cleanly(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..128)) {
            let _ = decode_twist(&bytes, false);
            let _ = decode_twist(&bytes, true);
            let _ = decode_ackermann(&bytes);
            let _ = crate::rmw::parse_attachment(&bytes);
        }

        /// What a ROS publisher writes reads back: any speeds, any frame id.
        #[test]
        fn twists_round_trip(
            linear in proptest::prelude::any::<f64>(),
            angular in proptest::prelude::any::<f64>(),
            frame in "[a-z_]{0,20}",
            stamped in proptest::prelude::any::<bool>(),
        ) {
            let mut w = Writer::new();
            if stamped {
                Header { stamp: Duration::new(7, 9), frame_id: &frame }.write(&mut w);
            }
            w.f64s(&[linear, 0.1, 0.2, 0.3, 0.4, angular]);
            let twist = decode_twist(&w.finish(), stamped).expect("decodes");
            proptest::prop_assert_eq!(twist.linear.to_bits(), linear.to_bits());
            proptest::prop_assert_eq!(twist.angular.to_bits(), angular.to_bits());
        }
    }
}
