"""The 17 jawline points of a 51-point landmark set (iBUG-68 without the jaw)."""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError
from scan2morph.landmarks.canonical import canonical
from scan2morph.landmarks.cascade import Cascade, features
from scan2morph.landmarks.detect import cached_model, check_grid
from scan2morph.landmarks.face import find_face

#: iBUG-68 indices of the jawline (0-based) and of the 51 inner points.
JAW = np.arange(17)
INNER = np.arange(17, 68)


def _similarity(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ~ s R src + t``: (s, R (2, 2), t (2,))."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    u, sv, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    R = u @ np.diag([1.0, d]) @ vt
    s = float((sv * np.array([1.0, d])).sum() / max((a**2).sum(), 1e-12))
    return s, R, md - s * ms @ R.T


def complete_jawline(
    points51: np.ndarray,
    color: np.ndarray,
    xyz: np.ndarray,
    source: str,
    model: Cascade | None = None,
) -> np.ndarray:
    """Add the jawline to 51 inner iBUG points.

    The model's mean shape is placed on the 51 points (least-squares similarity), then the
    cascade moves the jawline only, the 51 points held where they were given.

    Parameters
    ----------
    points51 : (51, 2) float
        iBUG points 18-68 in order, px on the take's grid.
    color : (H, W, 3) uint8 or (H, W) uint8
    xyz : (H, W, 3) float
        mm, NaN = no surface.
    source : str
        Named in errors.
    model : Cascade, optional
        Default: the committed model.

    Returns
    -------
    (68, 2) float64
        The 68 points, px: the jawline detected, the 51 as given.

    Raises
    ------
    InputError
        Not (51, 2) finite points; the grid's errors (see :func:`scan2morph.landmarks.detect`).
    """
    pts = np.asarray(points51, dtype=np.float64)
    if pts.shape != (51, 2) or not np.isfinite(pts).all():
        raise InputError(
            source, f"points51: expected 51 finite (x, y) points, got shape {pts.shape}"
        )
    color, xyz = check_grid(color, xyz, source)
    model = model or cached_model()
    can = canonical(find_face(xyz, source), color)
    inner = can.to_cells(pts)
    s, R, t = _similarity(model.init[INNER], inner)
    shape = s * model.init @ R.T + t
    shape[INNER] = inner
    for stage in model.stages:
        if stage.radius == 0:  # the global stage predicts a whole shape: the 51 points do
            continue
        f = (features(can.channels, shape, stage.radius) - stage.mean) / stage.scale
        step = (f @ stage.weights + stage.bias).reshape(shape.shape)
        shape[JAW] += step[JAW]
    out = can.to_image(shape)
    out[INNER] = pts
    return out
