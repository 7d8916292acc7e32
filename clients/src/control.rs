//! Controlling the chassis: a [`Controller`] sends requests to the gateway's arbiter and gets an
//! answer to each; [`StatusReader`] reads the arbiter's status.

use std::time::{Duration, Instant};

use iceoryx2::port::client::Client;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use scout_protocol::{FaultClear, LightCommand};

use crate::client::{ClientError, Robot};
use crate::ipc::{
    self, CLEAR_ALL_FAULTS, Class, ControlRequest, ControlResponse, FixedText, Ipc, LightPayload,
    LightsRequest, RequestKind, Role, StatusPayload,
};

/// How long a request waits for the gateway's answer.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(1);

/// Why a request did not go through.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The arbiter refused it, with the reason.
    #[error("rejected: {reason}")]
    Rejected {
        /// The reason, as the gateway words it.
        reason: String,
        /// The rejection counter (see [`ipc::REJECTION_NAMES`]).
        code: u8,
    },
    /// No answer within [`ANSWER_TIMEOUT`]: the gateway is stopped, stuck or gone.
    #[error("no answer from gateway '{robot}' within {timeout:?}: is it running (not stopped)?")]
    NoAnswer {
        /// The robot.
        robot: String,
        /// How long it waited.
        timeout: Duration,
    },
    /// Talking to the gateway failed.
    #[error(transparent)]
    Client(#[from] ClientError),
}

/// An accepted request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Accepted {
    /// A speed beyond the caps was clamped.
    pub clamped: bool,
}

/// The lights to ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lights {
    /// Hand the lights back to the chassis' own logic.
    Auto,
    /// Front and rear as given (brightness 0..100 matters in custom mode).
    Manual(LightCommand),
}

fn iceoryx(error: impl std::fmt::Display) -> ClientError {
    ClientError::Iceoryx(error.to_string())
}

/// A named client of the arbiter. With a class it may drive; any controller may stop.
#[derive(Debug)]
pub struct Controller {
    robot: String,
    name: FixedText<32>,
    class: Option<Class>,
    node: [u64; 2],
    seq: u64,
    client: Client<Ipc, ControlRequest, (), ControlResponse, ()>,
    wake: Notifier<Ipc>,
}

impl Robot {
    /// A controller named `name` (shown in the status and the gateway's audit log) that drives
    /// as `class`; `None` for a controller that only stops, releases, resumes, sets lights...
    pub fn controller(&self, name: &str, class: Option<Class>) -> Result<Controller, ClientError> {
        if name.is_empty() || name.len() > FixedText::<32>::CAPACITY {
            return Err(ClientError::BadName(format!(
                "client name `{name}` must be 1 to 32 bytes"
            )));
        }
        let (requests, events) = ipc::control_services(self.node(), self.name(), Role::Client)?;
        Ok(Controller {
            robot: self.name().to_owned(),
            name: FixedText::new(name),
            class,
            node: ipc::node_halves(self.node().id().value()),
            seq: 0,
            client: requests.client_builder().create().map_err(iceoryx)?,
            wake: events.notifier_builder().create().map_err(iceoryx)?,
        })
    }

    /// Reads the arbiter's status.
    pub fn status(&self) -> Result<StatusReader, ClientError> {
        let service = ipc::status_services(self.node(), self.name(), Role::Client)?;
        let subscriber = service.subscriber_builder().create().map_err(iceoryx)?;
        Ok(StatusReader { subscriber })
    }
}

impl Controller {
    /// The class it drives as.
    pub fn class(&self) -> Option<Class> {
        self.class
    }

