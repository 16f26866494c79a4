"""Sampling the range image at the warped template vertices (Yano-Harada 3.1).

XYZ at a vertex is the bilinear interpolation of the four neighbouring pixels. The paper's rule
makes a vertex with any neighbour pixel without data invalid (NaN, never a placeholder); with
``min_weight`` < 1 a vertex at the edge of the data (the lips along the mouth opening, the rim of
a hole) keeps a value when the neighbours with data carry at least that share of the bilinear
weight: the affine function through them (exact on a plane with three, along the edge with two)
is evaluated at the vertex. Independently, ``max_slope_deg`` rejects a vertex whose neighbours
straddle a depth step (a lip over the chin, the nose over the cheek): interpolating across it
would put the vertex in mid-air. A step is told from a steep surface by the slope between two
neighbour pixels (extent along the scanner's optical axis against the extent across it), so the
rule does not depend on the scanner's resolution. Scanner XYZ may come in any right-handed frame:
the scanner's centre and optical axis are estimated from the range image's own pixel grid
(:func:`scan2morph.scan.view.scanner_view`), so the rules turn with the data. Texture coordinates
come from the pixel position (color and range are pixel to pixel).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.errors import InputError
from scan2morph.geometry import finite_points, unique_edges
from scan2morph.scan.view import (  # noqa: F401 (FRAME_SNAP_*: re-exported, imported from here)
    FRAME_SNAP_DEG,
    FRAME_SNAP_SHARE,
    SCANNER_FRAME,
    ScannerView,
    scanner_view,
)
from scan2morph.template.mesh import signed_area2

#: Corner offsets (dx, dy) of the four neighbour pixels, in the order of the bit masks below.
_CORNERS = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.float64)


def _partial_weights(fx: np.ndarray, fy: np.ndarray, have: np.ndarray) -> np.ndarray:
    """(4, V) weights of the four corners for vertices with some corners missing.

    The least-squares affine function ``mean + g . (d - d_mean)`` through the corners with data
    (``d`` = corner offsets; the gradient ``g`` of least norm when fewer than three, i.e. flat
    across a pair of corners, so the result does not depend on where the cell's origin is),
    evaluated at ``(fx, fy)``; missing corners weigh 0.
    """
    out = np.zeros((4, len(fx)))
    pattern = have.T @ (1 << np.arange(4))
    for code in np.unique(pattern):
        rows = np.flatnonzero(pattern == code)
        used, centre, solve = _corner_fit(int(code))
        if not len(used):
            continue
        at = np.column_stack([np.ones(len(rows)), fx[rows] - centre[0], fy[rows] - centre[1]])
        out[used[:, None], rows] = (at @ solve).T  # np.ix_ costs more than the assignment
    return out


@functools.cache
def _corner_fit(code: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The corners with data of a bit mask ``code`` (:func:`_partial_weights`), their centre
    (2,) and the pseudo-inverse (3, k) of their affine design (read-only): kept per mask."""
    used = np.flatnonzero((code >> np.arange(4)) & 1)
    centre = _CORNERS[used].mean(axis=0) if len(used) else np.zeros(2)
    design = np.column_stack([np.ones(len(used)), _CORNERS[used] - centre])
    out = (used, centre, np.linalg.pinv(design) if len(used) else np.zeros((3, 0)))
    for a in out:
        a.setflags(write=False)
    return out


def _steep(d: np.ndarray, view: np.ndarray, max_ratio: float) -> np.ndarray:
    """(n,) bool: segments ``d`` (n, 3) whose extent along the unit viewing direction ``view``
    ((3,) or (n, 3)) exceeds ``max_ratio`` times their extent across it: a depth step."""
    along = d @ view if view.ndim == 1 else np.einsum("nd,nd->n", d, view)
    across = np.linalg.norm(d - along[:, None] * view, axis=1)
    return np.abs(along) > max_ratio * across


def _straddles_step(
    corners: np.ndarray, have: np.ndarray, max_ratio: float, axis: np.ndarray
) -> np.ndarray:
    """(V,) bool: two corners with data joined by a step along the depth ``axis`` (unit (3,))."""
    out = np.zeros(corners.shape[1], dtype=bool)
    for a in range(4):
        for b in range(a + 1, 4):
            both = have[a] & have[b]
            d = np.where(both[:, None], corners[b] - corners[a], 0.0)
            out |= both & _steep(d, axis, max_ratio)
    return out


def behind_steps(
    vertices: np.ndarray,
    faces: np.ndarray,
    max_slope_deg: float,
    centre: np.ndarray | None = None,
) -> np.ndarray:
    """(V,) bool: vertices on the far side of a depth step in the fitted mesh.

    A mesh edge steeper than ``max_slope_deg`` to the image plane (its extent along the viewing
    ray through its midpoint against its extent across it) joins two surfaces at different
    depths, e.g. a vertex at the chin contour that fell on the neck behind it. Its endpoint
    farther from the scanner is flagged; the face is the surface in front.

    Parameters
    ----------
    vertices : (V, 3) float, mm, NaN = invalid (their edges are skipped)
    faces : (F, 3) int
    max_slope_deg : float in (0, 90)
    centre : (3,) float, optional
        The scanner's position in the frame of ``vertices`` (:func:`scanner_view` of the range
        image they were sampled from); default the origin (a scanner-centred frame).
    """
    v = np.asarray(vertices, dtype=np.float64)
    e = unique_edges(faces)
    a, b = v[e[:, 0]], v[e[:, 1]]
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    e, a, b = e[ok], a[ok], b[ok]
    if centre is not None and np.any(centre):
        a, b = a - centre, b - centre
    ray = a + b
    ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-300)
    steep = _steep(b - a, ray, np.tan(np.radians(max_slope_deg)))
    far = np.where(np.linalg.norm(b, axis=1) > np.linalg.norm(a, axis=1), e[:, 1], e[:, 0])
    out = np.zeros(len(v), dtype=bool)
    out[far[steep]] = True
    return out


