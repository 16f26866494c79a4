"""The chin of a doubtful detection placed on the face's outline below the mouth: :func:`fit_chin`.

iBUG's chin point (9) is the bottom of the face's outline as seen from the front, and the template
fit takes it as its lowest point. On the real head the cascade, trained on synthetic faces only,
puts it 7-40 px too low (median 18.6 px over its renders at about 1.6 px per mm; 5-23 px on the
real user's takes), on the throat, and a fit stretched down by it reaches onto the neck, where a
stereo scan's data is poor. Where the outline runs is in the take's geometry: down the face's
midline from the lower lip the surface comes forward over the chin and then turns back under it.

:func:`fit_chin` follows that profile in the face's own frame, not the camera's, so that a head
raised or lowered finds the same point:

1. the frame from the measured surface at the eye corners (iBUG 37, 40, 43, 46) and the mouth
   corners (49, 55): ``right`` along the outer eye corners, ``up`` from the mouth corners'
   middle to the eyes', ``forward`` perpendicular to both, towards the side of the nose tip (31);
2. the midline in the image: the straight line that fits the midpoints of the nose's root and
   bottom and of the lips (28, 34, 52, 63, 67, 58; not the nose's bridge and tip, which stand
   out of the face and slide sideways in a turned view), sampled from the lower lip's bottom
   (58) away from the nose, up to the image's edge, and read on the surface;
3. along it, the profile's height (``up``) and depth (``forward``), each surface between jumps
   smoothed by :data:`SMOOTHING_MM` on its own; past the most forward point (the chin's front),
   the chin is the first sample where the profile runs back within :data:`OUTLINE_DEG` of
   ``forward`` (the surface's normal more than 90 - that from ``forward``: the 72 degrees of our
   annotation's silhouette), or where it is flattest (no flatter just beyond) within
   :data:`FLATTEST_DEG`, or where the surface ends within the image or jumps (the chin in front
   of the neck, a shadow under it);
4. point 9 goes there and the rest of the jawline follows it, by a share falling linearly from 1
   at the chin to 0 at the jaw's ends (1 and 17, at the ears, stay).

Where the frame, the midline or the outline cannot be read (no surface at the points, a face
with no chin in front of its throat, a profile that reaches the image's edge before it turns, an
outline farther than :data:`MAX_MOVE` from the detection) the points stay as detected.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.ndimage import gaussian_filter1d

from scan2morph.landmarks.jaw import JAW
from scan2morph.template.sample import sample_range

#: iBUG-68 indices (0-based): the chin, the frame's eye and mouth corners, the nose tip, the
#: midline points the image's midline is fitted to (the nose's root and bottom, the lips'
#: midpoints), the nose's root and the lower lip's bottom.
CHIN = 8
EYE_CORNERS = (36, 39, 42, 45)
MOUTH_CORNERS = (48, 54)
NOSE_TIP = 30
MIDLINE = (27, 33, 51, 62, 66, 57)
NOSE_ROOT, LOWER_LIP = 27, 57
#: The profile is searched from this share of the outer eye corners' distance below the lower
#: lip (past the fold under the lip, about 14 mm: a lower lip standing in front of the chin is
#: not taken for its front) to this share (below the chin, about 90 mm).
START, END = 0.15, 1.0
#: Samples along the profile, px.
STEP_PX = 0.5
#: Smoothing of the profile (Gaussian sigma), mm.
SMOOTHING_MM = 1.5
#: The outline: where the profile runs back within this angle of ``forward``, degrees.
OUTLINE_DEG = 18.0
#: ... or where it is flattest within this angle, degrees (no sample over the next
#: ``FLAT_AHEAD_MM`` mm, counted in median steps, flatter by more than ``FLAT_TOLERANCE_DEG``
#: degrees): an under-chin whose
#: slope in the face's frame runs just above :data:`OUTLINE_DEG` (the real head's at 19 degrees,
#: raised 5 degrees and turned 10) would otherwise be followed onto the throat.
FLATTEST_DEG = 25.0
FLAT_AHEAD_MM, FLAT_TOLERANCE_DEG = 2.0, 0.5
#: A step between neighbouring samples longer than this many times their median step is a jump
#: (the chin seen in front of the neck; the surface at 72 degrees stretches a step 3.2 times).
#: Across a gap in the data (``k`` samples missing) the step may be longer by what skin at 72
#: degrees spans over the missing samples; beyond that it is a jump (a shadow under the chin).
#: A gap longer than ``MAX_GAP_MM`` (at the median step) is never bridged: over a long shadow
#: that allowance would reach the neck behind the chin.
JUMP = 8.0
MAX_GAP_MM = 3.0
#: Below this median step between samples (mm) the profile is not a face's at any scale.
MIN_SPACING_MM = 1e-3
#: The nose tip must stand this far in front of the eye and mouth corners for the frame's
#: ``forward`` to be told from its opposite, mm (faces: 20-35).
MIN_NOSE_MM = 5.0
#: The chin moves at most this share of the outer eye corners' distance (the real head's
#: detections: 0.02-0.33, the far one turned 20 degrees).
MAX_MOVE = 0.4


@dataclass(frozen=True)
class ChinFit:
    """A detection's chin placed by :func:`fit_chin`.

    Attributes
    ----------
    points : (68, 2) float64
        The landmarks, px: the jawline (iBUG 1-17) moved with the chin, the others as given.
    moved_px : float
        How far the chin moved, px (0 when it stayed).
    """

    points: np.ndarray
    moved_px: float


def _surface(xyz: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The surface (n, 3) mm at pixels ``uv`` (n, 2): bilinear, NaN where a neighbour pixel has
    no data or the pixel is off the grid (:func:`~scan2morph.template.sample.sample_range`)."""
    return sample_range(xyz, uv, "the chin's profile")[0]


