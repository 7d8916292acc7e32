"""The chassis state, as `scout echo --json` documents it, with typed attributes."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Dict, List, Optional


@dataclass(frozen=True)
class Link:
    """The gateway's link to the chassis and its counters."""

    state: str
    transport: str
    device: str
    rx_frames: int
    checksum_errors: int
    dropped_frames: int
    rejected_frames: int
    overflowed_frames: int
    discarded_bytes: int
    tx_frames: int
    reconnects: int


@dataclass(frozen=True)
class System:
    """The chassis' system status (0x151): state, control mode, battery, faults by name."""

    state: str
    control_mode: str
    battery_voltage: float
    fault_bits: int
    faults: List[str]
    age_ms: float


@dataclass(frozen=True)
class Motion:
    """The speeds the chassis reports (0x131): m/s and rad/s."""

    linear: float
    angular: float
    age_ms: float


@dataclass(frozen=True)
class Light:
    """One light: its mode (off, on, breath, custom) and brightness 0..100."""

    mode: str
    brightness: int


@dataclass(frozen=True)
class Lights:
    """The lights the chassis reports (0x141)."""

    enabled: bool
    front: Light
    rear: Light
    age_ms: float


@dataclass(frozen=True)
class Motor:
    """One motor's driver feedback (0x201-0x204): A, rpm, degrees C."""

    motor: int
    current: float
    rpm: int
    driver_temperature: int
    motor_temperature: int
    age_ms: float


@dataclass(frozen=True)
class Odometry:
    """The gateway's dead reckoning: m, rad, since its start or the last reset."""

    x: float
    y: float
    yaw: float
    distance: float
    resets: int


@dataclass(frozen=True)
class Command:
    """The motion command on the wire now (what the arbiter sends): m/s, rad/s."""

    linear: float
    angular: float


def _optional(kind: Any, fields: Optional[Dict[str, Any]]) -> Any:
    return None if fields is None else kind(**fields)


class State:
    """One chassis state, as the gateway published it (every 20 ms).

    The attributes mirror the `scout echo --json` schema; a section the chassis has not reported
    yet is None. `to_dict()` gives exactly that schema.
    """

    __slots__ = ("_fields", "published_ns", "robot", "seq", "age_ms", "link", "system", "motion", "lights",
                 "motors", "odometry", "command")

    published_ns: int
    """When the gateway published it: CLOCK_MONOTONIC ns, comparable with time.monotonic_ns()."""
    robot: str
    seq: int
    age_ms: float
    """Its age when this process read it from shared memory."""
    link: Link
    system: Optional[System]
    motion: Optional[Motion]
    lights: Optional[Lights]
    motors: List[Optional[Motor]]
    odometry: Odometry
    command: Command

    def __init__(self, published_ns: int, fields: Dict[str, Any]) -> None:
        self._fields = fields
        self.published_ns = published_ns
        self.robot = fields["robot"]
        self.seq = fields["seq"]
        self.age_ms = fields["age_ms"]
        self.link = Link(**fields["link"])
        self.system = _optional(System, fields["system"])
        self.motion = _optional(Motion, fields["motion"])
        lights = fields["lights"]
        self.lights = None if lights is None else Lights(
            enabled=lights["enabled"],
            front=Light(**lights["front"]),
            rear=Light(**lights["rear"]),
            age_ms=lights["age_ms"],
        )
        self.motors = [_optional(Motor, motor) for motor in fields["motors"]]
        self.odometry = Odometry(**fields["odometry"])
        self.command = Command(**fields["command"])

    def to_dict(self) -> Dict[str, Any]:
        """The state as `scout echo --json` prints it (a copy)."""
        return copy.deepcopy(self._fields)

    def __repr__(self) -> str:
        speed = "-" if self.motion is None else f"{self.motion.linear:+.2f} m/s"
        battery = "-" if self.system is None else f"{self.system.battery_voltage:.1f} V"
        return f"<State {self.robot} #{self.seq} link={self.link.state} {speed} {battery}>"
