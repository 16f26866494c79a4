"""Rigid alignment of a take's mesh to the subject's neutral mesh (Yano-Harada, Sec. 4.1).

The initial pose comes from six user-chosen point pairs (the same template vertices in both
meshes, placed where the mouth does not move them); it is refined by ICP over the upper face
only, so that the moving mouth does not bias the fit.

Two refinements are offered (``params["method"]``):

``"icp"`` (the paper's, default)
    open3d point-to-plane ICP with a robust kernel: closest points, target normals are the
    neutral mesh's vertex normals. The kernel's scale starts at ``max_correspondence_mm`` and
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
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from scan2morph.align.noise import mesh_noise
from scan2morph.align.rigid import invert, kabsch, rotation_angle_deg, transform_points
from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals

#: Default ICP parameters (mm where a unit applies). ``relative_fitness`` / ``relative_rmse``
#: stop the iteration when both the fitness and the inlier RMSE change by less than that
#: between iterations (open3d's criterion: absolute changes, despite the name); so does a pose
#: step below ``step_deg`` and ``step_mm``. ``trim_*``: trimming of the region's moving parts
#: (``trim_rounds`` 0: off). ``kernel_k_mm`` is the kernel's least final scale; it is widened to
#: ``kernel_noise_sigmas`` times the expected RMSE of the measured noise. ``min_fitness``,
#: ``max_rmse_ratio`` (times the expected RMSE; ``max_rmse_mm``, if not None, is an absolute
#: limit instead) and ``min_inlier_fraction`` are the quality gate of :attr:`AlignResult.ok`.
DEFAULT_ICP: dict[str, Any] = {
    "method": "icp",
    "max_correspondence_mm": 10.0,
    "max_iterations": 50,
    "robust_kernel": "tukey",
    "kernel_k_mm": 3.0,
    "kernel_noise_sigmas": 3.0,
    "min_fitness": 0.5,
    "relative_fitness": 1e-6,
    "relative_rmse": 1e-6,
    "step_deg": 0.01,
    "step_mm": 0.01,
    "trim_rounds": 6,
    "trim_radius_mm": 8.0,
    "trim_sigma": 3.0,
    "max_rmse_ratio": 3.0,
    "max_rmse_mm": None,
    "min_inlier_fraction": 0.3,
}

#: Averaged residuals below this never count as motion, mm (a floor to the robust threshold).
_TRIM_FLOOR_MM = 0.05

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

#: The relative RMSE limit is never below this, mm: on noise-free meshes the expected RMSE is
#: zero, but the template's vertices of two takes sample the skin at different points and the
#: point-to-plane residual of curved skin is not (0.02-0.05 mm on the synthetic faces).
_RMSE_FLOOR_MM = 0.1

_METHODS = ("icp", "correspondence")
_KERNELS = ("tukey", "huber", "none")


@dataclass(frozen=True)
class AlignResult:
    """Result of :func:`align_take`.

    Attributes
    ----------
    transform : (4, 4) float64
        Take scanner frame -> neutral frame (``p_neutral = transform @ [p_take, 1]``).
    initial : (4, 4) float64
        The initial pose from the point pairs alone.
    fitness : float
        Fraction of the upper-face source vertices with a correspondence within
        ``max_correspondence_mm`` at the final pose, in [0, 1].
    inlier_rmse : float
        RMS residual of those correspondences, mm (point-to-point distance).
    iterations : int
        Iterations run.
    converged : bool
        True if the final refinement met its stopping criterion before ``max_iterations``
        (after any recovery).
    method : str
        ``"icp"`` or ``"correspondence"``.
    n_points : int
        Number of upper-face source vertices used.
    residual_rmse : float
        RMS point-to-plane distance of the kept region vertices to the neutral mesh at the
        final pose, mm (the scan noise when the alignment is right; gated by ``rmse_limit``).
    inlier_fraction : float
        Share of the region's vertices kept after trimming its moving parts, in [0, 1]
        (gated by ``min_inlier_fraction``).
    ok : bool
        The alignment passed its quality gate: ``problems`` is empty.
    problems : list of str
        Why it did not (not converged after recovery, fitness, RMSE, too little of the region
        kept); empty when ``ok``.
    recovery : list of str
        What was done beyond the plain refinement: trimming, re-initialisation, kernel change.
    noise_take, noise_neutral : float
        Measurement noise of the take's and the neutral's ICP region, mm (standard deviation,
        estimated from each mesh's roughness; NaN if too few vertices).
    expected_rmse : float
        ``sqrt(noise_take^2 + noise_neutral^2)``: the point-to-plane RMSE of a right
        alignment, mm.
    rmse_limit : float
        The RMSE gate used, mm: ``max_rmse_ratio * expected_rmse`` (at least 0.1 mm), or
        ``max_rmse_mm`` when set.
    rmse_limit_kind : str
        ``"relative"`` or ``"absolute"`` (``max_rmse_mm`` set).
    kernel_k : float
        Final scale of the robust kernel used, mm (``kernel_k_mm`` widened to
        ``kernel_noise_sigmas * expected_rmse``).
    kept_indices : (k,) int64
        Template vertex indices of the take the final refinement used: the region's kept
        vertices and the still ones it grew into.
    constraint : float
        :func:`region_motion` only: how well the region's shape pins its motion, the RMS
        point-to-plane change per mm of the motion it constrains least (0 for a plane, 1 for
        a motion straight along every normal).
    """

    transform: np.ndarray
    initial: np.ndarray
    fitness: float
    inlier_rmse: float
    iterations: int
    converged: bool
    method: str = "icp"
    n_points: int = 0
    residual_rmse: float = 0.0
    inlier_fraction: float = 1.0
    ok: bool = True
    problems: list[str] = field(default_factory=list)
    recovery: list[str] = field(default_factory=list)
    noise_take: float = float("nan")
    noise_neutral: float = float("nan")
    expected_rmse: float = float("nan")
    rmse_limit: float = float("nan")
    rmse_limit_kind: str = "relative"
    kernel_k: float = float("nan")
    kept_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    constraint: float = float("nan")


def _params(params: dict[str, Any] | None, source: str) -> dict[str, Any]:
    p = dict(DEFAULT_ICP)
    if params:
        unknown = sorted(set(params) - set(DEFAULT_ICP))
        if unknown:
            raise InputError(
                source, f"icp params: unknown key(s) {unknown}; expected {sorted(DEFAULT_ICP)}"
            )
        p.update(params)
    if p["method"] not in _METHODS:
        raise InputError(
            source, f"icp params: method must be one of {_METHODS}, got {p['method']!r}"
        )
    if p["robust_kernel"] not in _KERNELS:
        raise InputError(
            source,
            f"icp params: robust_kernel must be one of {_KERNELS}, got {p['robust_kernel']!r}",
        )
    for key in (
        "max_correspondence_mm",
        "kernel_k_mm",
        "trim_radius_mm",
        "trim_sigma",
        "max_rmse_ratio",
        "kernel_noise_sigmas",
    ):
        v = float(p[key])
        if not (np.isfinite(v) and v > 0):
            raise InputError(source, f"icp params: {key} must be a positive number, got {p[key]!r}")
        p[key] = v
    if p["max_rmse_mm"] is not None:
        v = p["max_rmse_mm"]
        if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v > 0):
            raise InputError(
                source, f"icp params: max_rmse_mm must be a positive number or None, got {v!r}"
            )
        p["max_rmse_mm"] = float(v)
    for key in ("relative_fitness", "relative_rmse", "step_deg", "step_mm"):
        v = float(p[key])
        if not (np.isfinite(v) and v >= 0):
            raise InputError(source, f"icp params: {key} must be >= 0, got {p[key]!r}")
        p[key] = v
    for key in ("min_fitness", "min_inlier_fraction"):
        v = float(p[key])
        if not 0.0 <= v <= 1.0:
            raise InputError(source, f"icp params: {key} must be in [0, 1], got {p[key]!r}")
        p[key] = v
    for key, least in (("max_iterations", 1), ("trim_rounds", 0)):
        it = p[key]
        if isinstance(it, bool) or int(it) != it or it < least:
            raise InputError(source, f"icp params: {key} must be an integer >= {least}, got {it!r}")
        p[key] = int(it)
    return p


def _indices(idx: np.ndarray, n_vertices: int, name: str, source: str) -> np.ndarray:
    a = np.asarray(idx)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise InputError(source, f"{name}: expected a 1-D integer array, got {a.dtype} {a.shape}")
    bad = (a < 0) | (a >= n_vertices)
    if bad.any():
        raise InputError(
            source, f"{name}: vertex index {int(a[bad][0])} out of range [0, {n_vertices})"
        )
    return a.astype(np.int64)


def _mesh(vertices, valid, name: str, source: str, n_vertices: int | None = None) -> tuple:
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(source, f"{name}_vertices: expected (V, 3), got {v.shape}")
    if n_vertices is not None and v.shape[0] != n_vertices:
        raise InputError(
            source,
            f"{name}_vertices: expected {n_vertices} vertices (the take's template), "
            f"got {v.shape[0]}",
        )
    m = np.asarray(valid)
    if m.shape != (v.shape[0],) or m.dtype != np.bool_:
        raise InputError(
            source, f"{name}_valid: expected ({v.shape[0]},) bool, got {m.dtype} {m.shape}"
        )
    bad = m & ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise InputError(
            source,
            f"{name}_vertices: vertex {int(np.flatnonzero(bad)[0])} is marked valid "
            "but has non-finite coordinates",
        )
    return v, m


def _kernel_weights(r: np.ndarray, kernel: str, k: float) -> np.ndarray:
    if kernel == "tukey":
        return np.where(r <= k, (1.0 - (r / k) ** 2) ** 2, 0.0)
    if kernel == "huber":
        return np.where(r <= k, 1.0, k / np.maximum(r, k))
    return np.ones_like(r)


def _residual_stats(p: np.ndarray, q: np.ndarray, t: np.ndarray, max_d: float) -> tuple:
    r = np.linalg.norm(transform_points(t, p) - q, axis=1)
    inl = r <= max_d
    fitness = float(inl.mean())
    rmse = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else 0.0
    return r, fitness, rmse


def _small_step(t_new: np.ndarray, t_old: np.ndarray, prm: dict) -> bool:
    """True if the pose moved by less than ``step_deg`` and ``step_mm`` in one iteration."""
    d = t_new @ invert(t_old)
    return rotation_angle_deg(d[:3, :3]) < prm["step_deg"] and bool(
        np.linalg.norm(d[:3, 3]) < prm["step_mm"]
    )


def _refine_correspondence(p, q, initial, prm, source):
    """Iteratively reweighted Kabsch over vertex-to-vertex correspondences."""
    t = initial
    r, fitness, rmse = _residual_stats(p, q, t, prm["max_correspondence_mm"])
    converged = False
    it = 0
    for it in range(1, prm["max_iterations"] + 1):  # noqa: B007 (it is reported)
        inl = r <= prm["max_correspondence_mm"]
        # First pass plain least squares on the inliers: robust weights need a decent pose.
        w = (
            inl.astype(float)
            if it == 1
            else inl * _kernel_weights(r, prm["robust_kernel"], prm["kernel_k_mm"])
        )
        if np.count_nonzero(w) < 3:
            break
        t_old, t = t, kabsch(p, q, w, source=source)
        r, f_new, rmse_new = _residual_stats(p, q, t, prm["max_correspondence_mm"])
        done = (
            abs(f_new - fitness) < prm["relative_fitness"]
            and abs(rmse_new - rmse) < prm["relative_rmse"]
        ) or (it > 1 and _small_step(t, t_old, prm))
        fitness, rmse = f_new, rmse_new
        if done:
            converged = True
            break
    return t, fitness, rmse, it, converged


def _refine_icp(p, q, q_normals, initial, prm, k_start=None):
    """open3d point-to-plane ICP, stepped one iteration at a time to report iterations.

    The kernel scale halves from ``k_start`` (default ``max_correspondence_mm``) to
    ``kernel_k_mm``.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(q))
    tgt.normals = o3d.utility.Vector3dVector(q_normals)
    k_final = prm["kernel_k_mm"]
    k = max(prm["max_correspondence_mm"] if k_start is None else k_start, k_final)
    loss = {"tukey": reg.TukeyLoss, "huber": reg.HuberLoss}.get(prm["robust_kernel"])
    one_step = reg.ICPConvergenceCriteria(relative_fitness=0.0, relative_rmse=0.0, max_iteration=1)
    max_d = prm["max_correspondence_mm"]
    t = np.array(initial)
    prev = reg.evaluate_registration(src, tgt, max_d, t)
    fitness, rmse = prev.fitness, prev.inlier_rmse
    converged = False
    it = 0
    for it in range(1, prm["max_iterations"] + 1):  # noqa: B007 (it is reported)
        if fitness == 0.0:
            break
        est = reg.TransformationEstimationPointToPlane(loss(k) if loss else reg.L2Loss())
        res = reg.registration_icp(src, tgt, max_d, t, est, one_step)
        t_old, t = t, np.asarray(res.transformation)
        done = k == k_final and (
            (
                abs(res.fitness - fitness) < prm["relative_fitness"]
                and abs(res.inlier_rmse - rmse) < prm["relative_rmse"]
            )
            or _small_step(t, t_old, prm)
        )
        k = max(k / 2.0, k_final)
        fitness, rmse = res.fitness, res.inlier_rmse
        if done:
            converged = True
            break
    return t, float(fitness), float(rmse), it, converged


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
    src_vertices: np.ndarray,
    src_valid: np.ndarray,
    dst_vertices: np.ndarray,
    dst_valid: np.ndarray,
    faces: np.ndarray,
    pair_indices: np.ndarray,
    icp_indices: np.ndarray,
    params: dict[str, Any] | None = None,
    source: str = "subject/take",
    grow_indices: np.ndarray | None = None,
) -> AlignResult:
    """Rigidly align a take's mesh (src) to the neutral mesh (dst).

    Parameters
    ----------
    src_vertices : (V, 3) float, mm
        The take's mesh in its scanner frame; NaN where invalid.
    src_valid : (V,) bool
        Valid vertices of the take's mesh.
    dst_vertices : (V, 3) float, mm
        The neutral mesh (neutral frame), same template topology.
    dst_valid : (V,) bool
        Valid vertices of the neutral mesh.
    faces : (F, 3) int
        Template faces (used for the target's vertex normals).
    pair_indices : (n,) int
        Template vertex indices of the point pairs for the initial pose (the paper uses 6;
        at least 3 non-collinear). Pairs invalid in either mesh are left out; with fewer
        than 3 left the ICP region's vertices valid in both meshes give the initial pose
        (noted in ``recovery``).
    icp_indices : (m,) int
        Template vertex indices of the upper face, which the mouth does not move; the
        refinement uses the valid ones only.
    params : dict, optional
        Overrides of :data:`DEFAULT_ICP`: ``method`` ('icp' | 'correspondence'),
        ``max_correspondence_mm``, ``max_iterations``, ``robust_kernel``
        ('tukey' | 'huber' | 'none'), ``kernel_k_mm``, ``relative_fitness``, ``relative_rmse``,
        ``step_deg``, ``step_mm`` (convergence); ``trim_rounds``, ``trim_radius_mm``,
        ``trim_sigma`` (trimming the region's moving parts); ``kernel_noise_sigmas`` (the
        kernel's least scale in units of the expected RMSE of the measured noise);
        ``min_fitness``, ``max_rmse_ratio``, ``max_rmse_mm``, ``min_inlier_fraction`` (the
        quality gate).
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
    prm = _params(params, source)
    src, sv = _mesh(src_vertices, src_valid, "src", source)
    n_v = src.shape[0]
    dst, dv = _mesh(dst_vertices, dst_valid, "dst", source, n_v)
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise InputError(source, f"faces: expected (F, 3) integer array, got {f.dtype} {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= n_v):
        raise InputError(source, f"faces: vertex index out of range [0, {n_v})")
    pairs = _indices(pair_indices, n_v, "pair_indices", source)
    if pairs.size < 3:
        raise InputError(source, f"pair_indices: expected at least 3 point pairs, got {pairs.size}")
    upper = np.zeros(n_v, dtype=bool)
    upper[_indices(icp_indices, n_v, "icp_indices", source)] = True
    cand = upper.copy()  # the region and what it may grow into
    if grow_indices is not None:
        cand[_indices(grow_indices, n_v, "grow_indices", source)] = True
    initial, note = _initial_pose(src, sv, dst, dv, pairs, upper, source)
    recovery = [note] if note else []
    normals = vertex_normals(dst, f)
    if prm["method"] == "icp":
        p_idx = np.flatnonzero(cand & sv)
        q_idx = np.flatnonzero(cand & dv & np.isfinite(normals).all(axis=1))
    else:
        p_idx = q_idx = np.flatnonzero(cand & sv & dv)
    in_region = upper[p_idx]
    if p_idx.size < 3 or q_idx.size < 3:
        raise InputError(
            source,
            f"icp_indices: only {min(p_idx.size, q_idx.size)} upper-face vertices are valid; "
            "expected at least 3",
        )
    p, q = src[p_idx], dst[q_idx]
    r_p, r_q = p_idx[in_region], q_idx[upper[q_idx]]
    noise_take = mesh_noise(src, sv, at=r_p, source=source).region(r_p)
    noise_neutral = mesh_noise(dst, dv, at=r_q, source=source).region(r_q)
    expected = float(np.hypot(noise_take, noise_neutral))
    known = expected if np.isfinite(expected) else 0.0
    prm = prm | {"kernel_k_mm": max(prm["kernel_k_mm"], prm["kernel_noise_sigmas"] * known)}
    plane_region = cand & dv & np.isfinite(normals).all(axis=1)
    plane = SampledSurface(dst[plane_region], normals[plane_region], source).plane

    def refine(keep, start, prm_=prm, k_start=None):
        if prm["method"] == "icp":
            return _refine_icp(p[keep], q, normals[q_idx], start, prm_, k_start)
        return _refine_correspondence(p[keep], q[keep], start, prm_, source)

    keep = in_region.copy()
    t, fitness, rmse, iterations, conv = refine(keep, initial)
    keep, t, conv, n_it = _trim(p, keep, t, conv, refine, plane, prm, recovery, ~in_region)
    iterations += n_it
    if not conv:
        # re-initialise on the kept region from the point pairs, then a convex kernel
        attempts = [("re-initialised from the point pairs", initial, prm, None)]
        if prm["method"] == "icp" and prm["robust_kernel"] != "none":
            huber = prm | {"robust_kernel": "huber"}
            attempts.append(("resumed with a Huber kernel", None, huber, prm["kernel_k_mm"]))
        for what, start, prm_, k_start in attempts:
            t_new, _, _, n_it, conv = refine(keep, t if start is None else start, prm_, k_start)
            iterations += n_it
            recovery.append(f"not converged: {what} ({'converged' if conv else 'not converged'})")
            if np.isfinite(t_new).all():
                t = t_new
            if conv:
                break
    if not np.isfinite(t).all():
        t = initial
        recovery.append("non-finite pose: fell back to the point-pair pose")
    if prm["method"] == "icp":
        fitness, rmse = _nearest_stats(p[in_region], q, t, prm["max_correspondence_mm"])
    else:
        _, fitness, rmse = _residual_stats(
            p[in_region], q[in_region], t, prm["max_correspondence_mm"]
        )
    judged = p[keep & in_region]  # the region's kept vertices (grown ones are still by choice)
    gate = _rmse_gate(plane(transform_points(t, judged)), noise_take, noise_neutral, prm)
    kept = float(keep[in_region].mean())
    problems = _verdict(conv, iterations, fitness, kept, recovery, prm)
    problems += [gate.problem] if gate.problem else []
    return AlignResult(
        transform=t,
        initial=initial,
        fitness=float(fitness),
        inlier_rmse=float(rmse),
        iterations=int(iterations),
        converged=bool(conv),
        method=prm["method"],
        n_points=int(p_idx.size),
        residual_rmse=gate.residual_rmse,
        inlier_fraction=kept,
        ok=not problems,
        problems=problems,
        recovery=recovery,
        noise_take=noise_take,
        noise_neutral=noise_neutral,
        expected_rmse=expected,
        rmse_limit=gate.limit,
        rmse_limit_kind=gate.kind,
        kernel_k=prm["kernel_k_mm"],
        kept_indices=p_idx[keep].astype(np.int64),
    )


@dataclass(frozen=True)
class RmseGate:
    """The RMSE gate of an alignment (:func:`rmse_gate`).

    Attributes
    ----------
    residual_rmse : float
        RMS point-to-plane distance of the region's take vertices to the neutral mesh, mm.
    noise_take, noise_neutral : float
        Measured noise of the take's and the neutral's region, mm.
    limit : float
        The limit used, mm (:func:`rmse_limit`).
    kind : str
        ``"relative"`` or ``"absolute"``.
    problem : str or None
        Why the gate failed (naming the RMSE, the measured noise and the limit); None if passed.
    kept : float
        Share of the region judged (the rest left out as moved, as :func:`align_take` trims).
    """

    residual_rmse: float
    noise_take: float
    noise_neutral: float
    limit: float
    kind: str
    problem: str | None
    kept: float = 1.0


def rmse_gate(
    src_vertices: np.ndarray,
    src_valid: np.ndarray,
    dst_vertices: np.ndarray,
    dst_valid: np.ndarray,
    faces: np.ndarray,
    icp_indices: np.ndarray,
    transform: np.ndarray,
    params: dict[str, Any] | None = None,
    source: str = "subject/take",
) -> RmseGate:
    """Judge a given take -> neutral pose by the RMSE gate :func:`align_take` applies.

    The region's parts that moved are left out as :func:`align_take` trims them (at the given
    pose, which is not refined), and the RMSE of the rest is compared with :func:`rmse_limit`.

    Parameters
    ----------
    src_vertices, src_valid, dst_vertices, dst_valid, faces, icp_indices
        As :func:`align_take`.
    transform : (4, 4) float
        Take scanner frame -> neutral frame.
    params : dict, optional
        ``max_rmse_ratio``, ``max_rmse_mm``, ``trim_*`` (overrides of :data:`DEFAULT_ICP`).
    source : str
        ``subject/take`` for messages.

    Returns
    -------
    RmseGate
    """
    prm = _params(params, source)
    src, sv = _mesh(src_vertices, src_valid, "src", source)
    dst, dv = _mesh(dst_vertices, dst_valid, "dst", source, src.shape[0])
    region = np.zeros(src.shape[0], dtype=bool)
    region[_indices(icp_indices, src.shape[0], "icp_indices", source)] = True
    normals = vertex_normals(dst, np.asarray(faces))
    target = region & dv & np.isfinite(normals).all(axis=1)
    p_idx = np.flatnonzero(region & sv)
    if p_idx.size < 3 or np.count_nonzero(target) < 3:
        raise InputError(source, "icp_indices: fewer than 3 valid region vertices")
    q_idx = np.flatnonzero(target)
    noise_take = mesh_noise(src, sv, at=p_idx, source=source).region(p_idx)
    noise_neutral = mesh_noise(dst, dv, at=q_idx, source=source).region(q_idx)
    plane = SampledSurface(dst[target], normals[target], source).plane
    p = src[p_idx]
    t = np.asarray(transform, dtype=np.float64)

    def fixed(keep, pose):  # the pose is judged, not refined
        return pose, 0.0, 0.0, 0, True

    keep, *_ = _trim(p, np.ones(len(p), dtype=bool), t, True, fixed, plane, prm, [])
    gate = _rmse_gate(plane(transform_points(t, p[keep])), noise_take, noise_neutral, prm)
    return replace(gate, kept=float(keep.mean()))


def _rmse_gate(residuals, noise_take, noise_neutral, prm) -> RmseGate:
    rmse = float(np.sqrt(np.mean(residuals**2))) if residuals.size else float("inf")
    limit, kind = rmse_limit(noise_take, noise_neutral, prm)
    problem = _rmse_verdict(rmse, limit, kind, noise_take, noise_neutral, prm)
    return RmseGate(rmse, float(noise_take), float(noise_neutral), limit, kind, problem)


def rmse_limit(noise_take: float, noise_neutral: float, params: dict[str, Any]) -> tuple:
    """The point-to-plane RMSE above which an alignment is poor.

    Parameters
    ----------
    noise_take, noise_neutral : float
        Measured noise (standard deviation) of the take's and the neutral's ICP region, mm;
        NaN when unknown (counted as 0).
    params : dict
        ``max_rmse_ratio`` and ``max_rmse_mm`` (None: relative), as in :data:`DEFAULT_ICP`.

    Returns
    -------
    limit : float
        mm: ``max_rmse_mm`` if set, else ``max_rmse_ratio * sqrt(noise_take^2 +
        noise_neutral^2)``, at least :data:`_RMSE_FLOOR_MM`.
    kind : str
        ``"absolute"`` or ``"relative"``.
    """
    if params.get("max_rmse_mm") is not None:
        return float(params["max_rmse_mm"]), "absolute"
    expected = np.hypot(*(x if np.isfinite(x) else 0.0 for x in (noise_take, noise_neutral)))
    return float(max(params["max_rmse_ratio"] * expected, _RMSE_FLOOR_MM)), "relative"


def _nearest_stats(p: np.ndarray, q: np.ndarray, t: np.ndarray, max_d: float) -> tuple:
    """open3d's fitness and inlier RMSE: closest-point distances within ``max_d``."""
    d, _ = cKDTree(q).query(transform_points(t, p))
    inl = d <= max_d
    return float(inl.mean()), float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else 0.0


