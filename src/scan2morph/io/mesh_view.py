"""The frontal direction of a face mesh, found from its surface alone.

A mesh take is rendered through a virtual camera that must look at the face from the front.
The direction is found from the surface only (landmarks, when given, just seed the nose tip), so
that it holds whatever frame, winding or nose shape the scan comes with:

1. **One overall normal sign.** The triangles' normals (from their winding) are turned as one so
   that their area-weighted sum points away from the surface's centroid: out of a head or of the
   convex side of a face shell. Single normals are never flipped one by one.
2. **The nose tip** is the most protruding point: for points on a coarse grid over the surface,
   the height above the area-weighted centroid of the surface within
   :data:`PROTRUSION_RADIUS_MM`, along that neighbourhood's mean normal (scored on a sparser
   sample of the surface, :data:`MAX_COARSE_TRIANGLES`); the best ones are refined on the
   surface around them.
3. **A first direction:** the mean normal of the surface within :data:`FACE_RADIUS_MM` of the tip.
4. **The symmetry plane** through the tip: left-right axes perpendicular to the first direction
   are tried every 15 degrees; the :data:`SYMMETRY_STARTS` whose mirror images of the face lie
   closest to the surface are refined, and the closest-fitting refined plane is kept. The
   refinement is an ICP of the face with its own mirror image: each face point's mirror image is
   paired with the surface point nearest it, and a Gauss-Newton step on the pairs' point-to-plane
   distances (to the paired triangle's plane) turns and shifts the plane, until a step turns it
   by less than :data:`SYMMETRY_STOP_RAD` (5-15 steps from a trial 7.5 degrees off). The trials
   are ranked and refined on a quarter of the face points (:data:`COARSE_SYMMETRY_POINTS`); the
   kept plane is refined again on all of them (2-3 steps). On every take of the cohort's mesh
   subject the plane is within 0.015 degrees of the head's true symmetry plane. (The midpoint
   plane of point-to-point pairs used before converged slowly: after its 20 steps it was still
   0.2-4.2 degrees off.)
5. **The face plane:** the least-squares plane of the surface around the tip (Gaussian weights,
   :data:`FACE_SIGMA_MM`), its normal taken within the symmetry plane. The camera looks along
   that normal, into the face.

Without landmarks, :func:`surface_camera` also turns the camera about that direction from the
surface alone: its image x axis along the symmetry plane's normal, its image "down" from the nose
bridge to the mouth (along the face's profile the bridge stays close behind the tip, the upper lip
lies well behind it), centred :data:`CENTRE_BELOW_TIP_MM` below the tip.

Measured on every take of four synthetic subjects within 4.4 degrees of the true frontal
direction with the symmetry plane before its exact refinement (the cohort's mesh subject synth03,
measured again with it: 3.1 from the surface alone, 1.6 with the landmarks' nose tip), and 1.7
degrees on a real head scan; noses pointing down as real ones do (about 60 degrees below the
horizontal from bridge to tip) do not bias it.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.errors import InputError
from scan2morph.io.take import flat_surface

#: Neighbourhood radius of the protrusion that finds the nose tip, mm.
PROTRUSION_RADIUS_MM = 35.0
#: Grid step of the coarse search for the nose tip, mm.
TIP_GRID_MM = 8.0
#: At most this many triangles (an even stride of them) make the neighbourhoods of the coarse
#: grid's scores, which only rank the grid points for the refinement: on every take of four
#: synthetic heads and on a real head the tip is the same as with the refinement's triangles.
MAX_COARSE_TRIANGLES = 10000
#: The tip search refines this many of the best coarse grid points.
TIP_CANDIDATES = 10
#: At most about twice this many surface points around a coarse grid point are scored in the tip
#: search (an even stride of them when there are more), and the most scored in one call: it bounds
#: the search's time and memory on dense scans (a synthetic mesh scan of 108,000 triangles has at most about 400 there, a real
#: head subdivided to 1.1 million about 4,000).
MAX_TIP_POINTS = 500
#: Radius around the nose tip of the face region (first direction, symmetry plane), mm.
FACE_RADIUS_MM = 80.0
#: Gaussian width of the face plane's weights around the nose tip, mm.
FACE_SIGMA_MM = 30.0
#: At most this many triangles (an even stride of them) make the neighbourhoods of the tip search.
MAX_PROTRUSION_TRIANGLES = 30000
#: The symmetry plane is refined from this many of the best trial planes.
SYMMETRY_STARTS = 3
#: The symmetry plane's refinement stops when a step turns it by less than this (and shifts it
#: by less than :data:`SYMMETRY_STOP_MM`), radians, or after :data:`SYMMETRY_ITERATIONS` steps.
#: Near the answer the pairs can switch back and forth between two neighbouring surface points,
#: turning the plane by about 6e-7 rad a step.
SYMMETRY_STOP_RAD = 1e-5
#: See :data:`SYMMETRY_STOP_RAD`, mm.
SYMMETRY_STOP_MM = 1e-3
#: At most this many refinement steps of a symmetry plane (on the coarse points, then again on
#: all of them).
SYMMETRY_ITERATIONS = 30
#: The trial planes are ranked and refined on about this many face points (an even stride of the
#: :data:`MAX_SYMMETRY_POINTS`); the kept one is refined on all of them.
COARSE_SYMMETRY_POINTS = 1000
#: At most this many face points pair with their mirror images (an even stride of them).
MAX_SYMMETRY_POINTS = 4000
#: Nearest-surface searches of mirrored points stop at this distance: a search's median and the
#: pairs it keeps are exact whenever they lie within it, and it is repeated without the bound
#: otherwise; far points (a trial plane 90 degrees off) are what make unbounded searches slow, mm.
MIRROR_SEARCH_MM = 16.0
#: Points per leaf of the symmetry search's k-d tree: its nearest-neighbour queries (the same
#: answers at any leaf size) are about 10% faster than at scipy's default of 16.
NEAREST_LEAF_SIZE = 48
#: :func:`face_view` keeps the answers for this many meshes (in memory, keyed by a digest of the
#: whole input: vertices, faces, face normals and nose tip): a mesh seen again, as a take's ingest
#: and its checks see it, costs no second search (about 0.6 s for a 100k-triangle head).
VIEW_MEMO_SIZE = 8
_VIEWS: OrderedDict[bytes, FaceView] = OrderedDict()

#: Half-width of the band around the symmetry plane whose surface is the face's profile, mm.
PROFILE_BAND_MM = 4.0
#: The profile is compared this far above and below the nose tip (bridge against upper lip), mm.
PROFILE_SPAN_MM = (8.0, 20.0)
#: Without landmarks the image centre lies this far below the nose tip (the 68 landmarks'
#: centroid lies 1 mm above to 8 mm below it on the synthetic cohort's heads), mm.
CENTRE_BELOW_TIP_MM = 3.0
#: Without landmarks, the face extent (jawline across, brows to chin) that ``face_share`` of the
#: image frames: the 68 landmarks span 141-155 mm by 147-153 mm on the synthetic heads, mm.
NOMINAL_FACE_MM = 150.0


@dataclass(frozen=True)
class FaceView:
    """Where a face mesh faces.

    Attributes
    ----------
    direction : (3,) float64
        Unit vector from a frontal camera into the face, mesh frame.
    tip : (3,) float64
        The nose tip used (the landmark if given, else the surface's most protruding point), mm.
    left_right : (3,) float64
        Unit normal of the face's symmetry plane (sign arbitrary).
    symmetry_mm : float
        Median distance of the face's mirror image to the surface, mm (about 1 for a face).
    normal_sign : int
        +1 when the mesh's winding gave outward normals, -1 when they were turned.
    """

    direction: np.ndarray
    tip: np.ndarray
    left_right: np.ndarray
    symmetry_mm: float
    normal_sign: int


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _perpendicular(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) perpendicular to the unit vector ``n`` (3,) and to each other."""
    u = _unit(np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))]))
    return u, np.cross(n, u)


