//! Controlling the chassis: a [`Controller`] sends requests to the gateway's arbiter and gets an
//! answer to each; [`StatusReader`] reads the arbiter's status.

use std::time::{Duration, Instant};

use iceoryx2::port::subscriber::Subscriber;
use scout_interface::control::{
    Accepted, Class, DriveMode, LightsSetting, MAX_CLIENT_NAME, Rejected, RejectionKind,
    ReleaseTarget, Request, StatusPayload,
};
use scout_interface::services::{self, ControlPort, Ipc, RequestError, Role, Way};
use scout_interface::stop_socket::{Ask, StopClient, StopSocketError};
use scout_protocol::FaultClear;

use crate::client::{ClientError, Robot};
use scout_interface::failure::{Failure, FailureKind};
use scout_interface::robot::{Program, RobotName};

pub use scout_interface::services::ANSWER_TIMEOUT;

/// Why a request did not go through.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The arbiter refused it, with the reason.
    #[error("rejected: {0}")]
    Rejected(Rejected),
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
    Request(RequestError),
    /// Opening or reading the gateway's services failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The stop endpoint failed (no gateway, no answer, a socket error).
    #[error(transparent)]
    Stop(StopSocketError),
}

impl From<StopSocketError> for ControlError {
    fn from(error: StopSocketError) -> Self {
        match error {
            StopSocketError::NoAnswer { robot, timeout } => Self::NoAnswer { robot, timeout },
            other => Self::Stop(other),
        }
    }
}

impl FailureKind for ControlError {
    fn kind(&self) -> Failure {
        match self {
            Self::Rejected(_) => Failure::Refused,
            Self::NoAnswer { .. } => Failure::NoGateway,
            Self::Request(error) => error.kind(),
            Self::Client(error) => error.kind(),
            Self::Stop(error) => error.kind(),
        }
    }
}

impl ControlError {
    /// The kind of rejection, if the arbiter refused the request.
    pub fn rejection(&self) -> Option<RejectionKind> {
        match self {
            Self::Rejected(rejected) => rejected.kind,
            Self::NoAnswer { .. } | Self::Request(_) | Self::Client(_) | Self::Stop(_) => None,
        }
    }

    /// Whether this client lost (or never had) control: it must take control again, a
    /// deliberate act the library never does by itself.
    pub fn lost_control(&self) -> bool {
        match self {
            Self::Rejected(rejected) => rejected.lost_control(),
            Self::NoAnswer { .. } | Self::Request(_) | Self::Client(_) | Self::Stop(_) => false,
        }
    }
}

impl From<RequestError> for ControlError {
    fn from(error: RequestError) -> Self {
        match error {
            RequestError::Rejected(rejected) => Self::Rejected(rejected),
            RequestError::NoAnswer { robot, timeout } => Self::NoAnswer { robot, timeout },
            other => Self::Request(other),
        }
    }
}

/// The lights to ask for.
pub type Lights = LightsSetting;

/// A named client of the arbiter. With a class it may take control and drive; any controller
/// may stop and release (through the stop endpoint, which needs no shared memory and no slot).
#[derive(Debug)]
pub struct Controller {
    class: Option<Class>,
    port: ControlPort,
    safety: Stopper,
    lease: Option<u64>,
}

/// A client that only stops and releases: a safety monitor, an e-stop button. It talks to the
/// gateway's stop endpoint, a Unix datagram socket beside iceoryx2: a stop needs no shared
/// memory (a full `/dev/shm` cannot keep it from latching), no client slot and no set-up
/// beyond this value. Make it ahead of time; a stop then costs one datagram each way.
#[derive(Debug)]
pub struct Stopper {
    client: StopClient,
    /// Made by [`Stopper::with_fallback`]: the iceoryx2 stop service when the stop endpoint
    /// cannot be reached.
    fallback: Option<StopService>,
}

/// The iceoryx2 stop service of a robot, opened on first use: for a process in another
/// network namespace than the gateway (a container sharing its shared memory and
/// `/tmp/iceoryx2` but not its network), where the abstract stop socket cannot be reached.
#[derive(Debug)]
struct StopService {
    robot: RobotName,
    name: String,
    port: Option<ControlPort>,
    /// The port's node, dropped after it.
    node: Option<iceoryx2::node::Node<Ipc>>,
}

