"""Stencil mask over the upper face (Yano-Harada, Sec. 4.1, Fig. 7).

Seeds are the vertices on five shortest paths (Dijkstra on the mesh's edge graph, edges
weighted by their length) between empirically chosen vertex pairs; every vertex within 20 mm
(Euclidean) of a seed is *suppressed*: its viseme motion is set to zero.

The paths and spheres are computed on the **neutral** mesh. Vertices whose position is NaN
have no place on the surface: edges touching them are dropped from the graph (paths go
around them) and they are never suppressed (their motion is filled from neighbours later).
Invalid vertices that still carry finite (hole-filled) positions are used as they are.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from scan2morph.errors import InputError
from scan2morph.geometry import unique_edges


def _check_vertices(vertices: np.ndarray, source: str) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(source, f"vertices: expected (V, 3), got {v.shape}")
    return v


def _check_faces(faces: np.ndarray, n_vertices: int, source: str) -> np.ndarray:
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise InputError(source, f"faces: expected (F, 3) integer array, got {f.dtype} {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= n_vertices):
        raise InputError(source, f"faces: vertex index out of range [0, {n_vertices})")
    return f.astype(np.int64)


def _edge_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_array:
    """Sparse (V, V) graph of edge lengths (upper triangle; use with ``directed=False``)."""
    e = unique_edges(faces)
    length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    ok = np.isfinite(length)
    e, length = e[ok], length[ok]
    # A stored zero would read as "no edge"; coincident vertices get the smallest positive length.
    length = np.maximum(length, np.finfo(np.float64).tiny)
    n = len(vertices)
    return sp.csr_array((length, (e[:, 0], e[:, 1])), shape=(n, n))


def _vertex(i: object, vertices: np.ndarray, name: str, source: str) -> int:
    n = len(vertices)
    if isinstance(i, bool) or not isinstance(i, int | np.integer):
        raise InputError(source, f"{name}: expected an integer vertex index, got {i!r}")
    if not 0 <= int(i) < n:
        raise InputError(source, f"{name}: vertex index {int(i)} out of range [0, {n})")
    if not np.isfinite(vertices[int(i)]).all():
        raise InputError(source, f"{name}: vertex {int(i)} has no position (NaN)")
    return int(i)


def _trace(predecessors: np.ndarray, start: int, goal: int) -> np.ndarray:
    # Walks the predecessor tree of one Dijkstra run: one step per path vertex (tens), not per
    # mesh vertex.
    path = [goal]
    while path[-1] != start:
        path.append(int(predecessors[path[-1]]))
    return np.array(path[::-1], dtype=np.int64)


def _paths(vertices, faces, pairs, source) -> list[np.ndarray]:
    graph = _edge_graph(vertices, faces)
    starts, row = np.unique(pairs[:, 0], return_inverse=True)
    dist, pred = dijkstra(graph, directed=False, indices=starts, return_predecessors=True)
    out = []
    for k, (s, g) in enumerate(pairs):
        if not np.isfinite(dist[row[k], g]):
            raise InputError(
                source,
                f"path_pairs[{k}] = ({s}, {g}): start and goal lie in different connected "
                "components of the mesh (no path along valid edges)",
            )
        out.append(_trace(pred[row[k]], int(s), int(g)))
    return out


def dijkstra_path(
    vertices: np.ndarray, faces: np.ndarray, start: int, goal: int, source: str = "mesh"
) -> np.ndarray:
    """Shortest path along mesh edges (Dijkstra, edges weighted by their length).

    Parameters
    ----------
    vertices : (V, 3) float, mm
        Vertex positions; NaN rows are left out of the graph.
    faces : (F, 3) int
        Triangles.
    start, goal : int
        Vertex indices.
    source : str
        Label for error messages (``subject`` or a file).

    Returns
    -------
    path : (n,) int64
        Vertex indices from start to goal inclusive; consecutive vertices share an edge.

    Raises
    ------
    InputError
        Index out of range, a NaN endpoint, or start and goal in different components.
    """
    v = _check_vertices(vertices, source)
    f = _check_faces(faces, len(v), source)
    s = _vertex(start, v, "start", source)
    g = _vertex(goal, v, "goal", source)
    return _paths(v, f, np.array([[s, g]]), source)[0]


def stencil_mask(
    vertices: np.ndarray,
    faces: np.ndarray,
    path_pairs: np.ndarray,
    radius_mm: float = 20.0,
    source: str = "mesh",
) -> tuple[np.ndarray, np.ndarray]:
    """Stencil mask of the vertices whose viseme motion is suppressed.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        The neutral mesh's vertices (NaN where there is no position).
    faces : (F, 3) int
        Template faces.
    path_pairs : (P, 2) int
        (start, goal) vertex pairs of the shortest paths (the paper uses five).
    radius_mm : float
        Sphere radius around each seed, mm (paper: 20).
    source : str
        Label for error messages.

    Returns
    -------
    suppressed : (V,) bool
        Vertices within ``radius_mm`` (inclusive, Euclidean) of a seed.
    seeds : (S,) int64
        Sorted unique vertex indices on the paths.

    Raises
    ------
    InputError
        Bad shapes, indices out of range, NaN endpoints, a non-positive radius, or a pair whose
        start and goal are in different connected components.
    """
    v = _check_vertices(vertices, source)
    f = _check_faces(faces, len(v), source)
    pairs = np.asarray(path_pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or pairs.shape[0] < 1:
        raise InputError(source, f"path_pairs: expected (P, 2) with P >= 1, got {pairs.shape}")
    if not np.issubdtype(pairs.dtype, np.integer):
        raise InputError(source, f"path_pairs: expected integer vertex indices, got {pairs.dtype}")
    for k, (s, g) in enumerate(pairs):
        _vertex(s, v, f"path_pairs[{k}] start", source)
        _vertex(g, v, f"path_pairs[{k}] goal", source)
    r = float(radius_mm)
    if not (np.isfinite(r) and r > 0):
        raise InputError(source, f"radius_mm: expected a positive number, got {radius_mm!r}")

    seeds = np.unique(np.concatenate(_paths(v, f, pairs.astype(np.int64), source)))
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    d, _ = cKDTree(v[seeds]).query(v[finite], k=1)
    suppressed = np.zeros(len(v), dtype=bool)
    suppressed[finite[d <= r]] = True
    return suppressed, seeds


__all__ = ["dijkstra_path", "stencil_mask"]
