"""The 2D template face mesh: a canonical frontal face, fiducials at vertices, a mouth hole.

Canonical frame
---------------
The template lives in a 2D frame that mimics image coordinates: **x to the right, y down**, in
units of half the outer-eye-corner distance. The outer eye corners, iBUG 37 and 46, sit at
(-1, 0) and (+1, 0); the face is left-right symmetric about x = 0. iBUG 1-36 and 37-42 are on
the image's left (the subject's right, suffix ``_r`` in names); 43-48 and 17-27 on the image's right.

The canonical positions of all 68 iBUG points (``IBUG_CANONICAL``, 0-based rows = iBUG number - 1)
form a mean-like frontal face drawn from average facial proportions (eye line to chin 2.45,
eye line to nose tip 1.02, mouth width 1.12, face width 2.76 at the ears). iBUG numbers are
**1-based** everywhere in this module's data (``FIDUCIAL_SETS``, ``NAMED_POINTS``), as in the
iBUG-68 annotation scheme; array rows are number - 1.

Mesh
----
441 vertices and 800 faces, as the paper's template (its Fig. 1 quotes 441 / 804). The outline
runs along the jaw contour, inset by ``JAW_INSET`` at the ears and touching landmark 9 at the chin,
and closes over a forehead that reaches ``FOREHEAD_RATIO`` x the brow-to-nose-tip distance above
the brows. The mouth is a thin lens-shaped hole whose boundary is exactly the inner-lip points
61-68 (upper 62-64 and lower 66-68 ``2 * MOUTH_HALF_GAP`` apart at the centre): an open mouth is
fitted by the open-mouth fiducial set, a closed mouth keeps it a slit. iBUG points 9 and 18-68
are all vertices, so any fiducial set drawn from them can be used.

Faces are **counter-clockwise as seen in the image** (x right, y down), i.e. the usual signed area
``(x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)`` is **negative** in template and pixel
coordinates. Then the normal ``(v1 - v0) x (v2 - v0)`` of a mesh sampled from any right-handed
scanner frame points towards the scanner (out of the face), as OpenGL front faces do.

The mesh is generated deterministically: fixed points (outline, mouth, iBUG points, named
points) plus free points spread by farthest-point sampling and relaxed by a spring model
(Persson and Strang's distmesh idea) with Delaunay re-triangulation, then the mouth triangles
removed.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from scan2morph.errors import InputError
from scan2morph.geometry import unique_edges
from scan2morph.tol import N_IBUG

#: The closed-mouth fiducial set (20 iBUG numbers, 1-based), as the paper's 20 feature points:
#: chin, brows (outer, middle, inner), nose bridge, nose tip, nostril wings and subnasale,
#: eye corners, mouth corners and outer-lip midpoints.
CLOSED_MOUTH = (9, 18, 20, 22, 23, 25, 27, 28, 31, 32, 34, 36, 37, 40, 43, 46, 49, 52, 55, 58)
#: The inner-lip contour (iBUG 61-68, the mouth hole's boundary).
INNER_LIPS = (61, 62, 63, 64, 65, 66, 67, 68)
#: The inner-lip corners: in the template 0.06 units from the mouth corners 49 / 55 and in a
#: photo on them within a pixel or two, so they add no information to the spline but, with
#: independent click noise on two almost coincident points, make it ill-conditioned (the noise
#: gain at the template outline rises from 1.36 to 1.86, see ``noise_gain``).
INNER_LIP_CORNERS = (61, 65)
#: Fiducial sets by name (1-based iBUG numbers). ``open`` (the paper's open-mouth set, whose
#: points the paper does not list) adds the inner-lip contour without its corners: the lens
#: corners follow the mouth corners; ``open_corners`` adds all eight.
FIDUCIAL_SETS: dict[str, tuple[int, ...]] = {
    "closed": CLOSED_MOUTH,
    "open": CLOSED_MOUTH + tuple(n for n in INNER_LIPS if n not in INNER_LIP_CORNERS),
    "open_corners": CLOSED_MOUTH + INNER_LIPS,
}
#: The paper's choice of set per take kind: neutral and expressions closed, visemes open.
DEFAULT_FIDUCIAL_SET_BY_KIND = {"neutral": "closed", "expression": "closed", "viseme": "open"}

#: Named template vertices that later stages use: an int is a 1-based iBUG number, a pair is a
#: canonical (x, y) position. ``_r`` / ``_l`` are the subject's right / left (image left / right).
NAMED_POINTS: dict[str, int | tuple[float, float]] = {
    "chin": 9,
    "brow_r_outer": 18,
    "brow_r_inner": 22,
    "brow_l_inner": 23,
    "brow_l_outer": 27,
    "nose_bridge": 28,
    "nose_mid": 29,
    "nose_tip": 31,
    "eye_r_outer": 37,
    "eye_r_inner": 40,
    "eye_l_inner": 43,
    "eye_l_outer": 46,
    "mouth_r": 49,
    "mouth_l": 55,
    "forehead_centre": (0.0, -1.12),
    "temple_r": (-1.05, -0.92),
    "temple_l": (1.05, -0.92),
    "cheekbone_r": (-1.1, 0.36),
    "cheekbone_l": (1.1, 0.36),
}
#: The six stable points paired between takes for the initial ICP alignment (paper Fig. 5):
#: outer and inner eye corners, nose bridge and forehead centre.
ICP_POINTS = (
    "eye_r_outer",
    "eye_r_inner",
    "eye_l_inner",
    "eye_l_outer",
    "nose_bridge",
    "forehead_centre",
)
#: Start and goal of the five Dijkstra paths whose vertices seed the stencil mask over the upper
#: face (paper Fig. 7): across the forehead from temple to temple, along each brow, and under
#: each eye from the cheekbone to the nose bridge.
MASK_PATHS = (
    ("temple_r", "temple_l"),
    ("brow_r_outer", "brow_r_inner"),
    ("brow_l_inner", "brow_l_outer"),
    ("cheekbone_r", "nose_mid"),
    ("nose_mid", "cheekbone_l"),
)

#: Number of template vertices and of outline vertices (with the 8 mouth vertices this gives
#: 2 * 441 - (74 + 8) = 800 faces by Euler's formula for a disc with one hole).
N_VERTICES = 441
N_OUTLINE = 74
#: How far the jaw outline lies inside the iBUG jaw contour at the ears (canonical units,
#: about 5 mm on an adult face), tapering to zero at the chin (landmark 9).
JAW_INSET = 0.12
#: Forehead height above the highest brow point, as a fraction of the brow-to-nose-tip distance.
FOREHEAD_RATIO = 0.6
#: Half the gap between upper and lower inner lip at the mouth centre (canonical units).
MOUTH_HALF_GAP = 0.05
#: Template file format version (``save_template`` / ``load_template``).
TEMPLATE_FORMAT = 1

# The jaw as an ellipse: centre height, half width, depth below the centre.
_JAW_Y0, _JAW_A, _JAW_B = 0.1, 1.38, 2.35
# Squareness exponent of the forehead outline (2 = ellipse).
_FOREHEAD_N = 2.6


def _mirror(points: np.ndarray) -> np.ndarray:
    return points * np.array([-1.0, 1.0])


def _canonical_ibug() -> np.ndarray:
    """Canonical (68, 2) iBUG positions (rows = iBUG number - 1), symmetric about x = 0."""
    p = np.zeros((N_IBUG, 2))
    theta = np.pi * np.arange(17) / 16.0
    p[0:17] = np.column_stack([-_JAW_A * np.cos(theta), _JAW_Y0 + _JAW_B * np.sin(theta)])
    brow_r = np.array(
        [[-1.16, -0.40], [-0.97, -0.58], [-0.74, -0.66], [-0.48, -0.64], [-0.24, -0.56]]
    )
    p[17:22] = brow_r
    p[22:27] = _mirror(brow_r[::-1])
    p[27:31] = np.column_stack([np.zeros(4), [-0.02, 0.33, 0.68, 1.02]])
    nostrils_r = np.array([[-0.34, 1.20], [-0.17, 1.26]])
    p[31:33] = nostrils_r
    p[33] = (0.0, 1.29)
    p[34:36] = _mirror(nostrils_r[::-1])
    eye_r = np.array(
        [[-1.0, 0.0], [-0.82, -0.13], [-0.58, -0.13], [-0.4, 0.02], [-0.6, 0.09], [-0.82, 0.09]]
    )
    p[36:42] = eye_r
    p[42:48] = _mirror(eye_r[[3, 2, 1, 0, 5, 4]])
    # Outer lips 49-60: upper lip image left to right, then lower lip back.
    upper = np.array([[-0.56, 1.72], [-0.36, 1.6], [-0.14, 1.53], [0.0, 1.56]])
    p[48:52] = upper
    p[52:55] = _mirror(upper[2::-1])
    # Lower lip from the corner 55 back to 49: 56-57 on the image's right, 58 in the middle.
    lower_r = np.array([[-0.36, 1.86], [-0.16, 1.93]])  # beside 49, then towards the middle
    p[55:57] = _mirror(lower_r)
    p[57] = (0.0, 1.95)
    p[58:60] = lower_r[::-1]
    # Inner lips 61-68: a thin lens between the corners 61 and 65.
    # The inner corners sit just inside the outer ones (about 5% of the mouth width), as in
    # annotated faces; a wider inset squeezes the corner triangles until noise folds them.
    half_w, yc = 0.50, 1.72
    xs = np.array([-half_w, -0.24, 0.0, 0.24, half_w, 0.24, 0.0, -0.24])
    side = np.array([0, -1, -1, -1, 0, 1, 1, 1])
    p[60:68] = np.column_stack([xs, yc + side * MOUTH_HALF_GAP * (1.0 - (xs / half_w) ** 2)])
    return p


#: The canonical (68, 2) iBUG-68 positions (row = iBUG number - 1), template frame.
IBUG_CANONICAL = _canonical_ibug()
IBUG_CANONICAL.flags.writeable = False


@dataclass(frozen=True, eq=False)
class Template:
    """A 2D template face mesh with its fiducials (frozen; compared and hashed by identity).

    Attributes
    ----------
    vertices : (V, 2) float64
        Canonical template coordinates (x right, y down; units: half the outer-eye distance).
    faces : (F, 3) int64
        Counter-clockwise as seen in the image (negative standard signed area, see module doc).
    ibug_xy : (68, 2) float64
        Canonical positions of all iBUG-68 points (row = iBUG number - 1).
    ibug_vertex : (68,) int64
        Vertex index of each iBUG point, -1 where the point is not a vertex (the jaw contour).
    fiducials : dict of str to (ndarray, ndarray)
        Set name -> (iBUG numbers (1-based), vertex indices), e.g. ``"closed"`` and ``"open"``.
    named : dict of str to int
        Name -> vertex index (``NAMED_POINTS``: ICP points, mask path ends, ...).
    boundary : (B,) int64
        The outer boundary loop, in order (counter-clockwise as seen in the image).
    mouth_boundary : (M,) int64
        The mouth hole's loop, in order, starting at iBUG 61.
    level : int
        Number of 1-to-4 subdivisions applied to the base template (0 = base).
    """

    vertices: np.ndarray
    faces: np.ndarray
    ibug_xy: np.ndarray
    ibug_vertex: np.ndarray
    fiducials: dict[str, tuple[np.ndarray, np.ndarray]]
    named: dict[str, int]
    boundary: np.ndarray
    mouth_boundary: np.ndarray
    level: int = 0

    def __post_init__(self) -> None:
        for name in ("vertices", "faces", "ibug_xy", "ibug_vertex", "boundary", "mouth_boundary"):
            arr = np.array(getattr(self, name), copy=True)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        fid = {}
        for k, (numbers, idx) in self.fiducials.items():
            numbers, idx = np.array(numbers, dtype=np.int64), np.array(idx, dtype=np.int64)
            numbers.flags.writeable = False
            idx.flags.writeable = False
            fid[k] = (numbers, idx)
        object.__setattr__(self, "fiducials", fid)
        object.__setattr__(self, "named", {k: int(v) for k, v in self.named.items()})

    @property
    def n_vertices(self) -> int:
        """Number of vertices V."""
        return int(self.vertices.shape[0])

    def fiducial_set(
        self, which: str | tuple[int, ...] | list[int] | np.ndarray, source: str = "template"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Resolve a fiducial set to iBUG numbers and vertex indices.

        Parameters
        ----------
        which : str or sequence of int
            A set name (``"closed"``, ``"open"``) or 1-based iBUG numbers.
        source : str
            Label for error messages (e.g. ``"subject/take"``).

        Returns
        -------
        numbers : (m,) int64
            1-based iBUG numbers.
        indices : (m,) int64
            Their template vertex indices.

        Raises
        ------
        InputError
            Unknown set name, iBUG numbers out of 1..68, repeated, or not template vertices.
        """
        if isinstance(which, str):
            if which not in self.fiducials:
                raise InputError(
                    source,
                    f"fiducial_set: unknown set {which!r} (expected one of {sorted(self.fiducials)})",
                )
            return self.fiducials[which]
        numbers = np.asarray(which)
        if numbers.ndim != 1 or numbers.size == 0 or not np.issubdtype(numbers.dtype, np.integer):
            raise InputError(
                source, "fiducial_set: expected a set name or a 1-D list of iBUG numbers"
            )
        numbers = numbers.astype(np.int64)
        bad = numbers[(numbers < 1) | (numbers > N_IBUG)]
        if bad.size:
            raise InputError(
                source, f"fiducial_set: iBUG numbers {bad.tolist()} not in 1..{N_IBUG}"
            )
        if np.unique(numbers).size != numbers.size:
            raise InputError(source, "fiducial_set: repeated iBUG numbers")
        idx = self.ibug_vertex[numbers - 1]
        if (idx < 0).any():
            raise InputError(
                source,
                f"fiducial_set: iBUG points {numbers[idx < 0].tolist()} are not template vertices "
                "(usable: 9 and 18-68)",
            )
        return numbers, idx.astype(np.int64)


