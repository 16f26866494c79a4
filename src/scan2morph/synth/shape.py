"""The implicit head shape of one identity, and rays cast against it.

The head is the zero set of a smooth implicit function: smooth unions of ellipsoids for the
skull, face, jaw, neck, ears, cheeks, brows, nose and lips, and smooth subtractions for the
eye sockets and the eye openings. The function is negative inside and roughly a distance in
mm near the surface. Positions are in the head frame (mm; see :mod:`scan2morph.synth.head`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.geometry import in_blocks
from scan2morph.synth.identity import Identity

#: Thickness of a closed lid over the eyeball, mm.
_LID_MM = 1.2
#: Tilt of the eye's axis (its opening and its closed lid line), up at the outer corner, radians.
_EYE_TILT = 0.07
#: Positions evaluated together by :class:`_Shape` (its temporaries stay in the CPU's cache).
_CHUNK = 16384


def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum (smooth union) with blend radius ``k`` mm."""
    # in place, the operations in the order of b + (a - b) h - k h (1 - h), h = clip(0.5 +
    # 0.5 (b - a) / k): the same numbers with fewer temporaries (the sphere tracing's hot loop)
    h = b - a
    h *= 0.5
    h /= k
    h += 0.5
    np.clip(h, 0.0, 1.0, out=h)
    out = a - b
    out *= h
    out += b
    tail = k * h
    tail *= np.subtract(1.0, h, out=h)
    out -= tail
    return out


def _smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth maximum (smooth intersection / subtraction) with blend radius ``k`` mm."""
    return -_smin(-a, -b, k)


def _smoothstep(x: np.ndarray, e0: float, e1: float) -> np.ndarray:
    """Cubic step from 0 at ``e0`` to 1 at ``e1`` (same units as ``x``), flat outside."""
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function ``1 / (1 + exp(-x))``."""
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _rot_x(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` rad about x."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` rad about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class _Ellipsoid:
    """An ellipsoid: ``centre`` (3,) and semi-axes ``radii`` (3,) in mm, optionally rotated.

    ``rot`` (3, 3) maps the ellipsoid's axes to the head axes (orthonormal); None is
    axis-aligned.
    """

    centre: tuple
    radii: tuple
    rot: np.ndarray | None = None

    def _local(self, p: np.ndarray) -> np.ndarray:
        """Positions (N, 3) relative to the centre in the ellipsoid's axes, mm."""
        q = p - np.asarray(self.centre)
        if self.rot is not None:
            q = q @ self.rot  # head -> local (rot is orthonormal)
        return q

    def sdf(self, p: np.ndarray, columns: tuple | None = None) -> np.ndarray:
        """Approximate signed distance (a close lower bound near the surface), mm; (N,).

        ``columns`` are ``p``'s three columns as contiguous arrays, if the caller has them."""
        if self.rot is not None:
            q = self._local(p)
            q = (q[:, 0], q[:, 1], q[:, 2])
        else:
            columns = columns or (p[:, 0], p[:, 1], p[:, 2])
            q = tuple(c - o for c, o in zip(columns, self.centre, strict=True))
        k0, k1 = (_norm3(q, tuple(r**power for r in self.radii)) for power in (1, 2))
        np.maximum(k1, 1e-12, out=k1)
        out = k0 - 1.0
        out *= k0
        out /= k1
        return out

    def level(self, p: np.ndarray) -> np.ndarray:
        """Normalised radius of positions (N, 3): < 1 inside; (N,)."""
        return np.linalg.norm(self._local(p) / np.asarray(self.radii), axis=-1)

    def mirrored(self) -> _Ellipsoid:
        """The mirror image across the plane x = 0."""
        c = (-self.centre[0], self.centre[1], self.centre[2])
        rot = None
        if self.rot is not None:
            m = np.diag([-1.0, 1.0, 1.0])
            rot = m @ self.rot @ m
        return _Ellipsoid(c, self.radii, rot)


def _norm3(q: tuple, scale: tuple) -> np.ndarray:
    """sqrt((qx / sx)^2 + (qy / sy)^2 + (qz / sz)^2), (N,), from the three (N,) arrays ``q``."""
    total = None
    for c, r in zip(q, scale, strict=True):
        t = c / r
        t *= t
        if total is None:
            total = t
        else:
            total += t
    return np.sqrt(total, out=total)


def _round_cone(p: np.ndarray, a: np.ndarray, b: np.ndarray, ra: float, rb: float) -> np.ndarray:
    """Approximate distance (N,) from ``p`` (N, 3) to a capsule from ``a`` to ``b`` (3,).

    The capsule's radius goes from ``ra`` at ``a`` to ``rb`` at ``b``; all in mm.
    """
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1) - (ra + t * (rb - ra))


