//! Reading gateways through zenoh: a remote state reader for `scout echo --remote`. The keys,
//! the command JSON and the session settings are the contract's ([`scout_interface::remote`]).

use std::time::Duration;

use zenoh::Wait;

pub use scout_interface::remote::*;

/// Reads state JSON from gateways through zenoh (`scout echo --remote`).
pub struct RemoteStates {
    _session: zenoh::Session,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl std::fmt::Debug for RemoteStates {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteStates").finish_non_exhaustive()
    }
}

impl RemoteStates {
    /// Connects as a zenoh client to `endpoints` and subscribes to the state of `robot` (`*` for
    /// every robot).
    pub fn connect(settings: &SessionSettings, robot: &str) -> Result<Self, RemoteError> {
        let session = settings.open("client")?;
        let subscriber = session
            .declare_subscriber(state_key(robot))
            .wait()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        Ok(Self {
            _session: session,
            subscriber,
        })
    }

    /// The next state JSON, waiting at most `timeout`.
    pub fn next_timeout(
        &self,
        timeout: Duration,
    ) -> Result<Option<serde_json::Value>, RemoteError> {
        let Some(sample) = self
            .subscriber
            .recv_timeout(timeout)
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?
        else {
            return Ok(None);
        };
        let text = sample
            .payload()
            .try_to_string()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| RemoteError::Zenoh(format!("state is not JSON: {e}")))
    }
}
