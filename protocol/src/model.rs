//! The AgileX models this gateway drives: their speed limits, geometry and battery, as the
//! public sources give them (protocol-v2-notes 6, agilex-family-notes). One table for the
//! simulator and the gateway; each number says what it was checked against, or that it is
//! assumed.

listed! {
/// An AgileX model the gateway drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Model {
    /// The 2019 SCOUT (SCOUT 1.0 body; protocol v1 in this project's capture).
    Scout,
    /// SCOUT 2.0.
    Scout2,
    /// SCOUT MINI, skid-steer.
    ScoutMini,
    /// SCOUT MINI OMNI, mecanum wheels (also commands a lateral speed).
    ScoutMiniOmni,
    /// Tracer, a differential-drive indoor base (two driven wheels and castors; v2 only).
    Tracer,
    /// Tracer Mini (the vendor's driver tells it from the Tracer by a parameter alone).
    TracerMini,
    /// Bunker, tracked (two actuators).
    Bunker,
    /// Bunker Mini, tracked.
    BunkerMini,
    /// Bunker Pro, tracked.
    BunkerPro,
    /// Hunter 2.0, Ackermann steering (v2 only).
    Hunter2,
    /// Hunter SE, Ackermann steering (v2 only): smaller and faster than the 2.0, no parking
    /// brake the host works.
    HunterSe,
    /// Ranger Mini 2.0, four steered wheels with motion modes (v2 only).
    RangerMini2,
    /// Ranger Mini 3.0, four steered wheels with motion modes (v2 only).
    RangerMini3,
}
}

/// How a model's wheels move it: what the gateway's mapping, odometry and simulator take.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Drive {
    /// Four wheels turned in pairs (the SCOUTs): forward and a yaw rate.
    SkidSteer,
    /// Mecanum wheels (the OMNI): forward, sideways and a yaw rate.
    Mecanum,
    /// Two driven wheels on castors (the Tracers): forward and a yaw rate.
    Differential,
    /// Two tracks (the Bunkers): forward and a yaw rate.
    Tracked,
    /// Steered front wheels (the Hunter): forward and a steering angle; a yaw rate only while
    /// moving, no tighter than its minimum turning radius.
    Ackermann,
    /// Four steered wheels in motion modes (the Rangers): dual Ackermann (forward and a yaw
    /// rate, no tighter than a radius), parallel (forward and sideways) or spin (a yaw rate in
    /// place), one mode at a time, changed standing still.
    FourWheelSteering,
}

/// The Bunker's yaw-rate limit as its source writes it (just under pi/4, so kept, not rounded
/// up to the constant).
#[allow(clippy::approx_constant)]
const BUNKER_MAX_ANGULAR: f64 = 0.7853;

/// The Hunter 2.0's fastest turn: its top speed on its tightest circle, 1.5 m/s x
/// tan(0.461) / 0.650 m (`Model::steering`; a unit test recomputes it).
const HUNTER2_MAX_YAW_RATE: f64 = 1.146;

/// The Hunter SE's fastest turn: its top speed on its tightest circle, 4.8 m/s x
/// tan(0.3367) / 0.55 m (`Model::steering`; a unit test recomputes it).
const HUNTER_SE_MAX_YAW_RATE: f64 = 3.054;

/// How fast a model may be commanded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// m/s.
    pub linear: f64,
    /// rad/s.
    pub angular: f64,
    /// m/s, sideways (0 but on the OMNI).
    pub lateral: f64,
}

/// A steered model's steering (front-wheel Ackermann): what turns a yaw rate into a steering
/// angle and back (`kinematics`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steering {
    /// Front to rear axle, m.
    pub wheelbase: f64,
    /// Between the steered wheels, m.
    pub track: f64,
    /// The widest central (bicycle-model) angle, rad.
    pub max_central: f64,
    /// The widest inner-wheel angle, rad (what 0x111's steering field carries).
    pub max_inner: f64,
    /// How fast the wheels turn, rad/s.
    pub rate: f64,
}

