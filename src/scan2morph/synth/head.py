"""A procedural human head: a triangle mesh with an opening mouth and 68 iBUG landmarks.

The head is the zero set of a smooth implicit function (smooth unions of ellipsoids for the
skull, face, jaw, neck, ears, cheeks, brows, nose and lips; smooth subtractions for the eye
sockets and the eye openings), meshed by casting rays from the head centre over a
(polar, azimuth) grid that is dense over the face. The grid row through the mouth line is cut
between the mouth corners: the row's vertices are duplicated, faces above use the upper copies
and faces below the lower copies, so at rest the mouth is closed and a deformation opens it.
Behind the slit a pocket (the oral cavity) closes the surface, so a ray through an open mouth
meets the cavity. Two eyeballs (UV spheres whose pole looks along +z, with iris and pupil
rings) sit in the sockets.

Head frame (mm): x to the subject's left (image right when facing the camera), y up, z out of
the face; the origin is between the ears at about ear-canal height.

Articulation is a small set of displacement fields (lip protrusion, rounding, spreading, upper
lip raise, smile, sad) plus a jaw rotation about an axis near the ears whose weight is one on
the chin and lower lip and fades smoothly into the cheeks. All takes of one subject share one
topology; only the vertex positions change.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

#: Face segments: outer skin, eyebrow hair, scalp hair, oral cavity, eyeball, pupil.
SEG_SKIN, SEG_BROW, SEG_HAIR, SEG_CAVITY, SEG_EYE, SEG_PUPIL = range(6)
#: Segments of the outer head surface (``skin_faces`` in the truth).
SKIN_SEGMENTS = (SEG_SKIN, SEG_BROW, SEG_HAIR)

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
}

#: Articulation of each label at nominal intensity: ``jaw`` in degrees, the rest unitless
#: weights of the displacement fields (see :func:`articulate`).
LABEL_COEFFS: dict[str, dict[str, float]] = {
    "neutral": {},
    "car": {"jaw": 14.0, "spread": 0.15},
    "man": {"jaw": 8.0, "spread": 0.4},
    "she": {"jaw": 2.0, "protrude": 1.0, "round": 0.55, "raise": 0.8},
    "eel": {"jaw": 2.5, "spread": 1.0, "raise": 0.35},
    "too": {"jaw": 2.5, "round": 1.0, "protrude": 1.0},
    "smile": {"smile": 1.0},
    "sad": {"sad": 1.0},
}

#: Names of the displacement fields (``jaw`` is a rotation, not a field).
FIELDS = ("protrude", "round", "spread", "raise", "smile", "sad")


@dataclass(frozen=True)
class Identity:
    """The shape and colour parameters of one synthetic subject.

    Scale factors are relative to an average adult head (1.0); tones are in [0, 1].
    """

    width: float = 1.0
    height: float = 1.0
    depth: float = 1.0
    nose: float = 1.0
    nose_width: float = 1.0
    lips: float = 1.0
    mouth_width: float = 1.0
    eye_spacing: float = 1.0
    brow_mm: float = 0.0
    chin: float = 1.0
    skin_tone: float = 0.3
    hair_tone: float = 0.2
    iris: int = 0


def sample_identity(rng: np.random.Generator) -> Identity:
    """Draw a plausible identity.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (seed it for reproducible subjects).

    Returns
    -------
    Identity
    """
    n = np.clip(rng.standard_normal(10), -2.5, 2.5)
    return Identity(
        width=float(1 + 0.04 * n[0]),
        height=float(1 + 0.04 * n[1]),
        depth=float(1 + 0.04 * n[2]),
        nose=float(1 + 0.08 * n[3]),
        nose_width=float(1 + 0.08 * n[4]),
        lips=float(1 + 0.12 * n[5]),
        mouth_width=float(1 + 0.06 * n[6]),
        eye_spacing=float(1 + 0.03 * n[7]),
        brow_mm=float(2.0 * n[8]),
        chin=float(1 + 0.1 * n[9]),
        skin_tone=float(rng.uniform(0.0, 1.0)),
        hair_tone=float(rng.uniform(0.0, 1.0)),
        iris=int(rng.integers(0, 3)),
    )


@dataclass(frozen=True, eq=False)
class HeadModel:
    """A subject's head at rest (the neutral face) with its articulation model.

    Attributes
    ----------
    identity : Identity
    vertices : (N, 3) float64
        Rest positions in the head frame, mm.
    faces : (F, 3) int64
        Triangles, counter-clockwise seen from outside (from the mouth for the cavity).
    segment : (F,) int8
        ``SEG_*`` code of each face.
    albedo : (N, 3) float64
        Base colour of each vertex, RGB in [0, 1].
    landmarks : (68,) int64
        Vertex index of each iBUG-68 landmark.
    fields : dict of str to (N, 3) float64
        Displacement at unit weight of each field in :data:`FIELDS`, mm.
    jaw_weight : (N,) float64
        Fraction of the jaw rotation each vertex follows.
    jaw_pivot : (3,) float64
        A point on the jaw rotation axis (parallel to x), mm.
    slit_upper, slit_lower : (S,) int64
        Vertex indices of the upper and lower copies along the mouth slit (corners excluded).
    mouth : dict
        Mouth geometry at rest: ``corner_x`` (mm, half-width), ``y``, ``z`` of the centre.
    """

    identity: Identity
    vertices: np.ndarray
    faces: np.ndarray
    segment: np.ndarray
    albedo: np.ndarray
    landmarks: np.ndarray
    fields: dict = field(repr=False)
    jaw_weight: np.ndarray = field(repr=False)
    jaw_pivot: np.ndarray = field(repr=False)
    slit_upper: np.ndarray = field(repr=False)
    slit_lower: np.ndarray = field(repr=False)
    mouth: dict = field(repr=False)

    @property
    def skin_faces(self) -> np.ndarray:
        """(F,) bool: faces of the outer head surface (not cavity, not eyeball)."""
        return np.isin(self.segment, SKIN_SEGMENTS)


# --------------------------------------------------------------------------------------------
# implicit shape
# --------------------------------------------------------------------------------------------


def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum (smooth union) with blend radius ``k`` mm."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth maximum (smooth intersection / subtraction)."""
    return -_smin(-a, -b, k)


