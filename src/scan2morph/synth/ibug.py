"""The rest mesh's landmarks under the iBUG annotation's conventions (issue #33).

The generator's own truth (:mod:`~scan2morph.synth.landmarks`, the default) differs from how
iBUG, and our hand annotation of the real head (``tests/support/lps_landmarks.py``), place
some points. This module gives the rest mesh's points under the annotation's rules where they
differ and do not depend on the view:

* nose bridge (28-30): 28 on the midline at the inner eye corners' height (not 3 mm above the
  eyes' centres), 29 and 30 evenly between it and the tip 31;
* brows (18-27): five points on each brow's middle line (not 1 mm above it), the first and the
  last at the brow's ends (where its hair fades to half, 12.5 and 54 mm from the midline), the
  rest evenly between;
* open eyes' lid points (38, 39, 41, 42, 44, 45, 47, 48): on the lid margins at a third and two
  thirds of the way between the corners (not at 60 degrees around the opening); closed eyes
  already follow iBUG.

The jawline (1-17) depends on the view: :mod:`~scan2morph.synth.convention` traces it per take.
The other points (the eye corners, the nose's tip and bottom, the lips) are the generator's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.synth.features import _RestMesh
from scan2morph.synth.landmarks import _Front, _lid_cover, _nose

#: Where an eyebrow's hair is half faded at its inner and outer ends, mm from the midline
#: (the middle of the albedo's ramps, :func:`scan2morph.synth.albedo._brow_band`).
BROW_ENDS_MM = (12.5, 54.0)
#: Fractions of the way from the inner to the outer eye corner of the lid points.
LID_FRACTIONS = (1.0 / 3.0, 2.0 / 3.0)
#: Half-width of the strip across the eye's axis in which a lid point is looked for, mm.
_STRIP_MM = 0.9


@dataclass(frozen=True)
class IbugRest:
    """What the ``ibug`` convention needs of a head at rest.

    Attributes
    ----------
    landmarks : (68,) int64
        Vertex indices of the 68 points under the iBUG conventions, the jawline (1-17) left as
        the generator's (it is traced per view).
    jaw_candidates : (C,) int64
        Skin vertices the jawline may pass through: in front of the ears, off the neck, in the
        face's front half, no higher than ``jaw_top_y`` + 10 mm.
    jaw_top_y : float
        Height where the jawline ends on either side: the outer eye corners' mean height minus
        6 mm (head frame, mm).
    """

    landmarks: np.ndarray
    jaw_candidates: np.ndarray
    jaw_top_y: float


def _brows_ibug(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 18-27: five points on each brow's middle line, from end to end."""
    out = np.zeros(10, np.int64)
    inner, outer = BROW_ENDS_MM
    for k, ax in enumerate(np.linspace(outer, inner, 5)):
        yb = float(mesh.shape.brow_line(ax)[0])
        out[k] = front.visible(-ax, yb)
        out[9 - k] = front.visible(ax, yb)
    return out


def _lid_points(mesh: _RestMesh, front: _Front, corners: np.ndarray) -> np.ndarray:
    """Landmarks 37-48 of open eyes with the lid points at a third and two thirds between the
    corners, on the lid margins (the first lid skin across the axis, seen from the front).

    Parameters
    ----------
    mesh : _RestMesh
    front : _Front
    corners : (2,) int64
        Vertex indices of the subject's left eye's inner (43) and outer (46) corners.

    Returns
    -------
    (12,) int64
        Landmarks 37-48 (the right eye mirrors the left).
    """
    verts = mesh.vertices
    rel, _, covering = _lid_cover(mesh, front)
    ec = mesh.shape.eye_centre[:2]
    c_in, c_out = verts[corners[0], :2] - ec, verts[corners[1], :2] - ec
    length = float(np.linalg.norm(c_out - c_in))
    axis = (c_out - c_in) / length
    up = np.array([-axis[1], axis[0]])
    if up[1] < 0.0:
        up = -up
    along = (rel - c_in) @ axis
    across = (rel - c_in) @ up
    pts = {}
    for f in LID_FRACTIONS:
        strip = covering & (np.abs(along - f * length) < _STRIP_MM)
        for side in (1.0, -1.0):
            ok = strip & (side * across > 0.0)
            best = np.flatnonzero(ok)[np.argmin(side * across[ok])]
            pts[f, side] = front.visible(*front.xy[best])
    f1, f2 = LID_FRACTIONS
    left = np.array(
        [corners[0], pts[f1, 1.0], pts[f2, 1.0], corners[1], pts[f2, -1.0], pts[f1, -1.0]],
        np.int64,
    )
    right = [front.visible(-verts[left[k], 0], verts[left[k], 1]) for k in (3, 2, 1, 0, 5, 4)]
    return np.concatenate([right, left])


def _jaw_candidates(mesh: _RestMesh, front: _Front, top_y: float) -> np.ndarray:
    """Skin vertices the jawline may pass through (see :class:`IbugRest`)."""
    shape, pc = mesh.shape, mesh.vertices[front.index]
    neck = shape.neck(pc) < np.minimum(shape.jaw.sdf(pc), shape.chin.sdf(pc)) - 1.0
    ok = shape.clear_of_ears(pc) & ~neck & (front.z > 15.0 * shape.scale[2])
    ok &= pc[:, 1] <= top_y + 10.0
    return front.index[ok].astype(np.int64)


def ibug_rest(mesh: _RestMesh, segment: np.ndarray, landmarks: np.ndarray) -> IbugRest:
    """The rest mesh's points under the iBUG conventions.

    Parameters
    ----------
    mesh : _RestMesh
    segment : (F,) int8
        Final ``SEG_*`` code of each face.
    landmarks : (68,) int64
        The generator's own landmarks of the mesh (:func:`~scan2morph.synth.landmarks._landmarks`).

    Returns
    -------
    IbugRest
    """
    front = _Front.of(mesh, segment)
    verts = mesh.vertices
    lm = np.array(landmarks, np.int64)
    lm[17:27] = _brows_ibug(mesh, front)
    y_inner = float(np.mean(verts[landmarks[[39, 42]], 1]))
    lm[27:36] = _nose(mesh, front, y28=y_inner)
    if not mesh.shape.lids:  # closed eyes already follow iBUG
        lm[36:48] = _lid_points(mesh, front, landmarks[[42, 45]])
    top_y = float(np.mean(verts[landmarks[[36, 45]], 1])) - 6.0
    return IbugRest(lm, _jaw_candidates(mesh, front, top_y), top_y)