impl StopService {
    fn request(&mut self, request: &Request) -> Result<Accepted, ControlError> {
        let port = match self.port.take() {
            Some(port) => port,
            None => {
                let node = services::node(&self.robot.node(Program::Client))
                    .map_err(|error| ControlError::Client(error.into()))?;
                let port = ControlPort::open(&node, &self.robot, Way::Stop, &self.name)
                    .map_err(|error| ControlError::Client(error.into()))?;
                self.node = Some(node);
                port
            }
        };
        Ok(self.port.insert(port).request(request)?)
    }
}

impl Stopper {
    /// A stopper named `name` (1 to 32 bytes; the owner of its stops) for robot `robot`. It
    /// opens no iceoryx2 service: it works wherever the gateway's stop socket can be reached.
    pub fn new(robot: &str, name: &str) -> Result<Self, ClientError> {
        RobotName::new(robot)?;
        if name.is_empty() || name.len() > MAX_CLIENT_NAME {
            return Err(ClientError::BadClientName(name.to_owned()));
        }
        let client = StopClient::new(robot, name).map_err(ClientError::StopSocket)?;
        Ok(Self {
            client,
            fallback: None,
        })
    }

    /// [`Stopper::new`], falling back to the gateway's iceoryx2 stop service (opened on first
    /// use) where the stop endpoint cannot be reached: this process in another network
    /// namespace than the gateway.
    pub fn with_fallback(robot: &str, name: &str) -> Result<Self, ClientError> {
        let mut stopper = Self::new(robot, name)?;
        stopper.fallback = Some(StopService {
            robot: RobotName::new(robot)?,
            name: name.to_owned(),
            port: None,
            node: None,
        });
        Ok(stopper)
    }

    /// Latches a stop owned by this client's name: zero speed at once, until released. The
    /// answer's `stop` is its id.
    pub fn stop(&mut self, reason: &str) -> Result<Accepted, ControlError> {
        self.ask(Ask::Stop {
            reason: reason.to_owned(),
        })
    }

    /// Releases the stops `target` names (this client's own; another owner's or all need the
    /// operator role) that latched no later than stop `through`: the newest stop id its sender
    /// saw (the status' `newest_stop`, or the id a stop answered). A stop latched after that
    /// survives. Nothing moves until clients take control again (and autonomy is resumed).
    pub fn release(
        &mut self,
        target: ReleaseTarget,
        through: u64,
    ) -> Result<Accepted, ControlError> {
        self.ask(Ask::Release { target, through })
    }

    /// The newest stop the gateway latched (held or released since; `None`: none yet), asked
    /// through the stop endpoint alone: what a release names as `through` when no status can
    /// be read (a full `/dev/shm`).
    pub fn newest_stop(&mut self) -> Result<Option<u64>, ControlError> {
        let reply = self
            .client
            .request(Ask::Ping, ANSWER_TIMEOUT)
            .map_err(ControlError::from)?;
        Ok(reply.answer.map_err(ControlError::Rejected)?.stop)
    }

    /// The gateway's process id, asked through the stop endpoint (a ping).
    pub fn gateway_pid(&mut self) -> Result<u32, ControlError> {
        let reply = self
            .client
            .request(Ask::Ping, ANSWER_TIMEOUT)
            .map_err(ControlError::from)?;
        Ok(reply.gateway_pid)
    }

    fn ask(&mut self, ask: Ask) -> Result<Accepted, ControlError> {
        let request = ask.request();
        match (
            self.client.request(ask, ANSWER_TIMEOUT),
            &mut self.fallback,
            request,
        ) {
            (Ok(reply), ..) => reply.answer.map_err(ControlError::Rejected),
            // The gateway's services are there (a Robot connected) but its socket is not:
            // another network namespace.
            (Err(StopSocketError::NoGateway { .. }), Some(fallback), Some(request)) => {
                fallback.request(&request)
            }
            (Err(error), ..) => Err(error.into()),
        }
    }
}

