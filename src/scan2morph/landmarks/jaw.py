"""The 17 jawline points of a 51-point landmark set (iBUG-68 without the jaw)."""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError
from scan2morph.landmarks.cascade import Cascade
from scan2morph.landmarks.detect import cached_model, detect_canonical

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

    The detector runs on the take (:func:`scan2morph.landmarks.detect.detect_canonical`) and
    its jawline is moved onto the given points by the least-squares similarity that takes its
    own 51 inner points to them. (Moving the jawline further with the local stages, the 51
    held, made it worse on the synthetic cohort: their updates were learnt with every point
    free.)

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
    model = model or cached_model()
    can, shapes = detect_canonical(color, xyz, source, model)
    detected = np.median(shapes, axis=0)
    inner = can.to_cells(pts)
    s, R, t = _similarity(detected[INNER], inner)
    shape = s * detected @ R.T + t
    shape[INNER] = inner
    out = can.to_image(shape)
    out[INNER] = pts
    return out
