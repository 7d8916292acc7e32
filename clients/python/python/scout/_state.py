"""The chassis state, as `scout echo --json` documents it, with typed attributes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional

if TYPE_CHECKING:
    from . import _scout


@dataclass(frozen=True)
class Link:
    """The gateway's link to the chassis and its counters."""

    state: str
    transport: str
    device: str
    protocol: Optional[str]
    """The chassis' protocol, "v1" or "v2"; None until the gateway has told it."""
    rx_frames: int
    checksum_errors: int
    dropped_frames: int
    rejected_frames: int
    overflowed_frames: int
    discarded_bytes: int
    tx_frames: int
    reconnects: int


@dataclass(frozen=True)
class Chassis:
    """The model the gateway drives and its limits (m/s, rad/s; `max_lateral` m/s sideways, 0
    where it does not move sideways) and geometry (m)."""

    model: Optional[str]
    max_linear: float
    max_angular: float
    max_lateral: float
    track: float
    wheel_radius: float
    gear_ratio: float


@dataclass(frozen=True)
class System:
    """The chassis' system status (v1 0x151, v2 0x211): state, control mode, battery, faults.

    The control mode and fault names are the chassis protocol's: v1's control modes are rc,
    can and serial; v2's standby, can, uart and rc. `brake` is a Hunter's parking brake
    ("locked", "released"; None on a model without one).
    """

    state: str
    control_mode: str
    battery_voltage: float
    fault_bits: int
    faults: List[str]
    unknown_fault_bits: int
    brake: Optional[str]
    age_ms: float


@dataclass(frozen=True)
class Motion:
    """The speeds the chassis reports (v1 0x131, v2 0x221): m/s and rad/s; lateral on a MINI
    OMNI and a Ranger; steering (rad, positive to the left) on a Hunter and a Ranger, whose
    yaw rate (and a Ranger's sideways speed) the gateway derives from it; mode, a Ranger's
    motion mode ("dual_ackermann", "parallel", "spin"...; None on any other chassis), and
    whether it is changing to it; wheel_angles (rad) and wheel_speeds (m/s), a Ranger's four
    wheels as 0x271 and 0x281 report them, in their order (None on any other chassis)."""

    linear: float
    angular: float
    lateral: float
    steering: float
    mode: Optional[str]
    mode_changing: bool
    wheel_angles: Optional[List[float]]
    wheel_speeds: Optional[List[float]]
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
    """One motor (v1 0x200-0x203; v2 0x251-0x254 and 0x261-0x264): A, rpm, degrees C; on v2
    also its encoder pulses and its driver's voltage and state (None on v1)."""

    motor: int
    current: float
    rpm: int
    driver_temperature: Optional[int]
    motor_temperature: Optional[int]
    pulses: Optional[int]
    driver_voltage: Optional[float]
    driver_state: Optional[List[str]]
    driver_state_bits: Optional[int]
    age_ms: float


@dataclass(frozen=True)
class Odometer:
    """A v2 chassis' wheel odometers (0x311): cumulative distance of each side, m."""

    left: float
    right: float
    age_ms: float


@dataclass(frozen=True)
class Rc:
    """A v2 chassis' RC transmitter (0x241): switch positions (up, middle, down) and sticks."""

    swa: str
    swb: str
    swc: str
    swd: str
    right_horizontal: int
    right_vertical: int
    left_vertical: int
    left_horizontal: int
    knob: int
    age_ms: float


@dataclass(frozen=True)
class Bms:
    """A v2 chassis' smart battery (0x361, 0x362): %, V, A, degrees C, raw alarm bytes."""

    charge_percent: int
    health_percent: int
    voltage: float
    current: float
    temperature: float
    alarms: Optional[List[int]]
    age_ms: float


@dataclass(frozen=True)
class Battery:
    """The battery as the gateway judges it, on either protocol: the charge (a smart battery's
    report, or the gateway's estimate from the voltage: `source`), whether it charges (`status`:
    charging, discharging, not_charging, full, unknown), its `level` against the thresholds
    (ok, low, critical, unknown), and what set it (`level_from`: charge, chassis_warning,
    chassis_cutoff, none). None where nothing measures or estimates a value."""

    source: str
    percent: Optional[float]
    status: str
    level: str
    level_from: str
    voltage: Optional[float]
    current: Optional[float]
    health_percent: Optional[float]
    temperature: Optional[float]
    capacity_ah: Optional[float]
    low_percent: Optional[float]
    critical_percent: Optional[float]


@dataclass(frozen=True)
class Firmware:
    """A v2 chassis' firmware versions, as its answer to the version request says them."""

    text: str
    age_ms: float


@dataclass(frozen=True)
class Odometry:
    """The gateway's dead reckoning: m, rad, since its start or the last reset."""

    x: float
    y: float
    yaw: float
    distance: float
    resets: int
    distance_scale: float
    yaw_scale: float
    rotation: float


@dataclass(frozen=True)
class Command:
    """The motion command on the wire now (what the arbiter sends): m/s forward, m/s leftward,
    rad/s."""

    linear: float
    lateral: float
    angular: float


