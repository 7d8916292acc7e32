//! The native half of the Python package `scout` (`scout._scout`): the Rust client library
//! behind a small, GIL-free surface. States are read from shared memory by the calling Python
//! thread, which waits on the gateway's state event with the GIL released (the ports are
//! thread-safe). Control runs on an actor thread per robot that owns the connection, the
//! controllers and the stoppers; Python waits for its replies with the GIL released too. Every
//! wait is sliced so Ctrl-C interrupts it within [`SLICE`]. The Python half (`python/scout`)
//! gives it its public shape: `State`, context managers, exceptions, asyncio.

use std::collections::HashMap;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::ListenerWaitError;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use serde_json::Value;

use scout_clients::client::{ClientError, Robot, StateSubscriber};
use scout_clients::control::{ControlError, Controller, Lights, StatusReader, Stopper};
use scout_clients::interface::LAYOUT_VERSION;
use scout_clients::interface::control::parse_light_text;
use scout_clients::interface::json::{STATE_KEYS, state_field, state_json, status_json};
use scout_clients::interface::services::ServiceError;
use scout_clients::interface::stop_socket::StopSocketError;
use scout_clients::{
    Accepted, Class, DriveMode, ReleaseTarget, StatePayload, StatusPayload, monotonic_ns,
};
use scout_protocol::FaultClear;
use scout_protocol::message::{Light, LightCommand};

/// How long a wait holds off Ctrl-C at most.
const SLICE: Duration = Duration::from_millis(50);

/// Why a call failed, carried from the worker threads to Python's exceptions (`scout._errors`).
#[derive(Debug, Clone)]
enum Failure {
    NoGateway(String),
    Version(String),
    NoAnswer(String),
    Rejected {
        message: String,
        reason: String,
        cause: String,
    },
    /// Used in a child of `os.fork()`: the process that made it, and this one.
    Forked {
        made_in: u32,
        here: u32,
    },
    Other(String),
}

impl From<ClientError> for Failure {
    fn from(error: ClientError) -> Self {
        match &error {
            ClientError::Service(ServiceError::NoGateway { .. }) => {
                Failure::NoGateway(error.to_string())
            }
            ClientError::Service(ServiceError::Incompatible { .. }) => {
                Failure::Version(error.to_string())
            }
            _ => Failure::Other(error.to_string()),
        }
    }
}

impl From<ControlError> for Failure {
    fn from(error: ControlError) -> Self {
        match error {
            ControlError::Rejected(rejected) => Failure::Rejected {
                message: format!("rejected: {rejected}"),
                cause: rejected
                    .kind
                    .map_or("unknown", |kind| kind.name())
                    .to_owned(),
                reason: rejected.reason,
            },
            ControlError::NoAnswer { .. } => Failure::NoAnswer(error.to_string()),
            ControlError::Client(client) => client.into(),
            // The stop endpoint has no gateway behind it: the gateway is gone, as the CLI says.
            ControlError::Stop(StopSocketError::NoGateway { .. }) => {
                Failure::NoGateway(error.to_string())
            }
            ControlError::Request(_) | ControlError::Stop(_) => Failure::Other(error.to_string()),
        }
    }
}

impl Failure {
    /// The Python exception (from `scout._errors`) saying this.
    fn into_py(self, py: Python<'_>) -> PyErr {
        let made = (|| -> PyResult<Bound<'_, PyAny>> {
            let errors = py.import("scout._errors")?;
            match self {
                Failure::NoGateway(message) => errors.getattr("NoGatewayError")?.call1((message,)),
                Failure::Version(message) => errors.getattr("VersionError")?.call1((message,)),
                Failure::NoAnswer(message) => errors.getattr("NoAnswerError")?.call1((message,)),
                Failure::Rejected {
                    message,
                    reason,
                    cause,
                } => errors.getattr("Rejected")?.call1((message, reason, cause)),
                Failure::Forked { made_in, here } => errors.getattr("ForkError")?.call1((format!(
                    "this robot was connected in process {made_in}, and this is process {here}, \
                     a child of os.fork(): the connection's worker thread does not exist here. \
                     Connect again in the child (scout.Robot.connect), or start children with \
                     multiprocessing's 'spawn' or 'forkserver' method"
                ),)),
                Failure::Other(message) => errors.getattr("ScoutError")?.call1((message,)),
            }
        })();
        match made {
            Ok(exception) => PyErr::from_value(exception),
            Err(error) => error,
        }
    }
}

