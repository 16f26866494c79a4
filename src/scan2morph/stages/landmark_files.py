"""A take's landmarks on its measured surface, for the ``.xyz`` file a user can correct and give
back (:func:`written_points`), and the lifting of pixels onto a range image it rests on
(:func:`surface_points`)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from scan2morph.stages.part import Take
from scan2morph.store import paths
from scan2morph.template.sample import sample_range

#: A point whose neighbour pixels straddle a step steeper than this is lifted from one pixel,
#: not from their bilinear mix in mid-air (degrees to the image plane; the fit's
#: ``template.max_slope_deg`` default).
LIFT_SLOPE_DEG = 80.0


def written_points(xyz: np.ndarray, take: Take, points: np.ndarray) -> np.ndarray:
    """The take's landmarks for its ``.xyz`` file: each on the take's measured surface
    (:func:`surface_points` of :func:`measured`), except a mesh take's given points, which are
    written as its landmark file gives them (``clicks_3d``). A given point may lie where the
    render does not see it (the underside of the chin, seen from below on the render of another
    camera): lifted, it would come back as the surface in front of it, and a file given back
    would move with every round.

    Parameters
    ----------
    xyz : (H, W, 3) float
        The take's repaired range image, mm.
    take : Take
        Its ``data`` may hold ``clicks_3d`` (68, 3) mm.
    points : (68, 2) float
        The take's landmarks, px.

    Returns
    -------
    (68, 3) float64
        mm, in the take's frame (a mesh take's: the mesh's).
    """
    out = surface_points(measured(xyz, take), points)
    given = take.data.get(paths.clicks_3d(take.take))
    if given is not None:
        given = np.asarray(given, dtype=np.float64)
        rows = np.isfinite(given).all(axis=1)
        out[rows] = given[rows]
    return out


def measured(xyz: np.ndarray, take: Take) -> np.ndarray:
    """The repaired range image with the pixels the repair made up (filled holes, replaced
    spikes: no surface the scan measured) set to NaN, (H, W, 3) mm."""
    made_up = np.zeros(xyz.shape[:2], dtype=bool)
    for key in ("filled", "spikes"):
        mask = take.data.get(paths.range_image(take.take, key))
        if mask is not None and np.shape(mask) == made_up.shape:
            made_up |= np.asarray(mask, dtype=bool)
    return np.where(made_up[..., None], np.nan, xyz) if made_up.any() else xyz


def surface_points(xyz: np.ndarray, points: np.ndarray, source: str = "take") -> np.ndarray:
    """Landmarks lifted onto the take's surface: a mesh take's landmark file in 3D.

    Parameters
    ----------
    xyz : (H, W, 3) float
        The repaired range image, mm, NaN where there is no surface.
    points : (n, 2) float
        Pixels on its grid.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    (n, 3) float64
        The range image's bilinear sample at each point (the fit's rules at the edge of the
        data and at a depth step, :data:`LIFT_SLOPE_DEG`); a point without one (beyond the
        face's outline, in a hole, across a step) takes the nearest pixel with data, so that
        every point lies on the surface seen at it. All NaN when the image has no data.
    """
    lifted = sample_range(xyz, np.asarray(points, dtype=np.float64), source, 0.5, LIFT_SLOPE_DEG)[0]
    missing = ~np.isfinite(lifted).all(axis=1)
    has = np.isfinite(xyz).all(axis=2)
    if missing.any() and has.any():
        rows, cols = distance_transform_edt(~has, return_distances=False, return_indices=True)
        h, w = has.shape
        r = np.clip(np.rint(points[missing, 1]).astype(int), 0, h - 1)
        c = np.clip(np.rint(points[missing, 0]).astype(int), 0, w - 1)
        lifted[missing] = xyz[rows[r, c], cols[r, c]]
    return lifted