class State:
    """One chassis state, as the gateway published it (every 20 ms).

    The attributes mirror the `scout echo --json` schema; a section the chassis has not reported
    yet is None. Each section is made from the shared-memory copy when first read, so reading
    a state costs little until its fields are used. `to_dict()` gives exactly that schema.
    """

    __slots__ = ("_view", "_made")

    def __init__(self, view: "_scout.StateView") -> None:
        self._view = view
        self._made: Dict[str, Any] = {}

    def _field(self, key: str, make: Callable[[Any], Any]) -> Any:
        made = self._made.get(key, _UNMADE)
        if made is _UNMADE:
            made = make(self._view.field(key))
            self._made[key] = made
        return made

    @property
    def published_ns(self) -> int:
        """When the gateway published it: CLOCK_BOOTTIME ns, as `time.clock_gettime_ns(time.CLOCK_BOOTTIME)`."""
        return self._view.published_ns

    @property
    def seq(self) -> int:
        """Its sequence number (one per state the gateway publishes)."""
        return self._view.seq

    @property
    def robot(self) -> str:
        """The robot's name."""
        robot: str = self._field("robot", str)
        return robot

    @property
    def age_ms(self) -> float:
        """Its age when this process read it from shared memory, ms."""
        age: float = self._field("age_ms", float)
        return age

    @property
    def link(self) -> Link:
        """The gateway's link to the chassis and its counters."""
        link: Link = self._field("link", lambda fields: Link(**fields))
        return link

    @property
    def chassis(self) -> Chassis:
        """The model the gateway drives and its limits and geometry."""
        chassis: Chassis = self._field("chassis", lambda fields: Chassis(**fields))
        return chassis

    @property
    def system(self) -> Optional[System]:
        """The chassis' system status, or None before the first."""
        system: Optional[System] = self._field("system", lambda f: _optional(System, f))
        return system

    @property
    def motion(self) -> Optional[Motion]:
        """The speeds the chassis reports, or None before the first."""
        motion: Optional[Motion] = self._field("motion", lambda f: _optional(Motion, f))
        return motion

    @property
    def lights(self) -> Optional[Lights]:
        """The lights the chassis reports, or None before the first."""
        lights: Optional[Lights] = self._field("lights", _lights)
        return lights

    @property
    def motors(self) -> List[Optional[Motor]]:
        """The four motors' feedback (None before each one's first)."""
        motors: List[Optional[Motor]] = self._field(
            "motors", lambda items: [_optional(Motor, item) for item in items]
        )
        return motors

    @property
    def odometer(self) -> Optional[Odometer]:
        """The wheel odometers (protocol v2), or None before the first (always on v1)."""
        odometer: Optional[Odometer] = self._field(
            "odometer", lambda f: _optional(Odometer, f)
        )
        return odometer

    @property
    def rc(self) -> Optional[Rc]:
        """The RC transmitter (protocol v2, while it is on), or None before the first."""
        rc: Optional[Rc] = self._field("rc", lambda f: _optional(Rc, f))
        return rc

    @property
    def bms(self) -> Optional[Bms]:
        """The smart battery (protocol v2, when fitted), or None before the first."""
        bms: Optional[Bms] = self._field("bms", lambda f: _optional(Bms, f))
        return bms

    @property
    def battery(self) -> Battery:
        """The battery's charge, charging and level (docs/chassis.md, Battery)."""
        battery: Battery = self._field("battery", lambda fields: Battery(**fields))
        return battery

    @property
    def firmware(self) -> Optional[Firmware]:
        """The firmware versions (protocol v2), or None before the answer."""
        firmware: Optional[Firmware] = self._field(
            "firmware", lambda f: _optional(Firmware, f)
        )
        return firmware

    @property
    def odometry(self) -> Odometry:
        """The gateway's dead reckoning."""
        odometry: Odometry = self._field("odometry", lambda fields: Odometry(**fields))
        return odometry

    @property
    def command(self) -> Command:
        """The motion command on the wire now."""
        command: Command = self._field("command", lambda fields: Command(**fields))
        return command

    def to_dict(self) -> Dict[str, Any]:
        """The state as `scout echo --json` prints it (a new dict each call)."""
        fields: Dict[str, Any] = self._view.to_dict()
        return fields

    def __repr__(self) -> str:
        motion, system = self.motion, self.system
        speed = "-" if motion is None else f"{motion.linear:+.2f} m/s"
        battery = "-" if system is None else f"{system.battery_voltage:.1f} V"
        charge = self.battery.percent
        if charge is not None:
            battery += f" {charge:.0f} %"
        return f"<State {self.robot} #{self.seq} link={self.link.state} {speed} {battery}>"


_UNMADE = object()
"""A section not read yet (None is a section the chassis has not reported)."""


def _optional(kind: Any, fields: Optional[Dict[str, Any]]) -> Any:
    return None if fields is None else kind(**fields)


def _lights(fields: Optional[Dict[str, Any]]) -> Optional[Lights]:
    if fields is None:
        return None
    return Lights(
        enabled=fields["enabled"],
        front=Light(**fields["front"]),
        rear=Light(**fields["rear"]),
        age_ms=fields["age_ms"],
    )