/// A JSON value of the documented schemas as Python objects (dicts, lists, numbers, strings).
fn to_python<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(flag) => flag.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(number) => match (number.as_u64(), number.as_i64()) {
            (Some(unsigned), _) => unsigned.into_pyobject(py)?.into_any(),
            (None, Some(signed)) => signed.into_pyobject(py)?.into_any(),
            (None, None) => number
                .as_f64()
                .unwrap_or(f64::NAN)
                .into_pyobject(py)?
                .into_any(),
        },
        Value::String(text) => text.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(to_python(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(fields) => {
            let dict = PyDict::new(py);
            for (key, item) in fields {
                // Interned: the schema's few keys are made once per process, not per state.
                dict.set_item(PyString::intern(py, key), to_python(py, item)?)?;
            }
            dict.into_any()
        }
    })
}

fn answer_dict<'py>(py: Python<'py>, accepted: &Accepted) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("clamped", accepted.clamped)?;
    dict.set_item("lease", accepted.lease)?;
    dict.set_item("stop", accepted.stop)?;
    Ok(dict)
}

/// Waits for `receiver`'s one reply with the GIL released, checking for Ctrl-C between slices.
fn wait_reply<T: Send>(py: Python<'_>, mut receiver: Receiver<T>) -> PyResult<T> {
    loop {
        let (returned, reply) = py.detach(move || {
            let reply = receiver.recv_timeout(SLICE);
            (receiver, reply)
        });
        receiver = returned;
        match reply {
            Ok(reply) => return Ok(reply),
            Err(RecvTimeoutError::Timeout) => py.check_signals()?,
            Err(RecvTimeoutError::Disconnected) => {
                return Err(Failure::Other("the robot's worker thread is gone".into()).into_py(py));
            }
        }
    }
}

/// What the actor thread owns: the connection, and the controllers and stoppers by id.
struct Actor {
    robot: Robot,
    /// Opened with the connection, so the newest status is there when asked for.
    status: StatusReader,
    last_status: Option<StatusPayload>,
    controllers: HashMap<u64, Controller>,
    stoppers: HashMap<u64, Stopper>,
    next_id: u64,
}

type Job = Box<dyn FnOnce(&mut Actor) + Send>;

fn act(name: String, jobs: Receiver<Job>, connected: SyncSender<Result<(), Failure>>) {
    let (robot, status) = match Robot::connect(&name).and_then(|robot| Ok((robot.status()?, robot)))
    {
        Ok((status, robot)) => {
            let _ = connected.send(Ok(()));
            (robot, status)
        }
        Err(error) => {
            let _ = connected.send(Err(error.into()));
            return;
        }
    };
    let mut actor = Actor {
        robot,
        status,
        last_status: None,
        controllers: HashMap::new(),
        stoppers: HashMap::new(),
        next_id: 0,
    };
    for job in jobs {
        job(&mut actor);
    }
}

/// The robot's actor thread, in the process that started it.
#[derive(Debug, Clone)]
struct ActorHandle {
    jobs: Sender<Job>,
    /// The process that connected: after `os.fork()` a child has the handle but not the thread
    /// (only the forking thread lives on in a child), and a job sent would wait forever.
    pid: u32,
}

impl ActorHandle {
    /// Raises `ForkError` in a child of the process that connected.
    fn check_process(&self, py: Python<'_>) -> PyResult<()> {
        let here = std::process::id();
        if here == self.pid {
            return Ok(());
        }
        Err(Failure::Forked {
            made_in: self.pid,
            here,
        }
        .into_py(py))
    }
}

/// Runs `work` on the actor thread and waits for its result.
fn on_actor<T: Send + 'static>(
    py: Python<'_>,
    actor: &ActorHandle,
    work: impl FnOnce(&mut Actor) -> Result<T, Failure> + Send + 'static,
) -> PyResult<T> {
    actor.check_process(py)?;
    let jobs = &actor.jobs;
    let (reply, replied) = mpsc::sync_channel(1);
    jobs.send(Box::new(move |actor| {
        let _ = reply.send(work(actor));
    }))
    .map_err(|_| Failure::Other("the robot's worker thread is gone".into()).into_py(py))?;
    wait_reply(py, replied)?.map_err(|failure| failure.into_py(py))
}

fn parse_class(class: &str) -> PyResult<Class> {
    class
        .parse::<Class>()
        .map_err(|error| PyValueError::new_err(error.to_string()))
}

fn parse_light(light: &str) -> PyResult<Light> {
    parse_light_text(light).map_err(|error| PyValueError::new_err(error.to_string()))
}

