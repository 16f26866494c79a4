"""Trimming the parts of an ICP region that moved (an expression's moving skin), refining the
pose again after each change (:func:`trim_moving`)."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from scan2morph.align.rigid import transform_points
from scan2morph.geometry import edge_adjacency
from scan2morph.tol import MAD_TO_SIGMA

#: Averaged residuals below this never count as motion, mm (a floor to the robust threshold).
_TRIM_FLOOR_MM = 0.05


def neighbour_mean(p: np.ndarray, radius: float) -> sparse.csr_array:
    """The (n, n) operator averaging a value over each point's neighbours within ``radius`` (mm),
    the point itself included; ``p`` is (n, 3), mm."""
    n = len(p)
    pairs = cKDTree(p).query_pairs(radius, output_type="ndarray")
    adj = edge_adjacency(pairs, n) + sparse.eye_array(n, format="csr")  # each with itself
    return sparse.diags_array(1.0 / adj.sum(axis=1)) @ adj


def robust_sigma(r: np.ndarray) -> float:
    """The robust standard deviation of values ``r`` (n,): :data:`~scan2morph.tol.MAD_TO_SIGMA`
    times their median absolute deviation."""
    return float(MAD_TO_SIGMA * np.median(np.abs(r - np.median(r))))


def trim_moving(p, keep, t, conv, refine, plane, prm, grow=None) -> tuple:
    """Leave out the parts of the region that moved, refining again after each change.

    A vertex's residual averaged over its neighbours within ``trim_radius_mm`` (of the take's
    region vertices) separates a patch of moving skin from noise; the vertices whose average
    exceeds ``trim_sigma`` robust standard deviations of the kept ones' (at least
    :data:`_TRIM_FLOOR_MM`) are left out. Stops when the kept set repeats, after
    ``trim_rounds`` rounds, or when fewer than 3 vertices would be kept. Vertices marked
    ``grow`` (candidates outside the region) join the kept set in a round when their average is
    within the threshold and leave it when it is not; the region's vertices, once left out,
    stay out.

    Parameters
    ----------
    p : (n, 3) float
        The take's candidate vertices (the region's and those it may grow into), mm.
    keep : (n,) bool
        The vertices kept so far.
    t : (4, 4) float
        The pose refined on ``keep``.
    conv : bool
        Whether that refinement converged.
    refine : callable
        ``refine(keep, start) -> (t, fitness, rmse, iterations, converged)``: the refinement
        run again after each change of ``keep``.
    plane : callable
        ``plane(x) -> (n,)`` signed point-to-plane distance of points ``x`` (n, 3) to the
        target, mm.
    prm : IcpParams
        ICP settings (``trim_rounds``, ``trim_radius_mm``, ``trim_sigma``).
    grow : (n,) bool, optional
        Candidates outside the region.

    Returns
    -------
    keep : (n,) bool
    t : (4, 4) the pose refined on ``keep``
    converged : bool
        Of the last refinement.
    iterations : int
        Iterations of the refinements run here.
    notes : list of str
        What was left out and added (for the result's ``recovery``).
    """
    if prm.trim_rounds == 0 or not np.isfinite(t).all():
        return keep, t, conv, 0, []
    n = len(p)
    mean = neighbour_mean(p, prm.trim_radius_mm)
    grow = np.zeros(n, dtype=bool) if grow is None else grow
    region = ~grow
    iterations, rounds = 0, 0
    for rounds in range(1, prm.trim_rounds + 1):  # noqa: B007 (rounds is reported)
        r = mean @ plane(transform_points(t, p))
        rk = r[keep]
        sigma = robust_sigma(rk)
        new = (keep | grow) & (np.abs(r) <= max(prm.trim_sigma * sigma, _TRIM_FLOOR_MM))
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
        t_new, _, _, n_it, conv = refine(keep, t)
        iterations += n_it
        if not np.isfinite(t_new).all():
            conv = False
            break
        t = t_new
    notes = []
    if not keep[region].all():
        notes.append(
            f"left out {int((~keep[region]).sum())} of {int(region.sum())} region vertices that "
            f"moved ({rounds} trimming rounds)"
        )
    if grow.any():
        notes.append(f"added {int(keep[grow].sum())} of {int(grow.sum())} still vertices")
    return keep, t, conv, iterations, notes


__all__ = ["neighbour_mean", "robust_sigma", "trim_moving"]
