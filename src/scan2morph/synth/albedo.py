"""Colour: the base colour of every vertex, and the hair and brow segments it implies.

Skin of the identity's tone with a slight blush, red lips within the vermilion borders, dark
nostrils and lash lines, scalp hair above a hairline and eyebrow hair (both in the identity's
hair tone), a dark red oral cavity, and white eyeballs with a coloured iris and a black pupil.
"""

from __future__ import annotations

import numpy as np

from scan2morph.synth.features import (
    _IRIS_DEG,
    _KIND_EYE,
    _KIND_POCKET,
    _KIND_SKIN,
    _PUPIL_DEG,
    SEG_BROW,
    SEG_HAIR,
    SEG_SKIN,
    _RestMesh,
)
from scan2morph.synth.shape import _Shape, _sigmoid, _smoothstep

#: Colour ramps (RGB in [0, 1]) the identity's tones pick from, and the iris colours.
_SKIN_TONES = np.array(
    [[0.96, 0.80, 0.69], [0.82, 0.62, 0.48], [0.58, 0.40, 0.28], [0.40, 0.27, 0.19]]
)
_HAIR_TONES = np.array([[0.05, 0.04, 0.04], [0.18, 0.11, 0.07], [0.36, 0.24, 0.14]])
_IRIS = np.array([[0.36, 0.21, 0.10], [0.30, 0.45, 0.62], [0.34, 0.44, 0.27]])


def _tone(table: np.ndarray, t: float) -> np.ndarray:
    """(3,) colour at ``t`` in [0, 1] along a ramp of (K, 3) colours."""
    x = np.linspace(0.0, 1.0, len(table))
    return np.array([np.interp(t, x, table[:, k]) for k in range(3)])


def _brow_band(p: np.ndarray, shape: _Shape) -> np.ndarray:
    """Eyebrow hair weight (N,) in [0, 1] at head-frame positions (N, 3), mm."""
    ax = np.abs(p[:, 0])
    yb, t = shape.brow_line(ax)
    half = 4.8 - 2.6 * t
    inside = _smoothstep(half - np.abs(p[:, 1] - yb), -0.6, 0.6)
    ends = _smoothstep(ax, 11.0, 14.0) * (1.0 - _smoothstep(ax, 52.0, 56.0))
    return inside * ends * _smoothstep(p[:, 2], 55.0, 70.0)


def _hair_weight(verts: np.ndarray, shape: _Shape) -> np.ndarray:
    """Scalp hair weight (N,) in [0, 1]: above a hairline from the forehead over the ears to
    the nape, except on the ears."""
    x, y, z = verts[:, 0], verts[:, 1], verts[:, 2]
    az = np.abs(np.arctan2(x, z))
    hairline = (
        76.0 * shape.scale[1]
        + shape.idt.hairline_mm
        - 40.0 * _smoothstep(az, 0.7, 1.35)
        - 100.0 * _smoothstep(az, 1.75, 2.6)
    )
    return _sigmoid((y - hairline) / 1.5) * shape.clear_of_ears(verts)


def _eye_colour(polar: np.ndarray, iris: int) -> np.ndarray:
    """(E, 3) colour of eyeball vertices at angles ``polar`` (rad) from the gaze axis."""
    pol = np.rad2deg(polar)
    return np.where(
        (pol <= _PUPIL_DEG + 1e-6)[:, None],
        np.array([0.02, 0.02, 0.02]),
        np.where(
            (pol <= _IRIS_DEG)[:, None],
            _IRIS[iris] * (1.0 - 0.25 * (pol > 20.0))[:, None],
            np.array([0.90, 0.88, 0.84]),
        ),
    )


