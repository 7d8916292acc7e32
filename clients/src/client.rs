//! The client API: connect to a robot's gateway by name and read its state.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;

use crate::ipc::{self, Ipc, Role, ServiceError, StatePayload};

/// What can go wrong talking to a gateway.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The robot name is not valid.
    #[error("{0}")]
    BadName(String),
    /// The gateway's services could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// iceoryx2 failed.
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
}

fn iceoryx(error: impl std::fmt::Display) -> ClientError {
    ClientError::Iceoryx(error.to_string())
}

/// A connection to one robot's gateway.
#[derive(Debug)]
pub struct Robot {
    name: String,
    node: Node<Ipc>,
}

impl Robot {
    /// Connects to the gateway serving robot `name`. Fails with [`ServiceError::NoGateway`]
    /// when none runs.
    pub fn connect(name: &str) -> Result<Self, ClientError> {
        ipc::check_robot_name(name).map_err(ClientError::BadName)?;
        ipc::quiet_iceoryx2_logs();
        ipc::remove_dead_nodes();
        let node = ipc::node(&format!("scout-client-{name}")).map_err(iceoryx)?;
        ipc::state_services(&node, name, Role::Client)?;
        Ok(Self {
            name: name.to_owned(),
            node,
        })
    }

    /// The robot's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The iceoryx2 node of this process.
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// Subscribes to the chassis state. The latest state is available at once.
    pub fn subscribe(&self) -> Result<StateSubscriber, ClientError> {
        let (state, events) = ipc::state_services(&self.node, &self.name, Role::Client)?;
        let subscriber = state.subscriber_builder().create().map_err(iceoryx)?;
        let listener = events.listener_builder().create().map_err(iceoryx)?;
        Ok(StateSubscriber {
            subscriber,
            listener,
        })
    }
}

/// Receives the state a gateway publishes.
#[derive(Debug)]
pub struct StateSubscriber {
    subscriber: Subscriber<Ipc, StatePayload, ()>,
    listener: Listener<Ipc>,
}

impl StateSubscriber {
    /// The newest state received since the last call, without waiting; older ones are skipped.
    pub fn try_latest(&self) -> Result<Option<StatePayload>, ClientError> {
        let mut latest = None;
        while let Some(sample) = self.subscriber.receive().map_err(iceoryx)? {
            latest = Some(*sample);
        }
        Ok(latest)
    }

    /// The next state, in order, without waiting.
    pub fn try_next(&self) -> Result<Option<StatePayload>, ClientError> {
        Ok(self
            .subscriber
            .receive()
            .map_err(iceoryx)?
            .map(|sample| *sample))
    }

    /// Blocks (without polling) until a state arrives or `timeout` passes; returns the next one
    /// in order.
    pub fn next_timeout(&self, timeout: Duration) -> Result<Option<StatePayload>, ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(state) = self.try_next()? {
                return Ok(Some(state));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.listener.timed_wait(|_| {}, left).map_err(iceoryx)?;
        }
    }
}
