"""The process's offscreen renderers (scan2morph.offscreen): one per image size, kept for the
process, deleted when it exits."""

from __future__ import annotations

import subprocess
import sys

from scan2morph.offscreen import close_renderers, offscreen_renderer

#: A job that renders a textured box (as a textured mesh take is rendered) through a mesh
#: take's camera, with a job's console logging.
RENDERING_JOB = """
import logging
logging.basicConfig(level=logging.WARNING)
import numpy as np, trimesh
from PIL import Image
from scan2morph.io.mesh_scan import render_mesh
box = trimesh.creation.box(extents=(40.0, 40.0, 40.0))
uv = (box.vertices[:, :2] + 20.0) / 40.0
image = Image.fromarray(np.arange(16 * 16 * 3, dtype=np.uint8).reshape(16, 16, 3))
box.visual = trimesh.visual.TextureVisuals(uv=uv, image=image)
K = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
pose = np.eye(4)
pose[2, 3] = 200.0
color, depth = render_mesh(box, K, pose, (64, 48))
print("pixels", int(np.isfinite(depth).sum()))
"""


def test_a_job_that_rendered_exits_without_a_word():
    """Nothing on the console but the job's own output: the renderers are deleted before the
    interpreter's teardown (after it, PyOpenGL warned 'Python is likely shutting down' and
    printed a stray line of array types, on the console of every job that rendered a texture)."""
    run = subprocess.run(
        [sys.executable, "-c", RENDERING_JOB], capture_output=True, text=True, check=True
    )
    assert run.stderr == ""
    lines = run.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith("pixels ")
    assert int(lines[0].split()[1]) > 100  # the box was drawn


def test_a_renderer_is_kept_per_size_until_closed():
    first = offscreen_renderer(32, 24)
    assert offscreen_renderer(32, 24) is first and offscreen_renderer(24, 32) is not first
    close_renderers()
    assert offscreen_renderer(32, 24) is not first
