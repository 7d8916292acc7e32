"""Drive and watch an AgileX SCOUT through `scout-gateway`, with the gateway's safety rules.

    import scout

    robot = scout.Robot.connect("scout")
    print(robot.next(timeout=1.0).system)          # from shared memory, no JSON
    with robot.controller("planner", "autonomy") as c:
        c.take_control()
        c.drive(0.3, 0.0)                          # every 20-100 ms while driving
    # leaving the block sends zero and gives up control

The state comes from the gateway's shared memory (iceoryx2) through the Rust client library;
control goes through the same arbiter as every other client: a stop outranks teleop, which
outranks autonomy; autonomy drives only after a `resume`; nothing restarts motion but taking
control again. Blocking calls release the GIL and Ctrl-C interrupts them. A process that dies
while driving is a dead client like any other: its commands stop and so does the robot.
"""

from __future__ import annotations

import asyncio
import enum
import threading
import time
from dataclasses import dataclass
from types import TracebackType
from typing import Any, AsyncIterator, Dict, Iterator, Optional, Type, Union

from . import _scout
from ._errors import (
    ForkError,
    NoAnswerError,
    NoGatewayError,
    Rejected,
    ScoutError,
    VersionError,
)
from ._state import (
    Battery,
    Bms,
    Chassis,
    Command,
    Firmware,
    Light,
    Lights,
    Link,
    Motion,
    Motor,
    Odometer,
    Odometry,
    Rc,
    State,
    System,
)

__all__ = [
    "LAYOUT_VERSION",
    "Answer",
    "Battery",
    "Bms",
    "Chassis",
    "Class",
    "Command",
    "Controller",
    "Firmware",
    "ForkError",
    "Light",
    "Lights",
    "Link",
    "Motion",
    "Motor",
    "NoAnswerError",
    "NoGatewayError",
    "Odometer",
    "Odometry",
    "Rc",
    "Rejected",
    "Robot",
    "ScoutError",
    "State",
    "Stopper",
    "System",
    "VersionError",
]

LAYOUT_VERSION: int = _scout.LAYOUT_VERSION
"""The interface version (shared-memory layout) this package speaks."""


class Class(str, enum.Enum):
    """The class a controller drives as: teleop outranks autonomy."""

    TELEOP = "teleop"
    AUTONOMY = "autonomy"


@dataclass(frozen=True)
class Answer:
    """The arbiter's answer to an accepted request (a refused one raises `Rejected`)."""

    clamped: bool
    """A speed was beyond the class' caps and was clamped."""
    lease: Optional[int]
    """For `take_control`: the lease this controller's drive commands name."""
    stop: Optional[int]
    """For a stop: the id of the stop it latched (or refreshed)."""

    @property
    def accepted(self) -> bool:
        """Always True: an answer is an acceptance, a refusal raises `Rejected`."""
        return True

    @staticmethod
    def _from(fields: Dict[str, Any]) -> "Answer":
        return Answer(clamped=fields["clamped"], lease=fields["lease"], stop=fields["stop"])


