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
from scipy import ndimage
from scipy.spatial import cKDTree

from scan2morph.errors import InputError

#: Median of a chi-square variable with one degree of freedom (its mean is 1).
CHI2_1_MEDIAN = 0.454936423119572
#: The 80th percentile of a chi-square with one degree of freedom (:func:`tail_rms`).
CHI2_1_Q80 = 1.642374415149818

#: Quadric terms plus a margin: fewer valid neighbours than this give no estimate at a vertex.
MIN_NEIGHBOURS = 9

#: The largest correction of :func:`smoothing_gain`. Beyond it the smoothing is wider than about
#: twice the vertex spacing, the noise's reading falls to the surface's own misfit of a quadric
#: (0.02-0.05 mm on the synthetic faces), and the correction would multiply that misfit: on a
#: test face at 1 px a vertex, a smoothing of 1.5 / 3 px reads gains of 20 / 171 where the noise
#: is 11 / 12 times its reading. At 1.6-3.6 px a vertex (RGB-D at 320 x 240 and 640 x 480,
#: smoothed over 1.5 px) the gains are 1.3-7, at most 25% above the truth.
MAX_SMOOTHING_GAIN = 10.0


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
    nb = _neighbourhoods(v, idx, targets, k)
    sq[targets] = _quadric_residuals(v[targets], v[nb])
    pooled = np.concatenate([sq[targets][:, None], sq[nb]], axis=1)
    noise[targets] = np.sqrt(np.nanmedian(pooled, axis=1) / CHI2_1_MEDIAN)
    return MeshNoise(noise, sq)


def smoothing_gain(
    vertices: np.ndarray,
    valid: np.ndarray,
    points2d: np.ndarray,
    sigma_px: float,
    neighbours: int = 12,
    draws: int = 4,
) -> float:
    """How many times a mesh's noise exceeds what :func:`mesh_noise` reads, when the range image
    the mesh was sampled from had its noise Gaussian-smoothed over ``sigma_px`` pixels (a depth
    camera's repair, :func:`~scan2morph.scan.depth_cleanup.smooth_depth`).

    Smoothed noise is correlated over about ``sigma_px``; where that is as wide as the vertex
    spacing, the quadric through a vertex's neighbours follows the noise and the roughness reads
    low (a quarter of the noise on 320 x 240 depth, smoothed over 1.5 px, 3 mm on the skin).
    The gain is that bias, measured on this mesh's own sampling: white noise images are
    smoothed with the same Gaussian (3 sigma window), sampled bilinearly at the vertices'
    pixels, and read by the roughness estimate (at every valid vertex, as
    :meth:`MeshNoise.region` reads a region); the gain is the noise's RMS over the reading's
    (RMS over ``draws`` fixed-seed images), at most :data:`MAX_SMOOTHING_GAIN`. White noise
    (``sigma_px`` 0) reads right: the gain is 1.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        The fitted mesh; NaN where invalid.
    valid : (V,) bool
    points2d : (V, 2) float, px
        Each vertex's position (x, y) on the range image it was sampled from.
    sigma_px : float
        The smoothing's standard deviation, px (0: none).
    neighbours : int
        As :func:`mesh_noise`.
    draws : int
        Noise images averaged.

    Returns
    -------
    float
        >= 1; exactly 1.0 without smoothing or without enough valid vertices.
    """
    v = np.asarray(vertices, dtype=np.float64)
    xy = np.asarray(points2d, dtype=np.float64)
    usable = np.asarray(valid, dtype=bool) & np.isfinite(v).all(axis=1) & np.isfinite(xy).all(1)
    idx = np.flatnonzero(usable)
    if not sigma_px > 0 or idx.size <= max(int(neighbours), MIN_NEIGHBOURS):
        return 1.0
    nb = _neighbourhoods(v, idx, idx, int(neighbours))
    frame = _QuadricFrame(v[idx], v[nb])
    margin = int(np.ceil(3.0 * sigma_px)) + 2
    lo = np.floor(xy[idx].min(axis=0)).astype(int) - margin
    hi = np.ceil(xy[idx].max(axis=0)).astype(int) + margin
    rng = np.random.default_rng(0)
    true_sq = read_sq = 0.0
    z = np.zeros(len(v))  # the noise at the vertices, in units of the image's
    for _ in range(int(draws)):
        image = ndimage.gaussian_filter(
            rng.standard_normal((hi[1] - lo[1] + 1, hi[0] - lo[0] + 1)), sigma_px, truncate=3.0
        )
        z[idx] = ndimage.map_coordinates(image, (xy[idx, 1] - lo[1], xy[idx, 0] - lo[0]), order=1)
        true_sq += float(np.mean(z[idx] ** 2))
        read_sq += float(np.median(frame.residuals(z[nb] - z[idx, None]))) / CHI2_1_MEDIAN
    return float(np.clip(np.sqrt(true_sq / read_sq), 1.0, MAX_SMOOTHING_GAIN))


