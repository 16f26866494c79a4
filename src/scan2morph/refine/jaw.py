"""The jaw prior: the skin of the chin moves with the mandible, rigidly.

Image correlation measures the chin's motion poorly once the jaw opens: the chin turns by
10-15 degrees, its shading and foreshortening change, and the pulled-back images differ by
several pixels that vary across it (synthetic ``car``: the flow leaves the chin 2-9 px from where
its skin went, and it moves a good start away by 1-2 px). The chin's *geometry* measures it: its
bony shape (the mentolabial sulcus over the chin's bulge) pins a rigid motion. So the neutral's
chin is registered to the take's surface by point-to-plane ICP
(:func:`scan2morph.align.region_motion`, started from the fit's correspondence), and each chin
vertex goes where that rigid motion carries its skin point, found in the take's range image
(:func:`scan2morph.template.sample.range_pixels`).

The prior holds only where the chin did move rigidly. It is used when the registration's
point-to-plane RMSE is within ``max_rmse_ratio`` times what the two meshes' measured noise
explains (a chin that the lips' rounding or a pout deforms is not rigid, and keeps the flow's
answer). Its weight rises from 0 to 1 along the way from the lower lip's outer midpoint
(iBUG 58) to the chin (iBUG 9), between the shares ``start`` and ``end`` of it: the lower lip
and the sulcus under it move with the lips as much as with the jaw.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import binary_erosion

from scan2morph.align import (
    DEFAULT_ICP,
    AlignResult,
    SampledSurface,
    invert,
    kabsch,
    region_motion,
    transform_points,
)
from scan2morph.align.noise import CHI2_1_MEDIAN
from scan2morph.errors import InputError
from scan2morph.geometry import surface_normals
from scan2morph.scan.repair import smooth_depth
from scan2morph.template.sample import range_pixels

__all__ = [
    "JawParams",
    "JawPrior",
    "chin_weights",
    "jaw_prior",
    "scan_surface",
    "LOWER_LIP",
    "CHIN",
]

#: iBUG number of the lower lip's outer midpoint.
LOWER_LIP = 58
#: iBUG number of the chin's lowest point.
CHIN = 9
#: Fewest chin vertices valid in both meshes for a registration.
MIN_VERTICES = 12
#: Smoothing of the take's range before its normals are taken, px; a jump in range beyond
#: NORMAL_JUMP_MM (mm) is another surface.
NORMAL_SIGMA_PX = 2.0
NORMAL_JUMP_MM = 3.0
#: Least :attr:`~scan2morph.align.AlignResult.constraint` of the chin's registration: the RMS
#: change of its fit (mm) per mm of the motion its shape pins least. The synthetic chins give
#: 0.07-0.09 (a slide known to about 0.1 mm); a plane gives 0.
MIN_CONSTRAINT = 0.02


@dataclass(frozen=True)
class JawParams:
    """Parameters of the jaw prior (config keys ``refine.jaw_*``).

    Attributes
    ----------
    enabled : bool
        Use the prior (``refine.jaw_prior``).
    start, end : float
        Shares of the way from iBUG 58 to iBUG 9 where the prior's weight starts to rise from 0
        and reaches 1; the vertices at weight 1 are the region registered.
    max_rmse_ratio : float
        The registration's RMSE gate, in units of the RMSE the measured noise explains.
    """

    enabled: bool = True
    start: float = 0.0
    end: float = 0.3
    max_rmse_ratio: float = 1.5

    def __post_init__(self):
        if not 0.0 <= self.start < self.end:
            raise InputError(
                "config",
                f"refine.jaw_start, refine.jaw_end: expected 0 <= start < end, got "
                f"{self.start} and {self.end}",
            )
        if not self.max_rmse_ratio > 0:
            raise InputError(
                "config",
                f"refine.jaw_max_rmse_ratio: expected a positive ratio, got {self.max_rmse_ratio}",
            )


@dataclass(frozen=True)
class JawPrior:
    """Where the jaw's rigid motion puts each chin vertex in a take.

    Attributes
    ----------
    points : (V, 2) float64
        Pixel positions in the take's image, px; NaN where there is no prior.
    weight : (V,) float64
        The prior's weight in [0, 1]; 0 everywhere when it is not used.
    motion : AlignResult
        The chin's registration (neutral frame onto the take's aligned surface).
    used : bool
    problem : str
        Why it is not used ("" when it is).
    """

    points: np.ndarray
    weight: np.ndarray
    motion: AlignResult | None
    used: bool
    problem: str

    def apply(self, points: np.ndarray, share: np.ndarray | None = None) -> np.ndarray:
        """``points`` (V, 2) moved towards the prior by ``share`` (V,) (default its weight; 0
        where it has no point)."""
        w = self.weight if share is None else np.asarray(share, dtype=np.float64)
        w = np.where(np.isfinite(self.points).all(axis=1), w, 0.0)[:, None]
        return np.asarray(points, dtype=np.float64) + w * np.nan_to_num(self.points - points)


def chin_weights(
    vertices2d: np.ndarray, ibug_xy: np.ndarray, start: float, end: float
) -> np.ndarray:
    """(V,) weight of the jaw prior at each template vertex.

    Parameters
    ----------
    vertices2d : (V, 2) float
        Template vertices, template units.
    ibug_xy : (68, 2) float
        The template's iBUG points.
    start, end : float
        Shares of the way from iBUG 58 to iBUG 9 (projected on that axis) where the weight
        starts to rise from 0 and reaches 1.
    """
    lip, chin = np.asarray(ibug_xy, dtype=np.float64)[[LOWER_LIP - 1, CHIN - 1]]
    axis = chin - lip
    share = (np.asarray(vertices2d, dtype=np.float64) - lip) @ axis / float(axis @ axis)
    return np.clip((share - start) / (end - start), 0.0, 1.0)


def jaw_prior(
    neutral: np.ndarray,
    neutral_valid: np.ndarray,
    take: np.ndarray,
    take_valid: np.ndarray,
    weights: np.ndarray,
    still: np.ndarray,
    take_xyz: np.ndarray,
    take_transform: np.ndarray,
    icp: dict[str, Any] | None = None,
    max_rmse_ratio: float = 1.5,
    source: str = "subject/take",
) -> JawPrior:
    """The jaw prior of one take.

    Parameters
    ----------
    neutral : (V, 3) float, mm
        The neutral's mesh (neutral frame); NaN where invalid.
    neutral_valid : (V,) bool
    take : (V, 3) float, mm
        The take's aligned fit (neutral frame); NaN where invalid. Its correspondence starts
        the registration.
    take_valid : (V,) bool
    weights : (V,) float
        :func:`chin_weights`; the vertices at 1 are registered.
    still : (V,) bool
        Skin that the alignment holds still (its ICP region): the rigidity gate's reference.
    take_xyz : (H, W, 3) float, mm
        The take's range image (its own frame): the surface registered to, and where the moved
        skin points are looked up.
    take_transform : (4, 4) float
        The take's alignment (its frame -> the neutral frame).
    icp : dict, optional
        ICP settings (:data:`scan2morph.align.DEFAULT_ICP` keys; the config section ``align``).
    max_rmse_ratio : float
        The rigidity gate: the chin's point-to-plane RMSE at most this many times the still
        skin's (robust) residual against the take's surface under the alignment, the RMSE that
        a rigid motion leaves on these scans.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    JawPrior
    """
    weights = np.asarray(weights, dtype=np.float64)
    n = len(weights)
    none = np.full((n, 2), np.nan)
    neutral = np.asarray(neutral, dtype=np.float64)
    take = np.asarray(take, dtype=np.float64)
    neutral_valid = np.asarray(neutral_valid, dtype=bool)
    core = (weights >= 1.0) & neutral_valid
    both = core & np.asarray(take_valid, dtype=bool)
    if both.sum() < MIN_VERTICES:
        problem = (
            f"only {int(both.sum())} chin vertices valid in both meshes "
            f"(at least {MIN_VERTICES} needed)"
        )
        return JawPrior(none, np.zeros(n), None, False, problem)
    start = kabsch(neutral[both], take[both], source=source)  # the fit's correspondence
    near = (weights > 0) & neutral_valid
    xyz = np.asarray(take_xyz, dtype=np.float64)
    surface, offset, window = scan_surface(
        xyz, take_transform, transform_points(start, neutral[near]), icp, source
    )
    # what a rigid motion leaves on these scans: the still skin's residual (robust: a smile's
    # temples move) under the alignment
    still_points = neutral[np.asarray(still, dtype=bool) & neutral_valid]
    still_surface = scan_surface(xyz, take_transform, still_points, icp, source)[0]
    if surface is None or still_surface is None:
        return JawPrior(none, np.zeros(n), None, False, "the take's scan does not show the chin")
    plane, seen, _ = still_surface.residuals(still_points, still_surface.reach(still_points, 0.0))
    reference = float(np.sqrt(np.median(plane[seen] ** 2) / CHI2_1_MEDIAN)) if seen.any() else 0.0
    limit = max_rmse_ratio * reference
    motion = region_motion(
        neutral[core],
        start,
        surface,
        (icp or {}) | {"max_rmse_mm": limit if limit > 0 else None},
        source,
    )
    if motion.ok and not motion.constraint >= MIN_CONSTRAINT:
        problem = (
            f"the chin's shape does not pin its motion: a slide of 1 mm changes its fit by "
            f"{motion.constraint:.3f} mm RMS (at least {MIN_CONSTRAINT:g} needed)"
        )
        return JawPrior(none, np.zeros(n), motion, False, problem)
    if not motion.ok:
        problem = "; ".join(motion.problems)
        if motion.converged and motion.residual_rmse > limit > 0:
            problem = (
                f"the chin did not move rigidly: point-to-plane RMSE {motion.residual_rmse:.3f} "
                f"mm > {limit:.3f} mm (refine.jaw_max_rmse_ratio {max_rmse_ratio:g} x the "
                f"{reference:.3f} mm the still skin leaves)"
            )
        return JawPrior(none, np.zeros(n), motion, False, problem)
    moved = transform_points(motion.transform, neutral[near])
    points = none.copy()
    points[near] = offset + range_pixels(
        window, transform_points(invert(take_transform), moved), source=source
    )
    found = np.isfinite(points).all(axis=1)
    return JawPrior(points, np.where(found, weights, 0.0), motion, True, "")


def scan_surface(xyz, transform, placed, icp=None, source="range image"):
    """A range image's surface (in the frame ``transform`` maps it to) where points ``placed``
    (n, 3) can be: ``(SampledSurface, offset, window)``, the window's offset (column, row) in
    the image, px; three None when the window is empty.

    The window holds the pixels within the ICP's correspondence distance of the points' box;
    their normals are those of the range smoothed over :data:`NORMAL_SIGMA_PX` (a pixel's own
    normal is tilted by its noise: 0.1 mm over 0.7 mm of spacing is 8 degrees, enough to pin a
    plane); pixels next to one without data are the data's edge.
    """
    reach = float((icp or {}).get("max_correspondence_mm", DEFAULT_ICP["max_correspondence_mm"]))
    lo, hi = placed.min(axis=0) - reach, placed.max(axis=0) + reach
    with np.errstate(invalid="ignore"):
        inside = (
            (transform_points(transform, xyz) >= lo) & (transform_points(transform, xyz) <= hi)
        ).all(axis=2)
    rows, cols = np.nonzero(inside)
    if not len(rows):
        return None, None, None
    pad = int(np.ceil(3 * NORMAL_SIGMA_PX)) + 1
    r0, c0 = max(rows.min() - pad, 0), max(cols.min() - pad, 0)
    window = xyz[r0 : rows.max() + pad + 1, c0 : cols.max() + pad + 1]
    normals = surface_normals(smooth_depth(window, NORMAL_SIGMA_PX, NORMAL_JUMP_MM))
    have = np.isfinite(window).all(axis=2) & np.isfinite(normals).all(axis=2)
    if have.sum() <= MIN_VERTICES:
        return None, None, None
    edge = have & ~binary_erosion(have, np.ones((3, 3), dtype=bool), border_value=1)
    rotation = np.asarray(transform, dtype=np.float64)[:3, :3]
    surface = SampledSurface(
        transform_points(transform, window[have]), normals[have] @ rotation.T, source, edge[have]
    )
    return surface, np.array([c0, r0], dtype=np.float64), window
