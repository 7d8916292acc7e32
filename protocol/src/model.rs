//! The SCOUT models: their speed limits and geometry, as the public sources give them
//! (protocol-v2-notes 6). One table for the simulator and the gateway.

listed! {
/// A SCOUT model.
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
}
}

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
        }
    }

    /// The geometry. SCOUT: the vendor SDK's track and the manual's 1:32 gearbox. SCOUT 2.0:
    /// the vendor URDF (track 0.58306 m, wheel radius 0.16459 m; gearbox unpublished, the
    /// SCOUT's assumed). MINI and OMNI: the vendor URDF's track 0.416503 m and the spec
    /// sheet's 1:4.3 gearbox; no public source gives a plausible wheel radius, 0.0875 m (a
    /// 175 mm wheel) is assumed: it only scales the motor rpm.
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
        }
    }

    /// The battery ([`crate::battery`]).
    pub const fn battery(self) -> crate::battery::BatterySpec {
        match self {
            Self::Scout | Self::Scout2 => crate::battery::SCOUT_BATTERY,
            Self::ScoutMini | Self::ScoutMiniOmni => crate::battery::SCOUT_MINI_BATTERY,
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
        }
    }
}

impl Model {
    /// Whether a chassis of this model may send what `sign` says: the OMNI moves sideways;
    /// no SCOUT steers its wheels or has motion modes.
    pub const fn may_send(self, sign: Sign) -> bool {
        match (self, sign) {
            (Self::ScoutMiniOmni, Sign::Lateral) => true,
            (Self::Scout | Self::Scout2 | Self::ScoutMini | Self::ScoutMiniOmni, _) => false,
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
            "not a model: give one of scout, scout2, scout-mini, scout-mini-omni"
        );
        assert_eq!(Model::Scout2.limits().linear, 1.5);
        assert_eq!(Model::ScoutMini.limits().angular, 2.5235);
        assert_eq!(Model::ScoutMiniOmni.limits().lateral, 2.0);
        assert_eq!(Model::ScoutMini.limits().lateral, 0.0);
        assert_eq!(
            Model::Scout.limits().angular,
            crate::units::DEFAULT_MAX_ANGULAR_SPEED
        );
    }
}