def _rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class _Ellipsoid:
    centre: tuple
    radii: tuple
    rot: np.ndarray | None = None  # maps ellipsoid axes to head axes

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Approximate signed distance (a close lower bound near the surface), mm."""
        q = p - np.asarray(self.centre)
        if self.rot is not None:
            q = q @ self.rot  # head -> local (rot is orthonormal)
        rx, ry, rz = self.radii
        qx, qy, qz = q[:, 0], q[:, 1], q[:, 2]
        k0 = np.sqrt((qx / rx) ** 2 + (qy / ry) ** 2 + (qz / rz) ** 2)
        k1 = np.sqrt((qx / rx**2) ** 2 + (qy / ry**2) ** 2 + (qz / rz**2) ** 2)
        return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)

    def level(self, p: np.ndarray) -> np.ndarray:
        """Normalised radius: < 1 inside."""
        q = p - np.asarray(self.centre)
        if self.rot is not None:
            q = q @ self.rot
        return np.linalg.norm(q / np.asarray(self.radii), axis=-1)


def _round_cone(p: np.ndarray, a: np.ndarray, b: np.ndarray, ra: float, rb: float) -> np.ndarray:
    """Approximate distance to a capsule from ``a`` to ``b`` whose radius goes from ra to rb."""
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1) - (ra + t * (rb - ra))


def _mirror(e: _Ellipsoid) -> _Ellipsoid:
    c = (-e.centre[0], e.centre[1], e.centre[2])
    rot = None
    if e.rot is not None:
        m = np.diag([-1.0, 1.0, 1.0])
        rot = m @ e.rot @ m
    return _Ellipsoid(c, e.radii, rot)


class _Shape:
    """The implicit head of one identity (negative inside, roughly a distance in mm)."""

    def __init__(self, idt: Identity):
        sx, sy, sz = idt.width, idt.height, idt.depth
        self.scale = np.array([sx, sy, sz])
        self.idt = idt

        def E(c, r, rot=None):
            return _Ellipsoid(
                (c[0] * sx, c[1] * sy, c[2] * sz), (r[0] * sx, r[1] * sy, r[2] * sz), rot
            )

        n, nw, lp, mw, es = idt.nose, idt.nose_width, idt.lips, idt.mouth_width, idt.eye_spacing
        self.eye_centre = np.array([32.5 * es * sx, 21.0 * sy, 71.0 * sz])
        self.eye_radius = 12.0
        self.stomion_y = -52.0 * sy
        self.lip_front_z = 97.0 * sz
        self.mouth_half_width = 25.0 * mw * sx
        self.brow_y0 = self.eye_centre[1] + 15.0 + idt.brow_mm

        self.cranium = E((0, 28, -5), (75, 100, 100))
        self.midface = E((0, -5, 25), (58, 55, 62))
        self.jaw = E((0, -55, 15), (52, 48, 62))
        self.chin = E((0, -90, 66), (24 * idt.chin, 15, 19))
        self.muzzle = E((0, -45, 58), (30 * mw, 25, 34))
        self.cheekbones = [E((48, 5, 55), (18, 12, 20))]
        self.cheeks = [E((38, -24, 50), (24, 24, 24))]
        self.brows = [E((27, 38 + idt.brow_mm * 0.5, 82), (26, 9, 12), _rot_z(-0.12))]
        self.ears = [E((73, 2, -10), (13, 30, 17), _rot_x(-0.2))]
        ecx, ecy = self.eye_centre[0], self.eye_centre[1]
        self.sockets = [_Ellipsoid((ecx, ecy + 2, 92 * sz), (19, 13, 12))]
        # the eye opening: an almond tilted up at the outer corner, carved deep behind the eyeball
        self.almond = _Ellipsoid((ecx, ecy - 0.8, 86.0 * sz), (16.0, 4.7, 13.0), _rot_z(0.07))
        self.almonds = [self.almond]
        # nose: a chain from the nasion to the tip, tip ball, alae, columella
        nasion = np.array([0.0, 22.0 * sy, 90.0 * sz])
        tip = nasion + n * np.array([0.0, -40.0 * sy, 26.0])
        self.nose_tip = tip
        self.nose_bridge = (nasion, tip + np.array([0.0, 3.0, -5.0]), 5.0 * nw, 7.5 * nw)
        self.nose_ball = _Ellipsoid(tuple(tip + [0.0, -1.0, -7.5]), (8.0 * nw, 7.5, 8.0))
        self.alae = [
            _Ellipsoid((10.0 * nw * n, tip[1] - 5.0 * n, tip[2] - 14.0 * n), (6.5 * nw, 5.5, 7.5))
        ]
        self.columella = _Ellipsoid(
            (0.0, tip[1] - 8.0 * n, tip[2] - 12.0 * n), (5.0 * nw, 4.0, 8.0)
        )
        sty = self.stomion_y
        self.upper_lip = _Ellipsoid(
            (0.0, sty + 6.5 * lp, 86.0 * sz), (23.0 * mw * sx, 8.0 * lp, 10.5 * lp)
        )
        self.lower_lip = _Ellipsoid(
            (0.0, sty - 7.0 * lp, 85.0 * sz), (21.0 * mw * sx, 8.5 * lp, 10.5 * lp)
        )
        self.neck_radii = (50.0 * sx, 50.0 * sz)
        self.neck_centre_z = -22.0 * sz
        self.neck_top = -40.0 * sy
        self.neck_bottom = -250.0

        for name in ("cheekbones", "cheeks", "brows", "ears", "sockets", "almonds", "alae"):
            lst = getattr(self, name)
            setattr(self, name, lst + [_mirror(e) for e in lst])

    def _neck(self, p: np.ndarray) -> np.ndarray:
        yb = -150.0 - p[:, 1]
        flare = 1.0 + 0.002 * (yb + np.sqrt(yb * yb + 400.0))
        rx, rz = self.neck_radii[0] * flare, self.neck_radii[1] * flare
        qx, qz = p[:, 0], p[:, 2] - self.neck_centre_z
        k0 = np.hypot(qx / rx, qz / rz)
        k1 = np.hypot(qx / rx**2, qz / rz**2)
        d2 = k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)
        return np.maximum(d2, np.maximum(p[:, 1] - self.neck_top, self.neck_bottom - p[:, 1]))

    def __call__(self, p: np.ndarray, carve: bool = True) -> np.ndarray:
        d = self.cranium.sdf(p)
        d = _smin(d, self.midface.sdf(p), 25.0)
        d = _smin(d, self.jaw.sdf(p), 22.0)
        d = _smin(d, self._neck(p), 25.0)
        for e in self.cheekbones:
            d = _smin(d, e.sdf(p), 15.0)
        for e in self.cheeks:
            d = _smin(d, e.sdf(p), 22.0)
        d = _smin(d, self.muzzle.sdf(p), 14.0)
        d = _smin(d, self.chin.sdf(p), 18.0)
        for e in self.brows:
            d = _smin(d, e.sdf(p), 14.0)
        for e in self.ears:
            d = _smin(d, e.sdf(p), 5.0)
        for e in self.sockets:
            d = _smax(d, -e.sdf(p), 8.0)
        nose = _round_cone(p, *self.nose_bridge)
        nose = _smin(nose, self.nose_ball.sdf(p), 6.0)
        for e in self.alae:
            nose = _smin(nose, e.sdf(p), 4.0)
        nose = _smin(nose, self.columella.sdf(p), 3.0)
        d = _smin(d, nose, 7.0)
        d = _smin(d, self.upper_lip.sdf(p), 5.0)
        d = _smin(d, self.lower_lip.sdf(p), 5.0)
        if carve:
            for e in self.almonds:
                d = _smax(d, -e.sdf(p), 1.2)
        return d


def _trace(
    shape: _Shape, origins: np.ndarray, dirs: np.ndarray, r_start: float = 320.0
) -> np.ndarray:
    """Distance along rays (from inside points) to the outermost crossing of the surface.

    Sphere-traces inward from ``r_start`` with steps of 0.6 x the implicit value (a lower
    bound of the distance), then bisects the bracketing step.
    """
    n = len(dirs)
    r = np.full(n, r_start)
    r_out = np.full(n, r_start)
    active = np.arange(n)
    for _ in range(600):
        if active.size == 0:
            break
        d = shape(origins[active] + dirs[active] * r[active, None])
        outside = d > 0.0
        keep = active[outside]
        r_out[keep] = r[keep]
        r[keep] -= np.maximum(0.6 * d[outside], 0.1)
        active = keep
    lo, hi = r.copy(), r_out.copy()  # lo inside, hi outside
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        inside = shape(origins + dirs * mid[:, None]) <= 0.0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return 0.5 * (lo + hi)


# --------------------------------------------------------------------------------------------
# the grid
# --------------------------------------------------------------------------------------------


def _warped(n: int, lo: float, hi: float, floor: float, *bands: tuple[float, float, float]):
    """``n`` samples on [lo, hi] (both included) with density ``floor`` plus ``(a, b, w)`` bands.

    Each band adds density ``w`` (smoothly) between ``a`` and ``b``.
    """
    t = np.linspace(lo, hi, 4097)
    soft = 0.04 * (hi - lo)
    rho = np.full_like(t, floor)
    for a, b, w in bands:
        rho += w * 0.5 * (np.tanh((t - a) / soft) - np.tanh((t - b) / soft))
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (rho[1:] + rho[:-1]) * np.diff(t))])
    return np.interp(np.linspace(0.0, cdf[-1], n), cdf, t)


def _smoothstep(x: np.ndarray, e0: float, e1: float) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _uv_sphere(centre: np.ndarray, radius: float, polar_deg: np.ndarray, n_seg: int):
    """A sphere with its pole on +z: rings at ``polar_deg``; returns vertices, faces, polar."""
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


# grid resolution: azimuth columns (even, symmetric about 0) and polar rows
_N_AZ_HALF = 120
_N_POLAR = 180
_N_NECK = 40
_PHI_NECK = np.deg2rad(150.0)
_NECK_ORIGIN_Y = -245.0
_POCKET_LEVELS = 8
_POCKET_DEPTH = 36.0
_POCKET_HEIGHT = 9.0
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
_PUPIL_DEG = 9.0
_IRIS_DEG = 27.5


def _pocket(verts, skin_tris, slit_upper, slit_lower, corner_l, corner_r):
    """The oral cavity: a bag glued to the slit boundary, closing the surface behind the lips.

    Loops of the slit boundary (corner, upper copies, corner, lower copies) are moved back and
    the upper/lower sheets bulge apart, then zip together into a line at the back.

    Returns
    -------
    pts : (M, 3) new vertices (indexed after ``verts``); tris : (T, 3) faces, oriented like the
    skin; t : (M,) depth fraction in (0, 1]; src : (M,) slit vertex each one hangs from;
    side : (M,) +1 upper sheet, -1 lower sheet, 0 corners.
    """
    ns = len(slit_upper)
    loop_idx = np.concatenate([[corner_l], slit_upper, [corner_r], slit_lower[::-1]])
    side = np.concatenate([[0.0], np.ones(ns), [0.0], -np.ones(ns)])
    S = verts[loop_idx]
    prof = np.sqrt(np.clip(1.0 - (S[:, 0] / (np.abs(verts[corner_l, 0]) + 1e-9)) ** 2, 0.0, 1.0))
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
    q = np.arange(len(loop_idx))
    qn = (q + 1) % len(loop_idx)
    tris = []
    for k in range(_POCKET_LEVELS):
        a0, a1 = loops[k][q], loops[k][qn]
        b0, b1 = loops[k + 1][q], loops[k + 1][qn]
        tris += [np.stack([a0, a1, b0], 1), np.stack([a1, b1, b0], 1)]
    tris = np.concatenate(tris)
    tris = tris[
        (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    ]
    # orient like the skin: a shared edge must run opposite ways in the two faces using it
    e0, e1 = slit_upper[0], slit_upper[1]

    def has_edge(f):
        return bool(np.any((f == e0) & (np.roll(f, -1, axis=1) == e1)))

    if has_edge(skin_tris) == has_edge(tris):
        tris = tris[:, ::-1]
    return (
        np.concatenate(pts),
        tris,
        np.concatenate(ts),
        np.concatenate(src),
        np.concatenate(sides),
    )


def _eyeballs(shape: _Shape, offset: int):
    """Two eyeballs looking along +z; returns vertices, faces (indices from ``offset``),
    face segments (eye or pupil) and each vertex's angle from the gaze axis (rad)."""
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


