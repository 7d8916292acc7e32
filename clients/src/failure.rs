//! The exit code of every program, from the kind of its error ([`Failure`], from the interface
//! crate): this library's error types and the interface crate's are listed once, in
//! [`crate::ERROR_KINDS`]; each program adds its own.

use std::error::Error;

pub use scout_interface::failure::{Failure, FailureKind, KindOf, kind_if};

/// The kind of `cause` if it is one of this library's errors or the interface crate's.
pub fn kind_of(cause: &(dyn Error + 'static)) -> Option<Failure> {
    scout_interface::failure::kind_in(crate::ERROR_KINDS, cause)
}

/// The exit code for an error given as its chain of causes (`anyhow::Error::chain`):
/// [`Failure::exit_code`] of the first cause of a kind other than `Failed`, `own` telling the
/// kinds of the program's own error types (a list of [`kind_if`]).
pub fn exit_code<'a>(
    chain: impl IntoIterator<Item = &'a (dyn Error + 'static)>,
    own: &[KindOf],
) -> u8 {
    let kind_of = |cause: &(dyn Error + 'static)| {
        scout_interface::failure::kind_in(own, cause).or_else(|| kind_of(cause))
    };
    Failure::of_chain(chain, kind_of).exit_code()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::ClientError;
    use crate::interface::services::ServiceError;

    #[test]
    fn a_missing_gateway_under_context_is_exit_3() {
        let error = anyhow::Error::new(ClientError::Service(ServiceError::NoGateway {
            robot: "r".into(),
        }))
        .context("reading the state");
        assert_eq!(exit_code(error.chain(), &[]), 3);
        assert_eq!(exit_code(anyhow::anyhow!("other").chain(), &[]), 1);
    }

    #[derive(Debug, thiserror::Error)]
    #[error("a bad flag")]
    struct BadFlag;

    impl FailureKind for BadFlag {
        fn kind(&self) -> Failure {
            Failure::Usage
        }
    }

    #[test]
    fn a_program_s_own_kind_comes_first() {
        let error = anyhow::Error::new(BadFlag);
        assert_eq!(exit_code(error.chain(), &[kind_if::<BadFlag>]), 2);
        assert_eq!(exit_code(error.chain(), &[]), 1);
    }
}
