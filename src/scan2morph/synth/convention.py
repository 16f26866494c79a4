"""Which landmark conventions a take's truth follows, and the per-view jawline (issue #33).

Two conventions:

* ``synth`` (the default): the generator's own points, :attr:`HeadModel.landmarks
  <scan2morph.synth.head.HeadModel>` (the jawline on the rest face's frontal outline);
* ``ibug``: the rules of our hand annotation of the real head (``tests/support/
  lps_landmarks.py``) as far as the synthetic head allows: the rest points of
  :mod:`~scan2morph.synth.ibug` and, per take, the jawline on the silhouette the take's camera
  sees: where the face's surface turns beyond 72 degrees from the view ray, from 6 mm below the
  outer eye corners on one side round the chin to the other, 17 points at equal arc lengths in
  the image.

Either way a take's truth points are vertices of the articulated head (68 indices).
"""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals
from scan2morph.open3d_light import open3d, triangle_scene

#: The conventions a take's truth can follow; the first is the default.
CONVENTIONS = ("synth", "ibug")
#: Beyond this angle between the surface normal and the view ray the surface is on the
#: silhouette, degrees (the annotation's).
SILHOUETTE_DEG = 72.0
#: Angular bins of the outline about the mouth centre, degrees.
_BIN_DEG = 1.0
#: An outline point more than this fraction nearer the mouth than the farthest of its
#: :data:`_DIP_BINS` neighbours on either side is not on the outline (a bin it barely reaches).
_DIP, _DIP_BINS = 0.03, 2
#: A candidate is visible when the first surface on its ray is no nearer than this, mm.
_VISIBLE_MM = 0.5


def check_convention(convention: str, source: str = "convention") -> str:
    """``convention`` if it is one of :data:`CONVENTIONS`, else :class:`InputError`."""
    if convention not in CONVENTIONS:
        raise InputError(source, f"expected one of {CONVENTIONS}, got {convention!r}")
    return convention


def landmark_vertices(
    head, vertices: np.ndarray, view: np.ndarray, convention: str = "synth"
) -> np.ndarray:
    """Vertex indices of a take's 68 truth landmarks.

    Parameters
    ----------
    head : HeadModel
    vertices : (N, 3) float64
        The articulated head, head frame, mm.
    view : (4, 4) float64
        Head frame -> the frame of the camera whose image the landmarks are for (camera at
        the origin looking along +z); used by ``ibug`` only.
    convention : str
        One of :data:`CONVENTIONS`.

    Returns
    -------
    (68,) int64
        ``head.landmarks`` itself for ``synth``.
    """
    if check_convention(convention) == "synth":
        return head.landmarks
    rest = head.ibug
    out = np.array(rest.landmarks, np.int64)
    out[:17] = silhouette_jaw(head, vertices, view, rest.jaw_candidates, rest.jaw_top_y)
    return out