impl Robot {
    /// A controller named `name` (shown in the status and the gateway's audit log) that drives
    /// as `class`; `None` for a controller that only stops, releases, resumes, sets lights...
    pub fn controller(&self, name: &str, class: Option<Class>) -> Result<Controller, ClientError> {
        if name.is_empty() || name.len() > MAX_CLIENT_NAME {
            return Err(ClientError::BadClientName(name.to_owned()));
        }
        Ok(Controller {
            class,
            port: ControlPort::open(self.node(), self.name(), Way::Control, name)?,
            safety: self.stopper(name)?,
            lease: None,
        })
    }

    /// A client named `name` that only stops and releases ([`Stopper::new`]); where the stop
    /// endpoint cannot be reached (this process in another network namespace than the
    /// gateway), it uses the iceoryx2 stop service instead.
    pub fn stopper(&self, name: &str) -> Result<Stopper, ClientError> {
        Stopper::with_fallback(self.name(), name)
    }

    /// Reads the arbiter's status.
    pub fn status(&self) -> Result<StatusReader, ClientError> {
        let service = services::status_services(self.node(), self.name(), Role::Client)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(ClientError::Subscribe)?;
        Ok(StatusReader { subscriber })
    }
}

impl Controller {
    /// The class it drives as.
    pub fn class(&self) -> Option<Class> {
        self.class
    }

    /// The lease it holds, if it took control and has not lost it.
    pub fn lease(&self) -> Option<u64> {
        self.lease
    }

    /// Sends one request and waits for its answer: stops and releases through the stop
    /// endpoint, the rest through the control service.
    pub fn request(&mut self, request: &Request) -> Result<Accepted, ControlError> {
        self.request_sent_at(request, scout_interface::services::monotonic())
    }

    /// [`Controller::request`] for a request sent at `sent` (CLOCK_BOOTTIME, as
    /// [`scout_interface::services::monotonic`] reads it): earlier than now for a command held
    /// up before it reached this process (a browser's), so that the gateway ages it from then.
    pub fn request_sent_at(
        &mut self,
        request: &Request,
        sent: Duration,
    ) -> Result<Accepted, ControlError> {
        let answer: Result<Accepted, ControlError> = match request {
            Request::Stop { reason } => self.safety.stop(reason),
            Request::Release { target, through } => self.safety.release(target.clone(), *through),
            _ => self
                .port
                .request_sent_at(request, sent)
                .map_err(ControlError::from),
        };
        match (&answer, request) {
            (Ok(accepted), Request::TakeControl { .. }) => self.lease = accepted.lease,
            // A stop revokes every lease, this one's too: a key pressed right after (before
            // a drive learnt of it) takes control again rather than driving a dead lease.
            (Ok(_), Request::Relinquish | Request::Stop { .. }) => self.lease = None,
            (Err(error), _) if error.lost_control() => self.lease = None,
            _ => {}
        }
        answer
    }

    /// Takes control as this controller's class: from now on it may drive, until a stop, a
    /// gap, a release, a takeover or silence ends its control ([`ControlError::lost_control`]);
    /// then only this call, made again on purpose, gives control back.
    pub fn take_control(&mut self) -> Result<Accepted, ControlError> {
        let Some(class) = self.class else {
            return Err(ControlError::Rejected(Rejected {
                kind: Some(RejectionKind::UnknownClass),
                reason: "this controller has no class: give teleop or autonomy".into(),
            }));
        };
        self.request(&Request::TakeControl { class })
    }

    /// Drives at `linear` m/s and `angular` rad/s until the class's maximum age passes (send
    /// again at 20-50 Hz to keep driving).
    pub fn drive(&mut self, linear: f64, angular: f64) -> Result<Accepted, ControlError> {
        self.drive_for(linear, angular, None)
    }

    /// Drives with a command that lives at most `ttl` (capped by the class's maximum age),
    /// under the control [`Controller::take_control`] took.
    pub fn drive_for(
        &mut self,
        linear: f64,
        angular: f64,
        ttl: Option<Duration>,
    ) -> Result<Accepted, ControlError> {
        self.drive_body(linear, 0.0, angular, ttl)
    }