/// A four-wheel-steered model's steering (the Rangers, [`Drive::FourWheelSteering`]): what
/// turns a body velocity into a mode's speed and wheel angle and back (`kinematics`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FourWheel {
    /// Front to rear axle, m.
    pub wheelbase: f64,
    /// Between the left and right wheels, m.
    pub track: f64,
    /// The widest inner-wheel angle in dual Ackermann, rad (what 0x111's steering carries).
    pub max_inner: f64,
    /// The widest wheel angle in parallel mode, rad.
    pub max_parallel: f64,
    /// The spin rate goes in 0x111's bytes 4-5 (the lateral field), not 2-3.
    pub spin_in_lateral: bool,
    /// How fast the wheels turn, rad/s.
    pub rate: f64,
    /// How long a mode change takes, s (the simulator's).
    pub mode_change: f64,
}

/// A model's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Distance between the left and right wheels, m.
    pub track: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// Motor turns per wheel turn.
    pub gear_ratio: f64,
}

impl Model {
    /// The name on the command line and in logs.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Scout => "scout",
            Self::Scout2 => "scout2",
            Self::ScoutMini => "scout-mini",
            Self::ScoutMiniOmni => "scout-mini-omni",
            Self::Tracer => "tracer",
            Self::TracerMini => "tracer-mini",
            Self::Bunker => "bunker",
            Self::BunkerMini => "bunker-mini",
            Self::BunkerPro => "bunker-pro",
            Self::Hunter2 => "hunter2",
            Self::HunterSe => "hunter-se",
            Self::RangerMini2 => "ranger-mini-2",
            Self::RangerMini3 => "ranger-mini-3",
        }
    }

    /// How its wheels move it.
    pub const fn drive(self) -> Drive {
        match self {
            Self::Scout | Self::Scout2 | Self::ScoutMini => Drive::SkidSteer,
            Self::ScoutMiniOmni => Drive::Mecanum,
            Self::Tracer | Self::TracerMini => Drive::Differential,
            Self::Bunker | Self::BunkerMini | Self::BunkerPro => Drive::Tracked,
            Self::Hunter2 | Self::HunterSe => Drive::Ackermann,
            Self::RangerMini2 | Self::RangerMini3 => Drive::FourWheelSteering,
        }
    }

    /// Its steering, for a model that steers ([`Drive::Ackermann`]). Hunter 2.0: wheelbase
    /// 0.650 m, track 0.605 m, the central (bicycle) angle at most 0.461 rad and the inner
    /// wheel's at most 0.58 rad, checked against agilexrobotics/hunter_ros2 `hunter_params.hpp`
    /// `HunterV2Params` (commit 583d2e0; "from user manual v1.2.6_S P4").
    ///
    /// Hunter SE: the inner wheel at most 0.4 rad, checked against the vendor's HUNTER SE user
    /// manual (table 3.3, 0x111 bytes 6-7: "effective value +-400" in 0.001 rad; read in a
    /// public mirror of the manual). Wheelbase 0.55 m and track 0.54 m, measured between the
    /// wheel centres of the vendor's dimension drawing (in TrossenRobotics/agilex_hunter_se_docs
    /// `specifications/_images/hunter_se_major_dimensions.jpg`, commit a302eb2: 0.549 m front to
    /// rear at the drawing's own scale; the front wheels 0.54 m apart, the rear 0.55 m, as its
    /// 644 mm width less an 89 mm wheel gives). The drawing's 608.54 mm is the top rails'
    /// length, not the wheelbase, which agilexrobotics/ugv_gazebo_sim's `hunter_se` controller
    /// configuration takes for it (0.608 m); that repository's URDF says 0.55 m, and its track
    /// (0.46 m) is narrower than the body. The widest central angle is the inner one's with this
    /// geometry (0.3367 rad, 1.571 m at the tightest): a 2 cm error in the track moves it by
    /// less than 1 %.
    ///
    /// The rate at which the wheels turn is in no source for either: 1.0 rad/s is assumed (the
    /// simulator's).
    pub const fn steering(self) -> Option<Steering> {
        match self {
            Self::Hunter2 => Some(Steering {
                wheelbase: 0.650,
                track: 0.605,
                max_central: 0.461,
                max_inner: 0.58,
                rate: 1.0,
            }),
            Self::HunterSe => Some(Steering {
                wheelbase: 0.55,
                track: 0.54,
                max_central: 0.3367,
                max_inner: 0.4,
                rate: 1.0,
            }),
            Self::Scout
            | Self::Scout2
            | Self::ScoutMini
            | Self::ScoutMiniOmni
            | Self::Tracer
            | Self::TracerMini
            | Self::Bunker
            | Self::BunkerMini
            | Self::BunkerPro
            | Self::RangerMini2
            | Self::RangerMini3 => None,
        }
    }

    /// Its four-wheel steering, for a Ranger ([`Drive::FourWheelSteering`]). Ranger Mini 2.0
    /// and 3.0 alike: wheelbase 0.494 m, track 0.364 m, the inner wheel at most 0.6981 rad in
    /// dual Ackermann (`max_steer_angle_ackermann`, which with this geometry gives the
    /// source's `min_turn_radius` 0.4764 m) and every wheel at most 1.570 rad in parallel,
    /// checked against agilexrobotics/ranger_ros2 `ranger_params.hpp` `RangerMiniV2Params`
    /// and `RangerMiniV3Params` (commit a297495). The Mini 2.0 takes its spin rate in bytes
    /// 4-5 (agilexrobotics/ugv_sdk PR 10, as agilex-family-notes reads it; not in the SDK
    /// commit fd728d4 this project read, whose Ranger path puts it in bytes 2-3, where the Mini
    /// 3.0 takes it). The wheels' turning rate and a mode change's duration are in no source:
    /// 1.0 rad/s and 1.0 s are assumed (the simulator's).
    pub const fn four_wheel(self) -> Option<FourWheel> {
        match self {
            Self::RangerMini2 | Self::RangerMini3 => Some(FourWheel {
                wheelbase: 0.494,
                track: 0.364,
                max_inner: 0.6981,
                max_parallel: 1.570,
                spin_in_lateral: matches!(self, Self::RangerMini2),
                rate: 1.0,
                mode_change: 1.0,
            }),
            Self::Scout
            | Self::Scout2
            | Self::ScoutMini
            | Self::ScoutMiniOmni
            | Self::Tracer
            | Self::TracerMini
            | Self::Bunker
            | Self::BunkerMini
            | Self::BunkerPro
            | Self::Hunter2
            | Self::HunterSe => None,
        }
    }

    /// Whether it has a parking brake the host locks and releases (0x131, reported in 0x211
    /// byte 6): the Hunter 2.0 (its protocol sheet and manual; a maintainer: "none of the
    /// other vehicles has a brake function", westonrobot/ugv_sdk PR 10). Not the Hunter SE:
    /// its manual lists no 0x131 and has 0x211 byte 6 "reserved".
    pub const fn parking_brake(self) -> bool {
        match self {
            Self::Hunter2 => true,
            Self::HunterSe
            | Self::Scout
            | Self::Scout2
            | Self::ScoutMini
            | Self::ScoutMiniOmni
            | Self::Tracer
            | Self::TracerMini
            | Self::Bunker
            | Self::BunkerMini
            | Self::BunkerPro
            | Self::RangerMini2
            | Self::RangerMini3 => false,
        }
    }

    /// How many actuators (motor drivers) report on protocol v2 (0x251.., 0x261..): four on
    /// the SCOUTs, two on the Tracers and Bunkers (agilex-family-notes' table; the Tracer's
    /// driver reads two, agilexrobotics/tracer_ros2 `tracer_messenger.hpp`).
    pub const fn actuators(self) -> u8 {
        match self.drive() {
            Drive::SkidSteer | Drive::Mecanum => 4,
            Drive::Ackermann => 3,
            Drive::FourWheelSteering => 4,
            Drive::Differential | Drive::Tracked => 2,
        }
    }

    /// Whether it speaks `protocol`. The Tracers speak v2 alone (the vendor SDK's
    /// `TracerRobot` is `TracerBaseV2`); the SCOUTs and Bunkers speak both.
    pub const fn speaks(self, protocol: crate::version::Protocol) -> bool {
        match (self, protocol) {
            (
                Self::Tracer
                | Self::TracerMini
                | Self::Hunter2
                | Self::HunterSe
                | Self::RangerMini2
                | Self::RangerMini3,
                crate::version::Protocol::V1,
            ) => false,
            (
                Self::Scout
                | Self::Scout2
                | Self::ScoutMini
                | Self::ScoutMiniOmni
                | Self::Tracer
                | Self::TracerMini
                | Self::Bunker
                | Self::BunkerMini
                | Self::BunkerPro
                | Self::Hunter2
                | Self::HunterSe
                | Self::RangerMini2
                | Self::RangerMini3,
                _,
            ) => true,
        }
    }

    /// The model called `name` ([`Model::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|model| model.name() == name)
    }

    /// The model called `name`, or an error that lists every name: the one parser of
    /// `--model` and the configuration's `model`.
    pub fn parse(name: &str) -> Result<Self, UnknownModel> {
        Self::from_name(name).ok_or(UnknownModel)
    }

    /// The byte that stands for it in shared memory.
    pub const fn raw(self) -> u8 {
        match self {
            Self::Scout => 1,
            Self::Scout2 => 2,
            Self::ScoutMini => 3,
            Self::ScoutMiniOmni => 4,
            Self::Tracer => 5,
            Self::TracerMini => 6,
            Self::Bunker => 7,
            Self::BunkerMini => 8,
            Self::BunkerPro => 9,
            Self::Hunter2 => 10,
            Self::RangerMini2 => 11,
            Self::RangerMini3 => 12,
            Self::HunterSe => 13,
        }
    }

    /// The model of a byte from [`Model::raw`].
    pub fn from_raw(raw: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|model| model.raw() == raw)
    }

    /// The model assumed when none is given: the 2019 SCOUT on protocol v1, SCOUT 2.0 on v2
    /// (the same limits: the slower of the models).
    pub const fn default_for(protocol: crate::version::Protocol) -> Self {
        match protocol {
            crate::version::Protocol::V1 => Self::Scout,
            crate::version::Protocol::V2 => Self::Scout2,
        }
    }

    /// The command limits. SCOUT and SCOUT 2.0: 1.5 m/s and 0.5235 rad/s (the vendor SDK's
    /// limits; manual v1.2.12 on). MINI and OMNI: 3.0 m/s and 2.5235 rad/s, the OMNI ±2.0 m/s
    /// sideways (vendor SDK `robot_limits.hpp` and the 2021 v2 SDK's clamps agree).
    /// Tracer: 1.5 m/s and 0.5235 rad/s, checked against westonrobot/ugv_sdk
    /// `include/wrp_sdk/platforms/tracer/tracer_types.hpp` (2020, `TracerMotionCmd`; the
    /// numbers are the SCOUT's, perhaps copied, and the only source). Bunker: 1.5 m/s and
    /// 0.7853 rad/s, checked against agilexrobotics/bunker_ros
    /// `bunker_base/include/bunker_base/bunker_params.hpp` ("from user manual v1.2.8 P18").
    /// Tracer Mini, Bunker Mini and Bunker Pro: no source gives theirs; their family's are
    /// assumed. A v2 chassis clamps to its own limits too: a cap lower than the chassis'
    /// is slower, never faster.
    pub const fn limits(self) -> Limits {
        match self {
            Self::Scout | Self::Scout2 => Limits {
                linear: crate::units::MAX_LINEAR_SPEED,
                angular: crate::units::DEFAULT_MAX_ANGULAR_SPEED,
                lateral: 0.0,
            },
            Self::ScoutMini => Limits {
                linear: 3.0,
                angular: 2.5235,
                lateral: 0.0,
            },
            Self::ScoutMiniOmni => Limits {
                linear: 3.0,
                angular: 2.5235,
                lateral: 2.0,
            },
            Self::Tracer | Self::TracerMini => Limits {
                linear: 1.5,
                angular: crate::units::DEFAULT_MAX_ANGULAR_SPEED,
                lateral: 0.0,
            },
            Self::Bunker | Self::BunkerMini | Self::BunkerPro => Limits {
                linear: 1.5,
                angular: BUNKER_MAX_ANGULAR,
                lateral: 0.0,
            },
            Self::Hunter2 => Limits {
                linear: 1.5,
                angular: HUNTER2_MAX_YAW_RATE,
                lateral: 0.0,
            },
            // Its manual's table 3.3 (0x111 bytes 0-1, "effective value +-4800" mm/s) and
            // spec sheet (4.8 m/s unladen, TrossenRobotics/agilex_hunter_se_docs).
            Self::HunterSe => Limits {
                linear: 4.8,
                angular: HUNTER_SE_MAX_YAW_RATE,
                lateral: 0.0,
            },
            // ranger_ros2 `ranger_params.hpp`: 1.5 m/s (the wheels' speed, so sideways too in
            // parallel mode) and 4.8 rad/s spinning.
            Self::RangerMini2 | Self::RangerMini3 => Limits {
                linear: 1.5,
                angular: 4.8,
                lateral: 1.5,
            },
        }
    }

    /// The geometry. SCOUT: the vendor SDK's track and the manual's 1:32 gearbox. SCOUT 2.0:
    /// the vendor URDF (track 0.58306 m, wheel radius 0.16459 m; gearbox unpublished, the
    /// SCOUT's assumed). MINI and OMNI: the vendor URDF's track 0.416503 m and the spec
    /// sheet's 1:4.3 gearbox; no public source gives a plausible wheel radius, 0.0875 m (a
    /// 175 mm wheel) is assumed: it only scales the motor rpm. Tracer: the two driven wheels
    /// 0.34 m apart and 0.16 m in radius, checked against agilexrobotics/tracer_ros
    /// `tracer_description/urdf/tracer_v1.xacro` (the driven wheels sit at y = ±wheelbase/2:
    /// that file's "wheelbase" is the track); its gearbox is in no source (1:1 assumed, hub
    /// motors). Bunker: track 0.58306 m and wheel radius 0.165 m, checked against
    /// agilexrobotics/bunker_ros `bunker_params.hpp`, whose numbers are the SCOUT 2.0's and
    /// so doubtful; the SCOUT's 1:32 gearbox assumed. Tracer Mini, Bunker Mini and Bunker
    /// Pro: no source; their family's are assumed. Geometry scales the simulator's wheels and
    /// the motor rpm; the gateway's odometry integrates the chassis' reported speeds.
    pub const fn geometry(self) -> Geometry {
        match self {
            Self::Scout => Geometry {
                track: 0.583,
                wheel_radius: 0.165,
                gear_ratio: 32.0,
            },
            Self::Scout2 => Geometry {
                track: 0.58306,
                wheel_radius: 0.16459,
                gear_ratio: 32.0,
            },
            Self::ScoutMini | Self::ScoutMiniOmni => Geometry {
                track: 0.416503,
                wheel_radius: 0.0875,
                gear_ratio: 4.3,
            },
            Self::Tracer | Self::TracerMini => Geometry {
                track: 0.34,
                wheel_radius: 0.16,
                gear_ratio: 1.0,
            },
            Self::Bunker | Self::BunkerMini | Self::BunkerPro => Geometry {
                track: 0.58306,
                wheel_radius: 0.165,
                gear_ratio: 32.0,
            },
            Self::Hunter2 => Geometry {
                track: 0.605,
                wheel_radius: 0.165,
                gear_ratio: 30.0,
            },
            // The dimension drawing's track and 275 mm wheel (`Model::steering`); its gearbox
            // is in no source (the Hunter 2.0's assumed).
            Self::HunterSe => Geometry {
                track: 0.54,
                wheel_radius: 0.1375,
                gear_ratio: 30.0,
            },
            // The track is ranger_ros2's; the wheel and gearbox are in no source (assumed).
            Self::RangerMini2 | Self::RangerMini3 => Geometry {
                track: 0.364,
                wheel_radius: 0.09,
                gear_ratio: 1.0,
            },
        }
    }

    /// The battery ([`crate::battery`]). No source this project has gives a Tracer's or a
    /// Bunker's pack: the gateway gives no charge estimate for them (the chassis' own
    /// under-voltage bits still count) until the configuration's `[battery]` gives a curve.
    pub const fn battery(self) -> crate::battery::BatterySpec {
        match self {
            Self::Scout | Self::Scout2 => crate::battery::SCOUT_BATTERY,
            Self::ScoutMini | Self::ScoutMiniOmni => crate::battery::SCOUT_MINI_BATTERY,
            Self::Tracer
            | Self::TracerMini
            | Self::Bunker
            | Self::BunkerMini
            | Self::BunkerPro
            | Self::Hunter2
            | Self::HunterSe
            | Self::RangerMini2
            | Self::RangerMini3 => crate::battery::UNKNOWN_BATTERY,
        }
    }
}

