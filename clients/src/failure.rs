//! The kind of a client error ([`Failure`], from the interface crate) and, from it, the exit
//! code of every program: each program names its own error types, this module the library's.

use std::error::Error;

use crate::client::ClientError;
use crate::control::ControlError;
use crate::echo::EchoError;
pub use scout_interface::failure::Failure;

/// The kind of `cause` if it is one of this library's errors or the interface crate's.
pub fn kind_of(cause: &(dyn Error + 'static)) -> Option<Failure> {
    if let Some(error) = cause.downcast_ref::<ClientError>() {
        return Some(error.kind());
    }
    if let Some(error) = cause.downcast_ref::<ControlError>() {
        return Some(error.kind());
    }
    if let Some(error) = cause.downcast_ref::<EchoError>() {
        return Some(error.kind());
    }
    scout_interface::failure::kind_of(cause)
}

/// The exit code for an error given as its chain of causes (`anyhow::Error::chain`):
/// [`Failure::exit_code`] of the first cause of a kind other than `Failed`, `own` telling the
/// kinds of the program's own error types.
pub fn exit_code<'a>(
    chain: impl IntoIterator<Item = &'a (dyn Error + 'static)>,
    own: impl Fn(&(dyn Error + 'static)) -> Option<Failure>,
) -> u8 {
    Failure::of_chain(chain, |cause| own(cause).or_else(|| kind_of(cause))).exit_code()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interface::services::ServiceError;

    #[test]
    fn a_missing_gateway_under_context_is_exit_3() {
        let error = anyhow::Error::new(ClientError::Service(ServiceError::NoGateway {
            robot: "r".into(),
        }))
        .context("reading the state");
        assert_eq!(exit_code(error.chain(), |_| None), 3);
        assert_eq!(exit_code(anyhow::anyhow!("other").chain(), |_| None), 1);
    }

    #[test]
    fn a_program_s_own_kind_comes_first() {
        let error = anyhow::anyhow!("a bad flag");
        assert_eq!(exit_code(error.chain(), |_| Some(Failure::Usage)), 2);
    }
}