@functools.lru_cache(maxsize=8)
def build_head(identity: Identity) -> HeadModel:
    """Mesh a subject's head at rest and set up its articulation and landmarks.

    Parameters
    ----------
    identity : Identity
        Shape and colour parameters (see :func:`sample_identity`).

    Returns
    -------
    HeadModel
        Cached per identity; its arrays are read-only.
    """
    shape = _Shape(identity)
    # ---- directions: azimuth a about y (0 = +z), polar phi from +y
    a_half = _warped(_N_AZ_HALF + 1, 0.0, np.pi, 0.15, (-1.0, np.deg2rad(95.0), 0.85))
    az = np.concatenate([-a_half[:0:-1], a_half[:-1]])  # [-pi, ..., 0, ...), symmetric
    n_az = len(az)
    j0 = _N_AZ_HALF  # column at azimuth 0
    # rows: rays from the head centre down to 150 degrees from +y, then (for the neck) rays at
    # 150 degrees from origins sliding down the neck axis, so no ray grazes the neck
    # (denser from the nose tip to the chin, where the lips and nostrils face up or down)
    phi = _warped(
        _N_POLAR + 1,
        0.0,
        _PHI_NECK,
        0.2,
        (np.deg2rad(38.0), _PHI_NECK + 1.0, 0.8),
        (np.deg2rad(97.0), np.deg2rad(135.0), 1.2),
    )[1:]
    phi_m = np.pi / 2 + np.arctan2(-shape.stomion_y, shape.lip_front_z)
    i_m = int(np.argmin(np.abs(phi - phi_m)))
    off = phi_m - phi[i_m]
    phi = phi + off * np.exp(-np.abs(np.arange(len(phi)) - i_m) / 3.0)
    y_org = np.concatenate(
        [np.zeros(len(phi)), _NECK_ORIGIN_Y * (np.arange(1, _N_NECK + 1) / _N_NECK) ** 1.3]
    )
    phi = np.concatenate([phi, np.full(_N_NECK, _PHI_NECK)])
    n_ph = len(phi)

    P, A = np.meshgrid(phi, az, indexing="ij")
    dirs = np.stack([np.sin(P) * np.sin(A), np.cos(P), np.sin(P) * np.cos(A)], -1).reshape(-1, 3)
    poles = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    all_dirs = np.concatenate([dirs, poles])
    origins = np.zeros_like(all_dirs)
    origins[: n_ph * n_az, 1] = np.repeat(y_org, n_az)
    origins[-1, 1] = _NECK_ORIGIN_Y
    r = _trace(shape, origins, all_dirs)

    # mouth span: columns whose x at the mouth row is within the half-width
    r_row = r[i_m * n_az : (i_m + 1) * n_az]
    x_row = (all_dirs[i_m * n_az : (i_m + 1) * n_az] * r_row[:, None])[:, 0]  # origin 0
    front = np.abs(az) < np.pi / 2
    kc = int(np.argmin(np.where(front & (az >= 0), np.abs(x_row - shape.mouth_half_width), np.inf)))
    kc -= j0
    # crease along the mouth line (the lips meet in a shallow groove)
    rr = r[: n_ph * n_az].reshape(n_ph, n_az)
    a_c = az[j0 + kc]
    span = 1.0 - _smoothstep(np.abs(az), a_c - np.deg2rad(4.0), a_c + np.deg2rad(6.0))
    crease = 2.2 * np.exp(-((((P - phi_m) * rr) / 1.6) ** 2))
    rr = rr - crease * span[None, :]
    r[: n_ph * n_az] = rr.reshape(-1)

    grid = origins + all_dirs * r[:, None]
    n_grid = n_ph * n_az
    top, bottom = n_grid, n_grid + 1

    def gid(i, j):
        return i * n_az + (j % n_az)

    # ---- skin faces
    I, J = np.meshgrid(np.arange(n_ph - 1), np.arange(n_az), indexing="ij")
    I, J = I.reshape(-1), J.reshape(-1)
    a, b, c, d = gid(I, J), gid(I + 1, J), gid(I, J + 1), gid(I + 1, J + 1)
    quads_lower_band = I == i_m  # faces between row i_m and i_m + 1 (below the mouth row)
    tri1 = np.stack([a, b, c], 1)
    tri2 = np.stack([b, d, c], 1)
    jj = np.arange(n_az)
    cap_top = np.stack([np.full(n_az, top), gid(0, jj), gid(0, jj + 1)], 1)
    cap_bot = np.stack([gid(n_ph - 1, jj + 1), gid(n_ph - 1, jj), np.full(n_az, bottom)], 1)

    # ---- slit: duplicate the interior of the mouth row for the lower lip
    slit_cols = np.arange(j0 - kc + 1, j0 + kc)
    slit_upper = gid(i_m, slit_cols)
    slit_lower = n_grid + 2 + np.arange(len(slit_cols))
    remap_lower = np.arange(n_grid + 2)
    remap_lower[slit_upper] = slit_lower
    lower_band = np.concatenate([quads_lower_band, quads_lower_band])
    skin_tris = np.concatenate([tri1, tri2])
    skin_tris = np.where(lower_band[:, None], remap_lower[skin_tris], skin_tris)
    skin_tris = np.concatenate([cap_top, skin_tris, cap_bot])

    verts = np.concatenate([grid, grid[slit_upper]])
    n_skin_v = len(verts)

    # ---- pocket (oral cavity) behind the slit, then the eyeballs
    corner_l, corner_r = gid(i_m, j0 - kc), gid(i_m, j0 + kc)
    pocket_pts, pocket_tris, pocket_t, pocket_src, pocket_side = _pocket(
        verts, skin_tris, slit_upper, slit_lower, corner_l, corner_r
    )
    n_before_eyes = n_skin_v + len(pocket_pts)
    eye_pts, eye_tris, eye_seg, eye_polar = _eyeballs(shape, n_before_eyes)
    verts = np.concatenate([verts, pocket_pts, eye_pts])
    n_v = len(verts)

    # ---- per-vertex bookkeeping
    kind = np.zeros(n_v, np.int8)  # 0 skin, 1 pocket, 2 eye
    kind[n_skin_v:n_before_eyes] = 1
    kind[n_before_eyes:] = 2
    vside = np.zeros(n_v)  # +1 upper slit copy, -1 lower slit copy
    vside[slit_upper] = 1.0
    vside[slit_lower] = -1.0
    vsrc = np.arange(n_v)
    vsrc[n_skin_v:n_before_eyes] = pocket_src
    vt = np.zeros(n_v)
    vt[n_skin_v:n_before_eyes] = pocket_t
    vside[n_skin_v:n_before_eyes] = pocket_side

    # mouth geometry at rest
    cl, cr = verts[corner_l], verts[corner_r]
    mouth = {
        "corner_x": float(0.5 * (cr[0] - cl[0])),
        "y": float(verts[gid(i_m, j0), 1]),
        "z": float(verts[gid(i_m, j0), 2]),
        "corner_y": float(0.5 * (cl[1] + cr[1])),
    }
    slit_x = verts[slit_upper, 0]
    slit_y = verts[slit_upper, 1]
    line_x = np.concatenate([[cl[0]], slit_x, [cr[0]]])
    line_y = np.concatenate([[cl[1]], slit_y, [cr[1]]])

    fields, jaw_w, pivot = _articulation(verts, vside, kind, vsrc, vt, mouth, line_x, line_y, shape)

    # ---- faces and segments
    faces = np.concatenate([skin_tris, pocket_tris, eye_tris]).astype(np.int64)
    segment = np.concatenate(
        [np.full(len(skin_tris), SEG_SKIN), np.full(len(pocket_tris), SEG_CAVITY), eye_seg]
    ).astype(np.int8)
    albedo, brow_w, hair_w = _albedo(verts, kind, vt, eye_polar, mouth, line_x, line_y, shape)
    skin_face = segment == SEG_SKIN
    fb = brow_w[faces].mean(axis=1)
    fh = hair_w[faces].mean(axis=1)
    segment[skin_face & (fh > 0.5)] = SEG_HAIR
    segment[skin_face & (fb > 0.5)] = SEG_BROW

    landmarks = _landmarks(
        verts,
        kind,
        faces,
        segment,
        shape,
        slit_upper,
        slit_lower,
        corner_l,
        corner_r,
        mouth,
        line_x,
        line_y,
    )
    arrays = dict(
        vertices=verts,
        faces=faces,
        segment=segment,
        albedo=albedo,
        landmarks=landmarks,
        jaw_weight=jaw_w,
        jaw_pivot=pivot,
        slit_upper=slit_upper.astype(np.int64),
        slit_lower=slit_lower.astype(np.int64),
    )
    for v in list(arrays.values()) + list(fields.values()):
        v.setflags(write=False)
    return HeadModel(identity=identity, fields=fields, mouth=mouth, **arrays)