/// One robot: its state subscriber (read on the caller's thread) and its actor thread.
#[pyclass(module = "scout._scout")]
#[derive(Debug)]
struct NativeRobot {
    name: String,
    /// `None` only once dropped in a child of `os.fork()` (see [`Drop`]).
    connection: Option<Connection>,
    actor: ActorHandle,
    last: Option<StatePayload>,
}

/// What a robot reads its states with.
#[derive(Debug)]
struct Connection {
    states: StateSubscriber,
    /// The connection the subscriber belongs to, dropped after it.
    _robot: Robot,
}

impl Drop for NativeRobot {
    /// In a child of `os.fork()` the connection is the parent's (its iceoryx2 node and ports):
    /// dropping it there would take them from the parent, so it is left alone.
    fn drop(&mut self) {
        if std::process::id() != self.actor.pid {
            std::mem::forget(self.connection.take());
        }
    }
}

impl NativeRobot {
    /// The connection, in the process that made it.
    fn connection(&self, py: Python<'_>) -> PyResult<&Connection> {
        self.actor.check_process(py)?;
        self.connection
            .as_ref()
            .ok_or_else(|| Failure::Other("this robot was closed".into()).into_py(py))
    }
}

/// One state as read from shared memory: a copy of the gateway's payload, turned into the
/// `scout echo --json` schema's fields only when asked for (each top-level field on its own).
#[pyclass(module = "scout._scout", frozen)]
#[derive(Debug)]
struct StateView {
    state: StatePayload,
    /// When this process read it (CLOCK_BOOTTIME): the ages are as of then.
    read_ns: u64,
}

impl StateView {
    fn new(state: StatePayload) -> Self {
        StateView {
            state,
            read_ns: monotonic_ns(),
        }
    }
}

#[pymethods]
impl StateView {
    /// When the gateway published it: CLOCK_BOOTTIME ns, as `time.clock_gettime_ns(time.CLOCK_BOOTTIME)`.
    #[getter]
    fn published_ns(&self) -> u64 {
        self.state.published_ns
    }

    /// Its sequence number.
    #[getter]
    fn seq(&self) -> u64 {
        self.state.seq
    }

    /// One top-level field of the `scout echo --json` schema (`link`, `system`, `motors`...).
    fn field<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyAny>> {
        let value = state_field(&self.state, key, self.read_ns).ok_or_else(|| {
            PyValueError::new_err(format!("the state has no field {key:?}: {STATE_KEYS:?}"))
        })?;
        to_python(py, &value)
    }

    /// The whole state as `scout echo --json` prints it.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &state_json(&self.state, self.read_ns))
    }
}

#[pymethods]
impl NativeRobot {
    /// Connects to the gateway serving robot `name` (raises `NoGatewayError`, `VersionError`).
    #[new]
    fn new(py: Python<'_>, name: String) -> PyResult<Self> {
        let (robot, states) = py
            .detach(|| Robot::connect(&name).and_then(|robot| Ok((robot.subscribe()?, robot))))
            .map(|(states, robot)| (robot, states))
            .map_err(|error| Failure::from(error).into_py(py))?;
        let (jobs, inbox) = mpsc::channel::<Job>();
        let (connected, actor_connected) = mpsc::sync_channel(1);
        std::thread::Builder::new()
            .name(format!("scout-{name}-control"))
            .spawn({
                let name = name.clone();
                move || act(name, inbox, connected)
            })
            .map_err(|error| Failure::Other(format!("starting a thread: {error}")).into_py(py))?;
        wait_reply(py, actor_connected)?.map_err(|failure| failure.into_py(py))?;
        Ok(NativeRobot {
            name,
            connection: Some(Connection {
                states,
                _robot: robot,
            }),
            actor: ActorHandle {
                jobs,
                pid: std::process::id(),
            },
            last: None,
        })
    }

    /// The robot's name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The newest state (a view of it, read field by field in the `scout echo --json` schema),
    /// or None before the first. Skips the ones not read.
    fn latest<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, StateView>>> {
        if let Some(newest) = self
            .connection(py)?
            .states
            .try_latest()
            .map_err(|error| Failure::from(error).into_py(py))?
        {
            self.last = Some(newest);
        }
        self.last
            .map(|state| Bound::new(py, StateView::new(state)))
            .transpose()
    }

