"""Shared fixtures of the Python package's tests (ctest: avp_python_test; docs/python.md)."""

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

import avp

# A short episode: 3 views of the smallest tomato scenario, noise on, the oracle segmenter.
SCENARIO = "tomato-single-cluster"
VIEWS = 3


@pytest.fixture(scope="session")
def tmp_root():
    """A folder for the session's outputs (AVP_TEST_TMP under ctest), emptied first."""
    base = os.environ.get("AVP_TEST_TMP")
    if base:
        root = Path(base)
        shutil.rmtree(root, ignore_errors=True)
        root.mkdir(parents=True)
        yield root
    else:
        with tempfile.TemporaryDirectory(prefix="avp-python-test-") as d:
            yield Path(d)


@pytest.fixture(scope="session")
def avp_binary():
    """The avp program built beside the module (AVP_BINARY), or the test is skipped."""
    binary = os.environ.get("AVP_BINARY")
    if not binary or not Path(binary).exists():
        pytest.skip("AVP_BINARY is not set to the avp program (ctest sets it)")
    return binary


@pytest.fixture(scope="session")
def episode(tmp_root):
    """One short episode run from Python, shared by the map and run tests."""
    return avp.run(tmp_root / "episode", scenario=SCENARIO, seed=2, episode={"views": VIEWS},
                   progress=False)


def run_cli(binary, *args):
    """Runs the avp program; fails the test with its output when it fails."""
    p = subprocess.run([binary, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, f"avp {' '.join(map(str, args))} failed:\n{p.stdout}\n{p.stderr}"
    return p