# --------------------------------------------------------------------------------------------
# articulation
# --------------------------------------------------------------------------------------------


def _mouth_coords(p: np.ndarray, mouth: dict, line_x: np.ndarray, line_y: np.ndarray):
    """Mouth-relative coordinates: height above the mouth line ``s`` (mm) and ``u = x / xc``."""
    s = p[:, 1] - np.interp(p[:, 0], line_x, line_y)
    return s, p[:, 0] / mouth["corner_x"]


def _articulation(verts, vside, kind, vsrc, vt, mouth, line_x, line_y, shape):
    """Displacement fields at unit weight, jaw weights and the jaw pivot."""
    pe = verts[vsrc]
    x, y, z = pe[:, 0], pe[:, 1], pe[:, 2]
    ax = np.abs(x)
    xc, ym, zm = mouth["corner_x"], mouth["y"], mouth["z"]
    s, u = _mouth_coords(pe, mouth, line_x, line_y)
    slit = (kind == 0) & (vside != 0)
    side_e = vside
    # vertical sign: +1 upper lip, -1 lower lip (exact on the two copies of the slit)
    v = np.where(slit | (kind == 1), side_e, np.tanh(s / 3.0))
    # lower-side indicator: a sharp step at the slit inside the mouth, smooth over the cheeks
    sharp = np.where(slit | (kind == 1), (side_e < 0).astype(float), (s < 0).astype(float))
    s_eff = s + 0.35 * np.maximum(ax - xc, 0.0)
    smooth = _sigmoid(-s_eff / (1.5 + 0.5 * np.maximum(ax - xc + 4.0, 0.0)))
    blend = _smoothstep(ax, xc - 7.0, xc + 3.0)
    below = sharp * (1.0 - blend) + smooth * blend

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
    up = 1.0 - below
    R = up * lipx * np.exp(-(((s - 4.0) / 10.0) ** 2)) * frontw
    fields["raise"] = vec(0.0, 3.5 * R, 1.0 * R)
    corner_y = mouth["corner_y"]
    C = np.exp(-((ax - xc) ** 2 + (y - corner_y) ** 2) / (2 * 11.0**2)) * front_wide
    K = np.exp(-((ax - 38.0) ** 2 / (2 * 15.0**2) + (y - (ym + 30.0)) ** 2 / (2 * 14.0**2)))
    K = K * front_wide
    fields["smile"] = vec(
        4.0 * sgx * C, 6.0 * C + 3.0 * K + 1.0 * up * lipx * near, -3.0 * C + 2.5 * K
    )
    ment = np.exp(-(((y - (ym - 22.0)) / 10.0) ** 2)) * lipx * frontw
    B = np.exp(-((ax - 14.0) ** 2 / (2 * 10.0**2) + (y - shape.brow_y0) ** 2 / (2 * 12.0**2)))
    B = B * _smoothstep(z, 55.0, 75.0)
    fields["sad"] = vec(-1.0 * sgx * C - 1.2 * sgx * B, -4.0 * C + 2.0 * ment + 5.0 * B, 0.0)

    # jaw: the chin, lower lip and jaw follow, fading into the cheeks and the neck
    sy, sz = shape.scale[1], shape.scale[2]
    pivot = np.array([0.0, -5.0 * sy, 5.0 * sz])
    region = _smoothstep(z, -5.0, 35.0) * (
        1.0 - _smoothstep(-y, 110.0 * sy, 130.0 * sy) * (1.0 - _smoothstep(z, 55.0, 75.0))
    )
    jaw_w = below * region
    pocket = kind == 1
    jaw_w[pocket] = 0.5 - 0.5 * vside[pocket] * (1.0 - vt[pocket])
    eye = kind == 2
    jaw_w[eye] = 0.0
    decay = np.where(pocket, (1.0 - vt) ** 2, 1.0)
    decay[eye] = 0.0
    for k in fields:
        fields[k] = fields[k] * decay[:, None]
    return fields, jaw_w, pivot