def sample_range(
    xyz: np.ndarray,
    points: np.ndarray,
    source: str = "range image",
    min_weight: float = 1.0,
    max_slope_deg: float | None = None,
    view: ScannerView | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear samples of a range image.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    points : (V, 2) float, pixel coordinates ((0, 0) = centre of the top-left pixel)
    source : str
        Label for error messages.
    min_weight : float in (0, 1]
        A point whose neighbour pixels with data carry less than this share of its bilinear
        weight is invalid. 1 (the paper's rule): all four neighbours must have data. Below 1, a
        point with some neighbours missing takes the value of the affine function through the
        neighbours with data.
    max_slope_deg : float in (0, 90), optional
        A point is invalid when two of its neighbours with data are joined by a segment steeper
        than this to the image plane (its extent along the scanner's optical axis >
        ``tan(max_slope_deg)`` times its extent across it, mm): it straddles a depth step.
        None: no check.
    view : ScannerView, optional
        The scanner's optical axis for ``max_slope_deg``; default :func:`scanner_view` of
        ``xyz``, so that the rule does not depend on the frame the scanner XYZ come in.

    Returns
    -------
    vertices : (V, 3) float64, mm; NaN where invalid
    valid : (V,) bool
        True where the point lies in ``[0, W-1] x [0, H-1]`` and passes the two rules above
        (x, y, z of a pixel all finite = the pixel has data). Non-finite points are invalid.

    Raises
    ------
    InputError
        ``xyz`` not (H, W, 3) with H, W >= 2, ``points`` not (V, 2), ``min_weight`` outside
        (0, 1] or ``max_slope_deg`` outside (0, 90).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or min(xyz.shape[:2]) < 2:
        raise InputError(source, f"xyz: expected (H, W, 3) with H, W >= 2, got {xyz.shape}")
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(source, f"points: expected (V, 2) pixel coordinates, got {points.shape}")
    if not 0 < min_weight <= 1:
        raise InputError(source, f"min_weight: expected a share in (0, 1], got {min_weight}")
    if max_slope_deg is not None and not 0 < max_slope_deg < 90:
        raise InputError(
            source, f"max_slope_deg: expected an angle in (0, 90) degrees, got {max_slope_deg}"
        )
    h, w = xyz.shape[:2]
    x, y = points[:, 0], points[:, 1]
    inside = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (y >= 0) & (x <= w - 1) & (y <= h - 1)
    # The last row / column samples the cell to its left / above with weight 1 on its own pixel.
    x0 = np.clip(np.floor(np.where(inside, x, 0)).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(np.where(inside, y, 0)).astype(np.int64), 0, h - 2)
    fx = np.where(inside, x, 0) - x0
    fy = np.where(inside, y, 0) - y0
    corners = np.stack([xyz[y0 + dy, x0 + dx] for dx, dy in _CORNERS.astype(np.int64)])
    have = finite_points(corners)  # (4, V)
    weights = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy])
    full = have.all(axis=0)
    valid = inside & full
    if min_weight < 1:
        share = (weights * have).sum(axis=0)
        partial = inside & ~full & (share >= min_weight - 1e-12)
        weights[:, partial] = _partial_weights(fx[partial], fy[partial], have[:, partial])
        valid |= partial
    weights[~have] = 0.0
    out = np.einsum("kv,kvd->vd", weights, np.where(have[..., None], corners, 0.0))
    if max_slope_deg is not None:
        axis = (view if view is not None else scanner_view(xyz)).axis
        valid &= ~_straddles_step(corners, have, np.tan(np.radians(max_slope_deg)), axis)
    out[~valid] = np.nan
    return out, valid


