//! The zenoh check, when asked (`--zenoh ENDPOINT`): a zenoh client session to that endpoint, and
//! the robot's state arriving through it, as a remote peer would see it.

use std::time::Duration;

use scout_clients::remote::{RemoteError, RemoteStates, SessionSettings};

use crate::check::Check;

/// Connects to `endpoint` as a zenoh client and waits up to `window` for robot `robot`'s state.
pub fn inspect(robot: &str, endpoint: &str, window: Duration) -> Check {
    let settings = SessionSettings {
        config_file: None,
        listen: Vec::new(),
        connect: vec![endpoint.to_owned()],
    };
    let states = match RemoteStates::connect(&settings, robot) {
        Ok(states) => states,
        Err(error @ (RemoteError::Config(_) | RemoteError::Zenoh(_))) => {
            return Check::fail(
                "zenoh",
                format!("{endpoint}: {error}"),
                "give an endpoint as tcp/HOST:PORT (the gateway listens on tcp/127.0.0.1:7448 \
                 unless --zenoh-listen says otherwise)",
            );
        }
        Err(error @ RemoteError::Open(_)) => {
            return Check::fail(
                "zenoh",
                format!("cannot reach {endpoint}: {error}"),
                "is the gateway (or the zenoh router) listening there? `scout-gateway \
                 --zenoh-listen tcp/0.0.0.0:7448` listens beyond this machine; check firewalls",
            );
        }
        // Commands are not sent here: subscribing has no answer to refuse or miss.
        Err(error @ (RemoteError::Refused { .. } | RemoteError::NoAnswer { .. })) => {
            return Check::fail("zenoh", format!("{endpoint}: {error}"), "see the error");
        }
    };
    match states.next_timeout(window.max(Duration::from_secs(1))) {
        Ok(Some(_)) => {
            return Check::pass(
                "zenoh",
                format!("robot {robot}'s state arrives through zenoh at {endpoint}"),
            );
        }
        Ok(None) => {}
        Err(error) => {
            return Check::fail(
                "zenoh",
                format!("reading robot {robot}'s state at {endpoint}: {error}"),
                "see the error; `scout echo --remote` shows what arrives",
            );
        }
    }
    Check::fail(
        "zenoh",
        format!("connected to {endpoint}, but no state of robot {robot} arrived in {window:.1?}"),
        "does the gateway run with zenoh (not --no-zenoh) and this --name? `scout echo --remote \
         --name '*'` lists the robots that publish there",
    )
}
