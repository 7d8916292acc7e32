"""The stub matches the native module (stubtest), and the package, its examples and these tests
type-check under `mypy --strict`."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1]

if os.environ.get("SCOUT_REQUIRE_PYTHON"):
    import mypy  # noqa: F401  (CI installs it: these checks must run there)
else:
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


def test_the_package_and_its_examples_type_check_for_python_3_9() -> None:
    # The wheel is abi3 for Python 3.9 and newer; no Python 3.9 runs here, so mypy checks
    # that nothing newer than 3.9 is used in what users import and copy.
    result = run("mypy", "--strict", "--python-version", "3.9", "examples", "python/scout")
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_installed_module_is_the_abi3_build_for_3_9_and_newer() -> None:
    import scout._scout as native

    assert native.__file__ is not None and native.__file__.endswith(".abi3.so"), native.__file__
    pyproject = (PACKAGE / "pyproject.toml").read_text()
    assert 'requires-python = ">=3.9"' in pyproject
    cargo = (PACKAGE / "Cargo.toml").read_text()
    assert "abi3-py39" in cargo
