"""The result of a rigid alignment with its verdict (:class:`AlignResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
        estimated from each mesh's roughness, times its noise gain for a depth camera's
        smoothed noise; NaN if too few vertices).
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
        ``kernel_noise_sigmas`` times the RMSE the roughness alone explains, without the
        noise gains).
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


__all__ = ["AlignResult"]