def _trim(p, keep, t, conv, refine, plane, prm, recovery, grow=None) -> tuple:
    """Leave out the parts of the region that moved, refining again after each change.

    A vertex's residual averaged over its neighbours within ``trim_radius_mm`` (of the take's
    region vertices) separates a patch of moving skin from noise; the vertices whose average
    exceeds ``trim_sigma`` robust standard deviations of the kept ones' (at least
    :data:`_TRIM_FLOOR_MM`) are left out. Stops when the kept set repeats, after
    ``trim_rounds`` rounds, or when fewer than 3 vertices would be kept. Vertices marked
    ``grow`` (candidates outside the region) join the kept set in a round when their average is
    within the threshold and leave it when it is not; the region's vertices, once left out,
    stay out.

    Returns
    -------
    keep : (n,) bool
    t : (4, 4) the pose refined on ``keep``
    converged : bool
        Of the last refinement.
    iterations : int
        Iterations of the refinements run here.
    """
    if prm["trim_rounds"] == 0 or not np.isfinite(t).all():
        return keep, t, conv, 0
    pairs = cKDTree(p).query_pairs(prm["trim_radius_mm"], output_type="ndarray")
    n = len(p)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(n)])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(n)])
    adj = sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    mean = sparse.diags(1.0 / np.asarray(adj.sum(axis=1)).ravel()) @ adj
    grow = np.zeros(n, dtype=bool) if grow is None else grow
    region = ~grow
    iterations, rounds = 0, 0
    for rounds in range(1, prm["trim_rounds"] + 1):  # noqa: B007 (rounds is reported)
        r = mean @ plane(transform_points(t, p))
        rk = r[keep]
        sigma = 1.4826 * np.median(np.abs(rk - np.median(rk)))
        new = (keep | grow) & (np.abs(r) <= max(prm["trim_sigma"] * sigma, _TRIM_FLOOR_MM))
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
        t_new, _, _, n_it, conv = refine(keep, t)
        iterations += n_it
        if not np.isfinite(t_new).all():
            conv = False
            break
        t = t_new
    if not keep[region].all():
        recovery.append(
            f"left out {int((~keep[region]).sum())} of {int(region.sum())} region vertices that "
            f"moved ({rounds} trimming rounds)"
        )
    if grow.any():
        recovery.append(f"added {int(keep[grow].sum())} of {int(grow.sum())} still vertices")
    return keep, t, conv, iterations


