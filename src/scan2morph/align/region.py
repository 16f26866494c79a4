"""The rigid motion of one region of skin onto a sampled surface, with a verdict on its rigidity
(:func:`region_motion`; the jaw prior registers the chin with it)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from scan2morph.align.gate import residual_gate
from scan2morph.align.noise import mesh_noise
from scan2morph.align.result import AlignResult
from scan2morph.align.rigid import transform_points
from scan2morph.align.settings import IcpParams, icp_settings, kernel_weights
from scan2morph.align.surface import SampledSurface
from scan2morph.errors import InputError

#: Damping of a region's ICP step (:func:`region_motion`), a share of the largest eigenvalue of
#: its normal matrix (rotations in mm at the region's radius): directions constrained less than
#: this move slowly, and noise does not throw them far.
_DAMPING = 1e-3
#: A region's ICP step that turns back on the last (the cosine of their motions of the points
#: below this) halves the steps after it, down to :data:`_MIN_STEP_SCALE` of a full step
#: (:func:`_region_icp`): a swing between two poses settles between them, and a wrong pose is
#: still left at 1/16 of the full step's pace, so that it is not stopped far from the answer.
_TURN_BACK_COSINE = -0.5
_MIN_STEP_SCALE = 1.0 / 16.0
#: A region's ICP has converged when a step moves its points by less than this share of the
#: expected residual RMS (:func:`_region_icp`).
_STEP_NOISE_SHARE = 0.25


def region_motion(
    region: np.ndarray,
    initial: np.ndarray,
    surface: SampledSurface,
    params: IcpParams | None = None,
    source: str = "subject/take",
) -> AlignResult:
    """The rigid motion of one region of skin onto a surface, with a verdict on its rigidity.

    ICP moves the region's points onto the surface (point-to-plane; each step about the region's
    centroid and damped, so that a direction the region's shape hardly constrains moves
    slowly; the kernel annealed as in :func:`~scan2morph.align.align_take` and never narrower than
    ``kernel_noise_sigmas`` times the RMSE the measured noise explains; points off the surface's
    data left out). Nothing is trimmed; the verdict judges the region's robust point-to-plane
    RMS (from the 80th percentile of the squares, :func:`~scan2morph.align.noise.tail_rms`):
    up to a fifth of outlying points (a depth camera's noisy grazing edge) does not count, a
    deformed quarter of the region does.

    Parameters
    ----------
    region : (n, 3) float, mm
        The region's points (finite), n >= 6.
    initial : (4, 4) float
        The initial pose (for example the least-squares fit of a template correspondence).
    surface : SampledSurface
        The target (a range image's samples, in the region's frame).
    params : IcpParams, optional
        The ICP settings (used: ``max_correspondence_mm``, ``max_iterations``,
        ``robust_kernel``, ``kernel_k_mm``, ``kernel_noise_sigmas``, ``step_mm``, ``min_fitness``
        and the RMSE gate's keys); its RMSE gate
        (``max_rmse_ratio`` times the expected RMSE, or ``max_rmse_mm``) judges rigidity, over
        the points the surface's data covers; ``min_fitness`` is the least share of those.
    source : str
        ``subject/take`` label for error messages.

    Returns
    -------
    AlignResult
        ``transform`` maps the region onto the surface; ``residual_rmse`` is the region's
        robust point-to-plane RMS there; ``fitness`` the share of the region the surface covers;
        ``noise_take`` and ``noise_neutral`` are the measured noise of the surface and of the
        region; ``ok`` is False, with the reasons in ``problems``, when ICP did not converge,
        the fitness is below ``min_fitness`` or the RMSE is above :func:`rmse_limit` (the
        region did not move rigidly).

    Raises
    ------
    InputError
        Bad shapes or params, fewer than 6 region points.
    """
    prm = icp_settings(params, source)
    p, initial = _check_region(region, initial, source)
    every = np.ones(len(p), dtype=bool)
    noise_region = mesh_noise(p, every, source=source).region(every)
    placed = transform_points(initial, p)
    noise_surface = surface.noise(placed, source)
    expected = float(np.hypot(noise_surface, noise_region))
    known = expected if np.isfinite(expected) else 0.0
    prm = replace(prm, kernel_k_mm=max(prm.kernel_k_mm, prm.kernel_noise_sigmas * known))
    reach = surface.reach(placed, known)
    t, iterations, conv, constraint = _region_icp(p, surface, initial, prm, reach, known)
    if not np.isfinite(t).all():
        t, conv = initial, False
    plane, seen, d = surface.residuals(transform_points(t, p), reach)
    fitness = float(seen.mean())
    rmse = float(np.sqrt(np.mean(d[seen] ** 2))) if seen.any() else 0.0
    gate = residual_gate(plane[seen], noise_surface, noise_region, prm, robust=True)
    problems = _region_problems(conv, iterations, fitness, gate, prm)
    return AlignResult(
        transform=t,
        initial=initial,
        fitness=fitness,
        inlier_rmse=rmse,
        iterations=int(iterations),
        converged=bool(conv),
        method="icp",
        n_points=int(len(p)),
        residual_rmse=gate.residual_rmse,
        ok=not problems,
        problems=problems,
        noise_take=noise_surface,
        noise_neutral=noise_region,
        expected_rmse=expected,
        rmse_limit=gate.limit,
        rmse_limit_kind=gate.kind,
        kernel_k=prm.kernel_k_mm,
        constraint=constraint,
    )


def _check_region(region, initial, source: str) -> tuple[np.ndarray, np.ndarray]:
    """``region`` as (n, 3) float64 points (n >= 6, finite) and ``initial`` as a finite (4, 4)
    float64 transform."""
    p = np.asarray(region, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 6 or not np.isfinite(p).all():
        raise InputError(source, f"region: expected at least 6 finite (n, 3) points, got {p.shape}")
    initial = np.asarray(initial, dtype=np.float64)
    if initial.shape != (4, 4) or not np.isfinite(initial).all():
        raise InputError(
            source, f"initial: expected a finite (4, 4) transform, got {initial.shape}"
        )
    return p, initial


def _region_problems(conv, iterations, fitness, gate, prm) -> list[str]:
    """Why a region's motion is not rigid: ICP not converged, too little of it covered by the
    surface's data (``fitness`` below ``min_fitness``), its RMSE above the ``gate``'s limit."""
    problems = [] if conv else [f"ICP did not converge ({iterations} iterations)"]
    if fitness < prm.min_fitness:
        problems.append(
            f"the surface's data covers only {100 * fitness:.0f}% of the region (min_fitness "
            f"{prm.min_fitness:g})"
        )
    if gate.problem:
        problems.append(
            f"point-to-plane RMSE {gate.residual_rmse:.3f} mm over the region > {gate.limit:.3f}"
            " mm: it did not move rigidly"
        )
    return problems


def _region_icp(p, surface, initial, prm, reach=0.0, noise=0.0):
    """Point-to-plane ICP of a small region onto a target: ``(transform, iterations, converged,
    constraint)``; ``constraint`` is the RMS point-to-plane change per mm of the motion the
    region's shape constrains least (a rotation counted by how far it moves the points), at
    the last step: 0 for a plane, which slides freely.

    Each step is the least-squares twist about the weighted centroid of the region (not the
    frame's origin, a metre away: a rotation of a few degrees about it is a large, badly
    linearised translation), damped by :data:`_DAMPING` of its strongest direction, so that a
    direction the region's shape hardly constrains (a chin slides along its own curvature)
    moves slowly instead of taking a large step from noise. The kernel's scale halves from ``max_correspondence_mm`` to
    ``kernel_k_mm`` as in :func:`scan2morph.align.icp._refine_icp`; a correspondence farther than that scale (and
    than ``reach``, mm) is left out, so that points beyond the surface's data do not pull. It
    has converged when a step moves the points by less than ``step_mm`` RMS, or by less than
    :data:`_STEP_NOISE_SHARE` of the expected residual ``noise`` (mm): the nearest samples, and
    with them the step, jitter by about that much once the pose is found. Once the kernel is at
    its final scale, a step that turns back on the last one (:func:`_turned_back`) halves every
    later step, down to :data:`_MIN_STEP_SCALE`: the nearest samples alternate between two sets,
    and the pose between them is the answer (without it, a chin's ICP swung between two poses
    0.07-0.16 mm apart until its iterations ran out, in 2 of 16 click-noise draws of a car).
    """
    q, q_normals = surface.points, surface.normals
    t = np.array(initial, dtype=np.float64)
    k_final = prm.kernel_k_mm
    k = max(prm.max_correspondence_mm, k_final)
    tolerance = max(prm.step_mm, _STEP_NOISE_SHARE * noise)
    scale, last = 1.0, None  # the step's share; the points' motion in the last step
    it = 0
    for it in range(1, prm.max_iterations + 1):  # noqa: B007 (it is reported)
        x = transform_points(t, p)
        d, j = surface.tree.query(x, distance_upper_bound=prm.max_correspondence_mm)
        near = d <= max(k, reach)
        near[near] = ~surface.edge[j[near]]
        x, n = x[near], q_normals[j[near]]
        r = np.einsum("ij,ij->i", x - q[j[near]], n)
        w = kernel_weights(np.abs(r), prm.robust_kernel, k)
        if np.count_nonzero(w) < 6:
            return t, it, False, 0.0
        c = (w[:, None] * x).sum(axis=0) / w.sum()
        # the twist's rotation in mm at the region's radius, so that its six parts weigh alike
        radius = max(float(np.sqrt((w * np.sum((x - c) ** 2, axis=1)).sum() / w.sum())), 1e-12)
        a = np.hstack([np.cross(x - c, n) / radius, n])
        ata = a.T @ (w[:, None] * a) / w.sum()
        eigen = np.linalg.eigvalsh(ata)
        constraint = float(np.sqrt(max(eigen[0], 0.0)))
        # damped by a share of the strongest direction: one the region's shape hardly
        # constrains moves less per step, and not by a large step out of noise
        twist = np.linalg.solve(ata + _DAMPING * eigen[-1] * np.eye(6), -a.T @ (w * r) / w.sum())
        twist *= scale
        twist[:3] /= radius
        step = np.eye(4)
        step[:3, :3] = Rotation.from_rotvec(twist[:3]).as_matrix()
        step[:3, 3] = c - step[:3, :3] @ c + twist[3:]
        t_old, t = t, step @ t
        # the step's size where the region is (a turn about the frame's origin, a metre away,
        # is no measure of it)
        motion = transform_points(t, p) - transform_points(t_old, p)
        done = k == k_final and float(np.sqrt(np.mean(np.sum(motion**2, axis=1)))) < tolerance
        if k == k_final and last is not None and _turned_back(motion, last):
            # the samples alternate, the answer lies between
            scale = max(scale / 2.0, _MIN_STEP_SCALE)
        last = motion if k == k_final else None
        k = max(k / 2.0, k_final)
        if done:
            return t, it, True, constraint
    return t, it, False, constraint


def _turned_back(motion: np.ndarray, last: np.ndarray) -> bool:
    """Whether a step's motion of the points (n, 3) undoes the last's, mm: their fields point
    apart (cosine below :data:`_TURN_BACK_COSINE`), as in a swing between two poses, not in
    the jitter of a converged pose or a slow slide, whose steps point alike or at random."""
    norms = float(np.linalg.norm(motion) * np.linalg.norm(last))
    return norms > 0 and float(np.sum(motion * last)) < _TURN_BACK_COSINE * norms


__all__ = ["region_motion"]