def articulate(head: HeadModel, coeffs: dict[str, float]) -> np.ndarray:
    """Vertex positions of a deformed head.

    Parameters
    ----------
    head : HeadModel
    coeffs : dict of str to float
        Weights of the fields in :data:`FIELDS` and ``jaw`` (opening angle in degrees).
        Missing entries are zero; ``{}`` gives the rest (neutral) face exactly.

    Returns
    -------
    vertices : (N, 3) float64
        Head frame, mm.
    """
    v = np.array(head.vertices, dtype=float)
    for k, w in coeffs.items():
        if k == "jaw":
            continue
        v += w * head.fields[k]
    angle = np.deg2rad(coeffs.get("jaw", 0.0)) * head.jaw_weight
    if np.any(angle != 0.0):
        yp, zp = v[:, 1] - head.jaw_pivot[1], v[:, 2] - head.jaw_pivot[2]
        c, s = np.cos(angle), np.sin(angle)
        v[:, 1] = head.jaw_pivot[1] + yp * c - zp * s
        v[:, 2] = head.jaw_pivot[2] + yp * s + zp * c
    return v


def label_coefficients(label: str, rng: np.random.Generator | None = None) -> dict[str, float]:
    """Articulation weights of a label, varied slightly per take.

    Parameters
    ----------
    label : str
        A key of :data:`LABEL_COEFFS`.
    rng : numpy.random.Generator, optional
        When given, each weight is scaled by ``1 + 0.08 N(0, 1)`` (clipped to [0.8, 1.2]),
        so repeated takes of one label differ slightly in intensity.

    Returns
    -------
    dict of str to float
    """
    base = LABEL_COEFFS[label]
    if rng is None:
        return dict(base)
    out = {}
    for k in sorted(base):
        out[k] = float(base[k] * np.clip(1.0 + 0.08 * rng.standard_normal(), 0.8, 1.2))
    return out


