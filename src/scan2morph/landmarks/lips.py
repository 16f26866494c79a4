"""The mouth of a doubtful detection placed on the lips' colour edge: :func:`fit_lips`.

iBUG's outer lip contour (points 49-60) is the lips' vermilion border, where the skin turns red:
an edge of the image's red-green chroma (CIELAB ``a*``) that no face shape has to be learnt for.
On the real head the cascade, trained on synthetic faces whose lips are drawn with a sharp edge,
puts the mouth 7 px off (median; the corners 11-21 px, the mouth too wide), while the chroma
edge of its lips is plain. :func:`fit_lips` moves the detected 20 mouth points as one shape,
a shift and a stretch along the mouth's own axes (the line through its corners and across it),
to where their outline runs along the strongest outward fall of ``a*``: the shape's details
stay the detector's, its place and size come from the lips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates

from scan2morph.landmarks.image_fit import ascend, region, smoothed_channel

#: The mouth's points in iBUG-68 order (0-based): the outer contour (12), then the inner (8).
MOUTH = slice(48, 68)
#: The outer contour's points within :data:`MOUTH`, in order around the lips.
OUTER = 12
#: Outline samples per segment of the outer contour.
SAMPLES_PER_SEGMENT = 6
#: The chroma's smoothing (Gaussian sigma) as a share of the mouth's width.
SMOOTHING = 0.025
#: The region searched about the detected mouth, as a share of its width on every side: the
#: mouth's points stay within it.
MARGIN = 0.6
#: The search's steps (the shifts' as a share of the mouth's width, the stretches' as a factor),
#: coarse to fine; at each, steps are taken while one improves the edge.
STEPS = (0.08, 0.04, 0.02, 0.01)
#: The coarse grid of shifts the search also starts from (the best of): steps of this share of
#: the mouth's width, along the mouth and across it, up to :data:`GRID_REACH` either way.
GRID = 0.1
GRID_REACH = 0.3
#: The stretch's bounds along the mouth's axis and across it.
STRETCH = ((0.6, 1.5), (0.6, 1.6))
#: Below this standard deviation of the smoothed ``a*`` about the mouth (8-bit levels) the image
#: has no lips' colour to follow and the points stay: a grey shading of a geometry-only scan
#: (0), or a colour camera's noise alone (0.2-0.6 levels once smoothed; raw, noise of 1.5 grey
#: levels per channel exceeds 1). Lips give 4.8-5.7 on the real head's renders, 7.5 and more on
#: the synthetic heads.
MIN_CHROMA = 2.0


@dataclass(frozen=True)
class LipFit:
    """A detection's mouth placed by :func:`fit_lips`.

    Attributes
    ----------
    points : (68, 2) float64
        The landmarks, px; only the 20 mouth points (iBUG 49-68) differ from the given ones.
    moved_px : float
        The median distance the mouth points moved, px (0: no colour to follow).
    edge_before, edge_after : float
        The mean outward fall of ``a*`` across the outer contour, in standard deviations of
        ``a*`` about the mouth per mouth width, at the detected and at the fitted place.
    """

    points: np.ndarray
    moved_px: float
    edge_before: float
    edge_after: float


def outline(mouth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples along the outer lip contour and its outward normals.

    Parameters
    ----------
    mouth : (20, 2) float
        The mouth points (iBUG 49-68), px.

    Returns
    -------
    samples : (12 * SAMPLES_PER_SEGMENT, 2) float64
        px.
    normals : (12 * SAMPLES_PER_SEGMENT, 2) float64
        Unit vectors pointing away from the contour's centre.
    """
    start = np.asarray(mouth[:OUTER], dtype=np.float64)
    end = np.roll(start, -1, axis=0)
    t = (np.arange(SAMPLES_PER_SEGMENT) + 0.5) / SAMPLES_PER_SEGMENT
    samples = (start[:, None] + (end - start)[:, None] * t[:, None]).reshape(-1, 2)
    along = np.repeat(end - start, SAMPLES_PER_SEGMENT, axis=0)
    normals = np.stack([along[:, 1], -along[:, 0]], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    inward = np.einsum("ij,ij->i", normals, samples - start.mean(axis=0)) < 0
    normals[inward] *= -1
    return samples, normals


def _chroma_gradient(color: np.ndarray, box: tuple, width: float):
    """The gradient (gx, gy) of the smoothed, standardised ``a*`` of the region ``box``; None
    where the region has no lips' colour (grey, or flatter than :data:`MIN_CHROMA`)."""
    read = smoothed_channel(color, box, 1, SMOOTHING * width, MIN_CHROMA)
    if read is None:
        return None
    chroma, _, spread = read
    gy, gx = np.gradient((chroma - chroma.mean()) / spread)
    return gx, gy


def fit_lips(color: np.ndarray, points: np.ndarray) -> LipFit:
    """Move the detected mouth onto the lips' colour edge.

    Parameters
    ----------
    color : (H, W, 3) or (H, W, 4) array
        The take's colour image (RGB, uint8; floats in [0, 1] and wider integers are scaled) on
        its pixel grid; a grey image, (H, W) or (H, W, 1), keeps the points.
    points : (68, 2) float
        The detected iBUG-68 points, px (x right, y down).

    Returns
    -------
    LipFit
        The points with the mouth shifted (along the mouth's axis through its corners, iBUG 49
        and 55, and across it) and stretched along both (0.6-1.5 along, 0.6-1.6 across) to
        where its outer contour meets the strongest mean outward fall of ``a*``: coordinate
        searches, each step a share of the mouth's width (:data:`STEPS`), from the detected
        place and, when the best of a grid of shifts (:data:`GRID`, up to :data:`GRID_REACH` of
        the width either way) lies higher than where that search ends, from there too, the
        higher end kept: never below the detection's own edge.
    """
    points = np.asarray(points, dtype=np.float64)
    mouth = points[MOUTH]
    same = LipFit(points, 0.0, 0.0, 0.0)
    axis = mouth[6] - mouth[0]
    width = float(np.linalg.norm(axis))
    if color.ndim != 3 or color.shape[2] < 3 or not np.isfinite(mouth).all() or width < 4.0:
        return same
    box = region(mouth, MARGIN * width, color.shape)
    gradient = None if box is None else _chroma_gradient(color, box, width)
    if gradient is None:
        return same
    lo, hi = box
    u = axis / width
    frame = np.stack([u, [-u[1], u[0]]])  # rows: along the mouth, across it
    centre = mouth.mean(axis=0)
    local = (mouth - centre) @ frame.T

    def place(t: np.ndarray) -> np.ndarray:
        return centre + (local * t[2:] + t[:2]) @ frame

    def edge(shape: np.ndarray) -> float:
        samples, normals = outline(shape - lo)
        at = [samples[:, 1], samples[:, 0]]
        g = np.stack([map_coordinates(c, at, order=1, mode="nearest") for c in gradient], axis=1)
        return -float(np.mean(np.einsum("ij,ij->i", g, normals))) * width

    def value(t: np.ndarray) -> float:  # -inf beyond the stretch's bounds or the region
        shape = place(t)
        stretched = all(a <= s <= b for s, (a, b) in zip(t[2:], STRETCH, strict=True))
        return edge(shape) if stretched and (shape >= lo).all() and (shape <= hi).all() else -np.inf

    start = np.array([0.0, 0.0, 1.0, 1.0])
    before = edge(place(start))
    # a detection far off the lips (a smiling mouth 10 px low) sees no edge from where it is: the
    # search also starts from the best of a coarse grid of shifts, and the higher end wins
    shifts = GRID * np.arange(-round(GRID_REACH / GRID), round(GRID_REACH / GRID) + 1) * width
    grid = [np.array([x, y, 1.0, 1.0]) for x in shifts for y in shifts]
    scores = [value(t) for t in grid]
    unit = np.array([width, width, 1.0, 1.0])
    # from the detection as before the grid: its own edge (also when a point lies off the
    # region, where the search's value is -inf), so that the answer is never below it
    best, score = ascend(value, start, before, unit, STEPS)
    k = int(np.argmax(scores))
    if scores[k] > score + 1e-9:  # the grid's best place lies higher than that end: climb it
        found, value_found = ascend(value, grid[k], scores[k], unit, STEPS)
        if value_found > score + 1e-9:
            best, score = found, value_found
    out = points.copy()
    out[MOUTH] = place(best)
    moved = float(np.median(np.linalg.norm(out[MOUTH] - mouth, axis=1)))
    return LipFit(out, moved, before, score)
