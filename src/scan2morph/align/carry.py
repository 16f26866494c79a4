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

The points on skin that moves (the mouth, the jaw, the brows) cannot be carried rigidly.
:func:`track_points` follows them from the neutral by the skin's texture instead: the take's
image is brought onto the neutral's grid by the affine map that the rigid alignment predicts,
and an image-correlation flow (given by the caller, e.g.
:func:`scan2morph.refine.flow.measure_flow`) measures where each of the neutral's points went,
with a confidence. A tracked point inherits the neutral's error, not the take's own detection
error, so that the take's landmarks move with its skin relative to the neutral's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from scan2morph.align.point_plane import PointToPlane
from scan2morph.align.rigid import invert, kabsch, transform_points
from scan2morph.geometry import affine_fit, surface_normals
from scan2morph.template.sample import range_pixels, sample_range

#: Surface around the lifted stable points that the ICP aligns, mm.
SURFACE_RADIUS_MM = 20.0
#: ICP correspondences farther apart than this are dropped, mm.
MAX_PAIR_MM = 3.0
#: ICP iterations, at most.
ICP_ITERATIONS = 30
#: The ICP stops once an iteration changes the share of paired points and their RMS distance
#: (mm) by less than this (open3d's ``ICPConvergenceCriteria`` defaults).
ICP_CONVERGED = 1e-6
#: At most this many take pixels enter the ICP (an even stride of them).
MAX_ICP_POINTS = 6000
#: Image around the neutral's landmarks that the tracking correlates, px.
TRACK_MARGIN_PX = 40


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


def carry_points(
    take_xyz: np.ndarray,
    neutral_xyz: np.ndarray,
    neutral_points: np.ndarray,
    transform: np.ndarray,
    source: str = "take",
) -> np.ndarray:
    """The neutral's points carried rigidly into the take.

    Each point is lifted to the neutral's surface, moved by the inverse of ``transform`` and
    found on the take's range image (:func:`~scan2morph.template.sample.range_pixels`); a point
    the take's surface does not hold there (skin that moved: an opened mouth, a lowered jaw)
    goes where the 2D affine map fitted to the found ones puts it, as :func:`track_points`
    predicts the take's image.

    Parameters
    ----------
    take_xyz, neutral_xyz : (H, W, 3) float
        The repaired range images, mm, NaN where there is no surface.
    neutral_points : (n, 2) float
        Points on the neutral's grid, px.
    transform : (4, 4) float
        Take frame -> neutral frame, mm (:attr:`Carried.transform`).
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    (n, 2) float64
        Pixels on the take's grid; all NaN when fewer than 3 points are found on its surface.
    """
    pn = np.asarray(neutral_points, dtype=np.float64)
    predicted, affine = _rigid_prediction(take_xyz, neutral_xyz, pn, transform, source)
    if affine is None:
        return np.full((len(pn), 2), np.nan)
    found = np.isfinite(predicted).all(axis=1)[:, None]
    return np.where(found, predicted, pn @ affine[:, :2].T + affine[:, 2])


def _rigid_prediction(t_xyz, n_xyz, pn, transform, source) -> tuple:
    """The neutral's points ``pn`` (n, 2) px lifted, moved by the inverse of ``transform`` and
    found on the take's grid, (n, 2) px (NaN: not found), and the 2D affine map (2, 3) that the
    found ones fit (neutral px -> take px; None when fewer than 3 are found)."""
    lifted = sample_range(n_xyz, pn, source, 0.5)[0]
    predicted = range_pixels(t_xyz, transform_points(invert(transform), lifted), source=source)
    ok = np.isfinite(predicted).all(axis=1)
    if ok.sum() < 3:
        return predicted, None
    return predicted, affine_fit(pn[ok], predicted[ok]).T


