"""The Makefile's setup on a machine without Blender's Python: `make run` needs no Blender (only
tests/unit/test_blender.py does, and it skips naming why outside CI), so setup goes on without
it there, and stops under CI as that test would."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest

from tests.support.configs import REPO

MAKE = shutil.which("make")


def _blender_setup(tmp_path, ci: bool) -> subprocess.CompletedProcess:
    """Make the Blender environment's stamp with a Python that does not exist (no apt-get: the
    Debian packages' stamp is a file of the test's own)."""
    version = re.search(r"^BPY_VERSION := (\S+)$", (REPO / "Makefile").read_text(), re.M)[1]
    deb, venv = tmp_path / "deb-stamp", tmp_path / "blender"
    deb.touch()
    env = {k: v for k, v in os.environ.items() if k != "CI"} | ({"CI": "1"} if ci else {})
    command = [MAKE, "-s", f"DEB_STAMP={deb}", f"BLENDER_VENV={venv}"]
    command += ["BLENDER_PYTHON=python3-not-installed", f"{venv}/.bpy-{version}-stamp"]
    return subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, check=False)


@pytest.mark.skipif(MAKE is None, reason="no make on this machine")
def test_setup_goes_on_without_blenders_python_and_says_so(tmp_path):
    done = _blender_setup(tmp_path, ci=False)
    assert done.returncode == 0, done.stderr
    assert "python3-not-installed not found" in done.stdout
    assert "test_blender.py" in done.stdout
    assert not (tmp_path / "blender").exists()


@pytest.mark.skipif(MAKE is None, reason="no make on this machine")
def test_setup_under_ci_stops_without_blenders_python(tmp_path):
    done = _blender_setup(tmp_path, ci=True)
    assert done.returncode != 0
    assert "python3-not-installed" in done.stdout + done.stderr
