"""open3d imported without its web visualiser.

``import open3d`` imports ``open3d.visualization.draw_plotly``, which imports dash, plotly and
IPython for the browser viewer: half of open3d's import time (0.8 of 1.6 s wall, 0.35 of
0.7 CPU-s, measured on the 2-core reference machine), paid by every job that aligns or evaluates
a take although the pipeline never draws with plotly. :func:`open3d` imports open3d with that
submodule stood in for: its three functions (``get_plotly_fig``, ``draw_plotly``,
``draw_plotly_server``) import the real module on their first call and then behave as open3d's
own, so ``open3d.visualization.draw_plotly(...)`` still works in a process that imported open3d
here. :func:`triangle_scene` is the ray-casting scene of a triangle surface every layer builds
(closest points, first hits along rays).
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
import types

import numpy as np

#: The submodule left out of the import, and the names ``open3d.visualization`` takes from it.
PLOTLY_MODULE = "open3d.visualization.draw_plotly"
PLOTLY_NAMES = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


def open3d() -> types.ModuleType:
    """The ``open3d`` module, imported (once per process) without dash, plotly and IPython.

    Returns
    -------
    module
        ``open3d``; when another import already loaded it, that module as it is.
    """
    if "open3d" in sys.modules:
        return sys.modules["open3d"]
    stand_in = types.ModuleType(PLOTLY_MODULE, "Stand-in: the real module loads on first use.")
    for name in PLOTLY_NAMES:
        setattr(stand_in, name, _deferred(name))
    stand_in._stand_in_of = PLOTLY_MODULE
    stand_in.__getattr__ = _other_name
    sys.modules[PLOTLY_MODULE] = stand_in
    try:
        import open3d as o3d
    except BaseException:
        del sys.modules[PLOTLY_MODULE]
        raise
    return o3d


def triangle_scene(vertices: np.ndarray, faces: np.ndarray):
    """An open3d ray-casting scene of a triangle surface (closest points, rays' first hits).

    Parameters
    ----------
    vertices : (N, 3) float
        The surface's vertices, mm (cast to float32, open3d's precision).
    faces : (F, 3) int
        Vertex indices of its triangles.

    Returns
    -------
    open3d.t.geometry.RaycastingScene
    """
    o3d = open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)),
    )
    return scene


def _real_plotly() -> types.ModuleType:
    """open3d's plotly module, loaded in place of the stand-in on first use; its functions
    replace the stand-in's in ``open3d.visualization``."""
    module = sys.modules[PLOTLY_MODULE]
    if not hasattr(module, "_stand_in_of"):
        return module
    visualization = sys.modules["open3d.visualization"]
    spec = importlib.machinery.PathFinder.find_spec(PLOTLY_MODULE, visualization.__path__)
    real = importlib.util.module_from_spec(spec)
    sys.modules[PLOTLY_MODULE] = real
    try:
        spec.loader.exec_module(real)
    except BaseException:
        sys.modules[PLOTLY_MODULE] = module
        raise
    for name in PLOTLY_NAMES:
        setattr(visualization, name, getattr(real, name))
    return real


def _other_name(name: str):
    """The stand-in's other attributes: the real module's (the import machinery's own
    questions, ``__path__`` and the like, are answered by the stand-in)."""
    if name.startswith("__"):
        raise AttributeError(name)
    return getattr(_real_plotly(), name)


def _deferred(name: str):
    """A function that calls the real plotly module's ``name`` (loading it first)."""

    def call(*args, **kwargs):
        return getattr(_real_plotly(), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    return call


__all__ = ["open3d"]
