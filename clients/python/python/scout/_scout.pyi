"""The native half of `scout` (Rust, PyO3): use the `scout` module's classes instead."""

from typing import Any, Dict, Optional, final


__all__ = ["LAYOUT_VERSION", "NativeController", "NativeRobot", "NativeStopper", "StateView"]

LAYOUT_VERSION: int

@final
class NativeRobot:
    """A connection to one robot's gateway: a state reader thread and a control thread."""

    def __new__(cls, name: str) -> NativeRobot:
        """Connects (raises `NoGatewayError`, `VersionError`)."""
    @property
    def name(self) -> str:
        """The robot's name."""
    def latest(self) -> Optional[StateView]:
        """The newest state, or None before the first."""
    def next(self, timeout: float) -> Optional[StateView]:
        """The next state in order, or None after `timeout` seconds (GIL released)."""
    def status(self, timeout: float) -> Dict[str, Any]:
        """The arbiter's status as a dict."""
    def controller(self, name: str, class_: Optional[str] = None) -> NativeController:
        """A controller named `name` of class `class_` (teleop, autonomy) or none."""
    def stopper(self, name: str) -> NativeStopper:
        """A client that only stops and releases."""

@final
class NativeController:
    """A named client of the arbiter; each call returns the answer as a dict."""

    @property
    def lease(self) -> Optional[int]:
        """The lease it holds."""
    def take_control(self) -> Dict[str, Any]:
        """Takes control as its class."""
    def drive(
        self, linear: float, angular: float, lateral: float = 0.0, mode: Optional[str] = None
    ) -> Dict[str, Any]:
        """Drives (m/s, rad/s, m/s leftward), in motion mode `mode` if named."""
    def heartbeat(self, period: float) -> Dict[str, Any]:
        """Registers a heartbeat of `period` seconds (0 drops it)."""
    def resume(self) -> Dict[str, Any]:
        """Arms autonomy."""
    def relinquish(self) -> Dict[str, Any]:
        """Gives up control."""
    def stop(self, reason: str) -> Dict[str, Any]:
        """Latches a stop of its own."""
    def release(
        self, through: int, own: bool = True, owner: Optional[str] = None
    ) -> Dict[str, Any]:
        """Releases stops up to `through`."""
    def lights(self, auto: bool, front: str = "off", rear: str = "off") -> Dict[str, Any]:
        """Sets the lights."""
    def clear_fault(self, code: Optional[str] = None) -> Dict[str, Any]:
        """Sends a fault-clear code (None: all)."""
    def reset_odometry(self) -> Dict[str, Any]:
        """Resets the odometry."""
    def close(self) -> None:
        """Forgets the controller."""

@final
class NativeStopper:
    """A client that only stops and releases its own stops."""

    def stop(self, reason: str) -> Dict[str, Any]:
        """Latches a stop of its own."""
    def release(
        self, through: int, own: bool = True, owner: Optional[str] = None
    ) -> Dict[str, Any]:
        """Releases its stops up to `through`."""

@final
class StateView:
    """One state as read from shared memory; its fields made when asked for."""

    @property
    def published_ns(self) -> int:
        """When the gateway published it (CLOCK_MONOTONIC ns)."""
    @property
    def seq(self) -> int:
        """Its sequence number."""
    def field(self, key: str) -> Any:
        """One top-level field of the `scout echo --json` schema."""
    def to_dict(self) -> Dict[str, Any]:
        """The whole state as `scout echo --json` prints it."""