def visible(cam_vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which points of a surface the camera sees (ray cast with Open3D).

    Parameters
    ----------
    cam_vertices : (N, 3) float64
        The mesh in the camera frame (camera at the origin), mm.
    faces : (F, 3) int64
    points : (C, 3) float64
        Points on the mesh, camera frame, mm.

    Returns
    -------
    (C,) bool
        No surface nearer than the point by more than :data:`_VISIBLE_MM` along its ray.
    """
    o3d = open3d()
    scene = triangle_scene(cam_vertices, faces)
    dist = np.linalg.norm(points, axis=1)
    rays = np.concatenate([np.zeros_like(points), points / dist[:, None]], axis=1)
    hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    return hit >= dist - _VISIBLE_MM


def _outline(cam: np.ndarray, facing: np.ndarray, centre: np.ndarray, down: np.ndarray):
    """The face's outline about ``centre``: per angular bin the farthest facing candidate,
    bins whose point lies well inside their neighbours' left out.

    Parameters
    ----------
    cam : (C, 3) float64
        Visible candidates in the camera frame, mm.
    facing : (C,) bool
        Those within :data:`SILHOUETTE_DEG` of the view ray.
    centre : (2,) float64
        The mouth centre on the normalised image plane (x/z, y/z).
    down : (2,) float64
        Unit direction of the face's chin on that plane.

    Returns
    -------
    pick : (B,) int64
        Indices into ``cam`` of the outline's points, by angle.
    uv : (B, 2) float64
        Their normalised image coordinates.
    psi : (B,) float64
        Their angle from ``down``, degrees.
    """
    uv = cam[:, :2] / cam[:, 2:3]
    rel = uv - centre
    side = np.array([-down[1], down[0]])  # ``down`` turned a quarter
    psi = np.degrees(np.arctan2(rel @ side, rel @ down))
    rho = np.hypot(rel[:, 0], rel[:, 1])
    idx = np.flatnonzero(facing)
    bins = np.round(psi[idx] / _BIN_DEG).astype(int)
    order = np.lexsort((-rho[idx], bins))
    first = np.r_[True, bins[order][1:] != bins[order][:-1]]
    pick = idx[order[first]]
    pick = pick[np.argsort(psi[pick])]
    r = rho[pick]
    padded = np.pad(r, _DIP_BINS, mode="edge")
    near = np.lib.stride_tricks.sliding_window_view(padded, 2 * _DIP_BINS + 1).max(axis=1)
    pick = pick[r >= (1.0 - _DIP) * near]
    return pick, uv[pick], psi[pick]


def silhouette_jaw(
    head, vertices: np.ndarray, view: np.ndarray, candidates: np.ndarray, top_y: float
) -> np.ndarray:
    """Landmarks 1-17 on the face's silhouette as a camera sees it.

    Of the ``candidates`` the camera sees whose surface turns less than
    :data:`SILHOUETTE_DEG` from the view ray, per degree of angle about the mouth centre on
    the image the farthest one (see :func:`_outline`); the
    outline is followed from the chin outwards on either side until it rises above ``top_y``
    (rest height), and 17 points are set on it at equal arc lengths on the image.

    Parameters
    ----------
    head : HeadModel
    vertices : (N, 3) float64
        The articulated head, head frame, mm.
    view : (4, 4) float64
        Head frame -> camera frame (camera at the origin looking along +z).
    candidates : (C,) int64
        Vertices the jawline may pass through (:class:`~scan2morph.synth.ibug.IbugRest`).
    top_y : float
        Rest height where the jawline ends on either side, mm.

    Returns
    -------
    (17,) int64
        Vertex indices, iBUG 1 (the subject's right) to 17.
    """
    R, t = view[:3, :3], view[:3, 3]
    v_cam = vertices @ R.T + t
    cam = v_cam[candidates]
    normals = vertex_normals(vertices, head.faces, fill=0.0)[candidates] @ R.T
    ray = cam / np.linalg.norm(cam, axis=1, keepdims=True)
    seen = visible(v_cam, head.faces, cam)
    cam, candidates, normals, ray = cam[seen], candidates[seen], normals[seen], ray[seen]
    facing = -np.sum(normals * ray, axis=1) > np.cos(np.deg2rad(SILHOUETTE_DEG))
    mouth = np.concatenate([vertices[head.slit_upper], vertices[head.slit_lower]]).mean(0)
    m_cam = mouth @ R.T + t
    below = (mouth - [0.0, 20.0, 0.0]) @ R.T + t
    centre = m_cam[:2] / m_cam[2]
    down = below[:2] / below[2] - centre
    down /= np.linalg.norm(down)
    pick, uv, psi = _outline(cam, facing, centre, down)
    rest_y = head.vertices[candidates[pick], 1]
    chin = int(np.argmin(np.abs(psi)))
    lo = chin
    while lo > 0 and rest_y[lo - 1] <= top_y:
        lo -= 1
    hi = chin
    while hi < len(pick) - 1 and rest_y[hi + 1] <= top_y:
        hi += 1
    uv, pick = uv[lo : hi + 1], pick[lo : hi + 1]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(uv, axis=0), axis=1))])
    at = np.searchsorted(arc, np.linspace(0.0, arc[-1], 17)).clip(0, len(pick) - 1)
    out = candidates[pick[at]]
    if head.vertices[out[0], 0] > head.vertices[out[-1], 0]:  # iBUG 1 on the subject's right
        out = out[::-1]
    return out.astype(np.int64)