listed! {
/// Feedback no SCOUT sends: what a v2 chassis' frames say about its model. The ids are the
/// vendor SDK's (westonrobot/ugv_sdk `agilex_protocol_v2.h`: 0x271 `CAN_MSG_MOTOR_ANGLE_INFO`,
/// 0x291 `CAN_MSG_CURRENT_CTRL_MODE`; 0x221's third and fourth fields, lateral speed and
/// steering angle, `MotionStateFrame`), checked against that source, not against a chassis.
/// What a sign does not catch: a Tracer or a Bunker sends what a SCOUT sends, and a Hunter
/// whose wheels point straight ahead reports a steering angle of zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Sign {
    /// 0x271: the angles of steered wheels.
    SteeringAngles,
    /// 0x291: a motion mode (dual Ackermann, parallel, spin...).
    MotionMode,
    /// 0x221 with a steering angle other than zero.
    Steering,
    /// 0x221 with a sideways speed other than zero.
    Lateral,
    /// 0x211 with byte 6 other than zero: a parking brake reported (locked, or a value no
    /// Hunter sends).
    ParkingBrake,
}
}

impl Sign {
    /// What a frame with v2 id `id` says by its id alone.
    pub const fn of_v2_id(id: u16) -> Option<Self> {
        match id {
            crate::v2::id::MOTOR_ANGLES => Some(Self::SteeringAngles),
            crate::v2::id::MOTION_MODE_STATE => Some(Self::MotionMode),
            _ => None,
        }
    }