def range_pixels(
    xyz: np.ndarray,
    points: np.ndarray,
    start: np.ndarray | None = None,
    iterations: int = 8,
    tolerance_mm: float = 0.05,
    max_distance_mm: float = 2.0,
    min_weight: float = 0.5,
    source: str = "range image",
) -> np.ndarray:
    """Where in a range image given surface points lie: the inverse of :func:`sample_range`.

    Each point's pixel position is found, from ``start``, by Gauss-Newton steps on the range image's own
    bilinear interpolation (the step ``(J^T J)^-1 J^T (x - xyz(p))`` with ``J`` the image's
    derivative at ``p``, at most 2 px a step), so no camera model is needed: a laser scanner's,
    a stereo rig's distorted camera or an RGB-D colour camera's grid are all inverted alike.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    points : (n, 3) float, mm
        Points on (or within the noise of) the range image's surface, in its frame (a
        non-finite point is not found).
    start : (n, 2) float, optional
        Pixel positions to start from (within a few pixels of the answer); default: each
        point's nearest pixel with data (in 3D).
    iterations : int
        Gauss-Newton steps.
    tolerance_mm : float
        A point is found when the last step moved its sample by at most this (what is left of
        its distance to the sample is then along the surface's normal: noise).
    max_distance_mm : float
        A point farther than this from the sample at its pixel is not on the surface.
    min_weight : float
        :func:`sample_range`'s rule at the edge of the data.
    source : str
        Label for error messages.

    Returns
    -------
    (n, 2) float64
        Pixel positions; NaN where a point is not found (no data around it, farther than
        ``max_distance_mm`` from the surface, or not converged).
    """
    pts = np.asarray(points, dtype=np.float64)
    xyz = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or xyz.ndim != 3 or xyz.shape[2] != 3:
        raise InputError(
            source, f"xyz, points: expected (H, W, 3) and (n, 3), got {xyz.shape} and {pts.shape}"
        )
    finite = np.isfinite(pts).all(axis=1)
    if start is None:
        rows, cols = np.nonzero(np.isfinite(xyz).all(axis=2))
        p = np.full((len(pts), 2), np.nan)
        if not len(rows):
            return p
        nearest = cKDTree(xyz[rows, cols]).query(pts[finite])[1]
        p[finite] = np.column_stack([cols[nearest], rows[nearest]])
    else:
        p = np.array(start, dtype=np.float64)
        if p.shape != (len(pts), 2):
            raise InputError(source, f"start: expected ({len(pts)}, 2), got {p.shape}")
    half = np.array([[0.5, 0.0], [0.0, 0.5]])
    moved = np.full(len(p), np.inf)

    def sample(at):
        return sample_range(xyz, at, source, min_weight=min_weight)[0]

    for _ in range(int(iterations)):
        jac = np.stack([sample(p + d) - sample(p - d) for d in half], axis=-1)  # (n, 3, 2) mm/px
        jtj = np.einsum("nki,nkj->nij", jac, jac)
        jtr = np.einsum("nki,nk->ni", jac, pts - sample(p))
        ok = np.isfinite(jtj).all(axis=(1, 2)) & np.isfinite(jtr).all(axis=1)
        ok[ok] = np.linalg.det(jtj[ok]) > 1e-12
        step = np.zeros_like(p)
        step[ok] = np.clip(np.linalg.solve(jtj[ok], jtr[ok][..., None])[..., 0], -2.0, 2.0)
        p += step
        # how far the step moved the sample (along the surface), mm
        moved = np.where(ok, np.linalg.norm(np.einsum("nki,ni->nk", jac, step), axis=1), np.inf)
    off = np.linalg.norm(sample(p) - pts, axis=1)
    p[~((moved <= tolerance_mm) & (off <= max_distance_mm) & finite)] = np.nan
    return p


def texture_uv(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Texture coordinates of pixel positions.

    Parameters
    ----------
    points : (V, 2) float
        Pixel coordinates ((0, 0) = centre of the top-left pixel).
    width, height : int
        Image size W, H in pixels.

    Returns
    -------
    uv : (V, 2) float64
        ``u = (x + 0.5) / W``, ``v = (y + 0.5) / H``: image convention, origin at the top-left
        corner of the image (as glTF); the OBJ writer flips v. Clipped to [0, 1]: a vertex
        beyond the image's edge (it has no range data, so it is invalid; a template fitted to
        a face that fills its image reaches past the edge) takes the edge's texel, as a glTF
        sampler's clamp-to-edge would, and the exports stay valid.
    """
    points = np.asarray(points, dtype=np.float64)
    uv = np.column_stack([(points[:, 0] + 0.5) / width, (points[:, 1] + 0.5) / height])
    return np.clip(uv, 0.0, 1.0)


def folded_faces(points2d: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: warped triangles whose orientation flipped (or collapsed to zero area).

    Template faces have negative signed area in the image frame (see ``template.mesh``).
    """
    return signed_area2(points2d, faces) >= 0