    /// Sends one request and waits for its answer.
    fn request(
        &mut self,
        kind: RequestKind,
        fill: impl FnOnce(&mut ControlRequest),
    ) -> Result<Accepted, ControlError> {
        self.seq += 1;
        let mut request = ControlRequest {
            kind: kind as u8,
            class: self.class.map_or(0, |class| class as u8),
            client: self.name,
            node: self.node,
            seq: self.seq,
            ..ControlRequest::default()
        };
        fill(&mut request);
        let pending = self.client.send_copy(request).map_err(iceoryx)?;
        self.wake.notify().map_err(iceoryx)?;
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        while Instant::now() < deadline {
            while let Some(response) = pending.receive().map_err(iceoryx)? {
                if response.seq != self.seq {
                    continue;
                }
                return if response.accepted {
                    Ok(Accepted {
                        clamped: response.clamped,
                    })
                } else {
                    Err(ControlError::Rejected {
                        reason: response.reason.as_str().to_owned(),
                        code: response.code,
                    })
                };
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        Err(ControlError::NoAnswer {
            robot: self.robot.clone(),
            timeout: ANSWER_TIMEOUT,
        })
    }

    /// Drives at `linear` m/s and `angular` rad/s until the class's maximum age passes (send
    /// again at 20-50 Hz to keep driving).
    pub fn drive(&mut self, linear: f64, angular: f64) -> Result<Accepted, ControlError> {
        self.drive_for(linear, angular, None)
    }

    /// Drives with a command that lives at most `ttl` (capped by the class's maximum age).
    pub fn drive_for(
        &mut self,
        linear: f64,
        angular: f64,
        ttl: Option<Duration>,
    ) -> Result<Accepted, ControlError> {
        let ttl_ms = ttl.map_or(0, |ttl| {
            ttl.as_millis().clamp(1, u128::from(u32::MAX)) as u32
        });
        self.request(RequestKind::Drive, |r| {
            r.linear = linear;
            r.angular = angular;
            r.ttl_ms = ttl_ms;
        })
    }

    /// Latches the safety stop: zero speed at once, until someone releases it.
    pub fn stop(&mut self, reason: &str) -> Result<Accepted, ControlError> {
        self.request(RequestKind::Stop, |r| r.reason = FixedText::new(reason))
    }

    /// Releases the latched stop and whatever this controller drives. Nothing moves until a
    /// new drive command (teleop) or a resume and command (autonomy).
    pub fn release(&mut self) -> Result<Accepted, ControlError> {
        self.request(RequestKind::Release, |_| {})
    }

    /// Gives up this controller's control: the output ramps to zero. Leaves the stop alone (a
    /// client finishing its work must not release someone's stop).
    pub fn relinquish(&mut self) -> Result<Accepted, ControlError> {
        self.request(RequestKind::Relinquish, |_| {})
    }

    /// Arms autonomy.
    pub fn resume(&mut self) -> Result<Accepted, ControlError> {
        self.request(RequestKind::Resume, |_| {})
    }

    /// Sets the lights (the last writer wins).
    pub fn lights(&mut self, lights: Lights) -> Result<Accepted, ControlError> {
        let wire = match lights {
            Lights::Auto => LightsRequest {
                auto: true,
                ..LightsRequest::default()
            },
            Lights::Manual(command) => {
                let light = |l: scout_protocol::Light| LightPayload {
                    mode: l.mode.raw(),
                    brightness: l.brightness,
                };
                LightsRequest {
                    auto: false,
                    front: light(command.front),
                    rear: light(command.rear),
                }
            }
        };
        self.request(RequestKind::Lights, |r| r.lights = wire)
    }

    /// Sends `code` in the next 3 motion commands; `None` clears every fault in turn.
    pub fn clear_fault(&mut self, code: Option<FaultClear>) -> Result<Accepted, ControlError> {
        let raw = code.map_or(CLEAR_ALL_FAULTS, FaultClear::raw);
        self.request(RequestKind::ClearFault, |r| r.fault_clear = raw)
    }

    /// Registers this controller as a heartbeat stop source: if no request comes from it for
    /// `period`, the stop latches. `Duration::ZERO` deregisters. Any request is a beat.
    pub fn heartbeat(&mut self, period: Duration) -> Result<Accepted, ControlError> {
        let ms = period.as_millis().min(u128::from(u32::MAX)) as u32;
        self.request(RequestKind::Heartbeat, |r| r.heartbeat_ms = ms)
    }

    /// Resets the gateway's odometry to the origin.
    pub fn reset_odometry(&mut self) -> Result<Accepted, ControlError> {
        self.request(RequestKind::ResetOdometry, |_| {})
    }
}

/// Reads the arbiter's status.
#[derive(Debug)]
pub struct StatusReader {
    subscriber: Subscriber<Ipc, StatusPayload, ()>,
}

impl StatusReader {
    /// The newest status, waiting at most `timeout` for one (the gateway publishes at least once
    /// a second; a new reader gets the latest at once).
    pub fn latest(&self, timeout: Duration) -> Result<Option<StatusPayload>, ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            let mut latest = None;
            while let Some(sample) = self.subscriber.receive().map_err(iceoryx)? {
                latest = Some(*sample);
            }
            if latest.is_some() || Instant::now() >= deadline {
                return Ok(latest);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}