class Robot:
    """A connection to the gateway serving one robot (by its name)."""

    def __init__(self, native: _scout.NativeRobot) -> None:
        self._native = native

    @classmethod
    def connect(cls, name: str = "scout") -> "Robot":
        """Connects to the gateway of robot `name`.

        Raises `NoGatewayError` (with the same message as the `scout` tool) when none runs, and
        `VersionError` when it speaks another interface version.
        """
        return cls(_scout.NativeRobot(name))

    @property
    def name(self) -> str:
        """The robot's name."""
        return self._native.name

    def latest(self) -> Optional[State]:
        """The newest state, or None before the gateway published one. Does not wait."""
        latest = self._native.latest()
        return None if latest is None else State(latest)

    def next(self, timeout: float = 1.0) -> State:
        """The next state in order (every one the gateway publishes, none skipped).

        Waits at most `timeout` seconds; raises `TimeoutError` when none came (the gateway
        stopped publishing: it is gone or stuck).
        """
        state = self._native.next(timeout)
        if state is None:
            raise TimeoutError(
                f"no state from gateway '{self.name}' within {timeout} s: is it running?"
            )
        return State(state)

    def states(self, timeout: float = 3.0) -> Iterator[State]:
        """Every state in order, forever; raises `TimeoutError` after `timeout` s of silence."""
        while True:
            yield self.next(timeout)

    async def states_async(self, timeout: float = 3.0) -> AsyncIterator[State]:
        """`states()` for asyncio: `async for s in robot.states_async(): ...`.

        A connection of its own reads the states on a thread and hands them to the event loop
        (the newest 256 kept if the loop falls behind), so the loop never blocks; raises
        `TimeoutError` after `timeout` s of silence.
        """
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[Union[State, BaseException]] = asyncio.Queue(maxsize=256)
        halt = threading.Event()

        def put(item: Union[State, BaseException]) -> None:
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(item)

        def hand_over(item: Union[State, BaseException]) -> None:
            try:
                loop.call_soon_threadsafe(put, item)
            except RuntimeError:  # the loop closed: nobody is reading any more
                halt.set()

        def read() -> None:
            try:
                native = _scout.NativeRobot(self.name)
                heard = time.monotonic()
                while not halt.is_set():
                    state = native.next(0.1)
                    if state is not None:
                        heard = time.monotonic()
                        hand_over(State(state))
                    elif time.monotonic() - heard > timeout:
                        raise TimeoutError(
                            f"no state from gateway '{self.name}' within {timeout} s: "
                            "is it running?"
                        )
            except BaseException as error:  # handed to the consumer
                if not halt.is_set():
                    hand_over(error)

        reader = threading.Thread(target=read, name=f"scout-{self.name}-async", daemon=True)
        reader.start()
        try:
            while True:
                item = await queue.get()
                if isinstance(item, BaseException):
                    raise item
                yield item
        finally:
            halt.set()

    def status(self, timeout: float = 2.0) -> Dict[str, Any]:
        """The arbiter's status, as `scout status --json` prints it: stops with their owners
        and causes, who drives, the output, the sources, rejections, the tick."""
        return self._native.status(timeout)

    def controller(self, name: str, class_: Union[Class, str, None] = None) -> "Controller":
        """A controller named `name` (shown in the status and the gateway's audit log).

        With a class ("teleop" or "autonomy") it may take control and drive; without one it
        may stop, release its own stops, resume autonomy, set lights, clear faults. Use it in a
        `with` block: leaving it sends zero and gives up control.
        """
        class_name = None if class_ is None else Class(class_).value
        return Controller(self, self._native.controller(name, class_name))

    def stopper(self, name: str) -> "Stopper":
        """A client named `name` that only stops and releases its own stops: a safety monitor.

        It talks to the gateway's stop endpoint, which needs no shared memory: make it ahead of
        time and a stop costs one datagram each way.
        """
        return Stopper(self, self._native.stopper(name))

    def __repr__(self) -> str:
        return f"<scout.Robot {self.name!r}>"


def _newest_stop(robot: Robot) -> int:
    newest: int = robot.status()["newest_stop"]
    return newest