# --------------------------------------------------------------------------------------------
# colour
# --------------------------------------------------------------------------------------------

_SKIN_TONES = np.array(
    [[0.96, 0.80, 0.69], [0.82, 0.62, 0.48], [0.58, 0.40, 0.28], [0.40, 0.27, 0.19]]
)
_HAIR_TONES = np.array([[0.05, 0.04, 0.04], [0.18, 0.11, 0.07], [0.36, 0.24, 0.14]])
_IRIS = np.array([[0.36, 0.21, 0.10], [0.30, 0.45, 0.62], [0.34, 0.44, 0.27]])


def _tone(table: np.ndarray, t: float) -> np.ndarray:
    x = np.linspace(0.0, 1.0, len(table))
    return np.array([np.interp(t, x, table[:, k]) for k in range(3)])


def _vermilion(x: np.ndarray, xc: float, lips: float):
    """Heights of the upper and lower vermilion borders above/below the mouth line, mm."""
    u = np.clip(np.abs(x) / xc, 0.0, 1.0)
    taper = np.sqrt(np.clip(1.0 - u**2.2, 0.0, 1.0))
    bow = 1.0 + 0.16 * np.exp(-(((np.abs(x) - 6.0) / 3.5) ** 2)) - 0.1 * np.exp(-((x / 2.5) ** 2))
    return 8.0 * lips * taper * bow, 9.5 * lips * taper


def _brow_band(p: np.ndarray, shape: _Shape) -> np.ndarray:
    """Eyebrow hair weight in [0, 1] from head-frame positions (N, 3)."""
    ax = np.abs(p[:, 0])
    t = np.clip((ax - 12.0) / 42.0, 0.0, 1.0)
    yb = shape.brow_y0 + 4.5 * np.sin(np.pi * t * 0.9)
    half = 4.8 - 2.6 * t
    inside = _smoothstep(half - np.abs(p[:, 1] - yb), -0.6, 0.6)
    ends = _smoothstep(ax, 11.0, 14.0) * (1.0 - _smoothstep(ax, 52.0, 56.0))
    return inside * ends * _smoothstep(p[:, 2], 55.0, 70.0)


