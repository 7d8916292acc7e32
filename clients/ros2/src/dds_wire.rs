//! What the bridge's DDS readers decode, and how: ROS messages as RustDDS' CDR deserializer reads
//! them, a sample that must hold exactly one message ([`Whole`]), a Trigger call in either DDS
//! service mapping ([`TriggerCall`]). Without the node (feature `dds` alone), for the fuzz
//! targets.

use serde::{Deserialize, Serialize};

use crate::cdr::CdrError;
use crate::msgs::{AckermannDrive, PlanarTwist};

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Header {
    stamp: Time,
    frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

/// `geometry_msgs/Twist`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Twist {
    linear: Vector3,
    angular: Vector3,
}

/// `geometry_msgs/TwistStamped`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TwistStamped {
    header: Header,
    pub(crate) twist: Twist,
}

/// `ackermann_msgs/AckermannDrive`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct AckermannDriveFields {
    steering_angle: f32,
    steering_angle_velocity: f32,
    speed: f32,
    acceleration: f32,
    jerk: f32,
}

/// `ackermann_msgs/AckermannDriveStamped`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AckermannDriveStamped {
    header: Header,
    drive: AckermannDriveFields,
}

impl From<&AckermannDriveStamped> for AckermannDrive {
    fn from(message: &AckermannDriveStamped) -> Self {
        AckermannDrive {
            speed: f64::from(message.drive.speed),
            steering_angle: f64::from(message.drive.steering_angle),
        }
    }
}

impl From<&Twist> for PlanarTwist {
    fn from(twist: &Twist) -> Self {
        PlanarTwist {
            linear: twist.linear.x,
            lateral: twist.linear.y,
            angular: twist.angular.z,
        }
    }
}

/// A message that must fill its sample: `T`, then less than 8 bytes of alignment padding, as
/// [`crate::cdr::Reader::finish`] allows on the zenoh path. RustDDS' reader would decode the
/// first bytes of a longer sample (a writer of another type on the topic) as a `T`; this refuses
/// it, saying how many bytes followed.
#[derive(Debug, Clone)]
pub struct Whole<T>(pub T);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Whole<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Visitor<T> {
            type Value = Whole<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a message and nothing after it but padding")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Whole<T>, A::Error> {
                let message = seq
                    .next_element::<T>()?
                    .ok_or_else(|| serde::de::Error::custom("an empty sample"))?;
                // What follows, a byte at a time until the sample ends (the read that fails).
                let mut trailing = 0;
                while trailing < 8 && matches!(seq.next_element::<u8>(), Ok(Some(_))) {
                    trailing += 1;
                }
                if trailing < 8 {
                    Ok(Whole(message))
                } else {
                    Err(serde::de::Error::custom(CdrError::Trailing(trailing)))
                }
            }
        }
        // A CDR tuple is its elements back to back: the message, then the bytes after it.
        deserializer.deserialize_tuple(usize::MAX, Visitor(std::marker::PhantomData))
    }
}

/// Written as the message itself (a Trigger request type must be writable to be served).
impl<T: Serialize> Serialize for Whole<T> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(serializer)
    }
}

/// A `std_srvs/Trigger` request: no fields but CDR's placeholder byte.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TriggerRequest {
    structure_needs_at_least_one_member: u8,
}

/// A `std_srvs/Trigger` response.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub(crate) success: bool,
    pub(crate) message: String,
}

/// rmw_cyclonedds' request header, which it writes before every request and expects before
/// its reply (`cdds_request_header_t`: the client's id and the call's sequence number, two
/// 64-bit integers); kept as the bytes it came in, little-endian as on every platform ROS 2
/// runs on, and written back the same.
pub const CYCLONE_HEADER: usize = 16;

/// A Trigger call as either DDS service mapping carries it: Fast DDS' (and RustDDS' Enhanced
/// mapping) puts the request alone in the sample, the call's identity in its inline QoS;
/// rmw_cyclonedds puts its 16-byte header before the request. Told apart by length: the request
/// is one byte, padding less than 8; with the header 17 bytes and the same padding. Anything
/// else is refused as [`Whole`] refuses it.
#[derive(Debug, Clone)]
pub struct TriggerCall {
    pub(crate) cyclone_header: Option<[u8; CYCLONE_HEADER]>,
}