def _albedo(mesh: _RestMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base colour of every vertex of a rest mesh.

    Parameters
    ----------
    mesh : _RestMesh

    Returns
    -------
    albedo : (N, 3) float64
        RGB in [0, 1].
    brow_w, hair_w : (N,) float64
        Eyebrow and scalp hair weights in [0, 1] (0 off the skin).
    """
    shape, verts, kind, mouth = mesh.shape, mesh.vertices, mesh.kind, mesh.mouth
    idt = shape.idt
    skin = _tone(_SKIN_TONES, idt.skin_tone)
    hair = _tone(_HAIR_TONES, idt.hair_tone)
    x, y, z = verts[:, 0], verts[:, 1], verts[:, 2]
    alb = np.tile(skin, (len(verts), 1))
    # a slight blush on the cheeks
    cheek = np.exp(-((np.abs(x) - 40.0) ** 2 + (y + 22.0) ** 2) / (2 * 16.0**2))
    alb *= 1.0 + cheek[:, None] * np.array([0.02, -0.05, -0.04])
    # lips
    xc = mouth.corner_x
    s, _ = mouth.coords(verts)
    h_up, h_lo = mouth.vermilion(x, idt.lips)
    lipw = _smoothstep(h_up - s, -1.0, 1.0) * _smoothstep(s + h_lo, -1.0, 1.0)
    lipw *= (np.abs(x) < xc + 2.0) * _smoothstep(z, mouth.z - 25.0, mouth.z - 15.0)
    lip_col = skin * np.array([0.86, 0.50, 0.52]) + np.array([0.06, 0.0, 0.01])
    alb += (0.8 * lipw)[:, None] * (lip_col - alb)
    # nostrils
    tip = shape.nose_tip
    n = idt.nose
    for sgn in (-1.0, 1.0):
        c = np.array([sgn * 5.5 * idt.nose_width * n, tip[1] - 8.0 * n, tip[2] - 12.0 * n])
        w = np.exp(-np.sum((verts - c) ** 2, axis=1) / (2 * 2.6**2))
        alb *= 1.0 - 0.8 * w[:, None]
    # lash lines along the eye openings
    for e in shape.almonds:
        lev = e.level(verts)
        upper = y > e.centre[1]
        lash = np.exp(-(((lev - 1.0) / 0.07) ** 2)) * np.where(upper, 1.0, 0.45)
        alb *= 1.0 - 0.65 * lash[:, None]
    if shape.lids:  # closed eyes: the lashes along the lid line
        along, off = shape.lid_line(verts)
        lash = np.exp(-((off / 0.8) ** 2)) * (1.0 - _smoothstep(np.abs(along + 0.4), 13.0, 15.0))
        lash *= np.abs(verts[:, 0]) > 3.0
        alb *= 1.0 - 0.65 * lash[:, None]
    # hair on the skin: scalp and eyebrows
    skinish = kind == _KIND_SKIN
    hair_w = _hair_weight(verts, shape) * skinish
    brow_w = _brow_band(verts, shape) * skinish
    alb += (idt.brow_hair * brow_w)[:, None] * (hair - alb)
    alb += hair_w[:, None] * (hair - alb)
    # cavity: dark red, darker towards the back
    cav = kind == _KIND_POCKET
    alb[cav] = np.array([0.40, 0.10, 0.11]) * (1.0 - 0.75 * mesh.depth[cav])[:, None]
    alb[kind == _KIND_EYE] = _eye_colour(mesh.eye_polar, idt.iris)
    return np.clip(alb, 0.0, 1.0), brow_w, hair_w


def _hair_segments(mesh: _RestMesh, brow_w: np.ndarray, hair_w: np.ndarray) -> np.ndarray:
    """Face segments with skin faces mostly under scalp or eyebrow hair relabelled.

    Parameters
    ----------
    mesh : _RestMesh
    brow_w, hair_w : (N,) float64
        Eyebrow and scalp hair weight of each vertex (see :func:`_albedo`).

    Returns
    -------
    (F,) int8
        ``SEG_*`` code of each face; a skin face whose mean weight exceeds 0.5 becomes
        :data:`SEG_HAIR` or :data:`SEG_BROW` (brows win).
    """
    segment = mesh.segment.copy()
    skin_face = segment == SEG_SKIN
    fb = brow_w[mesh.faces].mean(axis=1)
    fh = hair_w[mesh.faces].mean(axis=1)
    segment[skin_face & (fh > 0.5)] = SEG_HAIR
    segment[skin_face & (fb > 0.5)] = SEG_BROW
    return segment
