"""Fixtures: real `scout-gateway --sim` processes, each with a robot name of its own."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
import uuid
from pathlib import Path
from typing import Callable, Iterator

import pytest

import scout

REPOSITORY = Path(__file__).resolve().parents[3]


def binary(name: str) -> str:
    """A program of the workspace: from $SCOUT_BIN_DIR (the system tests set it), the
    repository's target/debug, or PATH."""
    for directory in (os.environ.get("SCOUT_BIN_DIR"), REPOSITORY / "target" / "debug"):
        if directory and (Path(directory) / name).exists():
            return str(Path(directory) / name)
    found = shutil.which(name)
    if found is None:
        pytest.fail(f"no {name}: build the workspace (cargo build) or set SCOUT_BIN_DIR")
    return found


class Gateway:
    """A `scout-gateway --sim` of its own name, stopped at the end of the test."""

    def __init__(self, name: str, *args: str) -> None:
        self.name = name
        self.process = subprocess.Popen(
            [binary("scout-gateway"), "--sim", "--name", name, *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )

    def connect(self, limit: float = 10.0) -> scout.Robot:
        deadline = time.monotonic() + limit
        while True:
            try:
                return scout.Robot.connect(self.name)
            except scout.NoGatewayError:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def robot_name(test: str) -> str:
    return f"py-{test[:12]}-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def gateway(request: pytest.FixtureRequest) -> Iterator[Gateway]:
    started = Gateway(robot_name(request.node.name))
    try:
        yield started
    finally:
        started.stop()


@pytest.fixture
def robot(gateway: Gateway) -> Iterator[scout.Robot]:
    yield gateway.connect()


def scout_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """Runs the `scout` tool to its end (bounded)."""
    return subprocess.run(
        [binary("scout"), *args], capture_output=True, text=True, timeout=30, check=False
    )


def until(condition: Callable[[], bool], limit: float, what: str) -> None:
    """Waits (polling) for `condition`, failing with `what` after `limit` seconds."""
    deadline = time.monotonic() + limit
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"{what} within {limit} s")
        time.sleep(0.02)