    /// Drives at a body velocity (ROS conventions: `linear` m/s forward, `lateral` m/s
    /// leftward, `angular` rad/s counter-clockwise) with a command that lives at most `ttl`.
    /// A chassis that does not move sideways refuses a `lateral` other than zero, saying so.
    pub fn drive_body(
        &mut self,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Option<Duration>,
    ) -> Result<Accepted, ControlError> {
        self.drive_request(linear, lateral, angular, ttl, None)
    }

    /// Drives at a body velocity in motion mode `mode`, on a chassis that has them (a Ranger:
    /// [`DriveMode::Park`] with zero velocity parks it). A velocity the mode does not carry
    /// (a yaw rate in parallel mode, a speed in spin mode) is refused, saying so; so is a mode
    /// on a chassis without modes. The chassis changes mode standing still: the drive ramps
    /// down, the mode changes, and it ramps up again.
    pub fn drive_in_mode(
        &mut self,
        mode: DriveMode,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Option<Duration>,
    ) -> Result<Accepted, ControlError> {
        self.drive_request(linear, lateral, angular, ttl, Some(mode))
    }

    fn drive_request(
        &mut self,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Option<Duration>,
        mode: Option<DriveMode>,
    ) -> Result<Accepted, ControlError> {
        let Some(lease) = self.lease else {
            return Err(ControlError::Rejected(Rejected {
                kind: Some(RejectionKind::NoControl),
                reason: "no control: take control first".into(),
            }));
        };
        self.request(&Request::Drive {
            lease,
            linear,
            lateral,
            angular,
            ttl,
            mode,
        })
    }

    /// Latches a stop owned by this controller's name: zero speed at once, until released.
    pub fn stop(&mut self, reason: &str) -> Result<Accepted, ControlError> {
        self.request(&Request::Stop {
            reason: reason.to_owned(),
        })
    }

    /// Releases the stops `target` names (this controller's own; another owner's or all need
    /// the operator role) that latched no later than stop `through` ([`Stopper::release`]).
    /// Nothing moves until clients take control again (and autonomy is resumed).
    pub fn release(
        &mut self,
        target: ReleaseTarget,
        through: u64,
    ) -> Result<Accepted, ControlError> {
        self.request(&Request::Release { target, through })
    }

    /// Gives up this controller's control: the output ramps to zero. Leaves the stop alone (a
    /// client finishing its work must not release someone's stop).
    pub fn relinquish(&mut self) -> Result<Accepted, ControlError> {
        self.request(&Request::Relinquish)
    }

    /// Arms autonomy.
    pub fn resume(&mut self) -> Result<Accepted, ControlError> {
        self.request(&Request::Resume)
    }

    /// Sets the lights (the last writer wins).
    pub fn lights(&mut self, lights: Lights) -> Result<Accepted, ControlError> {
        self.request(&Request::Lights(lights))
    }

    /// Sends `code` in the next 3 motion commands; `None` clears every fault in turn.
    pub fn clear_fault(&mut self, code: Option<FaultClear>) -> Result<Accepted, ControlError> {
        self.request(&Request::ClearFault(code))
    }

    /// Registers this controller as a heartbeat stop source: if no request comes from it for
    /// `period`, the stop latches. `Duration::ZERO` deregisters. Any request is a beat.
    pub fn heartbeat(&mut self, period: Duration) -> Result<Accepted, ControlError> {
        self.request(&Request::Heartbeat { period })
    }

    /// Resets the gateway's odometry to the origin.
    pub fn reset_odometry(&mut self) -> Result<Accepted, ControlError> {
        self.request(&Request::ResetOdometry)
    }

    /// Asks the gateway to save its black box of the bus to disk (its log names the file).
    pub fn save_black_box(&mut self) -> Result<Accepted, ControlError> {
        self.request(&Request::SaveBlackBox)
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
            let latest = services::latest(&self.subscriber).map_err(ClientError::Receive)?;
            if latest.is_some() || Instant::now() >= deadline {
                return Ok(latest);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// The next status in the order the gateway published them, without waiting (a recorder
    /// sees every one; [`StatusReader::latest`] skips to the newest).
    pub fn try_next(&self) -> Result<Option<StatusPayload>, ClientError> {
        Ok(self
            .subscriber
            .receive()
            .map_err(ClientError::Receive)?
            .map(|sample| *sample))
    }
}
