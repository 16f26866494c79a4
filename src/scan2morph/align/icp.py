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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from scan2morph.align.rigid import kabsch, transform_points
from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals

#: Default ICP parameters (mm where a unit applies). ``relative_fitness`` / ``relative_rmse``
#: stop the iteration when both the fitness and the inlier RMSE change by less than that
#: between iterations (open3d's criterion: absolute changes, despite the name).
DEFAULT_ICP: dict[str, Any] = {
    "method": "icp",
    "max_correspondence_mm": 10.0,
    "max_iterations": 50,
    "robust_kernel": "tukey",
    "kernel_k_mm": 3.0,
    "min_fitness": 0.5,
    "relative_fitness": 1e-6,
    "relative_rmse": 1e-6,
}

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
        True if the stopping criterion was met before ``max_iterations``.
    method : str
        ``"icp"`` or ``"correspondence"``.
    n_points : int
        Number of upper-face source vertices used.
    """

    transform: np.ndarray
    initial: np.ndarray
    fitness: float
    inlier_rmse: float
    iterations: int
    converged: bool
    method: str = "icp"
    n_points: int = 0


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
    for key in ("max_correspondence_mm", "kernel_k_mm"):
        v = float(p[key])
        if not (np.isfinite(v) and v > 0):
            raise InputError(source, f"icp params: {key} must be a positive number, got {p[key]!r}")
        p[key] = v
    for key in ("relative_fitness", "relative_rmse"):
        v = float(p[key])
        if not (np.isfinite(v) and v >= 0):
            raise InputError(source, f"icp params: {key} must be >= 0, got {p[key]!r}")
        p[key] = v
    v = float(p["min_fitness"])
    if not 0.0 <= v <= 1.0:
        raise InputError(
            source, f"icp params: min_fitness must be in [0, 1], got {p['min_fitness']!r}"
        )
    p["min_fitness"] = v
    it = p["max_iterations"]
    if isinstance(it, bool) or int(it) != it or it < 1:
        raise InputError(source, f"icp params: max_iterations must be an integer >= 1, got {it!r}")
    p["max_iterations"] = int(it)
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
        t = kabsch(p, q, w, source=source)
        r, f_new, rmse_new = _residual_stats(p, q, t, prm["max_correspondence_mm"])
        done = (
            abs(f_new - fitness) < prm["relative_fitness"]
            and abs(rmse_new - rmse) < prm["relative_rmse"]
        )
        fitness, rmse = f_new, rmse_new
        if done:
            converged = True
            break
    return t, fitness, rmse, it, converged


def _refine_icp(p, q, q_normals, initial, prm):
    """open3d point-to-plane ICP, stepped one iteration at a time to report iterations."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(q))
    tgt.normals = o3d.utility.Vector3dVector(q_normals)
    k_final = prm["kernel_k_mm"]
    k = max(prm["max_correspondence_mm"], k_final)
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
        t = np.asarray(res.transformation)
        done = (
            k == k_final
            and abs(res.fitness - fitness) < prm["relative_fitness"]
            and abs(res.inlier_rmse - rmse) < prm["relative_rmse"]
        )
        k = max(k / 2.0, k_final)
        fitness, rmse = res.fitness, res.inlier_rmse
        if done:
            converged = True
            break
    return t, float(fitness), float(rmse), it, converged


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
        at least 3 non-collinear); each must be valid in both meshes.
    icp_indices : (m,) int
        Template vertex indices of the upper face, which the mouth does not move; the
        refinement uses the valid ones only.
    params : dict, optional
        Overrides of :data:`DEFAULT_ICP`: ``method`` ('icp' | 'correspondence'),
        ``max_correspondence_mm``, ``max_iterations``, ``robust_kernel``
        ('tukey' | 'huber' | 'none'), ``kernel_k_mm``, ``min_fitness``, ``relative_fitness``,
        ``relative_rmse``.
    source : str
        ``subject/take`` label for error messages.

    Returns
    -------
    AlignResult
        ``transform`` maps the take's scanner frame to the neutral frame.

    Raises
    ------
    InputError
        Bad shapes or indices, a pair vertex invalid in either mesh, too few valid upper-face
        vertices, or a final fitness below ``min_fitness`` (the alignment did not converge).
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
    for mask, which in ((sv, "src_valid (the take's mesh)"), (dv, "dst_valid (the neutral mesh)")):
        bad = pairs[~mask[pairs]]
        if bad.size:
            raise InputError(
                source,
                f"pair_indices: pair vertex {int(bad[0])} is invalid in {which}; "
                "expected pair vertices measured in both meshes",
            )
    initial = kabsch(src[pairs], dst[pairs], source=source)

    upper = np.zeros(n_v, dtype=bool)
    upper[_indices(icp_indices, n_v, "icp_indices", source)] = True
    if prm["method"] == "icp":
        normals = vertex_normals(dst, f)
        p_idx = np.flatnonzero(upper & sv)
        q_idx = np.flatnonzero(upper & dv & np.isfinite(normals).all(axis=1))
    else:
        p_idx = q_idx = np.flatnonzero(upper & sv & dv)
    if p_idx.size < 3 or q_idx.size < 3:
        raise InputError(
            source,
            f"icp_indices: only {min(p_idx.size, q_idx.size)} upper-face vertices are valid; "
            "expected at least 3",
        )
    if prm["method"] == "icp":
        t, fitness, rmse, it, conv = _refine_icp(
            src[p_idx], dst[q_idx], normals[q_idx], initial, prm
        )
    else:
        t, fitness, rmse, it, conv = _refine_correspondence(
            src[p_idx], dst[q_idx], initial, prm, source
        )
    if not np.isfinite(t).all() or fitness < prm["min_fitness"]:
        raise InputError(
            source,
            f"alignment did not converge: fitness {fitness:.3f} < min_fitness "
            f"{prm['min_fitness']:.3f} (fraction of upper-face vertices within "
            f"max_correspondence_mm={prm['max_correspondence_mm']:g} of the neutral mesh); "
            "check pair_indices and that the take shows the same subject",
        )
    return AlignResult(
        transform=t,
        initial=initial,
        fitness=float(fitness),
        inlier_rmse=float(rmse),
        iterations=int(it),
        converged=bool(conv),
        method=prm["method"],
        n_points=int(p_idx.size),
    )


__all__ = ["DEFAULT_ICP", "AlignResult", "align_take", "vertex_normals"]