def outward_normals(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Triangle centres, areas and normals, all normals turned by one common sign.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Any winding, any frame.

    Returns
    -------
    centres : (F, 3) float64, mm
    areas : (F,) float64, mm^2
    normals : (F, 3) float64
        Unit normals whose area-weighted sum points away from the area-weighted centroid.
    sign : int
        +1 or -1, the sign applied to the winding's normals.
    """
    centres = np.asarray(mesh.triangles_center, dtype=np.float64)
    areas = np.asarray(mesh.area_faces, dtype=np.float64)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    centroid = areas @ centres / areas.sum()
    sign = 1 if np.einsum("i,ij,ij->", areas, normals, centres - centroid) >= 0 else -1
    return centres, areas, sign * normals, sign


def _protrusion(tree, areas, normals, points, radius):
    """(n,) height of each point above its neighbourhood's centroid along its mean normal.

    ``tree`` holds the surface's triangle centres (``areas``, ``normals`` per centre, mm)."""
    pairs = cKDTree(points).sparse_distance_matrix(tree, radius, output_type="ndarray")
    row, idx = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    w = areas[idx]
    total = np.bincount(row, weights=w, minlength=len(points))

    def weighted_sums(values: np.ndarray) -> np.ndarray:  # (n, 3): the pairs' values gathered once
        return np.stack(
            [np.bincount(row, weights=w * values[:, k], minlength=len(points)) for k in range(3)],
            axis=1,
        )

    centroid = weighted_sums(tree.data[idx]) / np.maximum(total, 1e-300)[:, None]
    mean_normal = weighted_sums(normals[idx])
    norm = np.linalg.norm(mean_normal, axis=1)
    height = np.einsum("ij,ij->i", mean_normal, points - centroid) / np.maximum(norm, 1e-300)
    return np.where(norm > 0, height, -np.inf)


def _first_in_each_cell(cells: np.ndarray) -> np.ndarray:
    """Index of the first row of each distinct row of ``cells`` (n, 3) int, the rows in
    lexicographic order: ``np.unique(cells, axis=0, return_index=True)[1]``, from one int64 key
    per row (a 1-D unique is about 10x faster)."""
    lo = cells.min(axis=0)
    span = cells.max(axis=0) - lo + 1
    if float(np.prod(span.astype(np.float64))) >= 2.0**62:  # a key would overflow int64
        return np.unique(cells, axis=0, return_index=True)[1]
    c = cells - lo
    key = (c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2]
    return np.unique(key, return_index=True)[1]


def nose_tip(centres, areas, normals) -> np.ndarray:
    """(3,) the surface's most protruding point (module docstring, step 2), mm.

    Parameters
    ----------
    centres, areas, normals : (F, 3), (F,), (F, 3) float
        Triangle centres (mm), areas (mm^2) and outward unit normals (:func:`outward_normals`).
    """
    coarse = centres[_first_in_each_cell(np.floor(centres / TIP_GRID_MM).astype(np.int64))]
    every = max(1, len(centres) // MAX_COARSE_TRIANGLES)
    score = _protrusion(
        cKDTree(centres[::every]), areas[::every], normals[::every], coarse, PROTRUSION_RADIUS_MM
    )
    stride = max(1, len(centres) // MAX_PROTRUSION_TRIANGLES)
    tree = cKDTree(centres[::stride])
    sub_areas, sub_normals = areas[::stride], normals[::stride]
    # the best few coarse points (a grid point may sit off a sharp tip) refined on the surface;
    # their neighbourhoods overlap, so each surface point is scored once for all of them
    picks = []
    for k in np.argsort(score)[::-1][:TIP_CANDIDATES]:
        near = np.flatnonzero(np.linalg.norm(centres - coarse[k], axis=1) < 1.5 * TIP_GRID_MM)
        picks.append(near[:: max(1, len(near) // MAX_TIP_POINTS)])
    scored, where = np.unique(np.concatenate(picks), return_inverse=True)
    fine = np.concatenate(  # at most MAX_TIP_POINTS a call: the pairs' memory stays bounded
        [
            _protrusion(tree, sub_areas, sub_normals, centres[chunk], PROTRUSION_RADIUS_MM)
            for chunk in np.array_split(scored, -(-len(scored) // MAX_TIP_POINTS))
        ]
    )
    best, best_score, start = coarse[0], -np.inf, 0
    for near in picks:
        mine = fine[where[start : start + len(near)]]
        start += len(near)
        if mine.max() > best_score:
            best, best_score = centres[near[int(np.argmax(mine))]], float(mine.max())
    return best


def _mirror(points: np.ndarray, origin: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return points - 2.0 * ((points - origin) @ axis)[:, None] * axis


def symmetry_plane(
    tree, normals, points, origin, forward, iterations=SYMMETRY_ITERATIONS
) -> tuple[np.ndarray, float]:
    """The face's symmetry plane containing ``forward`` (module docstring, step 4).

    Parameters
    ----------
    tree : scipy.spatial.cKDTree
        Over the surface points, mm.
    normals : (m, 3) float
        Unit normals of the tree's surface points.
    points : (n, 3) float
        The face points to mirror, mm.
    origin : (3,) float
        A point on the plane (the nose tip), mm.
    forward : (3,) float
        Unit first direction; the left-right axes tried are perpendicular to it.
    iterations : int
        Refinement steps at most.

    Returns
    -------
    axis : (3,) float64
        Unit normal of the plane.
    residual : float
        Median distance of the mirrored points to the surface, mm.
    """
    u, v = _perpendicular(forward)
    trials = [np.cos(t) * u + np.sin(t) * v for t in np.radians(np.arange(0.0, 180.0, 15.0))]
    coarse = points[:: max(1, len(points) // COARSE_SYMMETRY_POINTS)]
    residuals = [_mirror_residual(tree, coarse, origin, x, bounded=True) for x in trials]
    if np.isfinite(residuals).sum() < SYMMETRY_STARTS:  # the ranking needs the far medians
        residuals = [_mirror_residual(tree, coarse, origin, x) for x in trials]
    refined = []
    for k in np.argsort(residuals)[:SYMMETRY_STARTS]:
        axis, centre = _refine_symmetry(tree, normals, coarse, origin, trials[k], iterations)
        refined.append((_mirror_residual(tree, coarse, centre, axis), axis, centre))
    _, axis, centre = min(refined, key=lambda r: r[0])
    axis, centre = _refine_symmetry(tree, normals, points, centre, axis, iterations)
    return axis, _mirror_residual(tree, points, centre, axis)


def _mirror_residual(tree, points, origin, axis, bounded=False) -> float:
    """Median distance of the points mirrored across a plane to the surface, mm: exact, or with
    ``bounded`` ``inf`` when it lies beyond :data:`MIRROR_SEARCH_MM`."""
    mirrored = _mirror(points, origin, axis)
    median = float(np.median(_nearest(tree, mirrored)[0]))
    if bounded or np.isfinite(median):
        return median
    return float(np.median(tree.query(mirrored)[0]))


def _nearest(tree, points):
    """Distances (n,) and indices (n,) of the surface points nearest ``points``: exact within
    :data:`MIRROR_SEARCH_MM`, ``inf`` (index ``tree.n``) beyond it."""
    return tree.query(points, distance_upper_bound=MIRROR_SEARCH_MM)


def _refine_symmetry(tree, normals, points, origin, axis, iterations):
    """Gauss-Newton steps of the plane ``axis . x = axis . origin`` (module docstring, step 4):
    the unit normal (3,) and a point on the plane (3,) found, mm."""
    offset = float(axis @ origin)
    for _ in range(iterations):
        side = points @ axis - offset  # signed distances to the plane
        mirrored = points - 2.0 * side[:, None] * axis
        dist, j = _nearest(tree, mirrored)
        limit = max(3.0 * float(np.median(dist)), 2.0)
        if not limit < MIRROR_SEARCH_MM:  # the pairs kept reach beyond the bounded search
            dist, j = tree.query(mirrored)
            limit = max(3.0 * float(np.median(dist)), 2.0)
        keep = dist < limit
        if keep.sum() < 3:
            break
        p, s, n = points[keep], side[keep], normals[j[keep]]
        r = np.einsum("ij,ij->i", mirrored[keep] - tree.data[j[keep]], n)
        # the mirror image p - 2 s a moves with the plane's turn (a + x0 u + x1 v, u and v
        # perpendicular to a) and shift (offset + x2)
        u, v = _perpendicular(axis)
        na = n @ axis
        jac = np.column_stack([-2.0 * (na * (p @ w) + s * (n @ w)) for w in (u, v)] + [2.0 * na])
        x = np.linalg.lstsq(jac, -r, rcond=None)[0]
        turned = axis + x[0] * u + x[1] * v
        length = float(np.linalg.norm(turned))
        axis, offset = turned / length, (offset + x[2]) / length
        if np.hypot(x[0], x[1]) < SYMMETRY_STOP_RAD and abs(x[2]) < SYMMETRY_STOP_MM:
            break
    return axis, offset * axis


def face_view(mesh, tip: np.ndarray | None = None, source: str = "mesh") -> FaceView:
    """The frontal view direction of a face mesh (module docstring).

    The same mesh and tip give the answer found before (:data:`VIEW_MEMO_SIZE`; its arrays are
    read-only).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The scan, mm, any frame and winding.
    tip : (3,) float, optional
        The nose tip (iBUG 31) if landmarks are given, mm; else found on the surface.
    source : str
        The mesh file, for messages.

    Returns
    -------
    FaceView

    Raises
    ------
    InputError
        No surface around the nose tip (an empty or degenerate mesh).
    """
    tip = None if tip is None else np.array(tip, dtype=np.float64)
    key = hashlib.sha256()
    for a in (mesh.vertices, mesh.faces, mesh.face_normals, tip):
        a = np.ascontiguousarray(np.empty(0) if a is None else a)
        key.update(f"{a.dtype.str}{a.shape};".encode())
        key.update(a.tobytes())
    key = key.digest()
    if key in _VIEWS:
        _VIEWS.move_to_end(key)
        return _VIEWS[key]
    view = _find_view(mesh, tip, source)
    for a in (view.direction, view.tip, view.left_right):
        a.flags.writeable = False
    _VIEWS[key] = view
    if len(_VIEWS) > VIEW_MEMO_SIZE:
        _VIEWS.popitem(last=False)
    return view


def nonzero_triangles(mesh, source: str = "mesh") -> np.ndarray:
    """The mask of a mesh's triangles of non-zero area.

    Raises
    ------
    InputError
        Fewer than 3 such triangles (every triangle collapsed, a single one): not a face.
    """
    keep = np.asarray(mesh.area_faces) > 0
    if keep.sum() < 3:
        raise InputError(
            source, f"mesh: {int(keep.sum())} triangles of non-zero area (expected a face)"
        )
    return keep


def _find_view(mesh, tip: np.ndarray | None, source: str) -> FaceView:
    """:func:`face_view` without its memo."""
    keep = nonzero_triangles(mesh, source)
    # the zero-area triangles dropped (a copy of the mesh only when there are some)
    centres, areas, normals, sign = outward_normals(
        mesh if keep.all() else mesh.submesh([keep], append=True)
    )
    tree = cKDTree(centres, leafsize=NEAREST_LEAF_SIZE)
    tip = nose_tip(centres, areas, normals) if tip is None else tip
    near = np.linalg.norm(centres - tip, axis=1) < FACE_RADIUS_MM
    first = -(areas[near] @ normals[near])
    if not near.any() or np.linalg.norm(first) == 0:
        raise InputError(source, f"mesh: no surface within {FACE_RADIUS_MM:g} mm of the nose tip")
    first = _unit(first)
    face = np.flatnonzero(near & (normals @ first < 0))
    face = face[:: max(1, len(face) // MAX_SYMMETRY_POINTS)]
    axis, residual = symmetry_plane(tree, normals, centres[face], tip, first)
    weight = areas * np.exp(-((centres - tip) ** 2).sum(axis=1) / (2.0 * FACE_SIGMA_MM**2))
    mean = weight @ centres / weight.sum()
    cov = ((centres - mean) * weight[:, None]).T @ (centres - mean) / weight.sum()
    across = np.eye(3) - np.outer(axis, axis)  # the plane's normal lies in the symmetry plane
    eigvec = np.linalg.eigh(across @ cov @ across + np.outer(axis, axis) * np.trace(cov))[1]
    direction = eigvec[:, 0] * np.sign(eigvec[:, 0] @ first)
    return FaceView(_unit(direction), tip, axis, residual, sign)


def face_up(vertices: np.ndarray, view: FaceView, source: str = "mesh") -> np.ndarray:
    """The face's "up" (from the mouth to the nose bridge) from its profile (module docstring).

    Parameters
    ----------
    vertices : (N, 3) float
        The scan's vertices, mm.
    view : FaceView
        From :func:`face_view`.
    source : str
        The mesh file, for messages.

    Returns
    -------
    (3,) float64
        Unit vector in the symmetry plane, perpendicular to ``view.direction``.

    Raises
    ------
    InputError
        The profile has no surface on one side of the nose tip (a flat mesh named so:
        :func:`~scan2morph.io.take.flat_surface`).
    """
    along = _unit(np.cross(view.direction, view.left_right))
    rel = np.asarray(vertices, dtype=np.float64) - view.tip
    band = np.abs(rel @ view.left_right) < PROFILE_BAND_MM
    s, depth = rel[band] @ along, rel[band] @ view.direction
    lo, hi = PROFILE_SPAN_MM
    behind = []
    for side in (1.0, -1.0):
        near = (side * s > lo) & (side * s < hi)
        if not near.any():
            if flat := flat_surface(vertices):  # its "nose tip" is a corner of a board
                raise InputError(source, f"mesh: {flat}: expected a scan of a face")
            across = float(np.ptp(np.asarray(vertices, dtype=np.float64), axis=0).max())
            raise InputError(
                source,
                f"mesh: no surface {lo:g}-{hi:g} mm from the nose tip along the face's profile "
                f"(expected a face around the nose; the mesh is {across:.4g} mm across: if that "
                "is not its true size, give its unit in the sheet's units column)",
            )
        bins = np.floor(side * s[near] / 2.0).astype(int)
        fronts = [depth[near][bins == b].min() for b in np.unique(bins)]  # frontmost surface
        behind.append(float(np.mean(fronts)))
    return along if behind[0] < behind[1] else -along


def surface_camera(
    vertices: np.ndarray, view: FaceView, settings: dict, source: str = "mesh"
) -> tuple[np.ndarray, np.ndarray]:
    """A frontal virtual camera found without landmarks (module docstring).

    Parameters
    ----------
    vertices : (N, 3) float
        The scan's vertices, mm.
    view : FaceView
        From :func:`face_view`.
    settings : dict
        ``width``, ``height`` (px), ``distance_mm``, ``pixel_mm`` (None: the
        :data:`NOMINAL_FACE_MM` face fills ``face_share`` of the image) and ``face_share``.
    source : str
        The mesh file, for messages.

    Returns
    -------
    K : (3, 3) float64, px
    pose : (4, 4) float64
        Mesh frame -> camera frame (x right, y down, z forward), mm.
    """
    z = view.direction
    y = -face_up(vertices, view, source)
    R = np.stack([np.cross(y, z), y, z])
    centre = view.tip + CENTRE_BELOW_TIP_MM * y
    return face_camera(R, centre, (NOMINAL_FACE_MM, NOMINAL_FACE_MM), settings)


def face_camera(
    rotation: np.ndarray, centre: np.ndarray, extent_mm: tuple[float, float], settings: dict
) -> tuple[np.ndarray, np.ndarray]:
    """A pinhole camera ``distance_mm`` in front of ``centre``, its axes the rows of
    ``rotation``, with ``pixel_mm`` mm per pixel at that distance (None: the face's
    ``extent_mm`` (across, down) fills ``face_share`` of the image).

    Returns
    -------
    K : (3, 3) float64, px
    pose : (4, 4) float64
        Mesh frame -> camera frame (x right, y down, z forward), mm.
    """
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = np.array([0.0, 0.0, settings["distance_mm"]]) - rotation @ centre
    w, h = settings["width"], settings["height"]
    pixel_mm = settings.get("pixel_mm")
    if pixel_mm is None:
        pixel_mm = max(extent_mm[0] / w, extent_mm[1] / h) / settings["face_share"]
    f = settings["distance_mm"] / pixel_mm
    K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return K, pose


__all__ = [
    "FaceView",
    "face_camera",
    "face_up",
    "face_view",
    "nonzero_triangles",
    "nose_tip",
    "outward_normals",
    "surface_camera",
    "symmetry_plane",
]