    /// What a decoded v2 message says: its id, or a motion or system state's fields.
    pub const fn of_v2_message(message: &crate::v2::MessageV2) -> Option<Self> {
        match message {
            crate::v2::MessageV2::MotionState(motion) => Self::of_motion_state(motion),
            crate::v2::MessageV2::SystemState(system) => match system.brake() {
                crate::v2::BrakeV2::Released => None,
                crate::v2::BrakeV2::Locked | crate::v2::BrakeV2::Unknown(_) => {
                    Some(Self::ParkingBrake)
                }
            },
            other => Self::of_v2_id(other.can_id()),
        }
    }

    /// What a v2 motion state (0x221) says.
    pub const fn of_motion_state(motion: &crate::v2::MotionV2) -> Option<Self> {
        if motion.steering_mrad != 0 {
            Some(Self::Steering)
        } else if motion.lateral_mm_s != 0 {
            Some(Self::Lateral)
        } else {
            None
        }
    }

    /// What the chassis sends, in a few words (for a stop's reason).
    pub const fn short(self) -> &'static str {
        match self {
            Self::SteeringAngles => "steering angles (0x271)",
            Self::MotionMode => "a motion mode (0x291)",
            Self::Steering => "a steering angle (0x221)",
            Self::Lateral => "a sideways speed (0x221)",
            Self::ParkingBrake => "a parking brake (0x211 byte 6)",
        }
    }

    /// The models that send it, as a person would name them.
    pub const fn suggests(self) -> &'static str {
        match self {
            Self::SteeringAngles | Self::Steering => {
                "a chassis with steered wheels (a Hunter or a Ranger Mini)"
            }
            Self::MotionMode => "a Ranger Mini (four-wheel steering with motion modes)",
            Self::Lateral => "a SCOUT MINI OMNI or a Ranger Mini (it moves sideways)",
            Self::ParkingBrake => {
                "a Hunter 2.0 (a Hunter SE has no parking brake to report; on any other model \
                 the byte is reserved: if this is not a Hunter, its firmware uses it otherwise)"
            }
        }
    }
}