impl<'de> Deserialize<'de> for TriggerCall {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = TriggerCall;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a Trigger request, after rmw_cyclonedds' header or not")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<TriggerCall, A::Error> {
                // The sample a byte at a time, up to what the longest form holds.
                let mut bytes = Vec::with_capacity(32);
                while bytes.len() < CYCLONE_HEADER + 8 + 1 {
                    match seq.next_element::<u8>() {
                        Ok(Some(byte)) => bytes.push(byte),
                        Ok(None) | Err(_) => break,
                    }
                }
                match bytes.len() {
                    0 => Err(serde::de::Error::custom("an empty sample")),
                    1..=8 => Ok(TriggerCall {
                        cyclone_header: None,
                    }),
                    17..=24 => {
                        let mut header = [0; CYCLONE_HEADER];
                        header.copy_from_slice(&bytes[..CYCLONE_HEADER]);
                        Ok(TriggerCall {
                            cyclone_header: Some(header),
                        })
                    }
                    _ => Err(serde::de::Error::custom(CdrError::Trailing(
                        bytes.len() - 1,
                    ))),
                }
            }
        }
        deserializer.deserialize_tuple(usize::MAX, Visitor)
    }
}

/// Written as the Enhanced mapping's request (a request type must be writable to be served).
impl Serialize for TriggerCall {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(2)?;
        if let Some(header) = &self.cyclone_header {
            tuple.serialize_element(header)?;
        }
        tuple.serialize_element(&0u8)?;
        tuple.end()
    }
}

/// A Trigger reply in the form its call came in: after rmw_cyclonedds' header when the call
/// had one.
#[derive(Debug, Clone, Deserialize)]
pub struct TriggerReply {
    #[serde(skip)]
    pub(crate) cyclone_header: Option<[u8; CYCLONE_HEADER]>,
    pub(crate) response: TriggerResponse,
}

impl Serialize for TriggerReply {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(2)?;
        if let Some(header) = &self.cyclone_header {
            tuple.serialize_element(header)?;
        }
        tuple.serialize_element(&self.response)?;
        tuple.end()
    }
}

/// Decodes a payload (with its encapsulation header) as a DDS reader of `T` does, with RustDDS'
/// CDR deserializer, refusing the encodings the reader refuses.
pub(crate) fn decode<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    use rustdds::no_key::DeserializerAdapter;
    let (header, body) = match bytes {
        [a, b, _, _, body @ ..] => ([*a, *b], body),
        _ => return Err(CdrError::Truncated(bytes.len())),
    };
    let encoding = rustdds::RepresentationIdentifier::from_bytes(&header)
        .map_err(|_| CdrError::Truncated(bytes.len()))?;
    if !<rustdds::CDRDeserializerAdapter<T> as DeserializerAdapter<T>>::supported_encodings()
        .contains(&encoding)
    {
        return Err(CdrError::Encapsulation(header));
    }
    rustdds::CDRDeserializerAdapter::<T>::from_bytes(body, encoding)
        .map_err(|error| CdrError::Malformed(error.to_string()))
}

/// Decodes a cmd_vel payload as the bridge's DDS reader does: the fuzz target's entry to it.
pub fn decode_cmd_vel(bytes: &[u8], stamped: bool) -> Result<PlanarTwist, CdrError> {
    if stamped {
        decode::<Whole<TwistStamped>>(bytes).map(|Whole(message)| PlanarTwist::from(&message.twist))
    } else {
        decode::<Whole<Twist>>(bytes).map(|Whole(message)| PlanarTwist::from(&message))
    }
}

/// Decodes an AckermannDriveStamped as the bridge's DDS reader does: the fuzz target's entry.
pub fn decode_ackermann(bytes: &[u8]) -> Result<AckermannDrive, CdrError> {
    decode::<Whole<AckermannDriveStamped>>(bytes)
        .map(|Whole(message)| AckermannDrive::from(&message))
}

/// Decodes a Trigger request as the bridge's DDS service does (either service mapping): the
/// fuzz target's entry to it. `Ok(true)` for rmw_cyclonedds' form.
pub fn decode_trigger_request(bytes: &[u8]) -> Result<bool, CdrError> {
    decode::<TriggerCall>(bytes).map(|call| call.cyclone_header.is_some())
}
