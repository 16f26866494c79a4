"""Mesh and range-image primitives shared by every stage: face, vertex and range-image normals,
unique edges.

A base module (like :mod:`scan2morph.tol`): it imports nothing from the stages, so any of them
may use it. Meshes follow the project convention: ``vertices`` (V, 3) float mm, ``faces``
(F, 3) int, counter-clockwise seen from the side the normals point to.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: A vertex whose summed (area-weighted) normal is shorter than this fraction of the longest
#: face normal has no usable direction (isolated, or its faces are degenerate or cancel out).
_NORMAL_RTOL = 1e-12


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Un-normalised face normals, by the right-hand rule.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
        Counter-clockwise triangles.

    Returns
    -------
    (F, 3) float64, mm^2
        ``(b - a) x (c - a)`` per face ``(a, b, c)``: its length is twice the face's area.
        NaN for faces with a NaN corner.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, *, fill: float = np.nan) -> np.ndarray:
    """Area-weighted unit vertex normals of a triangle mesh.

    Each vertex gets the normalised sum of the face normals ``(b - a) x (c - a)`` of its
    incident faces (so larger faces weigh more). Faces with a non-finite corner are skipped.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        NaN rows allowed.
    faces : (F, 3) int
        Counter-clockwise triangles (normals follow the right-hand rule).
    fill : float
        Value given to every component of a vertex's normal when it has no usable direction:
        no finite incident face, or a summed normal shorter than ``1e-12`` times the longest
        face normal (degenerate faces, or faces that cancel out). NaN by default; ``0.0``
        gives a zero vector.

    Returns
    -------
    (V, 3) float64
        Unit normals; ``fill`` where there is no usable direction.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = face_normals(v, f)
    ok = np.isfinite(fn).all(axis=1)
    if not ok.all():
        fn, f = fn[ok], f[ok]
    # Corner by corner, face order: a fixed summation order, so results are reproducible to the
    # bit. One 1-D np.add.at per component is several times faster than one on (V, 3) rows.
    acc = np.zeros((3, len(v)))
    for corner in range(3):
        for c in range(3):
            np.add.at(acc[c], f[:, corner], fn[:, c])
    n = np.ascontiguousarray(acc.T)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    scale = np.linalg.norm(fn, axis=1).max(initial=0.0)
    bad = length[:, 0] <= _NORMAL_RTOL * max(scale, np.finfo(np.float64).tiny)
    n = n / np.where(bad[:, None], 1.0, length)
    n[bad] = fill
    return n


def surface_normals(xyz: np.ndarray) -> np.ndarray:
    """Unit normals of a range image from central differences of neighbouring pixels.

    Parameters
    ----------
    xyz : (H, W, 3) float
        NaN where there is no data.

    Returns
    -------
    (H, W, 3) float64
        Unit normals facing the camera (``n . p < 0``); NaN where a pixel has no
        neighbour with data along a row or a column.
    """

    def diff(axis: int) -> np.ndarray:
        fwd = np.roll(xyz, -1, axis=axis) - xyz
        bwd = xyz - np.roll(xyz, 1, axis=axis)
        idx = [slice(None)] * 3
        idx[axis] = -1
        fwd[tuple(idx)] = np.nan
        idx[axis] = 0
        bwd[tuple(idx)] = np.nan
        central = 0.5 * (fwd + bwd)
        out = np.where(np.isfinite(central), central, np.where(np.isfinite(fwd), fwd, bwd))
        return out

    n = np.cross(diff(1), diff(0))
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
    flip = np.sum(n * xyz, axis=-1, keepdims=True) > 0
    return np.where(flip, -n, n)


def unique_edges(
    faces: np.ndarray, return_inverse: bool = False
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The undirected edges of a triangle list, each once.

    Parameters
    ----------
    faces : (F, 3) int
        Triangles ``(a, b, c)``; their sides are ``ab``, ``bc`` and ``ca``.
    return_inverse : bool
        Also return, for every side of every face, the index of its edge.

    Returns
    -------
    edges : (E, 2) int64
        ``(i, j)`` with ``i < j``, sorted lexicographically; sides joining a vertex to itself
        (degenerate faces) are left out.
    inverse : (F, 3) int64
        Only with ``return_inverse``: ``edges[inverse[k, s]]`` is side ``s`` (0: ab, 1: bc,
        2: ca) of face ``k``; -1 for a side joining a vertex to itself.
    """
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    keep = e[:, 0] != e[:, 1]
    # One int64 key per edge: a 1-D unique is far faster than np.unique(axis=0).
    base = np.int64(e.max()) + 1 if e.size else np.int64(1)
    key, inverse = np.unique(e[keep, 0] * base + e[keep, 1], return_inverse=True)
    edges = np.stack(np.divmod(key, base), axis=1)
    if not return_inverse:
        return edges
    full = np.full(len(e), -1, dtype=np.int64)
    full[keep] = inverse
    return edges, full.reshape(-1, 3)


def check_vertex_array(
    value,
    field: str,
    source: str,
    n_vertices: int | None = None,
    ref: str = "the base mesh",
    hint: str = "",
) -> np.ndarray:
    """Validate a (V, 3) array of finite vertex positions; return it as float64.

    Parameters
    ----------
    value : array-like
    field : str
        Its name in messages (``"vertices"``, ``"shapes['car']"``).
    source : str
        The file or label the error names.
    n_vertices : int, optional
        Required vertex count, checked against ``ref`` (named in the message).
    hint : str
        Appended to the non-finite message (what the caller should do).

    Raises
    ------
    InputError
        Wrong shape, wrong vertex count, or NaN/inf coordinates (counted, first index named).
    """
    from scan2morph.errors import InputError

    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(source, f"{field}: expected a (V, 3) array, got shape {arr.shape}")
    if n_vertices is not None and arr.shape[0] != n_vertices:
        raise InputError(
            source, f"{field}: expected {n_vertices} vertices (as {ref}), got {arr.shape[0]}"
        )
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise InputError(
            source,
            f"{field}: {int(bad.sum())} vertices are NaN/inf (first at index {int(np.argmax(bad))}){hint}",
        )
    return arr


def edge_adjacency(edges: np.ndarray, n: int) -> sp.csr_array:
    """Symmetric 0/1 vertex adjacency (n, n) of undirected edges (E, 2) int (each once, as
    :func:`unique_edges` gives them)."""
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    rows, cols = np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]]
    return sp.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n, n))


__all__ = [
    "check_vertex_array",
    "edge_adjacency",
    "face_normals",
    "unique_edges",
    "vertex_normals",
]
