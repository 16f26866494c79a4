"""Vertex regions of the template, defined in its canonical frame (so they hold for every take)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.template.mesh import inside_polygon


def upper_face(template, above: str = "nose_tip") -> np.ndarray:
    """Vertices above a named template point (the face part a mouth does not move).

    Parameters
    ----------
    template : Template
        Base or subdivided template (canonical frame: y down).
    above : str
        A key of ``template.named``; vertices with a smaller canonical y (higher on the face)
        belong to the region.

    Returns
    -------
    region : (V,) bool
    """
    if above not in template.named:
        raise InputError(
            "template",
            f"region bound {above!r} is not a named vertex (known: {sorted(template.named)})",
        )
    y0 = template.vertices[template.named[above], 1]
    return template.vertices[:, 1] < y0


def stable_face(template) -> np.ndarray:
    """Vertices that neither visemes nor common expressions move: ICP's default region.

    The upper forehead (more than 0.35 template units, about 16 mm, above the inner brow ends:
    brows rise when sad or surprised), the nose ridge between the bridge and the tip, and the
    temples (outside the outer eye corners, above the cheekbones: cheeks rise in a smile).
    Measured on the synthetic range subjects, ICP on this region alone aligns smiles and sad
    faces to < 0.16 degrees and < 0.15 mm, where the whole face above the nose tip gives up to
    0.6 degrees and 0.9 mm. A smile moves its lower temples by 1-3 mm, though, and once those are
    trimmed the rest constrains the rotation poorly (mesh and RGB-D takes: up to 0.21 and 0.38
    degrees); the align stage therefore grows the region into the still skin of the whole face
    (``align.grow_into``, :func:`~scan2morph.align.align_take`'s ``grow_indices``): above the
    nose tip alone, a brow raise or a frown on a depth camera leaves too little still skin, and
    no lever below it, to hold the rotation under 0.2 degrees.

    Returns
    -------
    region : (V,) bool
    """
    x, y = template.vertices[:, 0], template.vertices[:, 1]
    named = template.named
    brow = template.vertices[[named["brow_r_inner"], named["brow_l_inner"]], 1].min()
    bridge, tip = (
        template.vertices[named["nose_bridge"], 1],
        template.vertices[named["nose_tip"], 1],
    )
    forehead = y < brow - 0.35
    ridge = (np.abs(x) < 0.22) & (y > bridge) & (y < tip)
    temples = (np.abs(x) > 1.05) & (y < 0.3)
    return forehead | ridge | temples


def icp_region(template, name: str) -> np.ndarray:
    """The ICP region named in config: ``stable`` (:func:`stable_face`), ``upper_face`` or
    ``face`` (every template vertex: the region to grow into, ``align.grow_into``)."""
    if name == "stable":
        return stable_face(template)
    if name == "upper_face":
        return upper_face(template)
    if name == "face":
        return np.ones(len(template.vertices), dtype=bool)
    raise InputError(
        "config",
        f"align.icp_region: {name!r} unknown (expected 'stable', 'upper_face' or 'face')",
    )


def named_indices(template, names, what: str) -> np.ndarray:
    """Vertex indices of named template points, with a clear error for an unknown name.

    Parameters
    ----------
    template : Template
    names : sequence of str, or sequence of (str, str) pairs
    what : str
        The config key the names come from, for the message (e.g. ``"align.point_pairs"``).

    Returns
    -------
    indices : int64 array of the same shape as ``names``
    """
    arr = np.asarray(names, dtype=object)
    flat = []
    for name in arr.ravel():
        if name not in template.named:
            raise InputError(
                "config",
                f"{what}: {name!r} is not a named template vertex (known: {sorted(template.named)})",
            )
        flat.append(template.named[name])
    return np.asarray(flat, dtype=np.int64).reshape(arr.shape)


def inner_lip_midline(inner_lip: np.ndarray) -> np.ndarray:
    """(5, 2) the mouth's midline from the inner-lip contour, left to right.

    Parameters
    ----------
    inner_lip : (8, 2) float
        iBUG 61-68 in order (corner, upper lip, corner, lower lip); closed or open.

    Returns
    -------
    (5, 2) float64
        The corners and the mean of each upper/lower pair (62-68, 63-67, 64-66), sorted by x.
    """
    lip = np.asarray(inner_lip, dtype=np.float64)
    mid = np.vstack([lip[0], (lip[1:4] + lip[7:4:-1]) / 2.0, lip[4]])
    return mid[np.argsort(mid[:, 0])]


def lip_side(points: np.ndarray, midline: np.ndarray, band: float) -> np.ndarray:
    """Which lip each 2D point belongs to: above or below the mouth's midline.

    Parameters
    ----------
    points : (n, 2) float
        Positions in a frame whose y points down (an image, the template, :data:`FRONT`).
    midline : (m, 2) float
        The mouth's midline in the same frame, sorted by x (:func:`inner_lip_midline`, or the
        slit itself).
    band : float
        Points farther than this from the midline (same units) are on neither lip.

    Returns
    -------
    (n,) int8
        -1 above the midline (upper lip), +1 below (lower lip), 0 beyond its ends or the band.
    """
    mid = np.asarray(midline, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    offset = p[:, 1] - np.interp(p[:, 0], mid[:, 0], mid[:, 1])
    side = np.sign(offset).astype(np.int8)
    side[(p[:, 0] <= mid[0, 0]) | (p[:, 0] >= mid[-1, 0]) | (np.abs(offset) > band)] = 0
    return side


def mouth_faces(template) -> np.ndarray:
    """(F,) bool: the template's triangles inside the outer-lip contour (iBUG 49-60): the lips.

    Parameters
    ----------
    template : Template
        Base or subdivided template (canonical frame), with ``ibug_xy`` (68, 2).

    Returns
    -------
    (F,) bool
        True for each triangle whose centroid lies inside the outer-lip loop.
    """
    loop = np.asarray(template.ibug_xy, dtype=np.float64)[OUTER_LIP_ROWS]
    centroids = np.asarray(template.vertices, dtype=np.float64)[template.faces].mean(axis=1)
    return inside_polygon(centroids, loop)


#: iBUG rows (0-based) of the outer-lip contour (iBUG 49-60, a loop).
OUTER_LIP_ROWS = np.arange(48, 60)
#: iBUG rows (0-based) of each lip's outer contour, corner to corner: the vermilion border
#: (upper: iBUG 49-55; lower: iBUG 55-60 and 49).
LIP_BORDERS = {"upper": np.arange(48, 55), "lower": np.array([54, 55, 56, 57, 58, 59, 48])}
#: iBUG rows (0-based) of the inner-lip contour (iBUG 61-68: corner, upper lip, corner, lower lip).
INNER_LIP_ROWS = np.arange(60, 68)


@dataclass(frozen=True)
class Lip:
    """A lip's vertices of a (subdivided) template.

    Attributes
    ----------
    inner : (n,) int64
        Vertices of the mouth's boundary on the lip (the slit), corners excluded, by x.
    outline : (k,) int64
        Vertices on the lip's vermilion border (:data:`LIP_BORDERS`) between the inner-lip
        corners, by x.
    between : (m,) int64
        The vertices strictly between the slit and the border (the lip's body).
    """

    inner: np.ndarray
    outline: np.ndarray
    between: np.ndarray

    @property
    def vertices(self) -> np.ndarray:
        """(n,) int64 the lip's vertices: slit, body and border, each once."""
        return np.unique(np.concatenate([self.inner, self.between, self.outline]))

    def columns(self, vertices2d: np.ndarray) -> np.ndarray:
        """(n,) int64 for each of :attr:`vertices`, the slit vertex (its index in
        :attr:`inner`) nearest in x (template coordinates ``vertices2d`` (V, 2)): the column
        whose profile it lies on."""
        x = np.asarray(vertices2d, dtype=np.float64)[:, 0]
        return np.argmin(np.abs(x[self.vertices][:, None] - x[self.inner][None, :]), axis=1)

    def border_points(self, vertices2d: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(n,) the border's point above (or below) each slit vertex: ``points`` (V, d) of the
        vertices (pixel positions in an image, px) interpolated along the outline at the slit
        vertices' template x (a column straight across the lip in the template).

        Returns
        -------
        (n, d) float64
            NaN where an outline vertex next to it has a NaN point.
        """
        x = np.asarray(vertices2d, dtype=np.float64)[:, 0]
        p = np.asarray(points, dtype=np.float64)[self.outline]
        xo, xi = x[self.outline], x[self.inner]
        k = np.clip(np.searchsorted(xo, xi), 1, max(len(xo) - 1, 1))
        if len(xo) == 1:
            return np.repeat(p, len(xi), axis=0)
        w = np.clip((xi - xo[k - 1]) / (xo[k] - xo[k - 1]), 0.0, 1.0)[:, None]
        return (1.0 - w) * p[k - 1] + w * p[k]


def lip(template, side: str = "upper") -> Lip:
    """A lip of a template: its slit vertices, its vermilion border and its body.

    Parameters
    ----------
    template : Template
        Base or subdivided template (canonical frame: y down), with ``ibug_xy`` (68, 2) and
        ``mouth_boundary``.
    side : str
        ``"upper"`` or ``"lower"``.

    Returns
    -------
    Lip

    Raises
    ------
    InputError
        ``side`` is unknown, or the template has no vertex on the lip's vermilion border or no
        slit vertex on it.
    """
    if side not in LIP_BORDERS:
        raise InputError("template", f"lip side {side!r} unknown (expected 'upper' or 'lower')")
    sign = -1.0 if side == "upper" else 1.0  # y down: the upper lip above the slit
    v = np.asarray(template.vertices, dtype=np.float64)
    ibug = np.asarray(template.ibug_xy, dtype=np.float64)
    mid = inner_lip_midline(ibug[INNER_LIP_ROWS])
    mouth = np.asarray(template.mouth_boundary, dtype=np.int64)
    x = v[:, 0]
    inside = (x > mid[0, 0]) & (x < mid[-1, 0])
    on_side = sign * (v[:, 1] - np.interp(x, mid[:, 0], mid[:, 1])) > 0
    inner = mouth[inside[mouth] & on_side[mouth]]
    inner = inner[np.argsort(x[inner])]
    border_line = ibug[LIP_BORDERS[side]]
    f = np.asarray(template.faces, dtype=np.int64)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    tol = 0.25 * float(np.median(np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)))
    on_border = _polyline_distance(v, border_line) < tol
    outline = np.flatnonzero(on_border & inside)
    outline = outline[np.argsort(x[outline])]
    if len(inner) == 0 or len(outline) == 0:
        raise InputError(
            "template",
            f"no {side} lip: {len(inner)} slit vertices on its side of the inner-lip midline, "
            f"{len(outline)} vertices on its vermilion border between the mouth's corners",
        )
    order = np.argsort(border_line[:, 0])
    inside_border = (
        sign * (np.interp(x, border_line[order, 0], border_line[order, 1]) - v[:, 1]) > 0
    )
    body = inside & on_side & inside_border & ~on_border
    body[inner] = False
    return Lip(inner, outline, np.flatnonzero(body))


def _polyline_distance(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(n,) distance of 2D points to a polyline (k, 2), same units."""
    d = np.full(len(points), np.inf)
    for a, b in zip(line[:-1], line[1:], strict=True):
        ab = b - a
        t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
        d = np.minimum(d, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
    return d