class Controller:
    """A named client of the arbiter. Every call returns the `Answer` or raises `Rejected`."""

    def __init__(self, robot: Robot, native: _scout.NativeController) -> None:
        self._robot = robot
        self._native = native

    @property
    def lease(self) -> Optional[int]:
        """The lease it holds, if it took control and has not lost it."""
        return self._native.lease

    def take_control(self) -> Answer:
        """Takes control as its class: a deliberate act, and the only one that gives control
        back after a stop, a release, a takeover or silence ended it."""
        return Answer._from(self._native.take_control())

    def drive(
        self,
        linear: float,
        angular: float,
        lateral: float = 0.0,
        mode: Optional[str] = None,
    ) -> Answer:
        """Drives at `linear` m/s and `angular` rad/s, and `lateral` m/s to the left (a SCOUT
        MINI OMNI or a Ranger; any other chassis refuses a sideways speed, saying why),
        clamped to the class' caps (see `Answer.clamped`). Send it every 20-100 ms: silence
        stops the robot.

        `mode` names a Ranger's motion mode to drive in: "dual_ackermann", "parallel",
        "spin", or "park" (with zero speeds: parks it); None lets the gateway pick it from the
        velocity. A velocity the mode does not carry (a yaw rate in parallel mode) is refused
        with the reason (`Rejected`, `cause` "not_allowed"), as is a mode on a chassis
        without modes; an unknown name raises ValueError."""
        return Answer._from(
            self._native.drive(float(linear), float(angular), float(lateral), mode)
        )

    def heartbeat(self, period: float = 0.5) -> Answer:
        """Registers this controller as a heartbeat: if no request comes from it for `period`
        seconds, a stop latches. Every request is a beat; 0 deregisters."""
        return Answer._from(self._native.heartbeat(float(period)))

    def resume(self) -> Answer:
        """Arms autonomy (after a start, a stop, a release or a teleop takeover)."""
        return Answer._from(self._native.resume())

    def stop(self, reason: str) -> Answer:
        """Latches a stop owned by this controller's name: zero speed at once, until released."""
        return Answer._from(self._native.stop(reason))

    def release(self, own: bool = True, through: Optional[int] = None) -> Answer:
        """Releases this controller's own stops (`own=False`: every stop, which needs the
        operator role) latched up to stop `through` (default: the newest the status shows).
        Nothing moves until clients take control again."""
        if through is None:
            through = _newest_stop(self._robot)
        return Answer._from(self._native.release(through, own))

    def relinquish(self) -> Answer:
        """Gives up control: the output ramps to zero. Leaves stops alone."""
        return Answer._from(self._native.relinquish())

    def lights(self, front: str = "off", rear: str = "off", auto: bool = False) -> Answer:
        """Sets the lights: `front`/`rear` as `MODE[:BRIGHTNESS]` (off, on, breath, custom;
        0..100), or `auto=True` to hand them back to the chassis."""
        return Answer._from(self._native.lights(auto, front, rear))

    def clear_fault(self, code: Optional[str] = None) -> Answer:
        """Sends a fault-clear code (as `scout clear-fault` names them); None: every code."""
        return Answer._from(self._native.clear_fault(code))

    def reset_odometry(self) -> Answer:
        """Resets the gateway's odometry to the origin."""
        return Answer._from(self._native.reset_odometry())

    def close(self) -> None:
        """Sends zero and gives up control if it holds it; then forgets the controller."""
        try:
            if self._native.lease is not None:
                try:
                    self._native.drive(0.0, 0.0)
                finally:
                    self._native.relinquish()
        except Rejected:
            pass  # it had already lost control: nothing of its is moving
        finally:
            self._native.close()

    def __enter__(self) -> "Controller":
        return self

    def __exit__(
        self,
        kind: Optional[Type[BaseException]],
        error: Optional[BaseException],
        trace: Optional[TracebackType],
    ) -> None:
        self.close()


class Stopper:
    """A client that only stops and releases its own stops."""

    def __init__(self, robot: Robot, native: _scout.NativeStopper) -> None:
        self._robot = robot
        self._native = native

    def stop(self, reason: str) -> Answer:
        """Latches a stop owned by this stopper's name: zero speed at once, until released.
        Never refused."""
        return Answer._from(self._native.stop(reason))

    def release(self, through: Optional[int] = None) -> Answer:
        """Releases this stopper's own stops latched up to `through` (default: the newest the
        status shows). Restarts nothing."""
        if through is None:
            through = _newest_stop(self._robot)
        return Answer._from(self._native.release(through, True))
