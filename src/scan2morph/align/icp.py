"""Rigid alignment of a take's mesh to the subject's neutral mesh (Yano-Harada, Sec. 4.1).

The initial pose comes from six user-chosen point pairs (the same template vertices in both
meshes, placed where the mouth does not move them); it is refined by ICP over the upper face
only, so that the moving mouth does not bias the fit.

Two refinements are offered (``params.method``):

``"icp"`` (the paper's, default)
    Point-to-plane ICP with a robust kernel (open3d's step, against one k-d tree:
    :mod:`scan2morph.align.point_plane`): closest points, target normals are the neutral mesh's
    vertex normals. The kernel's scale starts at ``max_correspondence_mm`` and
    halves each iteration down to ``kernel_k_mm``: a redescending kernel (Tukey) as narrow as
    1 mm from the start would give zero weight to most points while the initial pose is still
    a few mm off, and the few left can pull a one-step solve anywhere.
``"correspondence"``
    Both meshes come from one template, so vertex i of one *is* vertex i of the other. The
    closed-form alternative is an iteratively reweighted Kabsch fit over the upper-face
    vertices (same robust kernel on the 3D residuals). It needs no closest-point search, but
    it inherits any tangential sliding of the template fit, which ICP ignores.

The stable region is not stable in every expression: a smile's cheek raise draws the skin of the
temples towards the eyes, a sad face's inner-brow raise lifts the lower forehead. After the
first refinement the region is therefore trimmed (``trim_rounds``): each vertex's point-to-plane
residual is averaged over its neighbours within ``trim_radius_mm`` (moving skin moves in
patches, noise does not), the vertices whose averaged residual exceeds ``trim_sigma`` robust
standard deviations are left out, and the refinement resumes on the rest, until the kept set
stops changing. A refinement that does not converge is re-initialised from the point pairs on
the kept region, then given a convex (Huber) kernel.

How far a right alignment leaves the two meshes apart depends on the scanner: 0.1 mm for a
laser scanner, a few mm for a depth camera. Each mesh's noise is therefore measured from the
mesh itself (:func:`scan2morph.align.noise.mesh_noise`: the roughness of its stable region
against a local quadric), and the expected point-to-plane RMSE of a right alignment is
``sqrt(noise_take^2 + noise_neutral^2)``. The robust kernel is never narrower than
``kernel_noise_sigmas`` times that (a Tukey kernel of 0.3 mm on a 3 mm scan weighs almost every
point zero), and the RMSE gate is ``max_rmse_ratio`` times it (``max_rmse_mm``, when set,
replaces it by an absolute limit).

The result carries a verdict (``ok``, ``problems``) instead of raising: not converged after that
recovery, fitness below ``min_fitness``, point-to-plane RMSE above the limit, less than
``min_inlier_fraction`` of the region kept.

The settings and their checks are in :mod:`scan2morph.align.settings`, the trimming in
:mod:`scan2morph.align.trim`, the RMSE gate in :mod:`scan2morph.align.gate`, and a single
region's rigid motion (the jaw prior's) in :mod:`scan2morph.align.region`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from scan2morph.align.gate import RmseGate, residual_gate, rmse_gate, rmse_limit
from scan2morph.align.noise import mesh_noise
from scan2morph.align.point_plane import PointToPlane
from scan2morph.align.region import region_motion
from scan2morph.align.result import AlignResult
from scan2morph.align.rigid import invert, kabsch, rotation_angle_deg, transform_points
from scan2morph.align.settings import (
    AlignMeshes,
    IcpParams,
    check_indices,
    check_mesh,
    icp_settings,
    kernel_weights,
    noise_gains,
)
from scan2morph.align.still import still_skin
from scan2morph.align.surface import SampledSurface
from scan2morph.align.trim import trim_moving
from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals


def _residual_stats(p: np.ndarray, q: np.ndarray, t: np.ndarray, max_d: float) -> tuple:
    r = np.linalg.norm(transform_points(t, p) - q, axis=1)
    inl = r <= max_d
    fitness = float(inl.mean())
    rmse = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else 0.0
    return r, fitness, rmse


def _small_step(t_new: np.ndarray, t_old: np.ndarray, prm: dict) -> bool:
    """True if the pose moved by less than ``step_deg`` and ``step_mm`` in one iteration."""
    d = t_new @ invert(t_old)
    return rotation_angle_deg(d[:3, :3]) < prm.step_deg and bool(
        np.linalg.norm(d[:3, 3]) < prm.step_mm
    )


def _refine_correspondence(p, q, initial, prm, source):
    """Iteratively reweighted Kabsch over vertex-to-vertex correspondences."""
    t = initial
    r, fitness, rmse = _residual_stats(p, q, t, prm.max_correspondence_mm)
    converged = False
    it = 0
    for it in range(1, prm.max_iterations + 1):  # noqa: B007 (it is reported)
        inl = r <= prm.max_correspondence_mm
        # First pass plain least squares on the inliers: robust weights need a decent pose.
        w = (
            inl.astype(float)
            if it == 1
            else inl * kernel_weights(r, prm.robust_kernel, prm.kernel_k_mm)
        )
        if np.count_nonzero(w) < 3:
            break
        t_old, t = t, kabsch(p, q, w, source=source)
        r, f_new, rmse_new = _residual_stats(p, q, t, prm.max_correspondence_mm)
        done = (
            abs(f_new - fitness) < prm.relative_fitness and abs(rmse_new - rmse) < prm.relative_rmse
        ) or (it > 1 and _small_step(t, t_old, prm))
        fitness, rmse = f_new, rmse_new
        if done:
            converged = True
            break
    return t, fitness, rmse, it, converged


def _refine_icp(p, q, q_normals, initial, prm, k_start=None):
    """Point-to-plane ICP (:class:`~scan2morph.align.point_plane.PointToPlane`: open3d's step
    against one k-d tree), one iteration at a time to report iterations.

    The kernel scale halves from ``k_start`` (default ``max_correspondence_mm``) to
    ``kernel_k_mm``.
    """
    surface = PointToPlane(q, q_normals, prm.max_correspondence_mm)
    k_final = prm.kernel_k_mm
    k = max(prm.max_correspondence_mm if k_start is None else k_start, k_final)
    t = np.array(initial, dtype=np.float64)
    pairs = surface.at(p, t)
    converged = False
    it = 0
    for it in range(1, prm.max_iterations + 1):  # noqa: B007 (it is reported)
        if pairs.fitness == 0.0:
            break
        t_old, t = t, surface.step(pairs, prm.robust_kernel, k, t)
        old, pairs = pairs, surface.at(p, t)
        done = k == k_final and (
            (
                abs(pairs.fitness - old.fitness) < prm.relative_fitness
                and abs(pairs.rmse - old.rmse) < prm.relative_rmse
            )
            or _small_step(t, t_old, prm)
        )
        k = max(k / 2.0, k_final)
        if done:
            converged = True
            break
    return t, float(pairs.fitness), float(pairs.rmse), it, converged


def _initial_pose(
    src: np.ndarray,
    sv: np.ndarray,
    dst: np.ndarray,
    dv: np.ndarray,
    pairs: np.ndarray,
    region: np.ndarray,
    source: str,
) -> tuple[np.ndarray, str | None]:
    """The initial pose from the point pairs measured in both meshes.

    A pair vertex that one mesh lacks (a squinting eye corner, a hole at low resolution) is
    left out when at least 3 non-collinear pairs remain; with fewer, the pose comes from
    every ICP-region vertex valid in both meshes (the meshes are in template correspondence,
    so vertex i of one is vertex i of the other). Both come with a note for ``recovery``.

    Parameters
    ----------
    src, dst : (V, 3) float
        The take's and the neutral mesh, mm.
    sv, dv : (V,) bool
        Their valid vertices.
    pairs : (n,) int
        Template vertex indices of the point pairs.
    region : (V,) bool
        The ICP region.
    source : str
        ``subject/take`` for errors.

    Returns
    -------
    pose : (4, 4) float64
        Take frame to neutral frame.
    note : str or None
        What was done instead of the configured pairs (None: all of them were used).

    Raises
    ------
    InputError
        Neither 3 usable pairs nor 3 region vertices valid in both meshes.
    """
    missing = []
    for mask, which in ((sv, "the take's mesh"), (dv, "the neutral mesh")):
        missing += [f"{int(i)} ({which})" for i in pairs[~mask[pairs]]]
    usable = pairs[sv[pairs] & dv[pairs]]
    if not missing:
        return kabsch(src[pairs], dst[pairs], source=source), None
    if usable.size >= 3:
        try:
            pose = kabsch(src[usable], dst[usable], source=source)
        except InputError:
            pass
        else:
            note = (
                f"initial pose from {usable.size} of {pairs.size} point pairs "
                f"(pair vertex {', '.join(missing)} invalid)"
            )
            return pose, note
    both = np.flatnonzero(region & sv & dv)
    if both.size < 3:
        raise InputError(
            source,
            f"pair_indices: pair vertex {', '.join(missing)} invalid, and only {both.size} "
            "ICP-region vertices are valid in both meshes; expected 3 pairs or 3 region "
            "vertices measured in both meshes",
        )
    note = (
        f"initial pose from the {both.size} ICP-region vertices valid in both meshes (only "
        f"{usable.size} of {pairs.size} point pairs usable: pair vertex {', '.join(missing)} "
        "invalid)"
    )
    return kabsch(src[both], dst[both], source=source), note


def align_take(
    meshes: AlignMeshes,
    pair_indices: np.ndarray,
    icp_indices: np.ndarray,
    params: IcpParams | None = None,
    source: str = "subject/take",
    grow_indices: np.ndarray | None = None,
) -> AlignResult:
    """Rigidly align a take's mesh (src) to the neutral mesh (dst).

    Parameters
    ----------
    meshes : AlignMeshes
        The take's mesh (src, in its scanner frame) and the neutral's (dst, neutral frame), in
        one template topology, with the template's faces.
    pair_indices : (n,) int
        Template vertex indices of the point pairs for the initial pose (the paper uses 6;
        at least 3 non-collinear). Pairs invalid in either mesh are left out; with fewer
        than 3 left the ICP region's vertices valid in both meshes give the initial pose
        (noted in ``recovery``).
    icp_indices : (m,) int
        Template vertex indices of the upper face, which the mouth does not move; the
        refinement uses the valid ones only.
    params : IcpParams, optional
        The ICP settings (default :class:`IcpParams`'s): method, convergence, trimming of the
        region's moving parts, the robust kernel and the quality gate.
    source : str
        ``subject/take`` label for error messages.
    grow_indices : (k,) int, optional
        Template vertex indices the region may grow into (for example the upper face): after
        the first refinement, each trimming round also adds those whose residual, averaged as
        the trimming averages, is within its threshold (skin that did not move in this take)
        and drops those beyond it. A face region only around the forehead and the nose ridge
        constrains the rotation poorly once an expression's moving parts are trimmed; the
        still skin elsewhere (the nose's sides, the cheeks in a viseme, the brows in a smile)
        adds both points and leverage. The quality gate still judges the region alone.

    Returns
    -------
    AlignResult
        ``transform`` maps the take's scanner frame to the neutral frame; ``ok`` is False, with
        the reasons in ``problems``, when the alignment failed its quality gate (not converged
        after recovery, fitness below ``min_fitness``, point-to-plane RMSE above
        :func:`rmse_limit`, less than ``min_inlier_fraction`` of the region kept); the measured
        noise and the limit used are in the result.

    Raises
    ------
    InputError
        Bad shapes, indices or params, too few valid upper-face vertices.
    """
    prm = icp_settings(params, source)
    src, sv = check_mesh(meshes.src_vertices, meshes.src_valid, "src", source)
    dst, dv = check_mesh(meshes.dst_vertices, meshes.dst_valid, "dst", source, src.shape[0])
    faces = _check_faces(meshes.faces, src.shape[0], source)
    pairs, upper, cand = _vertex_sets(src.shape[0], pair_indices, icp_indices, grow_indices, source)
    initial, note = _initial_pose(src, sv, dst, dv, pairs, upper, source)
    recovery = [note] if note else []
    s = _icp_problem((src, sv), (dst, dv, faces), upper, cand, prm.method, source)
    s = replace(s, gains=noise_gains(meshes, source))
    known = s.expected if np.isfinite(s.expected) else 0.0
    prm = replace(prm, kernel_k_mm=max(prm.kernel_k_mm, prm.kernel_noise_sigmas * known))

    def refine(keep, start, prm_=prm, k_start=None):
        if prm.method == "icp":
            return _refine_icp(s.p[keep], s.q, s.q_normals, start, prm_, k_start)
        return _refine_correspondence(s.p[keep], s.q[keep], start, prm_, source)

    keep = s.in_region.copy()
    t, _, _, iterations, conv = refine(keep, initial)
    keep, t, conv, n_it, notes = trim_moving(s.p, keep, t, conv, refine, s.plane, prm, ~s.in_region)
    recovery += notes
    iterations += n_it
    if prm.still_groups and np.isfinite(t).all():
        keep, t, conv, n_it, notes = _found_still(s, (keep, t, conv), refine, prm)
        recovery += notes
        iterations += n_it
    if not conv:
        t, conv, n_it = _recover(refine, keep, t, initial, prm, recovery)
        iterations += n_it
    if not np.isfinite(t).all():
        t = initial
        recovery.append("non-finite pose: fell back to the point-pair pose")
    return _judged(s, t, initial, keep, (conv, iterations), recovery, prm)


@dataclass(frozen=True)
class _IcpProblem:
    """The points of one take's alignment: the take's candidate vertices ``p`` (n, 3), mm (the
    region's and those it may grow into: ``in_region`` (n,) bool), their template indices
    ``p_idx``; the neutral's ``q`` (m, 3), ``q_normals`` and ``q_idx``; the measured noise of
    both regions as their roughness reads it and the RMSE they explain (``expected``, which
    sets the robust kernel's scale), mm; ``gains``, how many times each side's noise exceeds
    that reading (the gate's expected RMSE: :attr:`AlignMeshes.src_noise_gain`); ``plane``, the
    signed distance of points to the neutral's surface, mm."""

    p_idx: np.ndarray
    q_idx: np.ndarray
    in_region: np.ndarray
    p: np.ndarray
    q: np.ndarray
    q_normals: np.ndarray
    noise_take: float
    noise_neutral: float
    expected: float
    plane: Callable[[np.ndarray], np.ndarray]
    gains: tuple[float, float] = (1.0, 1.0)


def _check_faces(faces, n_v: int, source: str) -> np.ndarray:
    """``faces`` as an (F, 3) integer array indexing ``n_v`` vertices."""
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise InputError(source, f"faces: expected (F, 3) integer array, got {f.dtype} {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= n_v):
        raise InputError(source, f"faces: vertex index out of range [0, {n_v})")
    return f


def _vertex_sets(n_v: int, pair_indices, icp_indices, grow_indices, source: str) -> tuple:
    """Checked ``(pairs (n,) int64, region (V,) bool, candidates (V,) bool)`` of ``n_v``
    vertices: the point pairs, the ICP region and the region with what it may grow into."""
    pairs = check_indices(pair_indices, n_v, "pair_indices", source)
    if pairs.size < 3:
        raise InputError(source, f"pair_indices: expected at least 3 point pairs, got {pairs.size}")
    upper = np.zeros(n_v, dtype=bool)
    upper[check_indices(icp_indices, n_v, "icp_indices", source)] = True
    cand = upper.copy()  # the region and what it may grow into
    if grow_indices is not None:
        cand[check_indices(grow_indices, n_v, "grow_indices", source)] = True
    return pairs, upper, cand


def _icp_problem(take, neutral, upper, cand, method: str, source: str) -> _IcpProblem:
    """The points ICP aligns: ``take`` is ``(vertices (V, 3), valid (V,))``, ``neutral``
    ``(vertices, valid, faces)``; ``upper`` (V,) the region, ``cand`` (V,) it and what it may
    grow into. ``method`` "icp" takes every valid candidate of each mesh (the neutral's with a
    normal), "correspondence" the candidates valid in both."""
    (src, sv), (dst, dv, faces) = take, neutral
    normals = vertex_normals(dst, faces)
    target = cand & dv & np.isfinite(normals).all(axis=1)
    if method == "icp":
        p_idx, q_idx = np.flatnonzero(cand & sv), np.flatnonzero(target)
    else:
        p_idx = q_idx = np.flatnonzero(cand & sv & dv)
    if p_idx.size < 3 or q_idx.size < 3:
        raise InputError(
            source,
            f"icp_indices: only {min(p_idx.size, q_idx.size)} upper-face vertices are valid; "
            "expected at least 3",
        )
    in_region = upper[p_idx]
    r_p, r_q = p_idx[in_region], q_idx[upper[q_idx]]
    noise_take = mesh_noise(src, sv, at=r_p, source=source).region(r_p)
    noise_neutral = mesh_noise(dst, dv, at=r_q, source=source).region(r_q)
    return _IcpProblem(
        p_idx=p_idx,
        q_idx=q_idx,
        in_region=in_region,
        p=src[p_idx],
        q=dst[q_idx],
        q_normals=normals[q_idx],
        noise_take=noise_take,
        noise_neutral=noise_neutral,
        expected=float(np.hypot(noise_take, noise_neutral)),
        plane=SampledSurface(dst[target], normals[target], source).plane,
    )


def _found_still(s: _IcpProblem, trimmed: tuple, refine, prm) -> tuple:
    """The still skin among all the candidates (:func:`~scan2morph.align.still.still_skin`,
    from the region's trimmed ``(keep, t, converged)``), refined on, then trimmed with every
    candidate free to join or leave: ``(keep, t, converged, iterations, notes)`` as
    :func:`~scan2morph.align.trim.trim_moving` returns them. When no set of patches gives a
    pose, or no candidate agrees with the best one (the whole region moved), the region's
    trimmed pose is kept (and the RMSE gate judges it)."""
    keep, t, conv = trimmed
    found = still_skin(s.p, t, refine, s.plane, prm)
    if len(found.agree) == 0 or not found.keep.any():
        why = "no set of patches gave a pose" if len(found.agree) == 0 else "no skin agrees"
        note = f"still skin: {why}; the region's trimmed pose is kept"
        return keep, t, conv, found.iterations, [*found.notes, note]
    t_new, _, _, iterations, conv = refine(found.keep, found.transform)
    t = t_new if np.isfinite(t_new).all() else found.transform
    every = np.ones(len(s.p), dtype=bool)
    keep, t, conv, n_it, notes = trim_moving(s.p, found.keep, t, conv, refine, s.plane, prm, every)
    return keep, t, conv, found.iterations + iterations + n_it, found.notes + notes


def _recover(refine, keep, t, initial, prm, recovery) -> tuple:
    """A refinement that did not converge, tried again: re-initialised on the kept region from
    the point pairs' pose ``initial``, then (ICP with a robust kernel) resumed with a convex
    Huber kernel. Appends what was tried to ``recovery``; returns ``(t, converged,
    iterations)``."""
    attempts = [("re-initialised from the point pairs", initial, prm, None)]
    if prm.method == "icp" and prm.robust_kernel != "none":
        huber = replace(prm, robust_kernel="huber")
        attempts.append(("resumed with a Huber kernel", None, huber, prm.kernel_k_mm))
    iterations, conv = 0, False
    for what, start, prm_, k_start in attempts:
        t_new, _, _, n_it, conv = refine(keep, t if start is None else start, prm_, k_start)
        iterations += n_it
        recovery.append(f"not converged: {what} ({'converged' if conv else 'not converged'})")
        if np.isfinite(t_new).all():
            t = t_new
        if conv:
            break
    return t, conv, iterations


def _judged(s: _IcpProblem, t, initial, keep, run: tuple, recovery, prm) -> AlignResult:
    """The result of an alignment at its final pose ``t``, with the quality gate's verdict;
    ``run`` is ``(converged, iterations)`` of the refinements."""
    conv, iterations = run
    in_region = s.in_region
    # with the still skin searched for, the kept share is of every candidate (the region may
    # have moved), the RMSE still of the region's kept vertices (of every kept one if the
    # region kept fewer than 6)
    share = np.ones_like(in_region) if prm.still_groups else in_region
    judge = in_region if np.count_nonzero(keep & in_region) >= 6 else share
    if prm.method == "icp":
        final = PointToPlane(s.q, s.q_normals, prm.max_correspondence_mm).at(s.p[in_region], t)
        fitness, rmse = final.fitness, final.rmse
    else:
        _, fitness, rmse = _residual_stats(
            s.p[in_region], s.q[in_region], t, prm.max_correspondence_mm
        )
    judged = s.p[keep & judge]  # the region's kept vertices (grown ones are still by choice)
    noise_take, noise_neutral = s.noise_take * s.gains[0], s.noise_neutral * s.gains[1]
    gate = residual_gate(s.plane(transform_points(t, judged)), noise_take, noise_neutral, prm)
    kept = float(keep[share].mean())
    problems = _verdict(conv, iterations, fitness, kept, recovery, prm)
    problems += [gate.problem] if gate.problem else []
    return AlignResult(
        transform=t,
        initial=initial,
        fitness=float(fitness),
        inlier_rmse=float(rmse),
        iterations=int(iterations),
        converged=bool(conv),
        method=prm.method,
        n_points=int(s.p_idx.size),
        residual_rmse=gate.residual_rmse,
        inlier_fraction=kept,
        ok=not problems,
        problems=problems,
        recovery=recovery,
        noise_take=noise_take,
        noise_neutral=noise_neutral,
        expected_rmse=float(np.hypot(noise_take, noise_neutral)),
        rmse_limit=gate.limit,
        rmse_limit_kind=gate.kind,
        kernel_k=prm.kernel_k_mm,
        kept_indices=s.p_idx[keep].astype(np.int64),
    )


def _verdict(conv, iterations, fitness, kept, recovery, prm) -> list[str]:
    """The problems of an alignment against its quality gate; empty when it passed."""
    problems = []
    if not conv:
        tried = "; ".join(r for r in recovery if r.startswith("not converged")) or "none"
        problems.append(f"ICP did not converge ({iterations} iterations; recovery tried: {tried})")
    if fitness < prm.min_fitness:
        problems.append(
            f"fitness {fitness:.3f} < min_fitness {prm.min_fitness:.3f} (share of the "
            f"region within max_correspondence_mm={prm.max_correspondence_mm:g} of the "
            "neutral mesh): check the point pairs and that the take shows the same subject"
        )
    if kept < prm.min_inlier_fraction:
        problems.append(
            f"only {100 * kept:.0f}% of the region kept (min_inlier_fraction "
            f"{prm.min_inlier_fraction:g}): the stable region itself moved"
        )
    return problems


# The names below moved to modules of their own (settings, result, gate, region, surface); they
# stay importable from here.
__all__ = [
    "AlignMeshes",
    "IcpParams",
    "AlignResult",
    "RmseGate",
    "align_take",
    "region_motion",
    "SampledSurface",
    "rmse_gate",
    "rmse_limit",
    "vertex_normals",
]
