"""Shared fixtures; tests/support/slurm_run.py starts the SLURM run when the session starts."""

from __future__ import annotations

import gc
import os

import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

pytest_plugins = ["tests.support.slurm_run"]

#: The modules that take longest (about 4-15 CPU-s each, summed ``--junitxml`` times), longest first. A
#: parallel run (``make test-fast``: pytest-xdist, ``--dist loadscope``, one module to a worker
#: at a time) hands them out first, so that no worker is still busy with a long module while
#: the others have run out of work.
LONGEST_FIRST = (
    "test_landmarks_train.py",
    "test_landmarks.py",
    "test_mesh_camera.py",
    "test_synth_stereo.py",
    "test_bad_input.py",
    "test_realdata.py",
    "test_stereo.py",
    "test_figures.py",
    "test_mesh_geometry_only.py",
    "test_align.py",
    "test_landmark_inputs.py",
    "test_refine.py",
    "test_synth.py",
    "test_refine_shape.py",
    "test_modal_span.py",
    "test_synth_faces.py",
    "test_motion_noise.py",
    "test_mesh_scan.py",
)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """The longest modules first (:data:`LONGEST_FIRST`); the SLURM run's tests are moved last
    after this (tests/support/slurm_run.py)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable


def pytest_collection_finish(session):
    """The objects of the collected test modules (modules, functions, fixtures' definitions) are
    moved out of the garbage collector's view, and it runs less often: cyclic garbage of the tests
    (figures, meshes) is still collected, at about a quarter of the collector's time (1.6 -> 0.4 s
    on four of the longest modules)."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(50_000, 20, 20)