impl Model {
    /// Whether a chassis of this model sends what `sign` says, by how its wheels move it:
    /// mecanum wheels move sideways, steered wheels report their angles, the Rangers alone have
    /// motion modes, and a Hunter 2.0 alone reports a parking brake.
    pub const fn sends(self, sign: Sign) -> bool {
        match (self.drive(), sign) {
            (_, Sign::ParkingBrake) => self.parking_brake(),
            (Drive::Mecanum, Sign::Lateral)
            | (Drive::Ackermann, Sign::Steering | Sign::SteeringAngles)
            | (
                Drive::FourWheelSteering,
                Sign::Lateral | Sign::Steering | Sign::SteeringAngles | Sign::MotionMode,
            ) => true,
            (
                Drive::SkidSteer | Drive::Differential | Drive::Tracked,
                Sign::Lateral | Sign::Steering | Sign::SteeringAngles | Sign::MotionMode,
            )
            | (Drive::Mecanum, Sign::Steering | Sign::SteeringAngles | Sign::MotionMode)
            | (Drive::Ackermann, Sign::Lateral | Sign::MotionMode) => false,
        }
    }

    /// Whether the gateway drives a chassis of this model that sends what `sign` says: what
    /// it sends, and on any model but a Hunter a parking brake in 0x211 byte 6. That byte is
    /// reserved on the others and what their firmware puts there no capture shows (a Bunker
    /// Mini's and a Hunter SE's: 0), so it is judged only where it tells one Hunter from the
    /// other: a Hunter 2.0 starts with its brake locked, a Hunter SE has none to report.
    pub const fn may_send(self, sign: Sign) -> bool {
        match (self.drive(), sign) {
            (
                Drive::SkidSteer
                | Drive::Mecanum
                | Drive::Differential
                | Drive::Tracked
                | Drive::FourWheelSteering,
                Sign::ParkingBrake,
            ) => true,
            (Drive::Ackermann, _)
            | (_, Sign::Lateral | Sign::Steering | Sign::SteeringAngles | Sign::MotionMode) => {
                self.sends(sign)
            }
        }
    }
}

