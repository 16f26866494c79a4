"""ICP settings (:class:`IcpParams`) and the checks of an alignment's inputs.

Shared by the take alignment (:mod:`scan2morph.align.icp`), its RMSE gate
(:mod:`scan2morph.align.gate`) and a region's rigid motion (:mod:`scan2morph.align.region`).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError

_METHODS = ("icp", "correspondence")
_KERNELS = ("tukey", "huber", "none")
#: Settings that must be finite and positive, at least 0, or shares in [0, 1].
_POSITIVE = (
    "max_correspondence_mm",
    "kernel_k_mm",
    "trim_radius_mm",
    "trim_sigma",
    "still_sigma",
    "max_rmse_ratio",
    "kernel_noise_sigmas",
)
_NON_NEGATIVE = ("relative_fitness", "relative_rmse", "step_deg", "step_mm")
_SHARES = ("min_fitness", "min_inlier_fraction")


@dataclass(frozen=True)
class IcpParams:
    """ICP settings of an alignment (mm where a unit applies).

    Attributes
    ----------
    method : {"icp", "correspondence"}
        open3d point-to-plane ICP, or a robust Kabsch over matching vertices.
    max_correspondence_mm : float
        Correspondence distance, mm.
    max_iterations : int
        Iterations at most.
    robust_kernel : {"tukey", "huber", "none"}
        The robust kernel.
    kernel_k_mm : float
        The kernel's least final scale, mm (its scale halves each iteration from
        ``max_correspondence_mm``); widened to ``kernel_noise_sigmas`` times the RMSE the
        meshes' measured noise predicts.
    kernel_noise_sigmas : float
    relative_fitness, relative_rmse : float
        The iteration stops when both the fitness and the inlier RMSE change by less than these
        between iterations (open3d's criterion: absolute changes, despite the name); so does a
        pose step below ``step_deg`` (degrees) and ``step_mm``.
    step_deg, step_mm : float
    trim_rounds : int
        Rounds of trimming the region's moving parts (0: off): residuals averaged over
        ``trim_radius_mm`` beyond ``trim_sigma`` robust standard deviations are left out.
    trim_radius_mm, trim_sigma : float
    still_groups : int
        The search for the still skin of a take (0: off, the region is taken as still): the
        region and the skin it may grow into are split into this many patches, and the pose
        that the most of them agree with, fitted with up to ``still_drop`` patches left out,
        is kept (:func:`scan2morph.align.still.still_skin`). Off by default here, so that a
        library caller keeps the plain alignment; the pipeline's config turns it on (6).
    still_drop : int
        The most patches left out at once in that search.
    still_sigma : float
        A candidate agrees with a hypothesis' pose when its averaged residual is within this
        many robust standard deviations of the best-fitting hypothesis' (at least 0.05 mm).
    min_fitness : float
        Quality gate: least share of the region within ``max_correspondence_mm``.
    max_rmse_ratio : float
        Quality gate: most point-to-plane RMSE, in units of the RMSE the measured noise predicts.
    max_rmse_mm : float or None
        Quality gate: an absolute RMSE limit (mm) instead of ``max_rmse_ratio``.
    min_inlier_fraction : float
        Quality gate: least share of the region kept after trimming.

    Raises
    ------
    InputError
        A value out of its range (naming the attribute).
    """

    method: str = "icp"
    max_correspondence_mm: float = 10.0
    max_iterations: int = 50
    robust_kernel: str = "tukey"
    kernel_k_mm: float = 3.0
    kernel_noise_sigmas: float = 3.0
    min_fitness: float = 0.5
    relative_fitness: float = 1e-6
    relative_rmse: float = 1e-6
    step_deg: float = 0.01
    step_mm: float = 0.01
    trim_rounds: int = 6
    trim_radius_mm: float = 8.0
    trim_sigma: float = 3.0
    still_groups: int = 0
    still_drop: int = 2
    still_sigma: float = 2.0
    max_rmse_ratio: float = 3.0
    max_rmse_mm: float | None = None
    min_inlier_fraction: float = 0.3

    def __post_init__(self):
        for name, choices in (("method", _METHODS), ("robust_kernel", _KERNELS)):
            if getattr(self, name) not in choices:
                raise InputError(
                    "IcpParams", f"{name} must be one of {choices}, got {getattr(self, name)!r}"
                )
        for names, ok, expected in (
            (_POSITIVE, lambda v: np.isfinite(v) and v > 0, "a positive number"),
            (_NON_NEGATIVE, lambda v: np.isfinite(v) and v >= 0, ">= 0"),
            (_SHARES, lambda v: 0.0 <= v <= 1.0, "in [0, 1]"),
        ):
            for name in names:
                value = getattr(self, name)
                if isinstance(value, bool) or not isinstance(value, numbers.Real) or not ok(value):
                    raise InputError("IcpParams", f"{name} must be {expected}, got {value!r}")
                object.__setattr__(self, name, float(value))
        v = self.max_rmse_mm
        if v is not None:
            if (
                isinstance(v, bool)
                or not isinstance(v, numbers.Real)
                or not (np.isfinite(v) and v > 0)
            ):
                raise InputError(
                    "IcpParams", f"max_rmse_mm must be a positive number or None, got {v!r}"
                )
            object.__setattr__(self, "max_rmse_mm", float(v))
        for name, least in (
            ("max_iterations", 1),
            ("trim_rounds", 0),
            ("still_groups", 0),
            ("still_drop", 1),
        ):
            it = getattr(self, name)
            if (
                isinstance(it, bool)
                or not isinstance(it, numbers.Real)
                or int(it) != it
                or it < least
            ):
                raise InputError("IcpParams", f"{name} must be an integer >= {least}, got {it!r}")
            object.__setattr__(self, name, int(it))


@dataclass(frozen=True)
class AlignMeshes:
    """The two meshes of an alignment, in one template topology (checked by the functions that
    take them).

    Attributes
    ----------
    src_vertices : (V, 3) float, mm
        The take's mesh in its scanner frame; NaN where invalid.
    src_valid : (V,) bool
        Valid vertices of the take's mesh.
    dst_vertices : (V, 3) float, mm
        The neutral mesh (neutral frame).
    dst_valid : (V,) bool
        Valid vertices of the neutral mesh.
    faces : (F, 3) int
        Template faces (the target's vertex normals).
    src_noise_gain, dst_noise_gain : float
        How many times each mesh's noise exceeds what its roughness reads (a depth camera's
        smoothed noise: :func:`~scan2morph.align.noise.smoothing_gain`); 1 for white noise.
        The RMSE gate's expected RMSE uses the noise read times the gain.
    """

    src_vertices: np.ndarray
    src_valid: np.ndarray
    dst_vertices: np.ndarray
    dst_valid: np.ndarray
    faces: np.ndarray
    src_noise_gain: float = 1.0
    dst_noise_gain: float = 1.0


def icp_settings(params: IcpParams | None, source: str) -> IcpParams:
    """``params``, or the defaults for None; anything else is an error naming ``source``."""
    if params is None:
        return IcpParams()
    if not isinstance(params, IcpParams):
        raise InputError(source, f"params: expected IcpParams or None, got {type(params).__name__}")
    return params


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


def noise_gains(meshes: AlignMeshes, source: str) -> tuple[float, float]:
    """The meshes' checked noise gains ``(src, dst)``: finite numbers >= 1."""
    gains = (meshes.src_noise_gain, meshes.dst_noise_gain)
    for side, g in zip(("src", "dst"), gains, strict=True):
        if isinstance(g, bool) or not (isinstance(g, numbers.Real) and np.isfinite(g) and g >= 1):
            raise InputError(source, f"{side}_noise_gain: expected a finite number >= 1, got {g!r}")
    return float(gains[0]), float(gains[1])


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


__all__ = ["AlignMeshes", "IcpParams", "icp_settings"]