def _albedo(verts, kind, vt, eye_polar, mouth, line_x, line_y, shape):
    idt = shape.idt
    skin = _tone(_SKIN_TONES, idt.skin_tone)
    hair = _tone(_HAIR_TONES, idt.hair_tone)
    x, y, z = verts[:, 0], verts[:, 1], verts[:, 2]
    alb = np.tile(skin, (len(verts), 1))
    # a slight blush on the cheeks
    cheek = np.exp(-((np.abs(x) - 40.0) ** 2 + (y + 22.0) ** 2) / (2 * 16.0**2))
    alb *= 1.0 + cheek[:, None] * np.array([0.02, -0.05, -0.04])
    # lips
    xc = mouth["corner_x"]
    s, _ = _mouth_coords(verts, mouth, line_x, line_y)
    h_up, h_lo = _vermilion(x, xc, idt.lips)
    lipw = _smoothstep(h_up - s, -1.0, 1.0) * _smoothstep(s + h_lo, -1.0, 1.0)
    lipw *= (np.abs(x) < xc + 2.0) * _smoothstep(z, mouth["z"] - 25.0, mouth["z"] - 15.0)
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
    # hair: scalp above a hairline that runs from the forehead over the ears to the nape
    az = np.abs(np.arctan2(x, z))
    hairline = (
        76.0 * shape.scale[1]
        - 40.0 * _smoothstep(az, 0.7, 1.35)
        - 100.0 * _smoothstep(az, 1.75, 2.6)
    )
    not_ear = np.ones(len(verts), bool)
    for e in shape.ears:
        not_ear &= e.level(verts) > 1.35
    hair_w = _sigmoid((y - hairline) / 1.5) * not_ear
    brow_w = _brow_band(verts, shape)
    skinish = kind == 0
    hair_w = hair_w * skinish
    brow_w = brow_w * skinish
    alb += (0.9 * brow_w)[:, None] * (hair - alb)
    alb += hair_w[:, None] * (hair - alb)
    # cavity: dark red, darker towards the back
    cav = kind == 1
    alb[cav] = np.array([0.40, 0.10, 0.11]) * (1.0 - 0.75 * vt[cav])[:, None]
    # eyes
    eye = kind == 2
    pol = np.rad2deg(eye_polar)
    iris = _IRIS[idt.iris]
    ecol = np.where(
        (pol <= _PUPIL_DEG + 1e-6)[:, None],
        np.array([0.02, 0.02, 0.02]),
        np.where(
            (pol <= _IRIS_DEG)[:, None],
            iris * (1.0 - 0.25 * (pol > 20.0))[:, None],
            np.array([0.90, 0.88, 0.84]),
        ),
    )
    alb[eye] = ecol
    return np.clip(alb, 0.0, 1.0), brow_w, hair_w


# --------------------------------------------------------------------------------------------
# landmarks
# --------------------------------------------------------------------------------------------