/// A name that is no model's ([`Model::parse`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownModel;

impl core::fmt::Display for UnknownModel {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "not a model: give one of {Names}")
    }
}

/// Every model's name, comma-separated, for messages (written, nothing allocated).
#[derive(Debug, Clone, Copy)]
pub struct Names;

impl core::fmt::Display for Names {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for (i, model) in Model::ALL.into_iter().enumerate() {
            f.write_str(if i == 0 { "" } else { ", " })?;
            f.write_str(model.name())?;
        }
        Ok(())
    }
}

#[cfg(feature = "std")]
impl std::error::Error for UnknownModel {}

impl core::fmt::Display for Model {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_limits_are_the_sources() {
        for model in Model::ALL {
            assert_eq!(Model::from_name(model.name()), Some(model));
            assert_eq!(Model::from_raw(model.raw()), Some(model));
        }
        assert_eq!(Model::from_raw(0), None);
        for protocol in crate::version::Protocol::ALL {
            let limits = Model::default_for(protocol).limits();
            assert_eq!(
                limits,
                Model::Scout.limits(),
                "the default is the slower model"
            );
        }
        assert_eq!(Model::from_name("scout3"), None);
        assert_eq!(Model::parse("scout-mini"), Ok(Model::ScoutMini));
        let refused = Model::parse("scout3")
            .expect_err("no such model")
            .to_string();
        assert_eq!(
            refused,
            "not a model: give one of scout, scout2, scout-mini, scout-mini-omni, tracer, \
             tracer-mini, bunker, bunker-mini, bunker-pro, hunter2, hunter-se, ranger-mini-2, \
             ranger-mini-3"
        );
        assert_eq!(Model::Scout2.limits().linear, 1.5);
        assert_eq!(Model::ScoutMini.limits().angular, 2.5235);
        assert_eq!(Model::ScoutMiniOmni.limits().lateral, 2.0);
        assert_eq!(Model::ScoutMini.limits().lateral, 0.0);
        assert_eq!(
            Model::Scout.limits().angular,
            crate::units::DEFAULT_MAX_ANGULAR_SPEED
        );
        assert_eq!(
            Model::Tracer.limits().angular,
            crate::units::DEFAULT_MAX_ANGULAR_SPEED
        );
        assert_eq!(Model::Bunker.limits().angular, BUNKER_MAX_ANGULAR);
        assert_eq!(Model::Tracer.geometry().track, 0.34);
    }

