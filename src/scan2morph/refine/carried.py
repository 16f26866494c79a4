"""A take's map into its image with the upper face carried from the neutral, rigidly in 3D.

The template fit places a take's template by a thin-plate spline through the take's own
landmarks (:func:`scan2morph.template.fit_map`). Detected landmarks err differently in each view
of a face: on the real head's range scans the detector places the brows and the outline 10-13 px
off, and by another amount in a take whose head turned 8 degrees from the neutral's. The spline
then puts the forehead and temples on other skin than the neutral's, where the skin is too
foreshortened or plain for the refinement's correlation to correct it, and that difference
becomes motion: 10-14 mm of it on the turned side of a smile, which moves none there.

Once a take is aligned to its neutral, the skin that does not move with the mouth (the forehead,
the brows at rest, the temples, the eyes and the nose's bridge) is where the neutral's is,
carried by the alignment. The *carried map* therefore places the template's upper face (its
vertices above :data:`UPPER_FACE_BELOW`'s points: the top of the jaw line, at the eyes' height)
at the neutral's skin points moved by the take's rigid alignment and found on its range image
(:func:`scan2morph.align.carry.carry_points`), and the rest by the take's own landmarks below
that height (the mouth, the jaw, the nose's lower half): one spline through both. The motion of
the upper face is left to the refinement's correlation, as it is everywhere else.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from scan2morph.align.carry import carry_points
from scan2morph.template.tps import TPS

#: iBUG numbers (1-based) whose template height bounds the carried upper face: the jaw line's
#: top at either ear, level with the eyes.
UPPER_FACE_BELOW = (1, 17)


def in_upper_face(template, vertices: np.ndarray) -> np.ndarray:
    """Whether each of the base template's ``vertices`` (k,) int lies above
    :data:`UPPER_FACE_BELOW`'s height (the template's y grows downwards), (k,) bool."""
    level = float(np.mean(template.ibug_xy[np.array(UPPER_FACE_BELOW) - 1, 1]))
    return template.vertices[np.asarray(vertices, dtype=np.int64), 1] < level


def upper_face(template) -> np.ndarray:
    """Indices (U,) of the base template's vertices in the upper face (:func:`in_upper_face`)."""
    return np.flatnonzero(in_upper_face(template, np.arange(len(template.vertices))))


def carried_map(
    template,
    landmarks: np.ndarray,
    fiducial_set: str,
    neutral_map: Callable[[np.ndarray], np.ndarray],
    carry: Callable[[np.ndarray], np.ndarray],
    source: str = "take",
) -> TPS | None:
    """A take's map from template coordinates to its pixels, its upper face carried from the
    neutral.

    Parameters
    ----------
    template : Template
        The base template.
    landmarks : (68, 2) float
        The take's iBUG-68 landmarks, px.
    fiducial_set : str
        The take's fiducial set (:meth:`Template.fiducial_set`); those above the upper face's
        bound are left out.
    neutral_map : callable
        The neutral's fit map: template coordinates (n, 2) -> px (n, 2) in the neutral's image.
    carry : callable
        Neutral px (n, 2) -> take px (n, 2): the neutral's skin carried rigidly into the take
        (NaN where it cannot be; those points are left out).
    source : str
        ``subject/take`` for messages.

    Returns
    -------
    TPS or None
        Callable: template coordinates (n, 2) -> take px (n, 2), through the take's fiducials
        below the upper face and the carried upper face; None when the carry placed none of the
        upper face's points.
    """
    numbers, base_idx = template.fiducial_set(fiducial_set, source=source)
    src = template.vertices[base_idx]
    dst = np.asarray(landmarks, dtype=np.float64)[numbers - 1]
    below = ~in_upper_face(template, base_idx)
    upper = template.vertices[upper_face(template)]
    carried = np.asarray(carry(neutral_map(upper)), dtype=np.float64)
    found = np.isfinite(carried).all(axis=1)
    if not found.any():
        return None
    return TPS.fit(
        np.vstack([src[below], upper[found]]),
        np.vstack([dst[below], carried[found]]),
        source=source,
    )


def carried_start(
    template,
    landmarks: np.ndarray,
    fiducial_set: str,
    neutral_map: Callable[[np.ndarray], np.ndarray],
    xyz: tuple[np.ndarray, np.ndarray],
    transform: np.ndarray,
    anchors: np.ndarray,
    source: str = "take",
) -> tuple[TPS, np.ndarray] | None:
    """Where a take's refinement starts with its upper face carried from the neutral.

    Parameters
    ----------
    template, landmarks, fiducial_set, neutral_map, source
        As :func:`carried_map`'s.
    xyz : ((H, W, 3), (H', W', 3)) float
        The take's and the neutral's repaired range images, mm, NaN where there is no surface.
    transform : (4, 4) float
        Take frame -> neutral frame (the take's alignment), mm.
    anchors : (k,) int
        The base template's vertices whose fiducials pin the refinement.

    Returns
    -------
    (take_map, anchors) or None
        ``take_map``: :func:`carried_map`, the neutral's skin carried by
        :func:`~scan2morph.align.carry.carry_points` (which finds nothing when fewer than 3
        points are on the take's surface: then None); ``anchors`` (k',) int: those below the
        upper face (the take's landmarks above it are no constraint).
    """
    take_xyz, neutral_xyz = xyz

    def carry(points: np.ndarray) -> np.ndarray:
        return carry_points(take_xyz, neutral_xyz, points, transform, source)

    take_map = carried_map(template, landmarks, fiducial_set, neutral_map, carry, source)
    if take_map is None:
        return None
    return take_map, np.asarray(anchors)[~in_upper_face(template, anchors)]


__all__ = ["UPPER_FACE_BELOW", "carried_map", "carried_start", "in_upper_face", "upper_face"]
