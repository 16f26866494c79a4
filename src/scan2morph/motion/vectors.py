"""Per-vertex 3D motion vectors from the neutral mesh to an aligned take (Yano-Harada, Sec. 4.1).

Both meshes come from one template, so vertex i of one is vertex i of the other and the motion
is a plain difference once the take is in the neutral frame.
"""

from __future__ import annotations

import logging

import numpy as np

from scan2morph.errors import InputError
from scan2morph.motion.tear import torn_off

log = logging.getLogger("scan2morph")


def _mesh(v: np.ndarray, valid: np.ndarray | None, name: str, source: str) -> tuple:
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(source, f"{name}: expected (V, 3) vertices, got {v.shape}")
    ok = np.isfinite(v).all(axis=1)
    if valid is not None:
        valid = np.asarray(valid)
        if valid.shape != ok.shape or valid.dtype != np.bool_:
            raise InputError(
                source, f"{name}_valid: expected ({len(v)},) bool, got {valid.dtype} {valid.shape}"
            )
        ok &= valid
    return v, ok


def motion_vectors(
    aligned: np.ndarray,
    neutral: np.ndarray,
    aligned_valid: np.ndarray | None = None,
    neutral_valid: np.ndarray | None = None,
    source: str = "motion",
    *,
    faces: np.ndarray | None = None,
    max_stretch: float = np.inf,
) -> np.ndarray:
    """Motion of every template vertex from the neutral mesh to the aligned take.

    Parameters
    ----------
    aligned : (V, 3) float, mm
        The take's vertices in the neutral frame (after :func:`scan2morph.align.align_take`
        and :func:`scan2morph.align.transform_points`).
    neutral : (V, 3) float, mm
        The neutral mesh's vertices.
    aligned_valid, neutral_valid : (V,) bool, optional
        Valid flags; non-finite rows are invalid in any case.
    source : str
        ``subject/take`` label for error messages.
    faces : (F, 3) int, optional
        Template triangles; with a finite ``max_stretch``, the take's vertices torn off the
        face (:func:`scan2morph.motion.tear.torn_off`) count as invalid.
    max_stretch : float
        Stretch beyond which a mesh edge is cut (``smoothing.max_stretch``; ``inf``: none).

    Returns
    -------
    d : (V, 3) float64, mm
        ``aligned - neutral``; NaN rows where either vertex is invalid or torn off.
    """
    a, a_ok = _mesh(aligned, aligned_valid, "aligned", source)
    n, n_ok = _mesh(neutral, neutral_valid, "neutral", source)
    if a.shape != n.shape:
        raise InputError(source, f"aligned: expected the neutral's shape {n.shape}, got {a.shape}")
    d = a - n
    d[~(a_ok & n_ok)] = np.nan
    if faces is not None and np.isfinite(max_stretch):
        take = np.where(a_ok[:, None], a, np.nan)
        torn = torn_off(take, np.where(n_ok[:, None], n, np.nan), faces, max_stretch, source)
        if torn.any():
            log.info("%s: %d vertices torn off the face count as missing", source, torn.sum())
        d[torn] = np.nan
    return d


__all__ = ["motion_vectors"]
