"""The skin's own stiffness on the shell's DOFs: a tension, a foundation and a tether, uniform or
varying over the face (softer where the mimic muscles move the skin).

A membrane under an in-plane stress resultant ``T`` (N/mm) has the geometric stiffness
``T * integral of sum_a |grad u_a|^2``; over a foundation ``k_n`` (N/mm^3) its waves obey
``rho h omega^2 = T k^2 (+ k_n along the normal)``. Where ``T`` is lower (or the mass higher)
the waves are shorter at the same frequency, so the lowest modes put more of their shapes there:
:func:`mimic_weight` says where, :func:`face_field` and :func:`vertex_field` make the per-face
tension and per-vertex foundation of :func:`skin_stiffness` from it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError
from scan2morph.geometry import boundary_edges, vertex_normals
from scan2morph.modal.fem import DOF, _symmetric_csc, check_mesh, face_areas

#: The mimic skin of a face template (canonical frame: the outer eye corners at x = -1 and 1,
#: y down) as polylines of named template points and each one's width (template units, about
#: 45 mm): round the mouth (orbicularis oris, the lips and the corners), from each mouth corner
#: to its cheekbone (zygomaticus major, the cheeks a smile lifts), along the brows over the
#: glabella (corrugator, procerus, the frontalis's lower end) and across the forehead from
#: temple to temple (the frontalis, which lifts it with the brows). Not on it: the nose, the
#: eyes' corners, the sides of the face, the jaw and chin.
MIMIC_LINES: tuple[tuple[tuple[str, ...], float], ...] = (
    (("mouth_r", "mouth_l"), 0.45),
    (("mouth_r", "cheekbone_r"), 0.35),
    (("mouth_l", "cheekbone_l"), 0.35),
    (("brow_r_outer", "brow_r_inner", "brow_l_inner", "brow_l_outer"), 0.3),
    (("temple_r", "forehead_centre", "temple_l"), 0.35),
)


def mimic_weight(
    points: ArrayLike, lines: Sequence[tuple[ArrayLike, float]], source: str = "mimic skin"
) -> NDArray[np.float64]:
    """How much each point belongs to the mimic skin: ``exp(-d^2 / (2 w^2))`` of its distance
    ``d`` to the nearest polyline of ``lines``, ``w`` that line's width, the largest over the
    lines.

    Parameters
    ----------
    points : (V, 2) float
        Positions in the frame of the lines (a template's canonical frame, or mm on a scan).
    lines : sequence of ((n, 2) float, float)
        Each polyline (n >= 2 points) and its width w > 0, same units as ``points``.
    source : str
        Label for error messages.

    Returns
    -------
    (V,) float in [0, 1]
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(source, f"points: expected shape (V, 2), got {p.shape}")
    out = np.zeros(p.shape[0])
    for i, (line, width) in enumerate(lines):
        q = np.asarray(line, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 2 or q.shape[0] < 2:
            raise InputError(source, f"line {i}: expected shape (n >= 2, 2), got {q.shape}")
        if not (np.isfinite(width) and width > 0):
            raise InputError(source, f"line {i}: width expected > 0, got {width}")
        d = np.full(p.shape[0], np.inf)
        for a, b in zip(q[:-1], q[1:], strict=True):
            ab = b - a
            t = np.clip((p - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(p - a - t[:, None] * ab, axis=1))
        out = np.maximum(out, np.exp(-0.5 * (d / width) ** 2))
    return out


def mimic_skin(template) -> NDArray[np.float64]:
    """:func:`mimic_weight` of a (subdivided) template's vertices for :data:`MIMIC_LINES`.

    Parameters
    ----------
    template : Template
        With ``vertices`` (V, 2) in the canonical frame and the named points of
        :data:`MIMIC_LINES`.

    Returns
    -------
    (V,) float in [0, 1]
    """
    named = template.named
    missing = sorted({n for names, _ in MIMIC_LINES for n in names} - set(named))
    if missing:
        raise InputError("template", f"mimic skin: named points missing: {missing}")
    xy = np.asarray(template.vertices, dtype=np.float64)[:, :2]
    lines = [(xy[[named[n] for n in names]], width) for names, width in MIMIC_LINES]
    return mimic_weight(xy, lines, "template")


def vertex_field(
    value: float, factor: float, weight: ArrayLike | None, name: str = "value"
) -> float | NDArray[np.float64]:
    """``value * (1 + (factor - 1) * weight)`` per vertex (``value`` where weight is 0,
    ``factor * value`` where it is 1); ``value`` itself without a weight or with factor 1.

    Raises
    ------
    InputError
        ``factor`` not a positive number.
    """
    if not (np.isfinite(factor) and factor > 0):
        raise InputError("modal", f"{name}: expected a factor > 0, got {factor}")
    if weight is None or factor == 1.0:
        return float(value)
    return float(value) * (1.0 + (float(factor) - 1.0) * np.asarray(weight, dtype=np.float64))


def face_field(
    value: float, factor: float, weight: ArrayLike | None, faces: ArrayLike, name: str = "value"
) -> float | NDArray[np.float64]:
    """:func:`vertex_field` of the faces, with each face's mean corner weight, (F,) or a
    float."""
    if weight is None or factor == 1.0:
        return vertex_field(value, factor, None, name)
    w = np.asarray(weight, dtype=np.float64)[np.asarray(faces, dtype=np.int64)].mean(axis=1)
    return vertex_field(value, factor, w, name)


def cotangent_laplacian(
    vertices: ArrayLike,
    faces: ArrayLike,
    source: str = "mesh",
    face_weight: ArrayLike | None = None,
) -> tuple[sp.csr_matrix, NDArray[np.float64]]:
    """Cotangent Laplace-Beltrami stiffness and lumped (barycentric) vertex areas.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    source : str
        Label for error messages.
    face_weight : (F,) float, optional
        A weight per triangle on its part of the integral (``integral of c |grad f|^2``);
        None: 1.

    Returns
    -------
    L : (V, V) scipy.sparse.csr_matrix, symmetric positive semi-definite, dimensionless
        ``f^T L f = integral of |grad f|^2`` for a piecewise linear ``f`` (the Dirichlet energy;
        its null space on a connected mesh is the constants).
    area : (V,) float, mm^2
        A third of the area of each vertex's triangles.
    """
    v, f = check_mesh(vertices, faces, source)
    n = v.shape[0]
    c = np.ones(f.shape[0]) if face_weight is None else np.asarray(face_weight, dtype=np.float64)
    rows, cols, vals = [], [], []
    for k in range(3):  # the angle at corner k weighs the opposite edge (i, j)
        i, j, o = f[:, (k + 1) % 3], f[:, (k + 2) % 3], f[:, k]
        a, b = v[i] - v[o], v[j] - v[o]
        cot = c * np.einsum("ij,ij->i", a, b) / np.linalg.norm(np.cross(a, b), axis=1)
        rows += [i, j]
        cols += [j, i]
        vals += [-0.5 * cot, -0.5 * cot]
    off = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    lap = (off - sp.diags(np.asarray(off.sum(axis=1)).ravel())).tocsr()
    area = np.zeros(n)
    np.add.at(area, f.ravel(), np.repeat(face_areas(v, f) / 3.0, 3))
    return lap, area


def skin_stiffness(
    vertices: ArrayLike,
    faces: ArrayLike,
    tension_n_per_mm: float | ArrayLike = 0.0,
    foundation_n_per_mm3: float | ArrayLike = 0.0,
    tethered: ArrayLike | None = None,
    tether_n_per_mm3: float = 0.0,
    tether_normal_n_per_mm3: float = 0.0,
    source: str = "mesh",
) -> sp.csc_matrix:
    """Stiffness of a pre-tensioned skin on an elastic foundation, on the shell's DOFs.

    Three terms act on the translations ``u`` of each vertex (the rotations get nothing):

    - isotropic skin tension ``T`` (one value, or one per triangle): the geometric stiffness of
      a membrane under an in-plane stress resultant ``T``, ``T * integral of sum_a |grad u_a|^2`` over the surface
      (``T L`` per axis, ``L`` the :func:`cotangent_laplacian`); it resists every component of a
      short-wave motion alike and none of a rigid translation;
    - a foundation under the skin resisting motion along the surface normal (the soft tissue
      pressed against the skull): ``k_n * integral of (u . n)^2``;
    - a tether of the skin to the bone where it does not slide (``tethered`` vertices):
      ``k_t * integral of |u - (u . n) n|^2`` there, and the bone's extra resistance to motion
      along the normal, ``k_b * integral of (u . n)^2`` there.

    The integrals use each vertex's lumped (barycentric) area and the neutral's vertex normals.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    tension_n_per_mm : float or (F,) float
        ``T`` >= 0, N/mm, uniform or per triangle (:func:`face_field`).
    foundation_n_per_mm3 : float or (V,) float
        ``k_n`` >= 0, N/mm^3 (pressure per mm of normal motion), uniform or per vertex
        (:func:`vertex_field`).
    tethered : (V,) bool, optional
        Vertices tied tangentially; None: none.
    tether_n_per_mm3 : float
        ``k_t`` >= 0, N/mm^3.
    tether_normal_n_per_mm3 : float
        ``k_b`` >= 0, N/mm^3, added to ``k_n`` on the tethered vertices.
    source : str
        Label for error messages.

    Returns
    -------
    (6V, 6V) scipy.sparse.csc_matrix, symmetric positive semi-definite, N/mm
    """
    v, f = check_mesh(vertices, faces, source)
    values = {"tension_n_per_mm": tension_n_per_mm, "foundation_n_per_mm3": foundation_n_per_mm3}
    values["tether_n_per_mm3"] = tether_n_per_mm3
    values["tether_normal_n_per_mm3"] = tether_normal_n_per_mm3
    n_v = v.shape[0]
    shapes = {"tension_n_per_mm": f.shape[0], "foundation_n_per_mm3": n_v}
    for name, value in values.items():
        arr = np.asarray(value, dtype=np.float64)
        if arr.ndim and arr.shape != (shapes.get(name, -1),):
            raise InputError(
                source, f"{name}: expected a number or ({shapes.get(name)},), got {arr.shape}"
            )
        if not (np.isfinite(arr).all() and (arr >= 0).all()):
            raise InputError(source, f"{name}: expected numbers >= 0, got {value}")
    tension = np.broadcast_to(np.asarray(tension_n_per_mm, dtype=np.float64), f.shape[:1])
    lap, area = cotangent_laplacian(v, f, source, face_weight=tension)
    lap = lap.tocoo()
    rows = [DOF * lap.row + a for a in range(3)]
    cols = [DOF * lap.col + a for a in range(3)]
    vals = [lap.data] * 3
    normals = vertex_normals(v, f, fill=0.0)
    nn = np.einsum("vi,vj->vij", normals, normals)
    tie = np.zeros(n_v)
    press = np.broadcast_to(np.asarray(foundation_n_per_mm3, dtype=np.float64), (n_v,)).copy()
    if tethered is not None:
        mask = np.asarray(tethered)
        if mask.shape != (n_v,) or mask.dtype != np.bool_:
            raise InputError(source, f"tethered: expected a ({n_v},) bool mask, got {mask.shape}")
        tie = float(tether_n_per_mm3) * mask
        press += float(tether_normal_n_per_mm3) * mask
    blocks = area[:, None, None] * (
        press[:, None, None] * nn + tie[:, None, None] * (np.eye(3) - nn)
    )
    a_idx, b_idx = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    base = DOF * np.arange(n_v)[:, None, None]
    rows.append((base + a_idx).ravel())
    cols.append((base + b_idx).ravel())
    vals.append(blocks.ravel())
    return _symmetric_csc(
        np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), DOF * n_v
    )


def edge_springs(
    vertices: ArrayLike,
    faces: ArrayLike,
    held: ArrayLike,
    tension_n_per_mm: float,
    strip_mm: float,
    source: str = "mesh",
) -> sp.csc_matrix:
    """The skin beyond a cut edge: a strip ``l`` wide under the tension ``T``, held at its far
    edge, seen from the cut (a Robin boundary condition ``T du/dn + (T / l) u = 0``).

    The strip's energy ``T * integral over the strip of |grad u|^2`` is ``(T / l) * integral
    along the cut of |u|^2`` when the motion falls linearly across it; lumped on the held
    vertices of the mesh's boundary, vertex ``i`` gets a spring ``T L_i / l`` (N/mm) on each of
    its three translations, ``L_i`` half the length of the boundary edges at it. ``l -> 0`` is a
    clamp, ``l -> inf`` a free edge.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    held : (V,) bool
        The boundary vertices the strip holds (others, and interior vertices, get nothing).
    tension_n_per_mm : float
        ``T`` > 0, N/mm.
    strip_mm : float
        ``l`` > 0, mm.
    source : str
        Label for error messages.

    Returns
    -------
    (6V, 6V) scipy.sparse.csc_matrix, diagonal, N/mm
    """
    v, f = check_mesh(vertices, faces, source)
    n_v = v.shape[0]
    mask = np.asarray(held)
    if mask.shape != (n_v,) or mask.dtype != np.bool_:
        raise InputError(source, f"held: expected a ({n_v},) bool mask, got {mask.shape}")
    for name, value in (("tension_n_per_mm", tension_n_per_mm), ("strip_mm", strip_mm)):
        if not (np.isfinite(value) and value > 0):
            raise InputError(source, f"{name}: expected a number > 0, got {value}")
    cut = boundary_edges(f)
    half = 0.5 * np.linalg.norm(v[cut[:, 0]] - v[cut[:, 1]], axis=1)
    length = np.zeros(n_v)
    np.add.at(length, cut.ravel(), np.repeat(half, 2))
    k = float(tension_n_per_mm) / float(strip_mm) * np.where(mask, length, 0.0)
    idx = (DOF * np.arange(n_v)[:, None] + np.arange(3)).ravel()
    return sp.csc_matrix((np.repeat(k, 3), (idx, idx)), shape=(DOF * n_v, DOF * n_v))