def _landmarks(
    verts,
    kind,
    faces,
    segment,
    shape,
    slit_upper,
    slit_lower,
    corner_l,
    corner_r,
    mouth,
    line_x,
    line_y,
):
    """Vertex indices of the iBUG-68 landmarks on the rest mesh."""
    used = np.zeros(len(verts), bool)
    used[faces[np.isin(segment, SKIN_SEGMENTS)].reshape(-1)] = True
    cand = np.flatnonzero(used & (kind == 0))
    cxy = verts[cand, :2]
    cz = verts[cand, 2]

    def visible(x, y):
        d = np.hypot(cxy[:, 0] - x, cxy[:, 1] - y)
        for rad in (1.0, 1.6, 2.5, 4.0):
            ok = d < rad
            if ok.any():
                return int(cand[np.flatnonzero(ok)[np.argmax(cz[ok])]])
        return int(cand[np.argmin(d)])

    lm = np.zeros(68, np.int64)
    idt = shape.idt
    # jaw contour 1-17: the frontal silhouette of the face in front of the ears
    not_ear = np.ones(len(cand), bool)
    for e in shape.ears:
        not_ear &= e.level(verts[cand]) > 1.35
    ecy = shape.eye_centre[1]
    y_top = ecy - 6.0
    oy = mouth["y"]
    pc = verts[cand]
    neck = shape._neck(pc) < np.minimum(shape.jaw.sdf(pc), shape.chin.sdf(pc)) - 1.0
    sel = not_ear & ~neck & (cz > 15.0 * shape.scale[2]) & (cxy[:, 1] <= y_top)
    px, py = cxy[sel, 0], cxy[sel, 1]
    psi = np.degrees(np.arctan2(px, -(py - oy)))
    rho = np.hypot(px, py - oy)
    bins = np.round(psi * 2.0).astype(int)
    order = np.lexsort((-rho, bins))
    first = np.concatenate([[True], bins[order][1:] != bins[order][:-1]])
    sil = order[first]  # per half-degree bin, the farthest vertex
    # the contour ends where the outline reaches y_top on either side
    band = np.abs(py - y_top) < 2.0
    lo_end = np.flatnonzero(band)[np.argmin(px[band])]
    hi_end = np.flatnonzero(band)[np.argmax(px[band])]
    sil = sil[(psi[sil] >= psi[lo_end]) & (psi[sil] <= psi[hi_end])]
    sil = sil[np.argsort(psi[sil])]
    sxy = np.stack([px[sil], py[sil]], 1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(sxy, axis=0), axis=1))])
    targets = np.linspace(0.0, arc[-1], 17)
    pick = np.searchsorted(arc, targets).clip(0, len(sil) - 1)
    lm[0:17] = cand[np.flatnonzero(sel)[sil[pick]]]
    # brows 18-27
    for k, ax in enumerate((50.0, 41.0, 32.0, 23.5, 15.0)):
        t = np.clip((ax - 12.0) / 42.0, 0.0, 1.0)
        yb = shape.brow_y0 + 4.5 * np.sin(np.pi * t * 0.9) + 1.0
        lm[17 + k] = visible(-ax, yb)
        lm[26 - k] = visible(ax, yb)
    # nose bridge 28-31 and bottom 32-36
    mid = cand[np.abs(cxy[:, 0]) < 0.5]
    ny = verts[mid, 1]
    nose_zone = mid[(ny < shape.nose_tip[1] + 15.0) & (ny > shape.nose_tip[1] - 15.0)]
    tip_i = int(nose_zone[np.argmax(verts[nose_zone, 2])])
    y28 = ecy + 3.0
    ytip = verts[tip_i, 1]
    lm[27] = visible(0.0, y28)
    lm[28] = visible(0.0, y28 + (ytip - y28) / 3.0)
    lm[29] = visible(0.0, y28 + 2.0 * (ytip - y28) / 3.0)
    lm[30] = tip_i
    # subnasale: the midline point deepest behind the chord from the tip to the upper lip
    zone = mid[(verts[mid, 1] < ytip) & (verts[mid, 1] > mouth["y"] + 1.0) & (verts[mid, 2] > 40.0)]
    low = verts[zone, 1] < mouth["y"] + 12.0
    lip_top = zone[low][np.argmax(verts[zone[low], 2])]
    (ya, za), (yb, zb) = verts[tip_i, 1:], verts[lip_top, 1:]
    zone = zone[(verts[zone, 1] < ya) & (verts[zone, 1] > yb)]
    chord = za + (verts[zone, 1] - ya) * (zb - za) / (yb - ya)
    sn = int(zone[np.argmax(chord - verts[zone, 2])])
    # 34: the bottom of the columella just above the subnasale, as seen from the front
    ysn = verts[sn, 1]
    lm[33] = visible(0.0, ysn + 1.0)
    nw = idt.nose_width * idt.nose
    lm[32] = visible(-6.0 * nw, ysn + 1.2)
    lm[34] = visible(6.0 * nw, ysn + 1.2)
    lm[31] = visible(-11.5 * nw, ysn + 3.0)
    lm[35] = visible(11.5 * nw, ysn + 3.0)
    # eyes 37-48: the lid margin, where the skin seen from the front starts to cover the eyeball
    # (left eye 43-48: inner, upper-inner, upper-outer, outer, lower-outer, lower-inner)
    ec, er = shape.eye_centre, shape.eye_radius
    e = shape.almond
    tilt = np.arctan2(e.rot[1, 0], e.rot[0, 0]) if e.rot is not None else 0.0
    rel = cxy - ec[:2]
    rho = np.hypot(rel[:, 0], rel[:, 1])
    ez = ec[2] + np.sqrt(np.clip(er**2 - rho**2, 0.0, None))
    lid = shape(verts[cand], carve=False) > -0.3  # not carved by the eye opening
    covering = (rho < 1.6 * e.radii[0]) & lid & ((cz >= ez - 0.05) | (rho >= er))
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    for k, tau in enumerate(np.deg2rad([180.0, 120.0, 60.0, 0.0, -60.0, -120.0])):
        # direction on the almond at parameter tau
        dx, dy = np.cos(tau) * e.radii[0], np.sin(tau) * e.radii[1]
        dirn = np.arctan2(
            dx * np.sin(tilt) + dy * np.cos(tilt), dx * np.cos(tilt) - dy * np.sin(tilt)
        )
        if np.cos(tau) ** 2 > 0.99:  # a corner: the first covering point along the axis
            axis = np.array([np.cos(dirn), np.sin(dirn)])
            along = rel @ axis
            perp = np.abs(rel[:, 0] * axis[1] - rel[:, 1] * axis[0])
            ok = covering & (along > 0.0) & (perp < 0.9)
            best = np.flatnonzero(ok)[np.argmin(along[ok])]
        else:
            dang = np.abs(np.angle(np.exp(1j * (ang - dirn))))
            ok = covering & (dang < np.deg2rad(6.0))
            best = np.flatnonzero(ok)[np.argmin(rho[ok] + 3.0 * dang[ok])]
        lm[42 + k] = visible(*cxy[best])
    # right eye by mirror: 37 outer, 38 upper-outer, 39 upper-inner, 40 inner, 41 lower-inner,
    # 42 lower-outer
    for k, src in enumerate((45, 44, 43, 42, 47, 46)):
        p = verts[lm[src]]
        lm[36 + k] = visible(-p[0], p[1])
    # outer lip 49-60
    xc = mouth["corner_x"]
    lm[48] = visible(-(xc + 1.5), mouth["corner_y"])
    lm[54] = visible(xc + 1.5, mouth["corner_y"])
    for k, xx in zip((49, 50, 51, 52, 53), (-0.62 * xc, -6.0, 0.0, 6.0, 0.62 * xc), strict=True):
        h_up, _ = _vermilion(np.array([xx]), xc, idt.lips)
        lm[k] = visible(xx, float(np.interp(xx, line_x, line_y) + h_up[0]))
    for k, xx in zip(
        (55, 56, 57, 58, 59), (0.62 * xc, 0.3 * xc, 0.0, -0.3 * xc, -0.62 * xc), strict=True
    ):
        _, h_lo = _vermilion(np.array([xx]), xc, idt.lips)
        lm[k] = visible(xx, float(np.interp(xx, line_x, line_y) - h_lo[0]))
    # inner lip 61-68 on the slit
    sx = verts[slit_upper, 0]

    def col(xx):
        return int(np.argmin(np.abs(sx - xx)))

    lm[60] = corner_l
    lm[61] = slit_upper[col(-0.5 * xc)]
    lm[62] = slit_upper[col(0.0)]
    lm[63] = slit_upper[col(0.5 * xc)]
    lm[64] = corner_r
    lm[65] = slit_lower[col(0.5 * xc)]
    lm[66] = slit_lower[col(0.0)]
    lm[67] = slit_lower[col(-0.5 * xc)]
    return lm
