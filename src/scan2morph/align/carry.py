"""A take's stable landmarks carried over from its neutral, so that the two agree.

The nose bridge and the eye corners do not move when the mouth does: once a take is rigidly
aligned to its neutral, their points should coincide with the neutral's. Detected separately,
each take's would scatter by the detector's error. Carrying them over makes them agree up to the
alignment's error, and the template fit then places the upper face the same way in every take:

1. **Lift** the stable points of both grids to 3D (bilinear samples of each range image).
2. **Align** the take to the neutral: the least-squares rigid motion of the lifted pairs, then a
   point-to-plane ICP of the take's surface within :data:`SURFACE_RADIUS_MM` of those points
   onto the neutral's (the eye region and the nose: skin that stays still).
3. **Carry** the neutral's 3D stable points into the take's frame and find the pixels where the
   take's range image holds them (:func:`scan2morph.template.sample.range_pixels`: no camera
   model needed).

A point that cannot be carried (no surface there) keeps its detected position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.align.rigid import invert, kabsch, transform_points
from scan2morph.geometry import surface_normals
from scan2morph.open3d_light import open3d
from scan2morph.template.sample import range_pixels, sample_range

#: Surface around the lifted stable points that the ICP aligns, mm.
SURFACE_RADIUS_MM = 20.0
#: ICP correspondences farther apart than this are dropped, mm.
MAX_PAIR_MM = 3.0
#: ICP iterations.
ICP_ITERATIONS = 30
#: At most this many take pixels enter the ICP (an even stride of them).
MAX_ICP_POINTS = 6000


@dataclass(frozen=True)
class Carried:
    """Stable points carried from the neutral.

    Attributes
    ----------
    points : (68, 2) float64
        The take's landmarks with the carried stable points in place, px.
    carried : (n,) bool
        Which of the stable points were carried (the others kept their detected position).
    transform : (4, 4) float64
        Take frame -> neutral frame, as aligned here, mm.
    shift_px : (n,) float64
        How far each stable point moved from its detected position, px (NaN: not carried).
    """

    points: np.ndarray
    carried: np.ndarray
    transform: np.ndarray
    shift_px: np.ndarray


def carry_stable(
    take_xyz: np.ndarray,
    take_points: np.ndarray,
    neutral_xyz: np.ndarray,
    neutral_points: np.ndarray,
    stable: tuple[int, ...],
    source: str = "take",
) -> Carried:
    """The take's landmarks with its stable points carried over from the neutral.

    Parameters
    ----------
    take_xyz, neutral_xyz : (H, W, 3) float
        The repaired range images, mm, NaN where there is no surface (each in its own frame).
    take_points, neutral_points : (68, 2) float
        The landmarks on each grid, px.
    stable : tuple of int
        iBUG numbers (1-based) of the points that do not move with the mouth.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Carried
    """
    idx = np.asarray(stable, dtype=np.int64) - 1
    take_3d = sample_range(take_xyz, np.asarray(take_points, float)[idx], source, 0.5)[0]
    neutral_3d = sample_range(neutral_xyz, np.asarray(neutral_points, float)[idx], source, 0.5)[0]
    both = np.isfinite(take_3d).all(axis=1) & np.isfinite(neutral_3d).all(axis=1)
    points = np.array(take_points, dtype=np.float64)
    if both.sum() < 3:
        nothing = np.zeros(len(idx), dtype=bool)
        return Carried(points, nothing, np.eye(4), np.full(len(idx), np.nan))
    initial = kabsch(take_3d[both], neutral_3d[both], source=source)
    transform = _surface_icp(take_xyz, neutral_xyz, take_3d[both], initial)
    into_take = transform_points(invert(transform), neutral_3d)
    pixels = range_pixels(take_xyz, into_take, start=points[idx], source=source)
    carried = np.isfinite(pixels).all(axis=1)
    shift = np.full(len(idx), np.nan)
    shift[carried] = np.linalg.norm(pixels[carried] - points[idx][carried], axis=1)
    points[idx[carried]] = pixels[carried]
    return Carried(points, carried, transform, shift)


def _near(xyz: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """The grid's points (with data) within ``radius`` of any of ``centres``, (n, 3)."""
    pts = xyz.reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    d = np.linalg.norm(pts[:, None, :] - centres[None, :, :], axis=2).min(axis=1)
    return pts[d < radius]


def _surface_icp(
    take_xyz: np.ndarray, neutral_xyz: np.ndarray, take_centres: np.ndarray, initial: np.ndarray
) -> np.ndarray:
    """Point-to-plane ICP of the take's surface near ``take_centres`` onto the neutral's."""
    o3d = open3d()

    src = _near(np.asarray(take_xyz, float), take_centres, SURFACE_RADIUS_MM)
    src = src[:: max(1, len(src) // MAX_ICP_POINTS)]
    centres_n = transform_points(initial, take_centres)
    normals = surface_normals(np.asarray(neutral_xyz, float))
    ok = np.isfinite(neutral_xyz).all(axis=2) & np.isfinite(normals).all(axis=2)
    dst, dst_n = neutral_xyz[ok], normals[ok]
    near = np.linalg.norm(dst[:, None, :] - centres_n[None], axis=2).min(axis=1)
    keep = near < SURFACE_RADIUS_MM + MAX_PAIR_MM
    if len(src) < 50 or keep.sum() < 50:
        return initial
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(dst[keep]))
    target.normals = o3d.utility.Vector3dVector(dst_n[keep])
    result = o3d.pipelines.registration.registration_icp(
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src)),
        target,
        MAX_PAIR_MM,
        initial,
        o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=ICP_ITERATIONS),
    )
    return np.asarray(result.transformation, dtype=np.float64)


__all__ = ["Carried", "carry_stable"]