    #[test]
    fn every_model_is_drivable_on_v2_and_only_a_steered_one_sends_steering() {
        for model in Model::ALL {
            let limits = model.limits();
            assert!(limits.linear > 0.0 && limits.angular > 0.0, "{model}");
            // v2's int16 in mm/s and mrad/s holds ±32.767: every limit fits.
            assert!(limits.linear < 32.0 && limits.angular < 32.0, "{model}");
            let modes = model.drive() == Drive::FourWheelSteering;
            assert_eq!(
                limits.lateral > 0.0,
                model.drive() == Drive::Mecanum || modes,
                "{model}: sideways only on mecanum wheels and in parallel mode"
            );
            assert!(model.speaks(crate::version::Protocol::V2), "{model}");
            let steers = model.drive() == Drive::Ackermann;
            assert_eq!(model.steering().is_some(), steers, "{model}");
            assert_eq!(model.four_wheel().is_some(), modes, "{model}");
            for sign in [Sign::Steering, Sign::SteeringAngles] {
                assert_eq!(model.may_send(sign), steers || modes, "{model}");
            }
            assert_eq!(model.may_send(Sign::MotionMode), modes, "{model}");
            assert_eq!(
                model.sends(Sign::ParkingBrake),
                model.parking_brake(),
                "{model}"
            );
            for sign in Sign::ALL {
                assert!(
                    !model.sends(sign) || model.may_send(sign),
                    "{model} {sign:?}"
                );
            }
            let geometry = model.geometry();
            assert!(
                geometry.track > 0.0 && geometry.wheel_radius > 0.0,
                "{model}"
            );
        }
        assert!(!Model::Tracer.speaks(crate::version::Protocol::V1));
        assert!(Model::Bunker.speaks(crate::version::Protocol::V1));
        assert_eq!(Model::Tracer.actuators(), 2);
        assert_eq!(Model::Scout2.actuators(), 4);
    }
}