class SampledSurface:
    """A surface given by samples with normals (a range image's pixels): point-to-plane
    residuals against the nearest sample, and which points its data covers.

    Parameters
    ----------
    points, normals : (m, 3) float
        Samples, mm, and their unit normals (samples without a finite normal are left out).
    source : str
        Label for error messages.
    edge : (m,) bool, optional
        Samples on the edge of the data (a pixel next to one without data): a point nearest to
        one of them may lie beyond the data, and is not counted as covered.
    """

    def __init__(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        source: str = "surface",
        edge: np.ndarray | None = None,
    ):
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
            raise InputError(
                source,
                f"surface: expected (m, 3) points and normals, got {points.shape}, {normals.shape}",
            )
        edge = np.zeros(len(points), dtype=bool) if edge is None else np.asarray(edge, bool)
        if edge.shape != (len(points),):
            raise InputError(source, f"edge: expected ({len(points)},) bool, got {edge.shape}")
        ok = np.isfinite(points).all(axis=1) & np.isfinite(normals).all(axis=1)
        if not ok.any():
            raise InputError(source, "surface: no sample with a finite point and normal")
        self.points, self.normals, self.edge = points[ok], normals[ok], edge[ok]
        self.tree = cKDTree(self.points)

    def noise(self, x: np.ndarray, source: str = "surface") -> float:
        """The samples' noise where points ``x`` (n, 3) are (:func:`mesh_noise` of the nearest
        samples), mm."""
        near = np.unique(self.tree.query(x)[1])
        every = np.ones(len(self.points), dtype=bool)
        return mesh_noise(self.points, every, at=near, source=source).region(near)

    def reach(self, x: np.ndarray, noise: float) -> float:
        """How far from a sample a point on the surface near ``x`` (n, 3) can be, mm: twice the
        samples' median spacing there plus three times the ``noise`` (mm). A point whose nearest
        sample is farther is off the data (skin the scan did not see)."""
        near = np.unique(self.tree.query(x)[1])
        spacing = float(np.median(self.tree.query(self.points[near], k=2)[0][:, 1]))
        return 2.0 * spacing + 3.0 * float(noise)

    def plane(self, x: np.ndarray) -> np.ndarray:
        """(n,) signed distance of points ``x`` (n, 3) to their nearest sample's tangent plane,
        mm."""
        return self.residuals(x, np.inf)[0]

    def residuals(self, x: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(plane, seen, distance)`` of points ``x`` (n, 3): the signed distance to the nearest
        sample's tangent plane, whether the surface covers the point (that sample is within
        ``reach``, mm, and not on the data's edge, beyond which the point may lie), and the
        distance to that sample."""
        x = np.asarray(x, dtype=np.float64)
        d, j = self.tree.query(x)
        plane = np.einsum("ij,ij->i", x - self.points[j], self.normals[j])
        return plane, (d <= reach) & ~self.edge[j], d


def region_motion(
    region: np.ndarray,
    initial: np.ndarray,
    surface: SampledSurface,
    params: dict[str, Any] | None = None,
    source: str = "subject/take",
) -> AlignResult:
    """The rigid motion of one region of skin onto a surface, with a verdict on its rigidity.

    ICP moves the region's points onto the surface (point-to-plane; each step about the region's
    centroid and damped, so that a direction the region's shape hardly constrains moves
    slowly; the kernel annealed as in :func:`align_take` and never narrower than
    ``kernel_noise_sigmas`` times the RMSE the measured noise explains; points off the surface's
    data left out). Nothing is trimmed: the verdict says whether the *whole* region moved
    rigidly.

    Parameters
    ----------
    region : (n, 3) float, mm
        The region's points (finite), n >= 6.
    initial : (4, 4) float
        The initial pose (for example the least-squares fit of a template correspondence).
    surface : SampledSurface
        The target (a range image's samples, in the region's frame).
    params : dict, optional
        Overrides of :data:`DEFAULT_ICP` (used: ``max_correspondence_mm``, ``max_iterations``,
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
        point-to-plane RMSE there; ``fitness`` the share of the region the surface covers;
        ``noise_take`` and ``noise_neutral`` are the measured noise of the surface and of the
        region; ``ok`` is False, with the reasons in ``problems``, when ICP did not converge,
        the fitness is below ``min_fitness`` or the RMSE is above :func:`rmse_limit` (the
        region did not move rigidly).

    Raises
    ------
    InputError
        Bad shapes or params, fewer than 6 region points.
    """
    prm = _params(params, source)
    p = np.asarray(region, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 6 or not np.isfinite(p).all():
        raise InputError(source, f"region: expected at least 6 finite (n, 3) points, got {p.shape}")
    initial = np.asarray(initial, dtype=np.float64)
    if initial.shape != (4, 4) or not np.isfinite(initial).all():
        raise InputError(
            source, f"initial: expected a finite (4, 4) transform, got {initial.shape}"
        )
    every = np.ones(len(p), dtype=bool)
    noise_region = mesh_noise(p, every, source=source).region(every)
    placed = transform_points(initial, p)
    noise_surface = surface.noise(placed, source)
    expected = float(np.hypot(noise_surface, noise_region))
    known = expected if np.isfinite(expected) else 0.0
    prm = prm | {"kernel_k_mm": max(prm["kernel_k_mm"], prm["kernel_noise_sigmas"] * known)}
    reach = surface.reach(placed, known)
    t, iterations, conv, constraint = _region_icp(p, surface, initial, prm, reach, known)
    if not np.isfinite(t).all():
        t, conv = initial, False
    plane, seen, d = surface.residuals(transform_points(t, p), reach)
    fitness = float(seen.mean())
    rmse = float(np.sqrt(np.mean(d[seen] ** 2))) if seen.any() else 0.0
    gate = _rmse_gate(plane[seen], noise_surface, noise_region, prm)
    problems = [] if conv else [f"ICP did not converge ({iterations} iterations)"]
    if fitness < prm["min_fitness"]:
        problems.append(
            f"the surface's data covers only {100 * fitness:.0f}% of the region (min_fitness "
            f"{prm['min_fitness']:g})"
        )
    if gate.problem:
        problems.append(
            f"point-to-plane RMSE {gate.residual_rmse:.3f} mm over the region > {gate.limit:.3f}"
            " mm: it did not move rigidly"
        )
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
        kernel_k=prm["kernel_k_mm"],
        constraint=constraint,
    )


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
    ``kernel_k_mm`` as in :func:`_refine_icp`; a correspondence farther than that scale (and
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
    k_final = prm["kernel_k_mm"]
    k = max(prm["max_correspondence_mm"], k_final)
    tolerance = max(prm["step_mm"], _STEP_NOISE_SHARE * noise)
    scale, last = 1.0, None  # the step's share; the points' motion in the last step
    it = 0
    for it in range(1, prm["max_iterations"] + 1):  # noqa: B007 (it is reported)
        x = transform_points(t, p)
        d, j = surface.tree.query(x, distance_upper_bound=prm["max_correspondence_mm"])
        near = d <= max(k, reach)
        near[near] = ~surface.edge[j[near]]
        x, n = x[near], q_normals[j[near]]
        r = np.einsum("ij,ij->i", x - q[j[near]], n)
        w = _kernel_weights(np.abs(r), prm["robust_kernel"], k)
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


def _verdict(conv, iterations, fitness, kept, recovery, prm) -> list[str]:
    """The problems of an alignment against its quality gate; empty when it passed."""
    problems = []
    if not conv:
        tried = "; ".join(r for r in recovery if r.startswith("not converged")) or "none"
        problems.append(f"ICP did not converge ({iterations} iterations; recovery tried: {tried})")
    if fitness < prm["min_fitness"]:
        problems.append(
            f"fitness {fitness:.3f} < min_fitness {prm['min_fitness']:.3f} (share of the "
            f"region within max_correspondence_mm={prm['max_correspondence_mm']:g} of the "
            "neutral mesh): check the point pairs and that the take shows the same subject"
        )
    if kept < prm["min_inlier_fraction"]:
        problems.append(
            f"only {100 * kept:.0f}% of the region kept (min_inlier_fraction "
            f"{prm['min_inlier_fraction']:g}): the stable region itself moved"
        )
    return problems


def _rmse_verdict(residual_rmse, limit, kind, noise_take, noise_neutral, prm) -> str | None:
    """The RMSE gate's problem, naming the measured noise and the limit; None when it passed."""
    if residual_rmse <= limit:
        return None
    noise = f"measured noise: take {noise_take:.3f} mm, neutral {noise_neutral:.3f} mm"
    if kind == "absolute":
        why = f"max_rmse_mm {limit:g} (absolute; {noise})"
    else:
        expected = np.hypot(noise_take, noise_neutral)
        why = (
            f"limit {limit:.3f} mm (max_rmse_ratio {prm['max_rmse_ratio']:g} x the "
            f"{expected:.3f} mm a right alignment leaves; {noise})"
        )
    return (
        f"point-to-plane RMSE {residual_rmse:.3f} mm over the kept region > {why}: "
        "misaligned, or the stable region moved"
    )


__all__ = [
    "DEFAULT_ICP",
    "AlignResult",
    "RmseGate",
    "align_take",
    "region_motion",
    "SampledSurface",
    "rmse_gate",
    "rmse_limit",
    "vertex_normals",
]