class _Shape:
    """The implicit head of one identity (negative inside, roughly a distance in mm).

    Parameters
    ----------
    idt : Identity

    Attributes
    ----------
    idt : Identity
    scale : (3,) float64
        The identity's width, height and depth factors.
    eye_centre : (3,) float64
        Centre of the subject's left eyeball (x > 0), mm; the right one is its mirror image.
    eye_radius : float
        Eyeball radius, mm.
    stomion_y, lip_front_z : float
        Height of the mouth line and depth of the lip fronts, mm.
    mouth_half_width : float
        Half the mouth width, mm.
    brow_y0 : float
        Height of the inner brow, mm.
    nose_tip : (3,) float64
        Tip of the nose chain, mm.
    almond, almonds, ears, ... : _Ellipsoid or list of _Ellipsoid
        The parts (lists hold both sides); ``almonds`` (the eye openings) is empty and
        ``lids`` (spheres over the eyeballs) is not when the eyes are closed.
    """

    def __init__(self, idt: Identity):
        sx, sy, sz = idt.width, idt.height, idt.depth
        self.scale = np.array([sx, sy, sz])
        self.idt = idt

        def E(c, r, rot=None):
            return _Ellipsoid(
                (c[0] * sx, c[1] * sy, c[2] * sz), (r[0] * sx, r[1] * sy, r[2] * sz), rot
            )

        n, nw, lp, mw, es = idt.nose, idt.nose_width, idt.lips, idt.mouth_width, idt.eye_spacing
        self.eye_centre = np.array([32.5 * es * sx, 21.0 * sy + idt.eye_height_mm, 71.0 * sz])
        self.eye_radius = 12.0
        self.stomion_y = -52.0 * sy
        self.lip_front_z = 97.0 * sz
        self.mouth_half_width = 25.0 * mw * sx
        self.brow_y0 = self.eye_centre[1] + 15.0 + idt.brow_mm

        fw = idt.face_width
        self.cranium = E((0, 28, -5), (75, 100, 100))
        self.midface = E((0, -5, 25), (58 * fw, 55, 62))
        self.jaw = E((0, -55, 15), (52 * fw, 48, 62))
        self.chin = E((0, -90, 66), (24 * idt.chin, 15, 19))
        self.muzzle = E((0, -45, 58), (30 * mw, 25, 34))
        self.cheekbones = [E((48, 5, 55), (18, 12, 20))]
        self.cheeks = [E((38 * fw, -24, 50), (24 * fw, 24, 24))]
        brow_y = 38 + idt.brow_mm * 0.5 + idt.eye_height_mm / sy
        self.brows = [E((27, brow_y, 82), (26, 9, 12), _rot_z(-0.12))]
        self.ears = [E((73, 2, -10), (13, 30, 17), _rot_x(-0.2))]
        ecx, ecy = self.eye_centre[0], self.eye_centre[1]
        self.sockets = [_Ellipsoid((ecx, ecy + 2, 92 * sz), (19, 13, 12))]
        # the eye opening: an almond tilted up at the outer corner, carved deep behind the eyeball
        self.almond = _Ellipsoid((ecx, ecy - 0.8, 86.0 * sz), (16.0, 4.7, 13.0), _rot_z(_EYE_TILT))
        self.almonds = [self.almond]
        # closed eyes: a lid over each eyeball with a shallow groove along the lid line
        self.lids = []
        if idt.eyes_closed:
            self.almonds = []
            self.lids = [_Ellipsoid(tuple(self.eye_centre), (_LID_MM + self.eye_radius,) * 3)]
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

        sides = ("cheekbones", "cheeks", "brows", "ears", "sockets", "almonds", "alae", "lids")
        for name in sides:
            lst = getattr(self, name)
            setattr(self, name, lst + [e.mirrored() for e in lst])

    def neck(self, p: np.ndarray) -> np.ndarray:
        """Approximate signed distance (N,) of positions (N, 3) to the neck alone, mm.

        The neck is an elliptic cylinder along y that flares below y = -150 mm, cut at
        ``neck_top`` and ``neck_bottom``.
        """
        yb = -150.0 - p[:, 1]
        flare = 1.0 + 0.002 * (yb + np.sqrt(yb * yb + 400.0))
        rx, rz = self.neck_radii[0] * flare, self.neck_radii[1] * flare
        qx, qz = p[:, 0], p[:, 2] - self.neck_centre_z
        k0 = np.hypot(qx / rx, qz / rz)
        k1 = np.hypot(qx / rx**2, qz / rz**2)
        d2 = k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)
        return np.maximum(d2, np.maximum(p[:, 1] - self.neck_top, self.neck_bottom - p[:, 1]))

    def brow_line(self, ax):
        """Height of the middle of an eyebrow at ``|x| = ax`` (mm; array or scalar), mm.

        Also returns the fraction ``t`` in [0, 1] of the way from the brow's inner end
        (12 mm from the midline) to its outer end (54 mm).
        """
        t = np.clip((ax - 12.0) / 42.0, 0.0, 1.0)
        return self.brow_y0 + 4.5 * np.sin(np.pi * t * 0.9), t

    def clear_of_ears(self, p: np.ndarray) -> np.ndarray:
        """(N,) bool: positions (N, 3) clear of both ears."""
        out = np.ones(len(p), bool)
        for e in self.ears:
            out &= e.level(p) > 1.35
        return out

    def __call__(self, p: np.ndarray, carve: bool = True) -> np.ndarray:
        """The implicit function at positions ``p`` (N, 3), mm; (N,), negative inside.

        With ``carve=False`` the eye openings are left closed (the lids run over the eyes).
        """
        # every step is elementwise: cache-sized blocks, the same numbers (about 1.5x faster on
        # the head's 53,000 rays)
        return in_blocks(lambda q: self._value(q, carve), np.asarray(p, dtype=np.float64), _CHUNK)

    def _value(self, p: np.ndarray, carve: bool) -> np.ndarray:
        """:meth:`__call__` on one block of positions (N, 3), mm; (N,)."""
        cols = tuple(np.ascontiguousarray(p[:, k]) for k in range(3))
        d = self.cranium.sdf(p, cols)
        d = _smin(d, self.midface.sdf(p, cols), 25.0)
        d = _smin(d, self.jaw.sdf(p, cols), 22.0)
        d = _smin(d, self.neck(p), 25.0)
        for e in self.cheekbones:
            d = _smin(d, e.sdf(p, cols), 15.0)
        for e in self.cheeks:
            d = _smin(d, e.sdf(p, cols), 22.0)
        d = _smin(d, self.muzzle.sdf(p, cols), 14.0)
        d = _smin(d, self.chin.sdf(p, cols), 18.0)
        for e in self.brows:
            d = _smin(d, e.sdf(p, cols), 14.0)
        for e in self.ears:
            d = _smin(d, e.sdf(p, cols), 5.0)
        for e in self.sockets:
            d = _smax(d, -e.sdf(p, cols), 8.0)
        for e in self.lids:
            d = _smin(d, e.sdf(p, cols), 1.5)
        nose = _round_cone(p, *self.nose_bridge)
        nose = _smin(nose, self.nose_ball.sdf(p, cols), 6.0)
        for e in self.alae:
            nose = _smin(nose, e.sdf(p, cols), 4.0)
        nose = _smin(nose, self.columella.sdf(p, cols), 3.0)
        d = _smin(d, nose, 7.0)
        d = _smin(d, self.upper_lip.sdf(p, cols), 5.0)
        d = _smin(d, self.lower_lip.sdf(p, cols), 5.0)
        if carve:
            for e in self.almonds:
                d = _smax(d, -e.sdf(p, cols), 1.2)
            if self.lids:
                d = _smax(d, -self._lid_groove(p), 0.3)
        return d

    def lid_line(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where positions ``p`` (N, 3) lie against the nearer eye's closed lid line, mm.

        Returns ``along`` (N,), the distance along the eye's axis from its centre (towards the
        outer corner positive), and ``off`` (N,), the height above the lid line there. The
        line runs between the corners (``along`` -14 and 13.2 mm, 1 mm above the axis) and
        sags 2.5 mm in the middle.
        """
        ec = self.eye_centre
        rx, ry = np.abs(p[:, 0]) - ec[0], p[:, 1] - (ec[1] - 0.8)
        c, s = np.cos(_EYE_TILT), np.sin(_EYE_TILT)
        along, up = rx * c + ry * s, -rx * s + ry * c
        return along, up - _lid_height(along)

    def lid_point(self, along: float) -> tuple[float, float]:
        """The left eye's closed lid line at ``along`` mm along the eye's axis (the inverse of
        :meth:`lid_line`): its (x, y) in the head frame, mm."""
        ec = self.eye_centre
        c, s = np.cos(_EYE_TILT), np.sin(_EYE_TILT)
        up = _lid_height(along)
        return ec[0] + along * c - up * s, ec[1] - 0.8 + along * s + up * c

    def _lid_groove(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (N,) to the groove along the closed lids (0.5 mm deep), mm."""
        along, off = self.lid_line(p)
        across = np.maximum(np.abs(off) - 0.5, np.abs(along + 0.4) - 13.6)
        q = np.column_stack([np.abs(p[:, 0]), p[:, 1], p[:, 2]])
        shell = (
            np.abs(np.linalg.norm(q - self.eye_centre, axis=1) - (_LID_MM + self.eye_radius)) - 0.5
        )
        return np.maximum(across, shell)


def _lid_height(along):
    """Height of the closed lid line above the eye's axis at ``along`` mm along it, mm: 1 mm at
    the corners (``along`` +-13.6 and beyond), sagging 2.5 mm in the middle."""
    return 1.0 - 2.5 * (1.0 - np.clip(along / 13.6, -1.0, 1.0) ** 2)


def _trace(
    shape: _Shape, origins: np.ndarray, dirs: np.ndarray, r_start: float = 320.0
) -> np.ndarray:
    """Distance along rays (from inside points) to the outermost crossing of the surface.

    Sphere-traces inward from ``r_start`` with steps of 0.6 x the implicit value (a lower
    bound of the distance), then bisects the bracketing step.

    Parameters
    ----------
    shape : _Shape
    origins : (R, 3) float64
        Ray origins inside the head, mm.
    dirs : (R, 3) float64
        Unit ray directions.
    r_start : float
        Distance along each ray to start from (outside the head), mm.

    Returns
    -------
    (R,) float64
        Distance from each origin to the surface, mm.
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
