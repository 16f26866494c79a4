"""Articulation: displacement fields, the jaw rotation, and the weights of each label.

Articulation is a small set of displacement fields (lip protrusion, rounding, spreading, upper
lip raise, smile, sad, and the upper-face action units of the expressions: cheek raise and lid
squint in a smile, inner-brow raise and brow lowering in a sad face, and the strong brow
expressions that move the whole forehead: a brow raise and a frown) plus a jaw rotation about an
axis near the ears whose weight is one on the chin and lower lip and fades smoothly into the
cheeks. All takes of one subject share one topology; only the vertex positions change. The fields
are functions of each vertex's rest position, so they move the skin (brows, lashes, landmarks)
and the truth's displacement is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.synth.features import _KIND_EYE, _KIND_POCKET, _KIND_SKIN, _RestMesh
from scan2morph.synth.shape import _sigmoid, _smoothstep
from scan2morph.synth.skin import _Mouth

#: The kind of take each label belongs to.
LABEL_KIND = {
    "neutral": "neutral",
    "car": "viseme",
    "man": "viseme",
    "she": "viseme",
    "eel": "viseme",
    "too": "viseme",
    "smile": "expression",
    "sad": "expression",
    "brows": "expression",
    "frown": "expression",
}

#: Articulation of each label at nominal intensity: ``jaw`` in degrees, the rest unitless
#: weights of the displacement fields (see :func:`~scan2morph.synth.head.articulate`).
LABEL_COEFFS: dict[str, dict[str, float]] = {
    "neutral": {},
    "car": {"jaw": 14.0, "spread": 0.15},
    "man": {"jaw": 8.0, "spread": 0.4},
    "she": {"jaw": 2.0, "protrude": 1.0, "round": 0.55, "raise": 0.8},
    "eel": {"jaw": 2.5, "spread": 1.0, "raise": 0.35},
    "too": {"jaw": 2.5, "round": 1.0, "protrude": 1.0},
    "smile": {"smile": 1.0, "cheek_raise": 1.0, "squint": 1.0},
    "sad": {"sad": 1.0, "brow_inner_raise": 1.0, "brow_lower": 1.0},
    "brows": {"brow_raise": 1.0, "sad": 0.5},
    "frown": {"frown": 1.0},
}

#: Names of the displacement fields (``jaw`` is a rotation, not a field).
FIELDS = (
    "protrude",
    "round",
    "spread",
    "raise",
    "smile",
    "sad",
    "cheek_raise",
    "squint",
    "brow_inner_raise",
    "brow_lower",
    "brow_raise",
    "frown",
)

#: Fields that contract with another one: a take draws one intensity for the driver (the key
#: here) and its linked fields follow it (a Duchenne smile raises the cheeks as much as it pulls
#: the mouth corners). This also keeps a take's random stream, hence its pose and defects, the
#: same as with the driver alone.
LINKED = {"smile": ("cheek_raise", "squint"), "sad": ("brow_inner_raise", "brow_lower")}


@dataclass(frozen=True)
class _LipCoords:
    """Where each vertex sits relative to the mouth, taken at its skin source.

    Attributes
    ----------
    p : (N, 3) float64
        Rest position of each vertex's skin source (a pocket vertex's slit vertex), mm.
    s : (N,) float64
        Height above the mouth line, mm.
    u : (N,) float64
        ``x / corner_x``: -1 and 1 at the mouth corners.
    v : (N,) float64
        Vertical sign: +1 upper lip, -1 lower lip (exact on the two copies of the slit).
    below : (N,) float64
        Lower-side indicator: a sharp step at the slit inside the mouth, smooth over the cheeks.
    """

    p: np.ndarray
    s: np.ndarray
    u: np.ndarray
    v: np.ndarray
    below: np.ndarray


def _lip_coords(mesh: _RestMesh) -> _LipCoords:
    """Mouth-relative coordinates and lip sides of every vertex of a rest mesh."""
    pe = mesh.vertices[mesh.src]
    ax = np.abs(pe[:, 0])
    xc = mesh.mouth.corner_x
    s, u = mesh.mouth.coords(pe)
    slit = (mesh.kind == _KIND_SKIN) & (mesh.side != 0)
    exact = slit | (mesh.kind == _KIND_POCKET)
    v = np.where(exact, mesh.side, np.tanh(s / 3.0))
    sharp = np.where(exact, (mesh.side < 0).astype(float), (s < 0).astype(float))
    s_eff = s + 0.35 * np.maximum(ax - xc, 0.0)
    smooth = _sigmoid(-s_eff / (1.5 + 0.5 * np.maximum(ax - xc + 4.0, 0.0)))
    blend = _smoothstep(ax, xc - 7.0, xc + 3.0)
    below = sharp * (1.0 - blend) + smooth * blend
    return _LipCoords(p=pe, s=s, u=u, v=v, below=below)


def _unit_fields(
    lc: _LipCoords, mouth: _Mouth, brow_y0: float, eye: np.ndarray
) -> dict[str, np.ndarray]:
    """Displacement fields at unit weight on the skin (before fading into the pocket).

    Parameters
    ----------
    lc : _LipCoords
    mouth : _Mouth
    brow_y0 : float
        Height of the inner brow, mm.
    eye : (3,) float64
        Centre of the left eyeball (x > 0), mm.

    Returns
    -------
    dict of str to (N, 3) float64
        Displacement of each field in :data:`FIELDS`, mm.
    """
    x, y, z = lc.p[:, 0], lc.p[:, 1], lc.p[:, 2]
    s, u, v = lc.s, lc.u, lc.v
    ax = np.abs(x)
    xc, ym, zm = mouth.corner_x, mouth.y, mouth.z

    frontw = _smoothstep(z, zm - 45.0, zm - 20.0)
    front_wide = _smoothstep(z, zm - 65.0, zm - 35.0)
    lipx = np.exp(-((ax / (xc + 6.0)) ** 6))
    lipy = np.exp(-((s / 15.0) ** 2))
    G = lipx * lipy * frontw
    G2 = np.exp(-((ax / (xc + 12.0)) ** 4)) * np.exp(-((s / 20.0) ** 2)) * frontw
    open_prof = np.clip(1.0 - u**2, 0.0, 1.0)
    near = np.exp(-((s / 8.0) ** 2))
    sgx = np.sign(x)
    zeros = np.zeros_like(x)

    def vec(dx, dy, dz):
        return np.stack([dx + zeros, dy + zeros, dz + zeros], axis=1)

    fields = {}
    fields["protrude"] = vec(0.0, 1.0 * v * open_prof * near * frontw, 7.0 * G)
    fields["round"] = vec(-0.34 * x * G2, 1.6 * v * np.sqrt(open_prof) * near * frontw, 2.5 * G)
    fields["spread"] = vec(0.3 * x * G2, 0.0, -2.5 * G * u**2)
    up = 1.0 - lc.below
    R = up * lipx * np.exp(-(((s - 4.0) / 10.0) ** 2)) * frontw
    fields["raise"] = vec(0.0, 3.5 * R, 1.0 * R)
    C = np.exp(-((ax - xc) ** 2 + (y - mouth.corner_y) ** 2) / (2 * 11.0**2)) * front_wide
    K = np.exp(-((ax - 38.0) ** 2 / (2 * 15.0**2) + (y - (ym + 30.0)) ** 2 / (2 * 14.0**2)))
    K = K * front_wide
    fields["smile"] = vec(
        4.0 * sgx * C, 6.0 * C + 3.0 * K + 1.0 * up * lipx * near, -3.0 * C + 2.5 * K
    )
    ment = np.exp(-(((y - (ym - 22.0)) / 10.0) ** 2)) * lipx * frontw
    fields["sad"] = vec(-1.0 * sgx * C, -4.0 * C + 2.0 * ment, 0.0)
    return fields | _upper_face_fields(lc.p, brow_y0, eye) | _forehead_fields(lc.p, brow_y0)


def _upper_face_fields(p: np.ndarray, brow_y0: float, eye: np.ndarray) -> dict[str, np.ndarray]:
    """The expressions' upper-face action units at unit weight (nominal amplitude), mm.

    ``cheek_raise`` (AU6, orbicularis oculi, orbital part): the infraorbital skin rises 4.5 mm
    and bulges 1.5 mm, the skin lateral to the eye (crow's feet, the temples) is drawn 1.5 mm
    towards the eye and up. ``squint`` (lid tightening): the lower lid rises 2 mm, the upper lid
    drops 1.2 mm. ``brow_inner_raise`` (AU1, medial frontalis): the inner brow rises 5.5 mm; the
    forehead above follows, less towards the hairline (a third at 25 mm above the brow).
    ``brow_lower`` (AU4, corrugator, procerus): the brow drops 3.5 mm and moves 2.5 mm towards
    the midline, the glabella drops 1.5 mm and bunches forward. Amplitudes within the measured
    ranges (cheek raise 3-6 mm, inner brow raise 4-8 mm, brow lowering 3-5 mm).

    Parameters
    ----------
    p : (N, 3) float64
        Rest position of each vertex's skin source, mm.
    brow_y0 : float
        Height of the inner brow, mm.
    eye : (3,) float64
        Centre of the left eyeball, mm (the right one mirrors it).
    """
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    ax = np.abs(x)
    odd = np.tanh(x / 4.0)  # sign(x), smooth across the midline
    ex, ey = ax - eye[0], y - eye[1]
    face = _smoothstep(z, 20.0, 45.0)  # the front of the head, temples included
    forehead = _smoothstep(z, 55.0, 75.0)
    zeros = np.zeros_like(x)

    def vec(dx, dy, dz):
        return np.stack([dx + zeros, dy + zeros, dz + zeros], axis=1)

    # AU6: infraorbital triangle (narrower towards the nose) and the lateral orbit
    sx = np.where(ex < 2.0, 9.0, 14.0)
    infra = np.exp(-((ex - 2.0) ** 2) / (2 * sx**2) - (ey + 17.0) ** 2 / (2 * 9.0**2)) * face
    lateral = np.exp(-((ex - 20.0) ** 2) / (2 * 9.0**2) - (ey + 2.0) ** 2 / (2 * 11.0**2)) * face
    cheek = vec(-1.5 * odd * lateral, 4.5 * infra + 1.5 * lateral, 1.5 * infra)
    # lid tightening: both lids over the width of the eye opening
    lid = np.exp(-((ex / 14.0) ** 4)) * face
    squint = vec(
        0.0,
        lid * (2.0 * np.exp(-(((ey + 7.0) / 4.0) ** 2)) - 1.2 * np.exp(-(((ey - 7.0) / 4.0) ** 2))),
        0.0,
    )
    # AU1: medial brow, the forehead above it (fading towards the hairline), the upper lid below
    yb = y - brow_y0
    up = np.where(yb >= 0.0, np.exp(-((yb / 24.0) ** 2)), np.exp(-((yb / 9.0) ** 2)))
    medial = np.exp(-((ax - 11.0) ** 2) / (2 * 11.0**2)) * forehead
    inner = vec(0.0, 5.5 * medial * up, 0.0)
    # AU4: brows down and in, the glabella down and forward
    down = np.where(yb >= 0.0, np.exp(-((yb / 14.0) ** 2)), np.exp(-((yb / 8.0) ** 2)))
    body = np.exp(-((ax - 20.0) ** 2) / (2 * 12.0**2)) * down * forehead
    pull = np.exp(-((ax - 14.0) ** 2) / (2 * 10.0**2)) * down * forehead
    glabella = np.exp(-((ax / 8.0) ** 2) - ((yb + 6.0) / 8.0) ** 2) * forehead
    lower = vec(-2.5 * odd * pull, -3.5 * body - 1.5 * glabella, 0.8 * glabella)
    return {"cheek_raise": cheek, "squint": squint, "brow_inner_raise": inner, "brow_lower": lower}


def _forehead_fields(p: np.ndarray, brow_y0: float) -> dict[str, np.ndarray]:
    """The strong brow expressions, which move the whole forehead, at unit weight, mm.

    ``brow_raise`` (AU1 with AU2, frontalis): the inner brow rises 6.5 mm, the lateral brow
    less (half at about 30 mm from the midline), and the forehead above follows up to the hairline
    (two thirds at 25 mm above the brow, a fifth at 50 mm), folding into horizontal furrows
    0.4 mm deep, 11 mm apart. ``frown`` (a strong AU4 with the procerus): the brows drop 5 mm
    and move 3.5 mm towards the midline, the glabella drops 2 mm, bunches 1.2 mm forward and
    folds into two vertical furrows, and the forehead above follows the brows down (half at
    20 mm above them). Amplitudes at the upper end of the measured ranges (inner brow raise
    4-8 mm, brow lowering 3-5 mm), so that the still skin of a take is less than the
    forehead.

    Parameters
    ----------
    p : (N, 3) float64
        Rest position of each vertex's skin source, mm.
    brow_y0 : float
        Height of the inner brow, mm.
    """
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    ax = np.abs(x)
    odd = np.tanh(x / 4.0)
    yb = y - brow_y0
    forehead = _smoothstep(z, 55.0, 75.0)
    zeros = np.zeros_like(x)

    def vec(dx, dy, dz):
        return np.stack([dx + zeros, dy + zeros, dz + zeros], axis=1)

    # AU1+2: the brows and the forehead above them, furrowed
    up = np.where(yb >= 0.0, np.exp(-((yb / 40.0) ** 2)), np.exp(-((yb / 9.0) ** 2)))
    across = np.exp(-((ax - 10.0) ** 2) / (2 * 17.0**2)) * forehead
    furrow = 0.5 - 0.5 * np.cos(2.0 * np.pi * yb / 11.0)
    folds = furrow * _smoothstep(yb, 4.0, 12.0) * (1.0 - _smoothstep(yb, 40.0, 55.0))
    raise_ = vec(0.0, 6.5 * across * up, -0.4 * across * folds)
    # strong AU4: brows down and in, the forehead following, the glabella bunched and furrowed
    down = np.where(yb >= 0.0, np.exp(-((yb / 24.0) ** 2)), np.exp(-((yb / 8.0) ** 2)))
    body = np.exp(-((ax - 18.0) ** 2) / (2 * 14.0**2)) * down * forehead
    pull = np.exp(-((ax - 14.0) ** 2) / (2 * 10.0**2)) * down * forehead
    glabella = np.exp(-((ax / 9.0) ** 2) - ((yb + 4.0) / 10.0) ** 2) * forehead
    creases = np.exp(-(((ax - 4.5) / 1.8) ** 2))
    frown = vec(
        -3.5 * odd * pull,
        -5.0 * body - 2.0 * glabella,
        1.2 * glabella - 0.6 * creases * glabella,
    )
    return {"brow_raise": raise_, "frown": frown}


def _jaw(mesh: _RestMesh, lc: _LipCoords, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The jaw rotation: the chin, lower lip and jaw follow, fading into the cheeks and neck.

    Parameters
    ----------
    mesh : _RestMesh
    lc : _LipCoords
        Of ``mesh``.
    scale : (3,) float64
        The identity's width, height and depth factors.

    Returns
    -------
    weight : (N,) float64
        Fraction of the jaw rotation each vertex follows (half-way at the back of the pocket).
    pivot : (3,) float64
        A point on the rotation axis (parallel to x), mm.
    """
    y, z = lc.p[:, 1], lc.p[:, 2]
    sy, sz = scale[1], scale[2]
    pivot = np.array([0.0, -5.0 * sy, 5.0 * sz])
    region = _smoothstep(z, -5.0, 35.0) * (
        1.0 - _smoothstep(-y, 110.0 * sy, 130.0 * sy) * (1.0 - _smoothstep(z, 55.0, 75.0))
    )
    weight = lc.below * region
    pocket = mesh.kind == _KIND_POCKET
    weight[pocket] = 0.5 - 0.5 * mesh.side[pocket] * (1.0 - mesh.depth[pocket])
    weight[mesh.kind == _KIND_EYE] = 0.0
    return weight, pivot


def _articulation(mesh: _RestMesh) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The articulation model of a rest mesh.

    Parameters
    ----------
    mesh : _RestMesh

    Returns
    -------
    fields : dict of str to (N, 3) float64
        Displacement at unit weight of each field in :data:`FIELDS`, mm; they fade out
        towards the back of the pocket and are zero on the eyeballs.
    jaw_weight : (N,) float64
        Fraction of the jaw rotation each vertex follows.
    jaw_pivot : (3,) float64
        A point on the jaw rotation axis (parallel to x), mm.
    """
    lc = _lip_coords(mesh)
    decay = np.where(mesh.kind == _KIND_POCKET, (1.0 - mesh.depth) ** 2, 1.0)
    decay[mesh.kind == _KIND_EYE] = 0.0
    unit = _unit_fields(lc, mesh.mouth, mesh.shape.brow_y0, mesh.shape.eye_centre)
    fields = {k: f * decay[:, None] for k, f in unit.items()}
    jaw_weight, jaw_pivot = _jaw(mesh, lc, mesh.shape.scale)
    return fields, jaw_weight, jaw_pivot


def label_coefficients(label: str, rng: np.random.Generator | None = None) -> dict[str, float]:
    """Articulation weights of a label, varied slightly per take.

    Parameters
    ----------
    label : str
        A key of :data:`LABEL_COEFFS`.
    rng : numpy.random.Generator, optional
        When given, each weight is scaled by ``1 + 0.08 N(0, 1)`` (clipped to [0.8, 1.2]),
        so repeated takes of one label differ slightly in intensity; the fields
        :data:`LINKED` to a driver take its factor (one draw per driver).

    Returns
    -------
    dict of str to float
    """
    base = LABEL_COEFFS[label]
    if rng is None:
        return dict(base)
    linked = {f for fs in LINKED.values() for f in fs}
    out = {}
    for k in sorted(set(base) - linked):
        factor = float(np.clip(1.0 + 0.08 * rng.standard_normal(), 0.8, 1.2))
        for f in (k, *LINKED.get(k, ())):
            if f in base:
                out[f] = float(base[f] * factor)
    return {k: out[k] for k in sorted(out)}
