//! What kind of failure an error is: the one vocabulary every program's exit code comes from.
//!
//! Each error type says its kind through one trait, [`FailureKind`]; each crate lists its error
//! types once ([`KINDS`] here); [`Failure::exit_code`] maps kinds to exit codes, once for every
//! program; [`Failure::of_chain`] finds the kind of an error and its causes.

use std::error::Error;

#[cfg(feature = "zenoh")]
use crate::remote::RemoteError;
use crate::robot::BadRobotName;
use crate::services::{ControlPortError, RequestError, ServiceError};
use crate::stop_socket::StopSocketError;

/// The kinds of failure, each with its exit code (README.md's "Exit codes").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Something failed: I/O, a decode, a gateway of another interface version. Exit 1.
    Failed,
    /// The command line or a setting is wrong. Exit 2.
    Usage,
    /// No gateway with that name runs, or it stopped answering. Exit 3.
    NoGateway,
    /// The gateway refused the request, or ended the control a client held. Exit 4.
    Refused,
}

impl Failure {
    /// The process exit code of this kind.
    pub const fn exit_code(self) -> u8 {
        match self {
            Self::Failed => 1,
            Self::Usage => 2,
            Self::NoGateway => 3,
            Self::Refused => 4,
        }
    }

    /// The kind of an error given as its chain of causes (`anyhow::Error::chain`, or
    /// `error` then its `source()`s): the first cause with a kind other than `Failed`, as
    /// `kind_of` tells it (which knows the program's own error types, then calls
    /// [`kind_of`]); `Failed` if none has one.
    pub fn of_chain<'a>(
        chain: impl IntoIterator<Item = &'a (dyn Error + 'static)>,
        kind_of: impl Fn(&(dyn Error + 'static)) -> Option<Failure>,
    ) -> Failure {
        chain
            .into_iter()
            .filter_map(kind_of)
            .find(|kind| *kind != Self::Failed)
            .unwrap_or(Self::Failed)
    }
}

/// An error that knows what kind of failure it is.
pub trait FailureKind: Error + 'static {
    /// What kind of failure this is.
    fn kind(&self) -> Failure;
}

/// Tells the kind of an error, if it is of the type it knows.
pub type KindOf = fn(&(dyn Error + 'static)) -> Option<Failure>;

/// The kind of `cause` if it is an `E`: one entry of a crate's list of error types.
pub fn kind_if<E: FailureKind>(cause: &(dyn Error + 'static)) -> Option<Failure> {
    cause.downcast_ref::<E>().map(FailureKind::kind)
}

/// The kind of the first of `kinds` that knows `cause`.
pub fn kind_in(kinds: &[KindOf], cause: &(dyn Error + 'static)) -> Option<Failure> {
    kinds.iter().find_map(|kind_of| kind_of(cause))
}

/// This crate's error types.
pub const KINDS: &[KindOf] = &[
    kind_if::<ServiceError>,
    kind_if::<RequestError>,
    kind_if::<ControlPortError>,
    kind_if::<StopSocketError>,
    kind_if::<BadRobotName>,
    #[cfg(feature = "zenoh")]
    kind_if::<RemoteError>,
];

/// The kind of `cause` if it is one of this crate's errors.
pub fn kind_of(cause: &(dyn Error + 'static)) -> Option<Failure> {
    kind_in(KINDS, cause)
}

impl FailureKind for BadRobotName {
    fn kind(&self) -> Failure {
        Failure::Usage
    }
}

impl FailureKind for ServiceError {
    fn kind(&self) -> Failure {
        match self {
            Self::NoGateway { .. } => Failure::NoGateway,
            Self::Name(_)
            | Self::Incompatible { .. }
            | Self::PublishSubscribe { .. }
            | Self::Event { .. }
            | Self::RequestResponse { .. } => Failure::Failed,
        }
    }
}

impl FailureKind for RequestError {
    fn kind(&self) -> Failure {
        match self {
            Self::Rejected(_) => Failure::Refused,
            Self::NoAnswer { .. } => Failure::NoGateway,
            Self::Send(_) | Self::Wake(_) | Self::Receive(_) => Failure::Failed,
        }
    }
}

impl FailureKind for ControlPortError {
    fn kind(&self) -> Failure {
        match self {
            Self::Service(error) => error.kind(),
            Self::Name(_) => Failure::Usage,
            Self::Client { .. } | Self::Notifier(_) => Failure::Failed,
        }
    }
}

impl FailureKind for StopSocketError {
    fn kind(&self) -> Failure {
        match self {
            Self::NoGateway { .. } | Self::NoAnswer { .. } => Failure::NoGateway,
            Self::Reply { .. } | Self::Io { .. } => Failure::Failed,
        }
    }
}

/// A bad configuration is a usage error.
#[cfg(feature = "zenoh")]
impl FailureKind for RemoteError {
    fn kind(&self) -> Failure {
        match self {
            Self::Config(_) => Failure::Usage,
            Self::Zenoh(_) => Failure::Failed,
            Self::Refused { .. } => Failure::Refused,
            // Nothing reached to connect to, or nothing answered.
            Self::Open(_) | Self::NoAnswer { .. } => Failure::NoGateway,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn exit_codes_are_distinct_and_documented() {
        let all = [
            Failure::Failed,
            Failure::Usage,
            Failure::NoGateway,
            Failure::Refused,
        ];
        let codes: Vec<u8> = all.iter().map(|kind| kind.exit_code()).collect();
        assert_eq!(codes, [1, 2, 3, 4]);
    }

    #[test]
    fn the_first_cause_with_a_kind_decides() {
        #[derive(Debug, thiserror::Error)]
        #[error("wrapped")]
        struct Wrapper(#[source] StopSocketError);
        let error = Wrapper(StopSocketError::NoAnswer {
            robot: "r".into(),
            timeout: Duration::from_secs(1),
        });
        let chain: [&(dyn Error + 'static); 2] = [&error, &error.0];
        assert_eq!(Failure::of_chain(chain, kind_of), Failure::NoGateway);
        let plain = std::io::Error::other("x");
        assert_eq!(
            Failure::of_chain([&plain as &(dyn Error + 'static)], kind_of),
            Failure::Failed
        );
    }
}