def _near(xyz: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """The grid's points (with data) within ``radius`` of any of ``centres``, (n, 3)."""
    pts = xyz.reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    d = np.linalg.norm(pts[:, None, :] - centres[None, :, :], axis=2).min(axis=1)
    return pts[d < radius]


def _surface_icp(
    take_xyz: np.ndarray, neutral_xyz: np.ndarray, take_centres: np.ndarray, initial: np.ndarray
) -> np.ndarray:
    """Point-to-plane ICP of the take's surface near ``take_centres`` onto the neutral's:
    Gauss-Newton steps without a robust kernel against one k-d tree of the neutral
    (:class:`~scan2morph.align.point_plane.PointToPlane`, whose sums run in a fixed order: the
    same inputs give the same pose, bit for bit), from ``initial`` until converged."""
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
    surface = PointToPlane(dst[keep], dst_n[keep], MAX_PAIR_MM)
    pose = np.array(initial, dtype=np.float64)
    pairs = surface.at(src, pose)
    for _ in range(ICP_ITERATIONS):
        if pairs.fitness == 0.0:
            break
        pose = surface.step(pairs, "none", MAX_PAIR_MM, pose)
        old, pairs = pairs, surface.at(src, pose)
        if (
            abs(pairs.fitness - old.fitness) < ICP_CONVERGED
            and abs(pairs.rmse - old.rmse) < ICP_CONVERGED
        ):
            break
    return pose


@dataclass(frozen=True)
class Tracked:
    """The neutral's landmarks followed into a take by the skin's texture.

    Attributes
    ----------
    points : (68, 2) float64
        Where each of the neutral's points is in the take, px (NaN: not found).
    confidence : (68,) float64
        The flow's confidence at each neutral point, in [0, 1] (0 where not found).
    affine : (2, 3) float64
        The rigid alignment's prediction: neutral px -> take px (``affine @ [x, y, 1]``).
    """

    points: np.ndarray
    confidence: np.ndarray
    affine: np.ndarray


def track_points(
    take: tuple[np.ndarray, np.ndarray],
    neutral: tuple[np.ndarray, np.ndarray],
    neutral_points: np.ndarray,
    transform: np.ndarray,
    measure: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    source: str = "take",
) -> Tracked:
    """Follow the neutral's landmarks into a take by image correlation.

    Parameters
    ----------
    take, neutral : tuple of ((H, W, 3) float, (H, W) float)
        Each scan's repaired range image (mm, NaN = no surface) and grey image on the same grid.
    neutral_points : (n, 2) float
        The neutral's landmarks, px.
    transform : (4, 4) float
        Take frame -> neutral frame, mm (:attr:`Carried.transform`).
    measure : callable
        ``measure(reference, moving) -> (flow, confidence)`` on two (rows, cols) grey images
        (NaN = missing): ``moving(x + flow(x)) ~ reference(x)``, flow (rows, cols, 2) px,
        confidence (rows, cols) in [0, 1].
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Tracked
        All NaN / 0 when fewer than 3 of the neutral's points can be placed in the take.
    """
    (t_xyz, t_grey), (n_xyz, n_grey) = take, neutral
    pn = np.asarray(neutral_points, dtype=np.float64)
    n = len(pn)
    affine = _rigid_prediction(t_xyz, n_xyz, pn, transform, source)[1]  # (2, 3)
    if affine is None:
        return Tracked(np.full((n, 2), np.nan), np.zeros(n), np.full((2, 3), np.nan))
    h, w = np.shape(n_grey)
    x0, y0 = np.maximum(np.floor(pn.min(axis=0)) - TRACK_MARGIN_PX, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(pn.max(axis=0)) + TRACK_MARGIN_PX + 1, [w, h]).astype(int)
    gx, gy = np.meshgrid(np.arange(x0, x1, dtype=np.float64), np.arange(y0, y1, dtype=np.float64))
    mx = affine[0, 0] * gx + affine[0, 1] * gy + affine[0, 2]
    my = affine[1, 0] * gx + affine[1, 1] * gy + affine[1, 2]
    take_img = np.where(np.isfinite(t_xyz).all(axis=2), t_grey, np.nan).astype(np.float32)
    moving = cv2.remap(
        take_img,
        mx.astype(np.float32),
        my.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=float("nan"),
    )
    reference = np.where(np.isfinite(n_xyz).all(axis=2), n_grey, np.nan)[y0:y1, x0:x1]
    flow, conf = measure(reference, moving.astype(np.float64))
    rc = [pn[:, 1] - y0, pn[:, 0] - x0]
    shift = np.column_stack([map_coordinates(flow[..., k], rc, order=1) for k in (0, 1)])
    at = np.clip(map_coordinates(conf, rc, order=1, cval=0.0), 0.0, 1.0)
    moved = pn + shift
    points = moved @ affine[:, :2].T + affine[:, 2]
    return Tracked(points, at, affine)


__all__ = ["Carried", "Tracked", "carry_points", "carry_stable", "track_points"]
