"""The parts added to the skin: the oral-cavity pocket and the eyeballs, and the rest mesh.

Behind the mouth slit a pocket (the oral cavity) closes the surface, so a ray through an open
mouth meets the cavity. Two eyeballs (UV spheres whose pole looks along +z, with iris and
pupil rings) sit in the sockets. Positions are in the head frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.synth.shape import _Shape
from scan2morph.synth.skin import _Mouth, _Skin, _Slit

#: Face segments: outer skin, eyebrow hair, scalp hair, oral cavity, eyeball, pupil.
SEG_SKIN, SEG_BROW, SEG_HAIR, SEG_CAVITY, SEG_EYE, SEG_PUPIL = range(6)
#: Segments of the outer head surface (``skin_faces`` in the truth).
SKIN_SEGMENTS = (SEG_SKIN, SEG_BROW, SEG_HAIR)

#: Vertex kinds of the rest mesh (``_RestMesh.kind``).
_KIND_SKIN, _KIND_POCKET, _KIND_EYE = 0, 1, 2

_POCKET_LEVELS = 8
_POCKET_DEPTH = 36.0  # mm
_POCKET_HEIGHT = 9.0  # mm
#: Polar angles of the eyeball rings from the gaze axis, degrees.
_EYE_RINGS_DEG = (
    4.5,
    9.0,
    10.0,
    14.0,
    19.0,
    23.0,
    27.0,
    28.0,
    33.0,
    40.0,
    50.0,
    62.0,
    75.0,
    90.0,
    110.0,
    130.0,
    150.0,
    165.0,
)
#: Angular radius of the pupil and of the iris about the gaze axis, degrees.
_PUPIL_DEG = 9.0
_IRIS_DEG = 27.5


@dataclass(frozen=True)
class _Pocket:
    """The oral cavity hanging from the slit.

    Attributes
    ----------
    vertices : (M, 3) float64
        New vertices (indexed after the skin's), mm.
    faces : (T, 3) int64
        Triangles, oriented like the skin.
    depth : (M,) float64
        Depth fraction of each vertex in (0, 1].
    src : (M,) int64
        The slit vertex each one hangs from.
    side : (M,) float64
        +1 upper sheet, -1 lower sheet, 0 corners.
    """

    vertices: np.ndarray
    faces: np.ndarray
    depth: np.ndarray
    src: np.ndarray
    side: np.ndarray


def _stitch(loops: list[np.ndarray]) -> np.ndarray:
    """Triangles (T, 3) joining each closed loop of vertex indices to the next one.

    All loops have the same length; triangles with a repeated vertex (where a loop repeats
    indices) are dropped.
    """
    q = np.arange(len(loops[0]))
    qn = (q + 1) % len(q)
    tris = []
    for k in range(len(loops) - 1):
        a0, a1 = loops[k][q], loops[k][qn]
        b0, b1 = loops[k + 1][q], loops[k + 1][qn]
        tris += [np.stack([a0, a1, b0], 1), np.stack([a1, b1, b0], 1)]
    tris = np.concatenate(tris)
    return tris[
        (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    ]


def _orient_like(tris: np.ndarray, skin_tris: np.ndarray, e0: int, e1: int) -> np.ndarray:
    """``tris`` (T, 3), flipped if need be so that the edge between vertices ``e0`` and ``e1``,
    which both meshes use, runs opposite ways in the two (as in one consistently oriented
    surface)."""

    def has_edge(f):
        return bool(np.any((f == e0) & (np.roll(f, -1, axis=1) == e1)))

    if has_edge(skin_tris) == has_edge(tris):
        return tris[:, ::-1]
    return tris


def _pocket(verts: np.ndarray, skin_tris: np.ndarray, slit: _Slit) -> _Pocket:
    """The oral cavity: a bag glued to the slit boundary, closing the surface behind the lips.

    Loops of the slit boundary (corner, upper copies, corner, lower copies) are moved back and
    the upper/lower sheets bulge apart, then zip together into a line at the back.

    Parameters
    ----------
    verts : (V, 3) float64
        Skin vertices, mm.
    skin_tris : (F, 3) int64
        Skin triangles.
    slit : _Slit

    Returns
    -------
    _Pocket
    """
    ns = len(slit.upper)
    loop_idx = np.concatenate([[slit.corner_l], slit.upper, [slit.corner_r], slit.lower[::-1]])
    side = np.concatenate([[0.0], np.ones(ns), [0.0], -np.ones(ns)])
    S = verts[loop_idx]
    prof = np.sqrt(
        np.clip(1.0 - (S[:, 0] / (np.abs(verts[slit.corner_l, 0]) + 1e-9)) ** 2, 0.0, 1.0)
    )
    inward = np.array([0.0, -0.15, -1.0]) / np.hypot(0.15, 1.0)
    loops = [loop_idx]
    pts, ts, src, sides = [], [], [], []
    n_next = len(verts)
    for k in range(1, _POCKET_LEVELS + 1):
        t = k / _POCKET_LEVELS
        # the last level zips the sheets: one vertex per column, shared by both
        sel = np.arange(len(loop_idx) if k < _POCKET_LEVELS else ns + 2)
        Q = S[sel] + t * _POCKET_DEPTH * inward
        Q[:, 0] *= 1.0 - 0.3 * t
        Q[:, 1] += side[sel] * _POCKET_HEIGHT * prof[sel] * np.sin(np.pi * t)
        idx = n_next + np.arange(len(sel))
        n_next += len(sel)
        pts.append(Q)
        ts.append(np.full(len(sel), t))
        src.append(loop_idx[sel])
        sides.append(side[sel])
        if k == _POCKET_LEVELS:
            idx = np.concatenate([idx, idx[1 : ns + 1][::-1]])
        loops.append(idx)
    tris = _orient_like(_stitch(loops), skin_tris, slit.upper[0], slit.upper[1])
    return _Pocket(
        vertices=np.concatenate(pts),
        faces=tris,
        depth=np.concatenate(ts),
        src=np.concatenate(src),
        side=np.concatenate(sides),
    )


def _uv_sphere(centre: np.ndarray, radius: float, polar_deg: np.ndarray, n_seg: int):
    """A sphere with its pole on +z and rings at polar angles ``polar_deg`` (degrees).

    Parameters
    ----------
    centre : (3,) float64
        Centre, mm.
    radius : float
        Radius, mm.
    polar_deg : (K,) float64
        Polar angle of each ring from +z, degrees, increasing.
    n_seg : int
        Vertices per ring.

    Returns
    -------
    verts : (K * n_seg + 2, 3) float64
        The +z pole, the rings, the -z pole; mm.
    faces : (2 * K * n_seg, 3) int64
        Triangles, counter-clockwise seen from outside.
    polar : (K * n_seg + 2,) float64
        Polar angle of each vertex, rad.
    """
    pol = np.deg2rad(np.asarray(polar_deg, float))
    az = np.linspace(0.0, 2 * np.pi, n_seg, endpoint=False)
    ring = np.stack(
        [
            np.sin(pol)[:, None] * np.cos(az)[None, :],
            np.sin(pol)[:, None] * np.sin(az)[None, :],
            np.repeat(np.cos(pol)[:, None], n_seg, axis=1),
        ],
        axis=-1,
    ).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]]) * radius + centre
    polar = np.concatenate([[0.0], np.repeat(pol, n_seg), [np.pi]])
    nr = len(pol)
    j = np.arange(n_seg)
    jn = (j + 1) % n_seg
    faces = [np.stack([np.zeros(n_seg, int), 1 + j, 1 + jn], axis=1)]
    for i in range(nr - 1):
        a, b = 1 + i * n_seg + j, 1 + i * n_seg + jn
        c, d = 1 + (i + 1) * n_seg + j, 1 + (i + 1) * n_seg + jn
        faces += [np.stack([a, c, b], 1), np.stack([b, c, d], 1)]
    last = len(verts) - 1
    base = 1 + (nr - 1) * n_seg
    faces.append(np.stack([base + j, np.full(n_seg, last), base + jn], axis=1))
    return verts, np.concatenate(faces), polar


def _eyeballs(shape: _Shape, offset: int):
    """Two eyeballs looking along +z, the subject's right one first.

    Parameters
    ----------
    shape : _Shape
    offset : int
        Index of the first eyeball vertex in the whole mesh.

    Returns
    -------
    verts : (E, 3) float64
        mm.
    faces : (T, 3) int64
        Triangles, indices from ``offset``.
    segment : (T,) int64
        :data:`SEG_PUPIL` or :data:`SEG_EYE` of each face.
    polar : (E,) float64
        Angle of each vertex from its eye's gaze axis, rad.
    """
    pts, tris, segs, polar = [], [], [], []
    for sgn in (-1.0, 1.0):
        centre = shape.eye_centre * np.array([sgn, 1.0, 1.0])
        ev, ef, ep = _uv_sphere(centre, shape.eye_radius, np.array(_EYE_RINGS_DEG), 32)
        tris.append(ef + offset + sum(len(v) for v in pts))
        pts.append(ev)
        polar.append(ep)
        pupil = ep[ef].max(axis=1) <= np.deg2rad(_PUPIL_DEG) + 1e-9
        segs.append(np.where(pupil, SEG_PUPIL, SEG_EYE))
    return np.concatenate(pts), np.concatenate(tris), np.concatenate(segs), np.concatenate(polar)


@dataclass(frozen=True)
class _RestMesh:
    """The whole head at rest, before colour: skin, pocket and eyeballs, in that order.

    Attributes
    ----------
    shape : _Shape
        The implicit shape the skin was meshed from.
    vertices : (N, 3) float64
        Head frame, mm.
    faces : (F, 3) int64
        Triangles.
    segment : (F,) int8
        :data:`SEG_SKIN`, :data:`SEG_CAVITY`, :data:`SEG_EYE` or :data:`SEG_PUPIL` of each face
        (hair and brows are told apart later, by colour).
    kind : (N,) int8
        ``_KIND_SKIN``, ``_KIND_POCKET`` or ``_KIND_EYE`` of each vertex.
    side : (N,) float64
        +1 on the upper slit copies and the upper pocket sheet, -1 on the lower ones, else 0.
    src : (N,) int64
        The skin vertex each vertex follows (itself, or the slit vertex a pocket vertex hangs
        from).
    depth : (N,) float64
        Depth fraction of pocket vertices in (0, 1]; 0 elsewhere.
    eye_polar : (E,) float64
        Angle of each eyeball vertex (the last E) from its gaze axis, rad.
    slit : _Slit
    mouth : _Mouth
    """

    shape: _Shape
    vertices: np.ndarray
    faces: np.ndarray
    segment: np.ndarray
    kind: np.ndarray
    side: np.ndarray
    src: np.ndarray
    depth: np.ndarray
    eye_polar: np.ndarray
    slit: _Slit
    mouth: _Mouth


def _add_features(shape: _Shape, skin: _Skin) -> _RestMesh:
    """Close the skin behind the mouth with the pocket and put the eyeballs in.

    Parameters
    ----------
    shape : _Shape
    skin : _Skin
        The skin of ``shape``.

    Returns
    -------
    _RestMesh
    """
    n_skin_v = len(skin.vertices)
    pocket = _pocket(skin.vertices, skin.faces, skin.slit)
    n_before_eyes = n_skin_v + len(pocket.vertices)
    eye_pts, eye_tris, eye_seg, eye_polar = _eyeballs(shape, n_before_eyes)
    verts = np.concatenate([skin.vertices, pocket.vertices, eye_pts])
    n_v = len(verts)
    in_pocket = slice(n_skin_v, n_before_eyes)

    kind = np.full(n_v, _KIND_SKIN, np.int8)
    kind[in_pocket] = _KIND_POCKET
    kind[n_before_eyes:] = _KIND_EYE
    side = np.zeros(n_v)
    side[skin.slit.upper] = 1.0
    side[skin.slit.lower] = -1.0
    side[in_pocket] = pocket.side
    src = np.arange(n_v)
    src[in_pocket] = pocket.src
    depth = np.zeros(n_v)
    depth[in_pocket] = pocket.depth

    segment = [np.full(len(skin.faces), SEG_SKIN), np.full(len(pocket.faces), SEG_CAVITY), eye_seg]
    return _RestMesh(
        shape=shape,
        vertices=verts,
        faces=np.concatenate([skin.faces, pocket.faces, eye_tris]).astype(np.int64),
        segment=np.concatenate(segment).astype(np.int8),
        kind=kind,
        side=side,
        src=src,
        depth=depth,
        eye_polar=eye_polar,
        slit=skin.slit,
        mouth=skin.mouth,
    )
