"""Shared fixtures; tests/support/slurm_run.py starts the SLURM run when the session starts."""

from __future__ import annotations

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

pytest_plugins = ["tests.support.slurm_run"]