    /// The next state in order, waiting at most `timeout` seconds; None when none came.
    fn next<'py>(
        &mut self,
        py: Python<'py>,
        timeout: f64,
    ) -> PyResult<Option<Bound<'py, StateView>>> {
        self.connection(py)?;
        let timeout = Duration::try_from_secs_f64(timeout)
            .map_err(|_| PyValueError::new_err("timeout: a number of seconds, 0 or more"))?;
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let states = &self.connection(py)?.states;
            let next = match py.detach(|| states.next_timeout(left.min(SLICE))) {
                Ok(next) => next,
                // A signal (Ctrl-C) woke the wait: Python's handler runs below.
                Err(ClientError::Wait(ListenerWaitError::InterruptSignal)) => None,
                Err(error) => return Err(Failure::from(error).into_py(py)),
            };
            match next {
                Some(state) => {
                    self.last = Some(state);
                    return Bound::new(py, StateView::new(state)).map(Some);
                }
                None if Instant::now() >= deadline => return Ok(None),
                None => py.check_signals()?,
            }
        }
    }

    /// The arbiter's status (a dict of the `scout status --json` schema), waiting at most
    /// `timeout` seconds for one.
    fn status<'py>(&self, py: Python<'py>, timeout: f64) -> PyResult<Bound<'py, PyAny>> {
        let timeout = Duration::try_from_secs_f64(timeout)
            .map_err(|_| PyValueError::new_err("timeout: a number of seconds, 0 or more"))?;
        let name = self.name.clone();
        let status = on_actor(py, &self.actor, move |actor| {
            let wait = if actor.last_status.is_some() {
                Duration::ZERO
            } else {
                timeout
            };
            if let Some(newest) = actor.status.latest(wait).map_err(Failure::from)? {
                actor.last_status = Some(newest);
            }
            actor.last_status.ok_or_else(|| {
                Failure::NoAnswer(format!(
                    "gateway '{name}' published no status within {timeout:?}: is it running \
                         (not stopped)?"
                ))
            })
        })?;
        to_python(py, &status_json(&status, monotonic_ns()))
    }

    /// A controller named `name`, driving as `class` ("teleop", "autonomy") or not at all.
    #[pyo3(signature = (name, class_=None))]
    fn controller(
        &self,
        py: Python<'_>,
        name: String,
        class_: Option<&str>,
    ) -> PyResult<NativeController> {
        let class = class_.map(parse_class).transpose()?;
        let id = on_actor(py, &self.actor, move |actor| {
            let controller = actor
                .robot
                .controller(&name, class)
                .map_err(Failure::from)?;
            actor.next_id += 1;
            actor.controllers.insert(actor.next_id, controller);
            Ok(actor.next_id)
        })?;
        Ok(NativeController {
            actor: self.actor.clone(),
            id,
        })
    }

    /// A client named `name` that only stops and releases.
    fn stopper(&self, py: Python<'_>, name: String) -> PyResult<NativeStopper> {
        let id = on_actor(py, &self.actor, move |actor| {
            let stopper = actor.robot.stopper(&name).map_err(Failure::from)?;
            actor.next_id += 1;
            actor.stoppers.insert(actor.next_id, stopper);
            Ok(actor.next_id)
        })?;
        Ok(NativeStopper {
            actor: self.actor.clone(),
            id,
        })
    }
}

/// A named client of the arbiter, living on its robot's actor thread.
#[pyclass(module = "scout._scout")]
#[derive(Debug)]
struct NativeController {
    actor: ActorHandle,
    id: u64,
}

impl NativeController {
    fn call<'py>(
        &self,
        py: Python<'py>,
        request: impl FnOnce(&mut Controller) -> Result<Accepted, ControlError> + Send + 'static,
    ) -> PyResult<Bound<'py, PyDict>> {
        let id = self.id;
        let accepted = on_actor(py, &self.actor, move |actor| {
            let controller = actor
                .controllers
                .get_mut(&id)
                .ok_or_else(|| Failure::Other("this controller was closed".into()))?;
            request(controller).map_err(Failure::from)
        })?;
        answer_dict(py, &accepted)
    }
}

fn release_target(own: bool, owner: Option<String>) -> ReleaseTarget {
    match (owner, own) {
        (Some(owner), _) => ReleaseTarget::Owner(owner),
        (None, true) => ReleaseTarget::Own,
        (None, false) => ReleaseTarget::All,
    }
}

