"""The package against real `scout-gateway --sim` processes: every API point, and the safety
rules as a Python user meets them."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from typing import Any, Dict, List

import pytest

import scout
from conftest import Gateway, robot_name, scout_cli, until


def keys(value: Any) -> Any:
    """The shape of a JSON value: its keys, recursively (lists by their first element)."""
    if isinstance(value, dict):
        return {key: keys(item) for key, item in value.items()}
    if isinstance(value, list):
        return [keys(value[0])] if value else []
    return type(value).__name__ if value is not None else None


def test_no_gateway_error_says_what_the_cli_says() -> None:
    name = robot_name("nogateway")
    with pytest.raises(scout.NoGatewayError) as raised:
        scout.Robot.connect(name)
    cli = scout_cli("status", "--name", name)
    assert cli.returncode == 3
    assert cli.stderr.strip() == f"scout: {raised.value}"
    assert isinstance(raised.value, scout.ScoutError)


def test_latest_and_next(robot: scout.Robot) -> None:
    # The gateway's services come up a moment before its first state: once one is published,
    # latest() has it at once, without waiting.
    until(lambda: robot.latest() is not None, 5.0, "a first state")
    first = robot.next(timeout=1.0)
    second = robot.next(timeout=1.0)
    assert second.seq == first.seq + 1
    assert robot.latest() is not None
    assert first.robot == robot.name
    assert first.link.state == "ok"
    assert first.system is not None and first.system.battery_voltage > 20.0
    assert first.system.faults == []
    assert len(first.motors) == 4
    assert first.odometry.x == 0.0
    assert first.command.linear == 0.0
    assert "link=ok" in repr(first)
    # The simulated pack rests at 26.0 V: 80 % by the curve, estimated from the voltage.
    battery = robot.next(timeout=1.0).battery
    assert battery.source == "voltage" and battery.level == "ok", battery
    assert battery.percent is not None and 70.0 < battery.percent <= 81.0, battery
    assert battery.status == "discharging" and battery.current is None, battery


def test_to_dict_is_the_scout_echo_json_schema(robot: scout.Robot) -> None:
    # Both sides read a state with every section the chassis reports (the first states after
    # a start lack the frames that come later in a period).
    until(lambda: robot.next().motion is not None, 3.0, "a state with the motion")
    cli = scout_cli("echo", "--name", robot.name, "--json", "--count", "1")
    assert cli.returncode == 0, cli.stderr
    echoed = json.loads(cli.stdout.splitlines()[0])
    state = robot.next(timeout=1.0)
    as_dict = state.to_dict()
    assert keys(as_dict) == keys(echoed)
    assert as_dict["seq"] == state.seq
    assert as_dict["system"]["battery_voltage"] == state.system.battery_voltage  # type: ignore[union-attr]
    assert as_dict["link"]["rx_frames"] == state.link.rx_frames
    as_dict["seq"] = -1
    assert state.to_dict()["seq"] == state.seq, "to_dict gives a copy"


def test_a_thousand_states_in_order_with_no_gap(robot: scout.Robot) -> None:
    seqs = [state.seq for state, _ in zip(robot.states(timeout=3.0), range(1000))]
    gaps = [(a, b) for a, b in zip(seqs, seqs[1:]) if b != a + 1]
    assert gaps == [], f"{len(gaps)} gaps, first {gaps[:3]}"


def test_next_times_out(gateway: Gateway) -> None:
    robot = gateway.connect()
    gateway.process.send_signal(signal.SIGSTOP)
    try:
        robot.latest()
        started = time.monotonic()
        with pytest.raises(TimeoutError):
            robot.next(timeout=0.3)
        assert time.monotonic() - started < 2.0
    finally:
        gateway.process.send_signal(signal.SIGCONT)


def test_states_async(robot: scout.Robot) -> None:
    async def collect() -> List[int]:
        seqs: List[int] = []
        async for state in robot.states_async():
            seqs.append(state.seq)
            if len(seqs) == 20:
                break
        return seqs

    seqs = asyncio.run(collect())
    assert seqs == list(range(seqs[0], seqs[0] + 20))


def test_teleop_drives_and_leaving_the_block_stops(robot: scout.Robot) -> None:
    with robot.controller("pytest-teleop", scout.Class.TELEOP) as controller:
        answer = controller.take_control()
        assert answer.accepted and answer.lease is not None and controller.lease == answer.lease
        deadline = time.monotonic() + 5.0
        while True:
            answer = controller.drive(0.5, 0.0)
            assert not answer.clamped
            state = robot.next(timeout=1.0)
            if state.motion is not None and state.motion.linear > 0.3:
                break
            assert time.monotonic() < deadline, "the chassis never moved"
        assert controller.drive(50.0, 0.0).clamped
    until(lambda: robot.next().command.linear == 0.0, 3.0, "zero on the wire")
    until(lambda: abs(robot.next().motion.linear) < 0.01, 3.0, "the chassis at rest")  # type: ignore[union-attr]
    status = robot.status()
    assert status["selected"] is None, status


def test_autonomy_before_resume_is_refused_with_the_reason(robot: scout.Robot) -> None:
    with robot.controller("pytest-planner", "autonomy") as controller:
        with pytest.raises(scout.Rejected) as raised:
            controller.take_control()
        assert raised.value.cause == "autonomy_disarmed"
        assert "resume first" in raised.value.reason
        assert str(raised.value) == f"rejected: {raised.value.reason}"
        controller.resume()
        assert controller.take_control().lease is not None


def test_a_stop_latches_is_shown_and_released_by_its_owner(robot: scout.Robot) -> None:
    stopper = robot.stopper("lidar-guard")
    answer = stopper.stop("obstacle")
    assert answer.stop is not None
    status = robot.status()
    assert status["latched"] is True
    assert [(s["owner"], s["reason"]) for s in status["stops"]] == [("lidar-guard", "obstacle")]
    with robot.controller("pytest-teleop", "teleop") as controller:
        with pytest.raises(scout.Rejected) as raised:
            controller.take_control()
        assert raised.value.cause == "latched"
        # It has no stop of its own to release, and is told whose stop holds the robot.
        with pytest.raises(scout.Rejected) as refused:
            controller.release(own=True)
        assert "lidar-guard" in refused.value.reason
        assert robot.status()["latched"] is True
    stopper.release()
    until(lambda: robot.status()["stops"] == [], 2.0, "the stop released")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_a_forked_child_gets_an_error_and_the_parent_drives_on(robot: scout.Robot) -> None:
    controller = robot.controller("pytest-fork", "teleop")
    stopper = robot.stopper("pytest-fork-guard")
    controller.take_control()
    controller.drive(0.1, 0.0)
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # The child: every call raises at once, none waits (a hang dies of SIGALRM).
        signal.alarm(10)
        os.close(read)
        outcomes = []
        for call in (
            lambda: controller.drive(0.2, 0.0),
            lambda: controller.take_control(),
            lambda: stopper.stop("from the child"),
            lambda: robot.status(),
            lambda: robot.latest(),
            lambda: robot.next(timeout=0.1),
        ):
            try:
                call()
                outcomes.append("returned")
            except scout.ForkError as error:
                outcomes.append("ForkError" if "os.fork()" in str(error) else str(error))
            except BaseException as error:  # noqa: BLE001 - reported to the parent
                outcomes.append(repr(error))
        os.write(write, json.dumps(outcomes).encode())
        os._exit(0)
    os.close(write)
    # The parent drives on while the child tries.
    for _ in range(10):
        controller.drive(0.1, 0.0)
        time.sleep(0.02)
    _, status = os.waitpid(child, 0)
    with os.fdopen(read) as pipe:
        outcomes = json.loads(pipe.read() or "[]")
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    assert outcomes == ["ForkError"] * 6
    assert controller.drive(0.1, 0.0).accepted
    controller.close()


def test_heartbeat_missed_latches_a_stop(robot: scout.Robot) -> None:
    with robot.controller("pytest-beat") as controller:
        controller.heartbeat(0.3)
        time.sleep(0.8)
        status = robot.status()
        assert [s["cause"] for s in status["stops"]] == ["heartbeat"], status
        controller.heartbeat(0)
        controller.release()


def test_lights_fault_clear_and_odometry(robot: scout.Robot) -> None:
    with robot.controller("pytest-lights") as controller:
        assert not controller.lights(front="on", rear="breath:50").clamped

        def front_on() -> bool:
            lights = robot.next().lights
            return lights is not None and lights.front.mode == "on"

        until(front_on, 3.0, "the front light on (the chassis' feedback)")
        controller.lights(auto=True)
        controller.clear_fault()
        controller.reset_odometry()
        with pytest.raises(ValueError):
            controller.lights(front="dazzle")


DRIVER = textwrap.dedent(
    """
    import sys, scout
    robot = scout.Robot.connect(sys.argv[1])
    controller = robot.controller("doomed", "teleop")
    controller.take_control()
    while True:
        controller.drive(0.5, 0.0)
        state = robot.next()
        if state.motion is not None and state.motion.linear > 0.3:
            print("moving", flush=True)
    """
)


def test_a_killed_python_driver_is_a_dead_client(robot: scout.Robot) -> None:
    driver = subprocess.Popen(
        [sys.executable, "-c", DRIVER, robot.name], stdout=subprocess.PIPE, text=True
    )
    try:
        assert driver.stdout is not None
        assert driver.stdout.readline().strip() == "moving"
        driver.kill()
        driver.wait(timeout=10)
        until(lambda: robot.next().command.linear == 0.0, 2.0, "zero on the wire")
        until(lambda: abs(robot.next().motion.linear) < 0.01, 3.0, "the chassis at rest")  # type: ignore[union-attr]
    finally:
        driver.kill()


WAITER = textwrap.dedent(
    """
    import signal, sys, scout
    # Ctrl-C as in a terminal: a test run started in the background inherits SIGINT ignored.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    robot = scout.Robot.connect(sys.argv[1])
    robot.latest()
    try:
        print("waiting", flush=True)
        # States queued before the gateway stopped come first; then next() blocks.
        while True:
            robot.next(timeout=60)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
    """
)


def test_ctrl_c_interrupts_a_blocking_call(gateway: Gateway) -> None:
    gateway.connect()
    waiter = subprocess.Popen(
        [sys.executable, "-c", WAITER, gateway.name], stdout=subprocess.PIPE, text=True
    )
    try:
        assert waiter.stdout is not None
        assert waiter.stdout.readline().strip() == "waiting"
        gateway.process.send_signal(signal.SIGSTOP)  # no state comes: next() blocks
        time.sleep(0.3)
        started = time.monotonic()
        waiter.send_signal(signal.SIGINT)
        assert waiter.stdout.readline().strip() == "interrupted"
        assert waiter.wait(timeout=10) == 0
        assert time.monotonic() - started < 2.0
    finally:
        gateway.process.send_signal(signal.SIGCONT)
        waiter.kill()


def test_blocking_calls_release_the_gil(robot: scout.Robot) -> None:
    import threading

    ticks: List[float] = []
    done = threading.Event()

    def count() -> None:
        while not done.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.001)

    counter = threading.Thread(target=count)
    counter.start()
    try:
        for _ in range(25):
            robot.next(timeout=1.0)
    finally:
        done.set()
        counter.join()
    assert len(ticks) > 100, f"the other thread ran {len(ticks)} times in 0.5 s"


def test_help_is_useful() -> None:
    import pydoc

    text = pydoc.plain(pydoc.render_doc(scout.Controller))
    assert "take_control" in text and "a deliberate act" in text
    assert "NoGatewayError" in pydoc.plain(pydoc.render_doc(scout.Robot))
    assert scout.LAYOUT_VERSION >= 5


def test_a_protocol_v2_chassis_reads_and_drives_the_same() -> None:
    started = Gateway(robot_name("v2"), "--protocol", "v2", "--model", "scout-mini")
    try:
        robot = started.connect()

        def told() -> bool:
            state = robot.latest()
            return state is not None and state.firmware is not None and state.odometer is not None

        until(told, 5.0, "a v2 state with its odometers and firmware")
        state = robot.next(timeout=1.0)
        assert state.link.protocol == "v2"
        assert state.chassis.model == "scout-mini" and state.chassis.max_linear == 3.0
        assert state.system is not None and state.system.control_mode == "standby"
        motor = state.motors[0]
        assert motor is not None and motor.driver_voltage is not None and motor.pulses is not None
        assert state.to_dict()["odometer"]["left"] == state.odometer.left  # type: ignore[union-attr]
        with robot.controller("pytest-v2", scout.Class.TELEOP) as controller:
            controller.take_control()
            deadline = time.monotonic() + 5.0
            while True:
                assert not controller.drive(1.0, 0.0).clamped, "a MINI goes 1 m/s"
                state = robot.next(timeout=1.0)
                if state.odometry.distance > 0.3:
                    break
                assert time.monotonic() < deadline, "the chassis never moved"
            assert state.system is not None and state.system.control_mode == "can"
            assert state.odometer is not None and state.odometer.left > 0.1
        until(lambda: robot.next().command.linear == 0.0, 3.0, "zero on the wire")
    finally:
        started.stop()


def test_an_omni_drives_sideways_and_a_scout_refuses_it_whole(robot: scout.Robot) -> None:
    with robot.controller("pytest-sideways", scout.Class.TELEOP) as controller:
        controller.take_control()
        with pytest.raises(scout.Rejected) as refused:
            controller.drive(0.3, 0.0, lateral=0.2)
        assert refused.value.cause == "not_allowed"
        assert "does not move sideways" in refused.value.reason
    started = Gateway(robot_name("omni"), "--protocol", "v2", "--model", "scout-mini-omni")
    try:
        omni = started.connect()
        until(lambda: omni.next(timeout=1.0).chassis.max_lateral == 2.0, 5.0, "the OMNI's limits")
        with omni.controller("pytest-omni", scout.Class.TELEOP) as controller:
            controller.take_control()
            deadline = time.monotonic() + 5.0
            while True:
                controller.drive(0.0, 0.0, lateral=0.4)
                state = omni.next(timeout=1.0)
                if state.odometry.y > 0.2:
                    break
                assert time.monotonic() < deadline, "the OMNI never moved sideways"
            assert state.command.lateral > 0.0 and abs(state.odometry.x) < 0.05
    finally:
        started.stop()


def test_a_ranger_drives_in_the_mode_named_and_refuses_what_it_does_not_carry(
    robot: scout.Robot,
) -> None:
    with robot.controller("pytest-mode", scout.Class.TELEOP) as controller:
        controller.take_control()
        with pytest.raises(scout.Rejected) as refused:
            controller.drive(0.3, 0.0, mode="parallel")
        assert refused.value.cause == "not_allowed"
        assert "no motion modes" in refused.value.reason
        with pytest.raises(ValueError, match="sideways_please"):
            controller.drive(0.3, 0.0, mode="sideways_please")
    started = Gateway(robot_name("ranger"), "--protocol", "v2", "--model", "ranger-mini-3")
    try:
        ranger = started.connect()
        until(lambda: ranger.next(timeout=1.0).chassis.model == "ranger-mini-3", 5.0, "a Ranger")
        with ranger.controller("pytest-ranger", scout.Class.TELEOP) as controller:
            controller.take_control()
            with pytest.raises(scout.Rejected) as refused:
                controller.drive(0.3, 0.5, mode="parallel")
            assert refused.value.reason.startswith("parallel mode does not turn")
            deadline = time.monotonic() + 8.0
            while True:
                controller.drive(0.3, 0.0, mode="parallel")
                state = ranger.next(timeout=1.0)
                if state.odometry.x > 0.2:
                    break
                assert time.monotonic() < deadline, "the Ranger never moved in parallel mode"
            assert state.motion is not None and state.motion.mode == "parallel"
    finally:
        started.stop()


def test_status_is_the_scout_status_json_schema(robot: scout.Robot) -> None:
    until(lambda: robot.latest() is not None, 5.0, "a first state")
    cli = scout_cli("status", "--name", robot.name, "--json")
    assert cli.returncode == 0, cli.stderr
    echoed = json.loads(cli.stdout)
    status = robot.status()
    assert keys(status) == keys(echoed)
    assert status["robot"] == echoed["robot"] == robot.name
