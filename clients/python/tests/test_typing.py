"""The stub matches the native module (stubtest), and the package, its examples and these tests
type-check under `mypy --strict`."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1]

mypy = pytest.importorskip("mypy", reason="pip install mypy (CI does)")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=PACKAGE, capture_output=True, text=True, timeout=300,
        check=False,
    )


def test_the_stub_matches_the_native_module() -> None:
    result = run("mypy.stubtest", "scout._scout")
    assert result.returncode == 0, result.stdout + result.stderr


def test_examples_package_and_tests_pass_mypy_strict() -> None:
    result = run("mypy", "--strict", "examples", "python/scout", "tests")
    assert result.returncode == 0, result.stdout + result.stderr
