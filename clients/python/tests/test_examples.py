"""The examples run against a simulated chassis and do what they say."""

from __future__ import annotations

import csv
import io
import subprocess
import sys
from pathlib import Path

import scout
from conftest import Gateway

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example(name: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True, text=True, timeout=60, check=False,
    )


def test_logger_writes_every_state(gateway: Gateway) -> None:
    gateway.connect()
    result = example("logger_csv.py", "--name", gateway.name, "--count", "25")
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader(io.StringIO(result.stdout)))
    assert len(rows) == 25
    seqs = [int(row["seq"]) for row in rows]
    assert seqs == list(range(seqs[0], seqs[0] + 25))
    assert float(rows[0]["battery_voltage"]) > 20.0


def test_logger_without_a_gateway_says_so() -> None:
    result = example("logger_csv.py", "--name", "py-nobody-here", "--count", "1")
    assert result.returncode == 3
    assert "no gateway named 'py-nobody-here'" in result.stderr


def test_square_drives_and_comes_back_near_the_start(gateway: Gateway) -> None:
    robot = gateway.connect()
    result = example(
        "square.py", "--name", gateway.name, "--side", "0.3", "--speed", "0.5",
        "--turn-rate", "1.5",
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("side ") == 4
    state = robot.latest()  # the newest: next() would give the oldest not yet read
    assert state is not None and state.odometry.distance > 1.0, state
    assert robot.status()["selected"] is None, "it gave up control"


def test_battery_monitor_latches_a_stop_below_its_threshold(gateway: Gateway) -> None:
    robot = gateway.connect()
    result = example("battery_monitor.py", "--name", gateway.name, "--below", "30")
    assert result.returncode == 1
    stops = robot.status()["stops"]
    assert [(s["owner"], s["cause"]) for s in stops] == [("battery-monitor", "client")], stops
    assert "battery 26.0 V < 30.0 V" in stops[0]["reason"]
    # It is released by its owner or an operator, never by itself.
    assert isinstance(robot.stopper("battery-monitor").release(), scout.Answer)
