"""The 68 iBUG landmarks of a rest mesh, as vertex indices.

Most landmarks are the frontmost skin vertex of the outer surface near a target position
seen from the front (along -z): the jaw contour follows the face's frontal silhouette, the
eye points the lid margins, the outer lip points the vermilion borders, and the inner lip
points lie on the mouth slit. Indices below are 0-based (iBUG numbers are 1-based).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.synth.features import _KIND_SKIN, SKIN_SEGMENTS, _RestMesh


@dataclass(frozen=True)
class _Front:
    """The landmark candidates: skin vertices of the outer surface, seen from the front.

    Attributes
    ----------
    index : (C,) int64
        Vertex indices.
    xy : (C, 2) float64
        Their x and y, mm.
    z : (C,) float64
        Their z (towards the viewer), mm.
    """

    index: np.ndarray
    xy: np.ndarray
    z: np.ndarray

    @classmethod
    def of(cls, mesh: _RestMesh, segment: np.ndarray) -> _Front:
        """The candidates of a rest mesh whose faces have the ``SEG_*`` codes ``segment``."""
        used = np.zeros(len(mesh.vertices), bool)
        used[mesh.faces[np.isin(segment, SKIN_SEGMENTS)].reshape(-1)] = True
        index = np.flatnonzero(used & (mesh.kind == _KIND_SKIN))
        return cls(index, mesh.vertices[index, :2], mesh.vertices[index, 2])

    def visible(self, x: float, y: float) -> int:
        """The frontmost candidate within a small radius of (x, y) mm (the nearest if none)."""
        d = np.hypot(self.xy[:, 0] - x, self.xy[:, 1] - y)
        for rad in (1.0, 1.6, 2.5, 4.0):
            ok = d < rad
            if ok.any():
                return int(self.index[np.flatnonzero(ok)[np.argmax(self.z[ok])]])
        return int(self.index[np.argmin(d)])


def _jaw_contour(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 1-17: the frontal silhouette of the face in front of the ears.

    Per half-degree of angle about the mouth centre the farthest candidate, between the
    points where the outline reaches 6 mm below the eyes on either side, sampled at 17 equal
    arc lengths.
    """
    shape, verts, cand, cxy, cz = mesh.shape, mesh.vertices, front.index, front.xy, front.z
    pc = verts[cand]
    y_top = shape.eye_centre[1] - 6.0
    oy = mesh.mouth.y
    neck = shape.neck(pc) < np.minimum(shape.jaw.sdf(pc), shape.chin.sdf(pc)) - 1.0
    sel = shape.clear_of_ears(pc) & ~neck & (cz > 15.0 * shape.scale[2]) & (cxy[:, 1] <= y_top)
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
    return cand[np.flatnonzero(sel)[sil[pick]]]