#[pymethods]
impl NativeController {
    fn take_control<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, Controller::take_control)
    }

    #[pyo3(signature = (linear, angular, lateral=0.0, mode=None))]
    fn drive<'py>(
        &self,
        py: Python<'py>,
        linear: f64,
        angular: f64,
        lateral: f64,
        mode: Option<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = mode
            .as_deref()
            .map(str::parse::<DriveMode>)
            .transpose()
            .map_err(|error| PyValueError::new_err(error.to_string()))?;
        self.call(py, move |controller| match mode {
            Some(mode) => controller.drive_in_mode(mode, linear, lateral, angular, None),
            None => controller.drive_body(linear, lateral, angular, None),
        })
    }

    fn heartbeat<'py>(&self, py: Python<'py>, period: f64) -> PyResult<Bound<'py, PyDict>> {
        let period = Duration::try_from_secs_f64(period)
            .map_err(|_| PyValueError::new_err("period: a number of seconds, 0 or more"))?;
        self.call(py, move |controller| controller.heartbeat(period))
    }

    fn resume<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, Controller::resume)
    }

    fn relinquish<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, Controller::relinquish)
    }

    fn stop<'py>(&self, py: Python<'py>, reason: String) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, move |controller| controller.stop(&reason))
    }

    #[pyo3(signature = (through, own=true, owner=None))]
    fn release<'py>(
        &self,
        py: Python<'py>,
        through: u64,
        own: bool,
        owner: Option<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let target = release_target(own, owner);
        self.call(py, move |controller| controller.release(target, through))
    }

    /// `auto`, or the front and rear lights as `MODE[:BRIGHTNESS]` (as `scout lights`).
    #[pyo3(signature = (auto, front="off", rear="off"))]
    fn lights<'py>(
        &self,
        py: Python<'py>,
        auto: bool,
        front: &str,
        rear: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        let lights = if auto {
            Lights::Auto
        } else {
            Lights::Manual(LightCommand {
                enabled: true,
                front: parse_light(front)?,
                rear: parse_light(rear)?,
            })
        };
        self.call(py, move |controller| controller.lights(lights))
    }

    #[pyo3(signature = (code=None))]
    fn clear_fault<'py>(
        &self,
        py: Python<'py>,
        code: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let code = code
            .map(|name| {
                FaultClear::from_name(name)
                    .ok_or_else(|| PyValueError::new_err(format!("no fault-clear code {name:?}")))
            })
            .transpose()?;
        self.call(py, move |controller| controller.clear_fault(code))
    }

    fn reset_odometry<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, Controller::reset_odometry)
    }

    /// The lease it holds, if it took control and has not lost it.
    #[getter]
    fn lease(&self, py: Python<'_>) -> PyResult<Option<u64>> {
        let id = self.id;
        on_actor(py, &self.actor, move |actor| {
            Ok(actor.controllers.get(&id).and_then(Controller::lease))
        })
    }

    /// Forgets the controller (its client slot frees when the gateway sees it gone).
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let id = self.id;
        on_actor(py, &self.actor, move |actor| {
            actor.controllers.remove(&id);
            Ok(())
        })
    }
}

/// A client that only stops and releases, living on its robot's actor thread.
#[pyclass(module = "scout._scout")]
#[derive(Debug)]
struct NativeStopper {
    actor: ActorHandle,
    id: u64,
}

impl NativeStopper {
    fn call<'py>(
        &self,
        py: Python<'py>,
        request: impl FnOnce(&mut Stopper) -> Result<Accepted, ControlError> + Send + 'static,
    ) -> PyResult<Bound<'py, PyDict>> {
        let id = self.id;
        let accepted = on_actor(py, &self.actor, move |actor| {
            let stopper = actor
                .stoppers
                .get_mut(&id)
                .ok_or_else(|| Failure::Other("this stopper was closed".into()))?;
            request(stopper).map_err(Failure::from)
        })?;
        answer_dict(py, &accepted)
    }
}

#[pymethods]
impl NativeStopper {
    fn stop<'py>(&self, py: Python<'py>, reason: String) -> PyResult<Bound<'py, PyDict>> {
        self.call(py, move |stopper| stopper.stop(&reason))
    }

    #[pyo3(signature = (through, own=true, owner=None))]
    fn release<'py>(
        &self,
        py: Python<'py>,
        through: u64,
        own: bool,
        owner: Option<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let target = release_target(own, owner);
        self.call(py, move |stopper| stopper.release(target, through))
    }
}

#[pymodule]
fn _scout(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add_class::<NativeRobot>()?;
    module.add_class::<StateView>()?;
    module.add_class::<NativeController>()?;
    module.add_class::<NativeStopper>()?;
    module.add("LAYOUT_VERSION", LAYOUT_VERSION)?;
    Ok(())
}