def _frame(xyz: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The face's ``up`` and ``forward`` (unit (3,) each, step 1), or None."""
    corners = _surface(xyz, points[list(EYE_CORNERS + MOUTH_CORNERS + (NOSE_TIP,))])
    if not np.isfinite(corners).all():
        return None
    eyes, mouth, nose = corners[:4], corners[4:6], corners[6]
    right = eyes[3] - eyes[0]
    up = eyes.mean(axis=0) - mouth.mean(axis=0)
    forward = np.cross(right, up)
    norm = np.linalg.norm(forward)
    if not norm > 0:
        return None
    forward /= norm
    up = np.cross(forward, right)
    up /= np.linalg.norm(up)
    lead = float(forward @ (nose - corners[:6].mean(axis=0)))
    if abs(lead) < MIN_NOSE_MM:
        return None
    return up, forward * np.sign(lead)


def _outline(profile: np.ndarray, up: np.ndarray, forward: np.ndarray) -> int | None:
    """Index of the chin's outline on a profile (n, 3) mm read down the midline (step 3); the
    profile ends at the image's edge (NaN within it: no surface there)."""
    at = np.flatnonzero(np.isfinite(profile).all(axis=1))
    if at.size < 3:
        return None
    p = profile[at]
    gap = np.diff(at)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    spacing = float(np.median(step[gap == 1])) if (gap == 1).any() else np.nan
    if not (np.isfinite(spacing) and spacing >= MIN_SPACING_MM):
        return None
    stretch = 1.0 / np.cos(np.radians(90.0 - OUTLINE_DEG))
    # the surfaces between jumps (one in front of another: a lip's shadow, the neck behind the
    # chin), each smoothed on its own
    jump = (step > spacing * (JUMP + (gap - 1) * stretch)) | ((gap - 1) * spacing > MAX_GAP_MM)
    cuts = np.flatnonzero(jump) + 1
    height, depth = (
        np.concatenate(
            [
                gaussian_filter1d(x, SMOOTHING_MM / spacing, mode="nearest")
                for x in np.split(v, cuts)
            ]
        )
        for v in (p @ up, p @ forward)
    )
    front = int(np.argmax(depth))  # the chin's front, on the surface from ``lo`` to ``hi``
    k = np.searchsorted(cuts, front, side="right")
    lo, hi = (int(cuts[k - 1]) if k > 0 else 0), (int(cuts[k]) if k < len(cuts) else len(at))
    if hi - lo >= 3:
        tangent = np.stack([np.gradient(height[lo:hi]), np.gradient(depth[lo:hi])], axis=1)
        length = np.linalg.norm(tangent, axis=1)
        back = -tangent[:, 1] / np.maximum(length, 1e-300)  # the profile's run backwards
        angle = np.degrees(np.arccos(np.clip(back, -1.0, 1.0)))  # from forward
        # the flattest place: none flatter by FLAT_TOLERANCE_DEG over the next FLAT_AHEAD_MM
        w = int(np.ceil(FLAT_AHEAD_MM / spacing))
        # past the segment's end nothing is flatter where the surface ends or jumps; at the
        # image's edge the profile may run on flatter beyond it
        edge = hi == len(at) and at[-1] == len(profile) - 1
        ahead = np.concatenate([angle[1:], np.full(w, -np.inf if edge else np.inf)])
        ahead = sliding_window_view(ahead, w).min(axis=1)
        turned = (angle <= OUTLINE_DEG) | (
            (angle <= FLATTEST_DEG) & (angle <= ahead + FLAT_TOLERANCE_DEG)
        )
        turned = np.flatnonzero(turned[front - lo :])
        if turned.size:
            return int(at[front + int(turned[0])])
    ended = hi < len(at) or at[-1] < len(profile) - 1  # a jump, or no surface within the image
    if ended and front < hi - 1:
        return int(at[hi - 1])
    return None


def fit_chin(xyz: np.ndarray, points: np.ndarray) -> ChinFit:
    """Place a detection's chin (iBUG 9) on the face's outline below the mouth.

    Parameters
    ----------
    xyz : (H, W, 3) float
        The take's surface on its pixel grid, mm (NaN where there is none).
    points : (68, 2) float
        The detected iBUG-68 landmarks, px.

    Returns
    -------
    ChinFit
        The points with the jawline following the chin (module docstring), or as given.
    """
    points = np.asarray(points, dtype=np.float64)
    kept = ChinFit(points.copy(), 0.0)
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or min(xyz.shape[:2]) < 2:
        return kept
    if points.shape != (68, 2) or not np.isfinite(points).all():
        return kept
    frame = _frame(xyz, points)
    if frame is None:
        return kept
    mid = points[list(MIDLINE)]
    direction = np.linalg.svd(mid - mid.mean(axis=0))[2][0]
    if direction @ (points[LOWER_LIP] - points[NOSE_ROOT]) < 0:  # away from the nose
        direction = -direction
    eyes = float(np.linalg.norm(points[EYE_CORNERS[3]] - points[EYE_CORNERS[0]]))
    along = np.arange(START * eyes, END * eyes, STEP_PX)
    pixels = points[LOWER_LIP] + np.outer(along, direction)
    inside = (pixels >= 0.0).all(axis=1) & (pixels <= [xyz.shape[1] - 1, xyz.shape[0] - 1]).all(
        axis=1
    )
    pixels = pixels[: int(np.argmin(inside)) if not inside.all() else len(pixels)]
    k = _outline(_surface(xyz, pixels), *frame)
    if k is None:
        return kept
    shift = pixels[k] - points[CHIN]
    moved = float(np.linalg.norm(shift))
    if moved > MAX_MOVE * eyes:
        return kept
    out = points.copy()
    share = 1.0 - np.abs(JAW - CHIN) / CHIN
    out[JAW] += share[:, None] * shift
    return ChinFit(out, moved)