def _brows(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 18-27: five points along each eyebrow, 1 mm above its middle line."""
    out = np.zeros(10, np.int64)
    for k, ax in enumerate((50.0, 41.0, 32.0, 23.5, 15.0)):
        yb = mesh.shape.brow_line(ax)[0] + 1.0
        out[k] = front.visible(-ax, yb)
        out[9 - k] = front.visible(ax, yb)
    return out


def _nose(mesh: _RestMesh, front: _Front, y28: float | None = None) -> np.ndarray:
    """Landmarks 28-36: the bridge down to the tip, then the bottom of the nose.

    ``y28`` is the height of landmark 28 on the midline, mm (default: 3 mm above the eyes'
    centres); 29 and 30 lie evenly between it and the tip.
    """
    shape, verts, cand, cxy = mesh.shape, mesh.vertices, front.index, front.xy
    idt, mouth_y = shape.idt, mesh.mouth.y
    mid = cand[np.abs(cxy[:, 0]) < 0.5]
    ny = verts[mid, 1]
    nose_zone = mid[(ny < shape.nose_tip[1] + 15.0) & (ny > shape.nose_tip[1] - 15.0)]
    tip_i = int(nose_zone[np.argmax(verts[nose_zone, 2])])
    if y28 is None:
        y28 = shape.eye_centre[1] + 3.0
    ytip = verts[tip_i, 1]
    bridge = [
        front.visible(0.0, y28),
        front.visible(0.0, y28 + (ytip - y28) / 3.0),
        front.visible(0.0, y28 + 2.0 * (ytip - y28) / 3.0),
    ]
    # subnasale: the midline point deepest behind the chord from the tip to the upper lip
    zone = mid[(verts[mid, 1] < ytip) & (verts[mid, 1] > mouth_y + 1.0) & (verts[mid, 2] > 40.0)]
    low = verts[zone, 1] < mouth_y + 12.0
    lip_top = zone[low][np.argmax(verts[zone[low], 2])]
    (ya, za), (yb, zb) = verts[tip_i, 1:], verts[lip_top, 1:]
    zone = zone[(verts[zone, 1] < ya) & (verts[zone, 1] > yb)]
    chord = za + (verts[zone, 1] - ya) * (zb - za) / (yb - ya)
    sn = int(zone[np.argmax(chord - verts[zone, 2])])
    # 34: the bottom of the columella just above the subnasale, as seen from the front
    ysn = verts[sn, 1]
    nw = idt.nose_width * idt.nose
    bottom = [
        front.visible(-11.5 * nw, ysn + 3.0),
        front.visible(-6.0 * nw, ysn + 1.2),
        front.visible(0.0, ysn + 1.0),
        front.visible(6.0 * nw, ysn + 1.2),
        front.visible(11.5 * nw, ysn + 3.0),
    ]
    return np.array([*bridge, tip_i, *bottom], np.int64)


def _eyes(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 37-48: the lid margins, where the skin seen from the front starts to cover
    the eyeball.

    The subject's left eye (43-48: inner, upper-inner, upper-outer, outer, lower-outer,
    lower-inner) is found first; the right eye (37 outer, 38 upper-outer, 39 upper-inner,
    40 inner, 41 lower-inner, 42 lower-outer) mirrors it.
    """
    verts, cxy = mesh.vertices, front.xy
    if mesh.shape.lids:
        return _closed_eyes(mesh, front)
    e = mesh.shape.almond
    tilt = np.arctan2(e.rot[1, 0], e.rot[0, 0]) if e.rot is not None else 0.0
    rel, rho, covering = _lid_cover(mesh, front)
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    left = np.zeros(6, np.int64)
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
        left[k] = front.visible(*cxy[best])
    right = [front.visible(-verts[left[k], 0], verts[left[k], 1]) for k in (3, 2, 1, 0, 5, 4)]
    return np.concatenate([right, left])


def _lid_cover(mesh: _RestMesh, front: _Front) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the lids of the subject's left open eye cover the eyeball, seen from the front.

    Returns
    -------
    rel : (C, 2) float64
        The candidates' x and y relative to the eye's centre, mm.
    rho : (C,) float64
        Their distance from it, mm.
    covering : (C,) bool
        Lid skin at or in front of the eyeball (or beyond its radius), near the opening.
    """
    shape, cz = mesh.shape, front.z
    ec, er = shape.eye_centre, shape.eye_radius
    rel = front.xy - ec[:2]
    rho = np.hypot(rel[:, 0], rel[:, 1])
    ez = ec[2] + np.sqrt(np.clip(er**2 - rho**2, 0.0, None))
    lid = shape(mesh.vertices[front.index], carve=False) > -0.3  # not carved by the opening
    covering = (rho < 1.6 * shape.almond.radii[0]) & lid & ((cz >= ez - 0.05) | (rho >= er))
    return rel, rho, covering


#: Closed eyes: where the six points of an eye lie along its axis, mm (inner corner,
#: upper-inner, upper-outer, outer corner, lower-outer, lower-inner): the corners where an
#: open eye's are, the lid points at a third and two thirds of the way between them, the
#: upper and the lower one at the same place (as iBUG annotates a closed eye).
_CLOSED_ALONG = (-14.0, -14.0 + 27.2 / 3, -14.0 + 2 * 27.2 / 3, 13.2)


def _closed_eyes(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 37-48 of closed eyes: on the lid line, the upper and the lower lid points
    together (iBUG's convention; see :data:`_CLOSED_ALONG`)."""
    left = np.zeros(6, np.int64)
    c0, c1, c2, c3 = _CLOSED_ALONG
    for k, a in enumerate((c0, c1, c2, c3, c2, c1)):
        left[k] = front.visible(*mesh.shape.lid_point(a))
    verts = mesh.vertices
    right = [front.visible(-verts[left[k], 0], verts[left[k], 1]) for k in (3, 2, 1, 0, 5, 4)]
    return np.concatenate([right, left])


def _outer_lips(mesh: _RestMesh, front: _Front) -> np.ndarray:
    """Landmarks 49-60: the corners and the vermilion borders, clockwise from the right
    corner seen from the front."""
    mouth = mesh.mouth
    xc, lips = mouth.corner_x, mesh.shape.idt.lips

    def border(xx, upper):
        h_up, h_lo = mouth.vermilion(np.array([xx]), lips)
        y = mouth.line(xx) + h_up[0] if upper else mouth.line(xx) - h_lo[0]
        return front.visible(xx, float(y))

    upper = [border(xx, True) for xx in (-0.62 * xc, -6.0, 0.0, 6.0, 0.62 * xc)]
    lower = [border(xx, False) for xx in (0.62 * xc, 0.3 * xc, 0.0, -0.3 * xc, -0.62 * xc)]
    corner_l = front.visible(-(xc + 1.5), mouth.corner_y)
    corner_r = front.visible(xc + 1.5, mouth.corner_y)
    return np.array([corner_l, *upper, corner_r, *lower], np.int64)


def _inner_lips(mesh: _RestMesh) -> np.ndarray:
    """Landmarks 61-68: the corners and the slit copies at -xc/2, 0 and xc/2."""
    slit, xc = mesh.slit, mesh.mouth.corner_x
    sx = mesh.vertices[slit.upper, 0]
    cols = [int(np.argmin(np.abs(sx - xx))) for xx in (-0.5 * xc, 0.0, 0.5 * xc)]
    upper = slit.upper[cols]
    lower = slit.lower[cols[::-1]]
    return np.array([slit.corner_l, *upper, slit.corner_r, *lower], np.int64)


def _landmarks(mesh: _RestMesh, segment: np.ndarray) -> np.ndarray:
    """Vertex indices of the iBUG-68 landmarks on the rest mesh.

    Parameters
    ----------
    mesh : _RestMesh
    segment : (F,) int8
        Final ``SEG_*`` code of each face (with hair and brows).

    Returns
    -------
    (68,) int64
    """
    front = _Front.of(mesh, segment)
    lm = np.zeros(68, np.int64)
    lm[0:17] = _jaw_contour(mesh, front)
    lm[17:27] = _brows(mesh, front)
    lm[27:36] = _nose(mesh, front)
    lm[36:48] = _eyes(mesh, front)
    lm[48:60] = _outer_lips(mesh, front)
    lm[60:68] = _inner_lips(mesh)
    return lm
