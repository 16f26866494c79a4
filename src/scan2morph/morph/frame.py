"""The head frame of a subject: where glTF viewers expect a face (metres, +Y up, facing +Z).

The meshes stay in the **neutral frame** (the neutral take's scanner frame, mm): an arbitrary
right-handed frame in which no axis can be assumed to be up or towards the face. The head frame
is built from named template points of the neutral mesh (glTF's convention, as a viewer on +Z
looking down -Z sees the face from the front):

- origin: the midpoint of the four eye corners (between the eyes);
- +X: from the subject's right eye to the subject's left eye (the centre of each eye's two
  corners), i.e. to the viewer's right;
- +Y: up, from the midpoint of the mouth corners towards the origin, made orthogonal to X;
- +Z = X x Y: out of the face, towards the viewer (checked: the nose tip lies at +Z);
- unit: metres.

Why the mouth corners and not the nose ridge or the forehead for "up": on the synthetic heads the
eye-to-mouth-corner line lies within 2 degrees of the head's vertical, while the nose ridge
(bridge to tip) leans 28-30 degrees and the eyes-to-nose-tip line 43-45 degrees, varying with
the nose; the forehead centre is no clicked landmark (the thin-plate spline extrapolates it). Only
the neutral mesh is used (its mouth is closed), so the frame is the same for every take's model.

:func:`head_frame` returns the (4, 4) matrix ``H`` with ``[p_head_m, 1] = H @ [p_neutral_mm, 1]``:
``H[:3, :3] = 0.001 * R`` (rows of R: the X, Y, Z axes in the neutral frame) and
``H[:3, 3] = -0.001 * R @ origin``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.errors import InputError

#: Named template points the head frame is built from.
EYE_RIGHT = ("eye_r_outer", "eye_r_inner")
EYE_LEFT = ("eye_l_inner", "eye_l_outer")
MOUTH = ("mouth_r", "mouth_l")
NOSE_TIP = "nose_tip"
#: Head-frame unit per neutral-frame unit (mm -> m).
MM_TO_M = 1e-3
#: The head frame in words (glTF node and asset extras).
HEAD_FRAME_NAME = (
    "head frame of the neutral, metres: origin between the eyes (midpoint of the four eye "
    "corners), +X to the subject's left (the viewer's right), +Y up (mouth corners to eyes), "
    "+Z out of the face"
)


def head_frame(
    vertices: np.ndarray, named: Mapping[str, int], *, source: str = "head frame"
) -> np.ndarray:
    """The transform from the neutral frame (mm) to the head frame (m) of a neutral mesh.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        The neutral mesh (``/neutral/vertices``), in any right-handed frame.
    named : mapping name -> vertex index
        ``Template.named`` (base indices stay valid after subdivision).
    source : str
        Label for error messages.

    Returns
    -------
    (4, 4) float64
        ``H``, see the module docstring; ``H[:3, :3] / 0.001`` is a rotation (det +1).

    Raises
    ------
    InputError
        A named point missing or not finite, coincident eyes, eyes in line with the mouth, or a
        nose tip behind the eyes (a mirrored, left-handed mesh).
    """
    v = np.asarray(vertices, dtype=np.float64)
    names = (*EYE_RIGHT, *EYE_LEFT, *MOUTH, NOSE_TIP)
    missing = [n for n in names if n not in named]
    if missing:
        raise InputError(source, f"named template points missing: {missing}")
    p = {n: v[named[n]] for n in names}
    if not all(np.isfinite(x).all() for x in p.values()):
        raise InputError(source, "a named point of the neutral mesh is not finite")
    right = 0.5 * (p[EYE_RIGHT[0]] + p[EYE_RIGHT[1]])
    left = 0.5 * (p[EYE_LEFT[0]] + p[EYE_LEFT[1]])
    origin = 0.5 * (right + left)
    mouth = 0.5 * (p[MOUTH[0]] + p[MOUTH[1]])
    x = left - right
    if np.linalg.norm(x) <= 0:
        raise InputError(source, "the two eyes coincide: no head frame")
    x /= np.linalg.norm(x)
    y = origin - mouth
    y -= x * (x @ y)
    if np.linalg.norm(y) <= 1e-6 * np.linalg.norm(left - right):
        raise InputError(source, "the mouth lies on the line through the eyes: no head frame")
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    if z @ (p[NOSE_TIP] - origin) <= 0:
        raise InputError(
            source, "the nose tip lies behind the eyes: the mesh is mirrored (left-handed)"
        )
    rot = np.stack([x, y, z])
    out = np.eye(4)
    out[:3, :3] = MM_TO_M * rot
    out[:3, 3] = -MM_TO_M * rot @ origin
    return out


def apply_frame(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (..., 3) mapped by a (4, 4) affine transform."""
    t = np.asarray(transform, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ t[:3, :3].T + t[:3, 3]


__all__ = ["HEAD_FRAME_NAME", "MM_TO_M", "apply_frame", "head_frame"]