def _neighbourhoods(v: np.ndarray, idx: np.ndarray, targets: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` nearest of the vertices ``idx`` to each target vertex (itself left out),
    (n, k) vertex indices."""
    _, nn = cKDTree(v[idx]).query(v[targets], k=k + 1)
    return idx[nn[:, 1:]]  # the nearest is the vertex itself


class _QuadricFrame:
    """The local quadric fits of points (n, 3) to their neighbours ``nb`` (n, k, 3), mm: each in
    the tangent frame of its neighbours' principal axes."""

    def __init__(self, pts: np.ndarray, nb: np.ndarray):
        local = nb - pts[:, None, :]  # (n, k, 3), the vertex at the origin
        centred = local - local.mean(axis=1, keepdims=True)
        _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))  # ascending
        axes = vecs[:, :, ::-1].transpose(0, 2, 1)  # (n, 3, 3) rows: principal axes, normal last
        uvw = np.einsum("nkj,nij->nki", local, axes)
        u, w_ = uvw[..., 0], uvw[..., 1]
        self.heights = uvw[..., 2]  # (n, k): the neighbours' heights above the vertex, mm
        scale = np.sqrt(np.mean(u**2 + w_**2, axis=1, keepdims=True))  # conditioning
        u, w_ = u / scale, w_ / scale
        self.x = np.stack([np.ones_like(u), u, w_, u * u, u * w_, w_ * w_], axis=-1)  # (n, k, 6)
        xtx = np.einsum("nki,nkj->nij", self.x, self.x)  # (n, 6, 6), well scaled
        self.xtx_inv = np.linalg.inv(xtx + 1e-9 * np.eye(6))

    def residuals(self, heights: np.ndarray) -> np.ndarray:
        """Leverage-corrected squared height (n,) of each vertex above the quadric fitted to its
        neighbours' ``heights`` (n, k) above it, mm^2."""
        xth = np.einsum("nki,nk->ni", self.x, heights)
        # the vertex sits at the origin, its design row is (1, 0, ..., 0): the quadric's height
        # there is the first coefficient, its leverage the first diagonal element of (X^T X)^-1
        residual = -np.einsum("ni,ni->n", self.xtx_inv[:, 0, :], xth)
        return residual**2 / (1.0 + self.xtx_inv[:, 0, 0])


def _quadric_residuals(pts: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Leverage-corrected squared height of each point (n, 3) above the quadric fitted to its
    neighbours ``nb`` (n, k, 3), mm^2."""
    frame = _QuadricFrame(pts, nb)
    return frame.residuals(frame.heights)


__all__ = [
    "CHI2_1_MEDIAN",
    "MAX_SMOOTHING_GAIN",
    "MIN_NEIGHBOURS",
    "MeshNoise",
    "mesh_noise",
    "smoothing_gain",
]
