"""Laplacian smoothing of per-vertex motion vectors (Yano-Harada, Sec. 4.1).

The paper's explicit diffusion step on the template's 1-ring ("umbrella") operator::

    d_i <- d_i + w * L d_i,    L d_i = mean_{j in N(i)} (d_j - d_i),    0 <= w <= 1

iterated 30 times with w = 0.1. Suppressed (masked) vertices are held at zero every
iteration (a Dirichlet boundary); missing (invalid) vertices are first filled from their
neighbours.

The smoothing removes correspondence noise, and blurs real motion that varies over a few
vertices (the lips: ~6 mm of diffusion length at the paper's setting). Where the dense
refinement (:mod:`scan2morph.refine`) measured a vertex's correspondence in the skin's texture,
the motion is known to a fraction of a pixel: an optional per-vertex ``confidence`` in [0, 1]
shortens the step there, ``w_i = w * (1 - relief * confidence_i)`` (``relief`` 0: the paper's
uniform step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from scan2morph.errors import InputError
from scan2morph.geometry import edge_adjacency, unique_edges
from scan2morph.motion.mask import _check_faces


def _field(d: np.ndarray, source: str) -> np.ndarray:
    d = np.array(d, dtype=np.float64)  # a copy: the caller's array is never modified
    if d.ndim != 2 or d.shape[1] != 3:
        raise InputError(source, f"d: expected (V, 3) motion vectors, got {d.shape}")
    return d


def _flags(m: np.ndarray | None, n: int, name: str, source: str) -> np.ndarray:
    if m is None:
        return np.zeros(n, dtype=bool)
    m = np.asarray(m)
    if m.shape != (n,) or m.dtype != np.bool_:
        raise InputError(source, f"{name}: expected ({n},) bool, got {m.dtype} {m.shape}")
    return m


def _confidence(c: np.ndarray | None, n: int, missing: np.ndarray, source: str) -> np.ndarray:
    """(n,) per-vertex confidence in [0, 1]; 0 where missing (a filled vertex measured nothing)."""
    if c is None:
        return np.zeros(n)
    c = np.array(c, dtype=np.float64)
    if c.shape != (n,):
        raise InputError(source, f"confidence: expected ({n},) values in [0, 1], got {c.shape}")
    bad = np.isfinite(c) & ((c < 0) | (c > 1))
    if bad.any():
        raise InputError(
            source,
            f"confidence: expected values in [0, 1], got {float(c[bad][0])} at vertex "
            f"{int(np.flatnonzero(bad)[0])}",
        )
    c[~np.isfinite(c) | missing] = 0.0
    return c


def _adjacency(faces: np.ndarray, n: int) -> sp.csr_array:
    """Symmetric 0/1 vertex adjacency (V, V) of the mesh's edges."""
    return edge_adjacency(unique_edges(faces), n)


def _fill(d: np.ndarray, adj: sp.csr_array, known: np.ndarray) -> np.ndarray:
    """Grow known values into unknown vertices, one ring per round (mean of known neighbours).

    Vertices in a component with no known vertex end at zero.
    """
    d = d.copy()
    known = known.copy()
    d[~known] = 0.0
    while not known.all():
        count = adj @ known.astype(np.float64)
        new = ~known & (count > 0)
        if not new.any():
            break
        total = adj @ (d * known[:, None])
        d[new] = total[new] / count[new, None]
        known |= new
    return d


def fill_missing(
    d: np.ndarray,
    faces: np.ndarray,
    missing: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    source: str = "motion",
) -> np.ndarray:
    """Fill missing per-vertex vectors from their neighbours.

    Rounds grow inward from the known region: each round, every missing vertex with at least
    one known neighbour takes the mean of its known neighbours and becomes known.

    Parameters
    ----------
    d : (V, 3) float, mm
        Per-vertex vectors; non-finite rows count as missing too.
    faces : (F, 3) int
        Template faces (the 1-ring neighbourhoods).
    missing : (V,) bool, optional
        Vertices to fill.
    fixed : (V,) bool, optional
        Vertices held at zero; they count as known (with value zero).
    source : str
        Label for error messages.

    Returns
    -------
    (V, 3) float64, mm
        Filled copy. Missing vertices in a component with no known vertex are zero.
    """
    d = _field(d, source)
    n = len(d)
    f = _check_faces(faces, n, source)
    missing = _flags(missing, n, "missing", source) | ~np.isfinite(d).all(axis=1)
    fixed = _flags(fixed, n, "fixed", source)
    d[fixed] = 0.0
    return _fill(d, _adjacency(f, n), ~missing | fixed)


