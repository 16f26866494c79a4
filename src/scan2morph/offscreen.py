"""One headless OpenGL context per image size and process, shared by every renderer.

Creating a pyrender ``OffscreenRenderer`` per image and deleting it afterwards runs a full
garbage collection on each delete (pyrender frees its GL objects that way): measured with
``benchmarks/bench_profile.py``, 32 renders of the morph figures spent 14 s in ``gc.collect``
alone. A renderer kept for the process renders any number of scenes (pyrender drops the GL
objects of a scene's meshes when they leave the rendered scene).

The renderers are deleted when the interpreter exits (``atexit``), while imports still work:
deleted later, by the interpreter's own teardown, PyOpenGL tries to import as it frees the
context and prints a warning and a stray line on the job's console.
"""

from __future__ import annotations

import atexit
import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")  # headless, unless the caller chose

import pyrender  # noqa: E402

_RENDERERS: dict[tuple[int, int], pyrender.OffscreenRenderer] = {}


def offscreen_renderer(width: int, height: int) -> pyrender.OffscreenRenderer:
    """The process's offscreen renderer of ``width`` x ``height`` pixels (made on first use)."""
    key = (int(width), int(height))
    if key not in _RENDERERS:
        _RENDERERS[key] = pyrender.OffscreenRenderer(*key)
    return _RENDERERS[key]


@atexit.register
def close_renderers() -> None:
    """Delete every renderer of the process (their GL contexts); the next render makes a new
    one. Registered to run at the interpreter's exit."""
    while _RENDERERS:
        _, renderer = _RENDERERS.popitem()
        renderer.delete()


__all__ = ["close_renderers", "offscreen_renderer"]