def fold_excess(
    points2d: np.ndarray,
    faces: np.ndarray,
    max_fraction: float = 0.0,
    tolerated: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The folded faces, the judged ones and whether too many of those folded
    (:func:`check_no_folds`'s test, without the error).

    Parameters
    ----------
    points2d, faces, max_fraction, tolerated
        As in :func:`check_no_folds`.

    Returns
    -------
    folded : (F,) bool
    judged : (F,) bool
        The faces outside ``tolerated``.
    too_many : bool
        More than ``max_fraction`` of the judged faces folded.
    """
    folded = folded_faces(points2d, faces)
    judged = np.ones(len(faces), bool) if tolerated is None else ~np.asarray(tolerated, bool)
    return folded, judged, int((folded & judged).sum()) > max_fraction * int(judged.sum())


def check_no_folds(
    points2d: np.ndarray,
    faces: np.ndarray,
    source: str,
    max_fraction: float = 0.0,
    tolerated: np.ndarray | None = None,
) -> np.ndarray:
    """Check the warp for folds; returns the folded faces when there are few enough.

    A thin-plate spline is not guaranteed one-to-one: with an open or rounded mouth some small
    triangles of the lips, and a few between the nose and the lips, may flip. Folds of the
    ``tolerated`` faces (the lips: :func:`~scan2morph.template.regions.mouth_faces`) are never
    an error; up to ``max_fraction`` of the other faces may fold. The folded faces' vertices are
    then marked invalid by the caller. More than that means the landmarks fold the face itself
    (wrong order, mirrored, or from another face) and is an error naming the take.

    Parameters
    ----------
    points2d : (V, 2) float
        Warped template vertices, px.
    faces : (F, 3) int
    source : str
        ``subject/take`` for messages.
    max_fraction : float
        Share of the faces outside ``tolerated`` that may fold.
    tolerated : (F,) bool, optional
        Faces whose folds are not judged (default none).

    Returns
    -------
    (F,) bool
        The folded faces.
    """
    folded, judged, too_many = fold_excess(points2d, faces, max_fraction, tolerated)
    n_judged, n_out = int(judged.sum()), int((folded & judged).sum())
    if too_many:
        inside = int((folded & ~judged).sum())
        lips = f"; {inside} of {len(faces) - n_judged} in the lips, not judged" if inside else ""
        where = "" if tolerated is None else " outside the lips"
        raise InputError(
            source,
            f"landmarks fold the template: {n_out} of {n_judged} warped triangles{where} flip "
            f"orientation ({100 * n_out / max(n_judged, 1):.1f}%, at most "
            f"{100 * max_fraction:.1f}% may{lips}); check the landmark order: iBUG-68, "
            "left-right as seen in the image",
        )
    return folded


def sample_mesh(
    xyz: np.ndarray,
    points: np.ndarray,
    faces: np.ndarray,
    source: str = "range image",
    min_weight: float = 1.0,
    max_slope_deg: float | None = None,
    exclude: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's vertices sampled from a range image at their pixel positions.

    :func:`sample_range` with the fit's depth-step rules: with ``max_slope_deg`` a vertex is
    also invalid behind a depth step of the mesh (:func:`behind_steps`), both along the
    scanner's viewing direction estimated from ``xyz`` (:func:`scanner_view`).

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    points : (V, 2) float
        Pixel positions of the vertices.
    faces : (F, 3) int
        The mesh's triangles.
    source, min_weight, max_slope_deg
        As in :func:`sample_range`.
    exclude : (k,) int, optional
        Vertices invalid whatever the data (on folded triangles).

    Returns
    -------
    vertices : (V, 3) float64, mm; NaN where invalid
    valid : (V,) bool
    """
    view = scanner_view(xyz) if max_slope_deg is not None else SCANNER_FRAME
    vertices, valid = sample_range(
        xyz, points, source=source, min_weight=min_weight, max_slope_deg=max_slope_deg, view=view
    )
    if exclude is not None:
        valid[exclude] = False
    if max_slope_deg is not None:
        valid &= ~behind_steps(
            np.where(valid[:, None], vertices, np.nan), faces, max_slope_deg, view.centre
        )
    vertices[~valid] = np.nan
    return vertices, valid
