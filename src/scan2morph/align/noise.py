"""Measurement noise of a fitted mesh, estimated from the mesh itself (no ground truth).

A template vertex is sampled from the scan at one point; its neighbours a few mm away carry
independent noise (the scanner's noise is correlated over a few pixels, well under the template's
vertex spacing) but lie on the same smooth skin. The noise of a vertex is therefore what a
smooth surface through its neighbours does not explain: a quadric height field
``h = a + b u + c v + d u^2 + e u v + f v^2`` is fitted by least squares to the ``neighbours``
nearest valid vertices (in the tangent frame of their principal axes) and the vertex's height
above it is its roughness residual. Under independent Gaussian noise of standard deviation
sigma the residual has variance ``sigma^2 (1 + h0)``, ``h0`` the leverage of the vertex in the
fit, so ``residual^2 / (1 + h0)`` is an unbiased estimate of ``sigma^2`` per vertex. Medians of
these over a neighbourhood (a vertex's noise) or a region (a mesh's noise) make the estimate
robust to the few vertices where the skin is not a quadric (a crease, a nostril rim): the
median of a chi-square with one degree of freedom is :data:`CHI2_1_MEDIAN` times its mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.errors import InputError

#: Median of a chi-square variable with one degree of freedom (its mean is 1).
CHI2_1_MEDIAN = 0.454936423119572
#: The 80th percentile of a chi-square with one degree of freedom (:func:`tail_rms`).
CHI2_1_Q80 = 1.642374415149818

#: Quadric terms plus a margin: fewer valid neighbours than this give no estimate at a vertex.
MIN_NEIGHBOURS = 9


@dataclass(frozen=True)
class MeshNoise:
    """Noise of a mesh's vertices, mm.

    Attributes
    ----------
    vertex : (V,) float, mm
        Each vertex's noise standard deviation: the robust mean square of the roughness
        residuals of it and its ``neighbours`` nearest valid vertices; NaN where invalid or
        without enough valid neighbours.
    sq_residual : (V,) float, mm^2
        Each vertex's leverage-corrected squared roughness residual (an unbiased, single-sample
        estimate of its noise variance); NaN where not estimated.
    """

    vertex: np.ndarray
    sq_residual: np.ndarray

    def region(self, mask: np.ndarray) -> float:
        """The noise standard deviation of the vertices in ``mask`` (robust, from the median of
        their squared residuals), mm; NaN when none has an estimate."""
        r = self.sq_residual[np.asarray(mask)]
        r = r[np.isfinite(r)]
        return float(np.sqrt(np.median(r) / CHI2_1_MEDIAN)) if r.size else float("nan")


def tail_rms(residuals: np.ndarray) -> float:
    """The standard deviation of Gaussian residuals (n,) from the 80th percentile of their
    squares: up to a fifth of outlying residuals (a depth camera's noisy grazing edge) does
    not count, a deformed quarter of the region does; NaN for none."""
    r = np.asarray(residuals, dtype=np.float64)
    return float(np.sqrt(np.quantile(r**2, 0.8) / CHI2_1_Q80)) if r.size else float("nan")


def robust_rms(residuals: np.ndarray) -> float:
    """The standard deviation of Gaussian residuals (n,) from the median of their squares, so
    that a minority of outliers (skin that moved) does not count; NaN for none."""
    r = np.asarray(residuals, dtype=np.float64)
    return float(np.sqrt(np.median(r**2) / CHI2_1_MEDIAN)) if r.size else float("nan")


def mesh_noise(
    vertices: np.ndarray,
    valid: np.ndarray,
    neighbours: int = 12,
    at: np.ndarray | None = None,
    source: str = "mesh",
) -> MeshNoise:
    """Estimate each vertex's measurement noise from the roughness of the mesh around it.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        A fitted mesh (any frame); NaN where invalid.
    valid : (V,) bool
        Its valid vertices.
    neighbours : int
        Nearest valid vertices the quadric is fitted to (and over which a vertex's squared
        residuals are pooled), at least :data:`MIN_NEIGHBOURS`.
    at : (n,) int, optional
        Vertex indices to estimate at (their neighbours may be any valid vertex); default: every
        valid vertex. A vertex's pooled estimate uses the estimated ones among its neighbours.
    source : str
        ``subject/take`` for messages.

    Returns
    -------
    MeshNoise
    """
    v = np.asarray(vertices, dtype=np.float64)
    m = np.asarray(valid, dtype=bool)
    if v.ndim != 2 or v.shape[1] != 3 or m.shape != (v.shape[0],):
        raise InputError(
            source, f"mesh_noise: expected (V, 3) vertices and (V,) valid, got {v.shape}, {m.shape}"
        )
    if isinstance(neighbours, bool) or int(neighbours) != neighbours or neighbours < MIN_NEIGHBOURS:
        raise InputError(
            source,
            f"mesh_noise: neighbours must be an integer >= {MIN_NEIGHBOURS}, got {neighbours}",
        )
    n_v = v.shape[0]
    sq = np.full(n_v, np.nan)
    noise = np.full(n_v, np.nan)
    usable = m & np.isfinite(v).all(axis=1)
    idx = np.flatnonzero(usable)
    k = int(neighbours)
    if idx.size <= k:
        return MeshNoise(noise, sq)
    if at is not None:
        want = np.zeros(n_v, dtype=bool)
        want[np.asarray(at, dtype=np.int64)] = True
        targets = np.flatnonzero(want & usable)
    else:
        targets = idx
    if targets.size == 0:
        return MeshNoise(noise, sq)
    _, nn = cKDTree(v[idx]).query(v[targets], k=k + 1)
    nb = idx[nn[:, 1:]]  # the nearest is the vertex itself
    sq[targets] = _quadric_residuals(v[targets], v[nb])
    pooled = np.concatenate([sq[targets][:, None], sq[nb]], axis=1)
    noise[targets] = np.sqrt(np.nanmedian(pooled, axis=1) / CHI2_1_MEDIAN)
    return MeshNoise(noise, sq)


def _quadric_residuals(pts: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Leverage-corrected squared height of each point (n, 3) above the quadric fitted to its
    neighbours ``nb`` (n, k, 3), mm^2."""
    local = nb - pts[:, None, :]  # (n, k, 3), the vertex at the origin
    centred = local - local.mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))  # ascending
    axes = vecs[:, :, ::-1].transpose(0, 2, 1)  # (n, 3, 3) rows: principal axes, normal last
    uvw = np.einsum("nkj,nij->nki", local, axes)
    u, w_, h = uvw[..., 0], uvw[..., 1], uvw[..., 2]
    scale = np.sqrt(np.mean(u**2 + w_**2, axis=1, keepdims=True))  # conditioning
    u, w_ = u / scale, w_ / scale
    x = np.stack([np.ones_like(u), u, w_, u * u, u * w_, w_ * w_], axis=-1)  # (n, k, 6)
    xtx = np.einsum("nki,nkj->nij", x, x)  # (n, 6, 6), well scaled: u, v have unit RMS
    xtx_inv = np.linalg.inv(xtx + 1e-9 * np.eye(6))
    xth = np.einsum("nki,nk->ni", x, h)
    # the vertex sits at the origin, its design row is (1, 0, ..., 0): the quadric's height there
    # is the first coefficient, its leverage the first diagonal element of (X^T X)^-1
    residual = -np.einsum("ni,ni->n", xtx_inv[:, 0, :], xth)
    leverage = xtx_inv[:, 0, 0]
    return residual**2 / (1.0 + leverage)


__all__ = ["CHI2_1_MEDIAN", "MIN_NEIGHBOURS", "MeshNoise", "mesh_noise"]
