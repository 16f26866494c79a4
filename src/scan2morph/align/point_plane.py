"""Point-to-plane ICP steps against one nearest-neighbour tree.

The alignment steps ICP one iteration at a time (:func:`scan2morph.align.icp._refine_icp`
halves the robust kernel's scale between iterations and reports the iterations). open3d's
``registration_icp`` builds a k-d tree over the target and searches every correspondence twice
on each call, so stepping it rebuilt the tree hundreds of times a take, and its parallel sums
made the last digits of a pose vary from run to run. This module makes the same step against
one scipy k-d tree, with sums in a fixed order:

1. each source point (moved by the current pose) is paired with its closest target point within
   ``max_d`` mm;
2. the point-to-plane residual of a pair is ``r = (p - q) . n_q`` (mm), weighted by the robust
   kernel at ``|r|`` (:func:`~scan2morph.align.settings.kernel_weights`);
3. the Gauss-Newton step solves ``(sum w J J^T) x = -sum w J r`` with ``J = (p x n_q, n_q)``;
   ``x`` holds small rotations about x, y and z (radians) and a translation (mm), the rotation
   ``Rz Ry Rx`` (open3d's parametrisation), applied on the left of the pose;
4. a step that would move a paired point farther than :data:`TRUST_FACTOR` times ``max_d``
   (every pair lies within ``max_d``: a step far beyond it leaves the pairs it was computed
   from) is damped instead (Levenberg-Marquardt: ``lambda I`` added to the normal equations,
   ``lambda`` doubled until no paired point moves farther than that). The rotation about the
   frame's origin, far from the face (a scanner frame puts it a metre away), makes the normal
   equations ill-conditioned (condition numbers of 1e9 and more); from a start a few mm off on
   skin that slides along itself, open3d's undamped step went hundreds of mm astray. Any other
   step is taken as open3d takes it.

The fitness and inlier RMSE are open3d's: the share of source points with a pair, and the RMS
distance (not point-to-plane) of the pairs, mm.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.align.rigid import transform_points
from scan2morph.align.settings import kernel_weights

#: A step may move a paired point at most this many pairing distances (``max_d``) before it is
#: damped: right steps of the default cohort move points up to 1.2 ``max_d``, the diverging ones
#: 15-80.
TRUST_FACTOR = 2.0


def _rotation_zyx(angles: np.ndarray) -> np.ndarray:
    """(3, 3) rotation ``Rz(c) Ry(b) Rx(a)`` of ``angles`` (a, b, c), radians."""
    (ca, cb, cc), (sa, sb, sc) = np.cos(angles), np.sin(angles)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rz = np.array([[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


class Pairs(NamedTuple):
    """A pose's pairs (:meth:`PointToPlane.at`).

    Attributes
    ----------
    moved : (n, 3) float64
        The source points moved by the pose, mm.
    source, target : (k,) int
        The paired source points and their closest target points within ``max_d``.
    distance : (k,) float64
        Their distances, mm.
    fitness : float
        Share of the source points paired.
    rmse : float
        RMS distance of the pairs, mm (0 without pairs).
    """

    moved: np.ndarray
    source: np.ndarray
    target: np.ndarray
    distance: np.ndarray
    fitness: float
    rmse: float


class PointToPlane:
    """A target surface (points with unit normals) and its pairing distance.

    Parameters
    ----------
    target : (m, 3) float
        Target points, mm.
    normals : (m, 3) float
        Their unit normals.
    max_d : float
        Largest pairing distance, mm.
    """

    def __init__(self, target: np.ndarray, normals: np.ndarray, max_d: float):
        self.q = np.asarray(target, dtype=np.float64)
        self.n = np.asarray(normals, dtype=np.float64)
        self.max_d = float(max_d)
        self.tree = cKDTree(self.q)
        # a paired source point lies within max_d of its target: no farther from the origin
        far = float(np.max(np.linalg.norm(self.q, axis=1))) if len(self.q) else 0.0
        self.radius = far + self.max_d

    def at(self, source: np.ndarray, pose: np.ndarray) -> Pairs:
        """The pairs of ``source`` (n, 3) mm moved by ``pose`` (4, 4), with their fitness and
        inlier RMSE."""
        moved = transform_points(pose, source)
        d, j = self.tree.query(moved, distance_upper_bound=self.max_d)
        ok = np.isfinite(d)
        d = d[ok]
        rmse = float(np.sqrt(np.mean(d**2))) if d.size else 0.0
        fitness = d.size / len(source) if len(source) else 0.0
        return Pairs(moved, np.flatnonzero(ok), j[ok], d, fitness, rmse)

    def step(self, pairs: Pairs, kernel: str, k: float, pose: np.ndarray) -> np.ndarray:
        """One Gauss-Newton step from ``pose`` (4, 4), whose pairs are ``pairs``: the next pose,
        (4, 4) float64.

        ``kernel`` (``tukey``, ``huber`` or ``none``) and its scale ``k`` (mm) weigh the pairs.
        """
        p, q, n = pairs.moved[pairs.source], self.q[pairs.target], self.n[pairs.target]
        r = np.einsum("ij,ij->i", p - q, n)
        w = kernel_weights(np.abs(r), kernel, k)
        jac = np.hstack([np.cross(p, n), n])
        jtj = (jac * w[:, None]).T @ jac
        jtr = jac.T @ (w * r)
        try:
            x = np.linalg.solve(jtj, -jtr)
        except np.linalg.LinAlgError:  # too few pairs to fix every degree of freedom
            x = np.linalg.lstsq(jtj, -jtr, rcond=None)[0]
        if _moves_beyond(x, p, self.radius, TRUST_FACTOR * self.max_d):
            x = self._damped(jtj, jtr, p)
        return _update(x) @ pose

    def _damped(self, jtj: np.ndarray, jtr: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The Levenberg-Marquardt step ``(jtj + lambda I) x = -jtr`` with the smallest
        ``lambda`` (doubling from 1e-9 of ``jtj``'s trace) that moves no point of ``p`` farther
        than ``TRUST_FACTOR * max_d``; no step when none does within 200 doublings."""
        eye = np.eye(len(jtj))
        lam = 1e-9 * max(float(np.trace(jtj)), 1e-12)
        for _ in range(200):
            x = np.linalg.solve(jtj + lam * eye, -jtr)
            if not _moves_beyond(x, p, self.radius, TRUST_FACTOR * self.max_d):
                return x
            lam *= 2.0
        return np.zeros(len(jtj))


def _update(x: np.ndarray) -> np.ndarray:
    """(4, 4) rigid motion of a step ``x`` (three rotations about x, y, z, radians, and a
    translation, mm)."""
    update = np.eye(4)
    update[:3, :3] = _rotation_zyx(x[:3])
    update[:3, 3] = x[3:]
    return update


def _moves_beyond(x: np.ndarray, p: np.ndarray, radius: float, limit: float) -> bool:
    """Whether the step ``x`` moves a point of ``p`` (n, 3) mm, none farther than ``radius`` mm
    from the origin, farther than ``limit`` mm (a non-finite step does). A rotation by angles
    (a, b, c) turns by at most |a| + |b| + |c|, so no point moves farther than that times
    ``radius`` plus the translation: the exact check runs only when that bound exceeds ``limit``
    (it costs more than the step)."""
    if not np.isfinite(x).all():
        return True
    if len(p) == 0 or np.sum(np.abs(x[:3])) * radius + np.linalg.norm(x[3:]) <= limit:
        return False
    u = _update(x)
    moved = p @ (u[:3, :3] - np.eye(3)).T + u[:3, 3]
    return float(np.max(np.linalg.norm(moved, axis=1))) > limit
