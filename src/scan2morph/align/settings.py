"""ICP settings (:data:`DEFAULT_ICP`) and the checks of an alignment's inputs.

Shared by the take alignment (:mod:`scan2morph.align.icp`), its RMSE gate
(:mod:`scan2morph.align.gate`) and a region's rigid motion (:mod:`scan2morph.align.region`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scan2morph.errors import InputError

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


_METHODS = ("icp", "correspondence")
_KERNELS = ("tukey", "huber", "none")


def icp_settings(params: dict[str, Any] | None, source: str) -> dict[str, Any]:
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


def check_indices(idx: np.ndarray, n_vertices: int, name: str, source: str) -> np.ndarray:
    a = np.asarray(idx)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise InputError(source, f"{name}: expected a 1-D integer array, got {a.dtype} {a.shape}")
    bad = (a < 0) | (a >= n_vertices)
    if bad.any():
        raise InputError(
            source, f"{name}: vertex index {int(a[bad][0])} out of range [0, {n_vertices})"
        )
    return a.astype(np.int64)


def check_mesh(vertices, valid, name: str, source: str, n_vertices: int | None = None) -> tuple:
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


def kernel_weights(r: np.ndarray, kernel: str, k: float) -> np.ndarray:
    if kernel == "tukey":
        return np.where(r <= k, (1.0 - (r / k) ** 2) ** 2, 0.0)
    if kernel == "huber":
        return np.where(r <= k, 1.0, k / np.maximum(r, k))
    return np.ones_like(r)


__all__ = ["DEFAULT_ICP"]