@dataclass(frozen=True)
class Relief:
    """How much shorter :func:`laplacian_smooth`'s step is where a correspondence was measured.

    Attributes
    ----------
    confidence : (V,) float in [0, 1], optional
        How well each vertex's correspondence was measured (NaN and missing vertices: 0).
        None: 0 everywhere.
    share : float
        Share of the step taken off at confidence 1, in [0, 1] (0: the paper's uniform step).
    """

    confidence: np.ndarray | None = None
    share: float = 0.0


def laplacian_smooth(
    d: np.ndarray,
    faces: np.ndarray,
    w: float = 0.1,
    iterations: int = 30,
    fixed: np.ndarray | None = None,
    missing: np.ndarray | None = None,
    source: str = "motion",
    relief: Relief | None = None,
) -> np.ndarray:
    """Smooth per-vertex motion vectors with the 1-ring umbrella Laplacian.

    Parameters
    ----------
    d : (V, 3) float, mm
        Motion vectors; non-finite rows are treated as missing.
    faces : (F, 3) int
        Template faces.
    w : float
        Step, 0 <= w <= 1 (paper: 0.1).
    iterations : int
        Number of steps, >= 0 (paper: 30). 0 only fills missing vertices.
    fixed : (V,) bool, optional
        Suppressed vertices: zero before and after every step.
    missing : (V,) bool, optional
        Invalid vertices: first filled from their neighbours (:func:`fill_missing`).
    source : str
        Label for error messages.
    relief : Relief, optional
        Shorter steps where the correspondence was measured with confidence: vertex ``i``
        steps by ``w * (1 - relief.share * relief.confidence_i)``. None (default) is the
        paper's uniform step.

    Returns
    -------
    (V, 3) float64, mm
        Smoothed copy. Vertices without neighbours are left unchanged.

    Raises
    ------
    InputError
        Bad shapes, ``w`` or ``relief`` outside [0, 1], ``iterations`` < 0 or a confidence
        outside [0, 1].
    """
    w_f = float(w)
    if not 0.0 <= w_f <= 1.0:
        raise InputError(source, f"w: expected 0 <= w <= 1, got {w!r}")
    if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 0:
        raise InputError(source, f"iterations: expected an integer >= 0, got {iterations!r}")
    relief = relief or Relief()
    relief_f = float(relief.share)
    if not 0.0 <= relief_f <= 1.0:
        raise InputError(source, f"relief: expected 0 <= share <= 1, got {relief.share!r}")
    d = _field(d, source)
    n = len(d)
    f = _check_faces(faces, n, source)
    fixed = _flags(fixed, n, "fixed", source)
    missing = _flags(missing, n, "missing", source) | ~np.isfinite(d).all(axis=1)
    adj = _adjacency(f, n)
    d[fixed] = 0.0
    d = _fill(d, adj, ~missing | fixed)

    # One step is d <- M d with M = (1 - W) I + W D^-1 A on vertices that have neighbours,
    # W = diag(w_i)
    w_i = w_f * (1.0 - relief_f * _confidence(relief.confidence, n, missing, source))
    deg = adj.sum(axis=1)
    has = deg > 0
    inv_deg = np.divide(1.0, deg, out=np.zeros(n), where=has)
    step = sp.diags_array(1.0 - w_i * has) + sp.diags_array(w_i * inv_deg) @ adj
    step = sp.csr_array(step)
    for _ in range(int(iterations)):
        d = step @ d
        d[fixed] = 0.0
    return d


__all__ = ["Relief", "fill_missing", "laplacian_smooth"]