def signed_area2(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Twice the standard signed area of each triangle.

    Parameters
    ----------
    points : (V, 2) float
        2D vertex positions (template or pixel coordinates).
    faces : (F, 3) int
        Triangles.

    Returns
    -------
    area2 : (F,) float64
        ``(x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)``; negative for the template's
        orientation (counter-clockwise as seen with y down).
    """
    p = np.asarray(points, dtype=np.float64)[np.asarray(faces)]
    d1 = p[:, 1] - p[:, 0]
    d2 = p[:, 2] - p[:, 0]
    return d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]


def _outline(n: int, ibug: np.ndarray) -> np.ndarray:
    """The outer outline: ``n`` points equally spaced by arc length, starting at the chin.

    Below the ears the jaw ellipse (inset by ``JAW_INSET`` at the ears, 0 at the chin); above,
    a squarish forehead arc reaching ``FOREHEAD_RATIO`` x brow-to-nose-tip above the brows.
    Ordered counter-clockwise as seen with y down (chin, then the image's right side up).
    """
    brow_top = ibug[17:27, 1].min()
    brow_mean = ibug[17:27, 1].mean()
    top = brow_top - FOREHEAD_RATIO * (ibug[30, 1] - brow_mean)
    a = _JAW_A - JAW_INSET
    # Dense parametrisation: t in [0, 2 pi), t = 0 at the chin, going to the image's right;
    # x = a sin t, and the jaw is the part below the ears (cos t >= 0).
    t = np.linspace(0.0, 2.0 * np.pi, 20001)
    c, s = np.sin(t), np.cos(t)
    x = a * c
    y = np.where(
        s >= 0,
        _JAW_Y0 + _JAW_B * s,
        _JAW_Y0 - (_JAW_Y0 - top) * np.abs(s) ** (2.0 / _FOREHEAD_N),
    )
    x = np.where(s >= 0, x, a * np.sign(c) * np.abs(c) ** (2.0 / _FOREHEAD_N))
    seg = np.hypot(np.diff(x), np.diff(y))
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    targets = np.arange(n) * arc[-1] / n
    return np.column_stack([np.interp(targets, arc, x), np.interp(targets, arc, y)])


def inside_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(n,) bool: which 2D points (n, 2) lie inside a closed polygon (k, 2) (even-odd rule,
    vectorised over points and edges)."""
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (crosses & (x < xint)).sum(axis=1) % 2 == 1


def _segment_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance from each point to a closed polyline."""
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    ap = points[:, None, :] - a[None]
    t = np.clip((ap * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.sqrt((d * d).sum(-1)).min(axis=1)


def _segments_cross(p: np.ndarray, a: int, b: int, c: int, d: int) -> bool:
    """Whether segments ab and cd cross at a point interior to both."""

    def orient(i, j, k):
        return (p[j, 0] - p[i, 0]) * (p[k, 1] - p[i, 1]) - (p[j, 1] - p[i, 1]) * (p[k, 0] - p[i, 0])

    return orient(a, b, c) * orient(a, b, d) < 0 and orient(c, d, a) * orient(c, d, b) < 0


def _enforce_edges(points: np.ndarray, tri: np.ndarray, constraints) -> np.ndarray:
    """Make every constraint edge an edge of the triangulation by edge flips (Lawson/Sloan).

    Delaunay triangulation does not respect the thin mouth lens: an edge from the outer lip may
    cut across the lens boundary. Each edge crossing a missing constraint is flipped when its two
    triangles form a convex quad, until the constraint appears.
    """
    tri = [list(t) for t in tri]
    for a, b in constraints:
        for _ in range(10 * len(tri)):
            if any(a in t and b in t for t in tri):
                break
            flipped = False
            for i, t in enumerate(tri):
                for k in range(3):
                    c, d = t[k], t[(k + 1) % 3]
                    if {c, d} & {a, b} or not _segments_cross(points, a, b, c, d):
                        continue
                    e = t[(k + 2) % 3]
                    j = next((j for j, u in enumerate(tri) if j != i and c in u and d in u), None)
                    if j is None:
                        continue
                    f = next(v for v in tri[j] if v not in (c, d))
                    if not _segments_cross(points, e, f, c, d):  # quad not convex: try another edge
                        continue
                    tri[i], tri[j] = [e, f, d], [f, e, c]
                    flipped = True
                    break
                if flipped:
                    break
            if not flipped:
                raise RuntimeError(f"template: cannot recover constraint edge {a}-{b}")
    return np.asarray(tri, dtype=np.int64)


def _triangulate(points: np.ndarray, mouth: np.ndarray, enforce: bool = True) -> np.ndarray:
    """Delaunay triangles with the mouth lens's edges enforced, minus those inside the lens.

    ``enforce=False`` skips the (slower) edge recovery: enough for the relaxation's springs.
    """
    tri = Delaunay(points).simplices
    loop = np.asarray(mouth)
    if enforce:
        tri = _enforce_edges(points, tri, list(zip(loop, np.roll(loop, -1), strict=True)))
    centroids = points[tri].mean(axis=1)
    return tri[~inside_polygon(centroids, points[loop])]


def _relax(
    points: np.ndarray, n_fixed: int, outline: np.ndarray, mouth_poly: np.ndarray, mouth: np.ndarray
) -> np.ndarray:
    """Spring relaxation of the free points (rows >= n_fixed) with Delaunay re-triangulation."""
    p = points.copy()
    h = _spacing(outline, len(p))
    for _ in range(150):
        tri = _triangulate(p, mouth, enforce=False)
        bars = unique_edges(tri)
        vec = p[bars[:, 0]] - p[bars[:, 1]]
        length = np.hypot(vec[:, 0], vec[:, 1])
        target = 1.2 * np.sqrt((length**2).sum() / len(length))
        force = np.maximum(target - length, 0.0) / length
        fvec = force[:, None] * vec
        total = np.zeros_like(p)
        np.add.at(total, bars[:, 0], fvec)
        np.add.at(total, bars[:, 1], -fvec)
        total[:n_fixed] = 0.0
        step = 0.2 * total
        trial = p + step
        free = np.arange(n_fixed, len(p))
        ok = inside_polygon(trial[free], outline) & ~inside_polygon(trial[free], mouth_poly)
        ok &= _segment_distance(trial[free], outline) > 0.4 * h
        ok &= _segment_distance(trial[free], mouth_poly) > 0.4 * h
        p[free[ok]] = trial[free[ok]]
        if np.abs(step[free[ok]]).max(initial=0.0) < 1e-4 * h:
            break
    return p


def _spacing(outline: np.ndarray, n: int) -> float:
    """Edge length of an equilateral lattice of ``n`` points filling the outline (shoelace area)."""
    x, y = outline[:, 0], outline[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    return float(np.sqrt(2.0 * area / (np.sqrt(3.0) * n)))


def _farthest_points(candidates: np.ndarray, chosen: np.ndarray, n: int) -> np.ndarray:
    """Pick ``n`` candidates greedily, each the farthest from everything chosen so far."""
    dist = cKDTree(chosen).query(candidates)[0]
    picked = np.empty(n, dtype=np.int64)
    for k in range(n):
        i = int(np.argmax(dist))
        picked[k] = i
        dist = np.minimum(dist, np.hypot(*(candidates - candidates[i]).T))
    return candidates[picked]


@lru_cache(maxsize=1)
def build_template() -> Template:
    """Build the template mesh (deterministic; cached, the arrays are read-only).

    Returns
    -------
    Template
        441 vertices, 800 faces, fiducial sets ``FIDUCIAL_SETS``, named vertices
        ``NAMED_POINTS``; see the module documentation for the frame and orientation.
    """
    ibug = IBUG_CANONICAL.copy()
    outline = _outline(N_OUTLINE, ibug)
    mouth_numbers = np.array(INNER_LIPS)
    mouth_poly = ibug[mouth_numbers - 1]
    inner_numbers = np.array([n for n in range(18, 61)])
    named_xy = {k: np.asarray(v, float) for k, v in NAMED_POINTS.items() if not isinstance(v, int)}
    fixed = np.vstack([outline, mouth_poly, ibug[inner_numbers - 1], *named_xy.values()])
    n_fixed = len(fixed)
    # Free points: farthest-point sampling of a fine lattice inside the face, then relaxation.
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    g = 0.03
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], g), np.arange(lo[1], hi[1], g))
    cand = np.column_stack([gx.ravel(), gy.ravel()])
    cand = cand[inside_polygon(cand, outline) & ~inside_polygon(cand, mouth_poly)]
    # Free points start clear of the outline and the mouth (the relaxation keeps them clear): a
    # free point close to a boundary edge would make a sliver triangle with it.
    h = _spacing(outline, N_VERTICES)
    clear = _segment_distance(cand, outline) > 0.5 * h
    clear &= _segment_distance(cand, mouth_poly) > 0.5 * h
    cand = cand[clear]
    free = _farthest_points(cand, fixed, N_VERTICES - n_fixed)
    mouth_idx = np.arange(N_OUTLINE, N_OUTLINE + len(mouth_numbers))
    points = _relax(np.vstack([fixed, free]), n_fixed, outline, mouth_poly, mouth_idx)
    faces = _triangulate(points, mouth_idx)
    neg = signed_area2(points, faces) > 0
    faces[neg] = faces[neg][:, [0, 2, 1]]

    ibug_vertex = np.full(N_IBUG, -1, dtype=np.int64)
    ibug_vertex[8] = 0  # the chin is the first outline point
    ibug_vertex[mouth_numbers - 1] = mouth_idx
    ibug_vertex[inner_numbers - 1] = N_OUTLINE + len(mouth_numbers) + np.arange(len(inner_numbers))
    named = {}
    base = N_OUTLINE + len(mouth_numbers) + len(inner_numbers)
    for k, v in NAMED_POINTS.items():
        if isinstance(v, int):
            named[k] = int(ibug_vertex[v - 1])
        else:
            named[k] = base
            base += 1
    fiducials = {k: (np.array(v), ibug_vertex[np.array(v) - 1]) for k, v in FIDUCIAL_SETS.items()}
    return Template(
        vertices=points,
        faces=faces.astype(np.int64),
        ibug_xy=ibug,
        ibug_vertex=ibug_vertex,
        fiducials=fiducials,
        named=named,
        boundary=np.arange(N_OUTLINE, dtype=np.int64),
        mouth_boundary=mouth_idx.astype(np.int64),
    )
