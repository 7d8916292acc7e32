"""The exceptions the package raises, with the same words as the `scout` tool."""

from __future__ import annotations


class ScoutError(Exception):
    """Something went wrong talking to the gateway; the message says what and what to do."""


class NoGatewayError(ScoutError):
    """No gateway of that robot name runs (the `scout` tool exits 3 for this)."""


class VersionError(ScoutError):
    """The gateway speaks another interface version: use a package and a gateway of one release."""


class ForkError(ScoutError):
    """Used in a child of `os.fork()`: connect again in the child (the parent's connection and
    its worker thread stay with the parent)."""


class NoAnswerError(ScoutError):
    """The gateway did not answer in time: it is stopped, stuck or gone."""


class Rejected(ScoutError):
    """The arbiter refused the request (the `scout` tool exits 4 for this).

    `reason` is the gateway's wording (what to do is in it); `cause` names the kind of refusal:
    `autonomy_disarmed`, `latched`, `held`, `no_control`, `revoked`, `not_allowed`, ...
    """

    reason: str
    cause: str

    def __init__(self, message: str, reason: str, cause: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.cause = cause

    @property
    def lost_control(self) -> bool:
        """Whether this client lost (or never had) control: take it again, on purpose."""
        return self.cause in ("revoked", "no_control")
