"""The still skin of one take: the patches of skin that agree on one rigid pose
(:func:`still_skin`).

A region assumed still (the upper forehead, the nose ridge, the temples) is not still in every
expression: a brow raise carries the forehead up to the hairline, a frown pulls it down. When
the moving part is a large share of the region, trimming the region's worst residuals leaves
the compromise pose in place, since the pose has already spread the motion over all of them.
Instead, the candidate skin (the region and the skin it may grow into) is split into patches;
the pose is fitted again with every set of up to ``still_drop`` patches left out; and the pose
that the most skin agrees with (averaged point-to-plane residual within ``still_sigma`` robust
standard deviations of the best-fitting hypothesis) wins. A patch that moved pulls every pose
fitted with it away from the still skin, and only the hypotheses that leave it out let the
still skin agree again: the still skin is found from the residuals' spatial structure, not
assumed.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.align.rigid import transform_points
from scan2morph.align.trim import _TRIM_FLOOR_MM, neighbour_mean, robust_sigma

#: Rounds of Lloyd's k-means after the farthest-point seeds of the patches (:func:`patches`).
_LLOYD_ROUNDS = 8


@dataclass(frozen=True)
class StillSkin:
    """The outcome of :func:`still_skin`.

    Attributes
    ----------
    keep : (n,) bool
        The candidates that agree with the pose (the still skin found).
    transform : (4, 4) float64
        The pose fitted with ``dropped`` left out.
    converged : bool
        Whether that fit converged.
    iterations : int
        ICP iterations of every hypothesis' fit.
    dropped : tuple of int
        The patches left out by the winning hypothesis.
    labels : (n,) int64
        The patch of every candidate.
    agree : (h,) int64
        The number of candidates agreeing with each fitted hypothesis' pose.
    notes : list of str
        What was found (for the alignment's ``recovery``).
    """

    keep: np.ndarray
    transform: np.ndarray
    converged: bool
    iterations: int
    dropped: tuple
    labels: np.ndarray
    agree: np.ndarray
    notes: list


def patches(p: np.ndarray, k: int) -> np.ndarray:
    """Split points into ``k`` compact patches, deterministically.

    Farthest-point seeds (the first is the point farthest from the centroid), then
    :data:`_LLOYD_ROUNDS` rounds of Lloyd's k-means.

    Parameters
    ----------
    p : (n, 3) float
        Points, mm.
    k : int
        Patches wanted (at most ``n``).

    Returns
    -------
    labels : (n,) int64
        The patch of each point, 0..k-1.
    """
    p = np.asarray(p, dtype=np.float64)
    k = int(min(k, len(p)))
    seeds = [int(np.argmax(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))]
    d = np.sum((p - p[seeds[0]]) ** 2, axis=1)
    for _ in range(1, k):
        seeds.append(int(np.argmax(d)))
        d = np.minimum(d, np.sum((p - p[seeds[-1]]) ** 2, axis=1))
    centres = p[seeds]
    labels = cKDTree(centres).query(p)[1]
    for _ in range(_LLOYD_ROUNDS):
        centres = np.array(
            [p[labels == i].mean(axis=0) if np.any(labels == i) else centres[i] for i in range(k)]
        )
        labels = cKDTree(centres).query(p)[1]
    return labels.astype(np.int64)


def still_skin(p, t, refine, plane, prm) -> StillSkin:
    """The pose that the most candidate skin agrees with, and that skin.

    Parameters
    ----------
    p : (n, 3) float
        The take's candidate vertices (the region's and those it may grow into), mm.
    t : (4, 4) float
        The starting pose (for example the region's trimmed fit).
    refine : callable
        ``refine(keep, start) -> (t, fitness, rmse, iterations, converged)``: the rigid fit of
        the candidates ``keep`` (n,) bool from ``start``.
    plane : callable
        ``plane(x) -> (n,)`` signed point-to-plane distance of points ``x`` (n, 3) to the
        target, mm.
    prm : IcpParams
        ``still_groups`` patches, up to ``still_drop`` left out at once; the agreement
        threshold: ``still_sigma`` robust standard deviations of the averaged residuals (over
        ``trim_radius_mm``) of the best-fitting hypothesis, at least 0.05 mm.

    Returns
    -------
    StillSkin
    """
    n = len(p)
    labels = patches(p, prm.still_groups)
    k = int(labels.max()) + 1
    mean = neighbour_mean(p, prm.trim_radius_mm)
    hypotheses = [()] + [
        c for m in range(1, min(prm.still_drop, k - 1) + 1) for c in combinations(range(k), m)
    ]
    fits, iterations = [], 0
    for drop in hypotheses:
        use = ~np.isin(labels, drop)
        if use.sum() < 6:
            continue
        t_h, _, _, n_it, conv = refine(use, t)
        iterations += n_it
        if not np.isfinite(t_h).all():
            continue
        r = mean @ plane(transform_points(t_h, p))
        fits.append((drop, t_h, conv, r, robust_sigma(r[use])))
    if not fits:
        return StillSkin(
            np.ones(n, dtype=bool), t, False, iterations, (), labels, np.zeros(0, int), []
        )
    tau = max(prm.still_sigma * min(f[4] for f in fits), _TRIM_FLOOR_MM)
    agree = np.array([np.count_nonzero(np.abs(f[3]) <= tau) for f in fits], dtype=np.int64)
    drop, t_best, conv, r, _ = fits[int(np.argmax(agree))]  # the first: fewest left out
    keep = np.abs(r) <= tau
    notes = [
        f"still skin: {int(keep.sum())} of {n} candidates agree with the pose fitted without "
        f"{len(drop)} of {k} patches ({len(fits)} hypotheses, threshold {tau:.3f} mm)"
    ]
    return StillSkin(keep, t_best, bool(conv), iterations, tuple(drop), labels, agree, notes)


__all__ = ["StillSkin", "patches", "still_skin"]
