"""1-to-4 midpoint subdivision of the template (the paper's "high resolution" mesh)."""

from __future__ import annotations

import dataclasses

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import unique_edges


def subdivide(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One 1-to-4 midpoint subdivision.

    Parameters
    ----------
    vertices : (V, d) float
    faces : (F, 3) int

    Returns
    -------
    vertices : (V + E, d)
        The old vertices (same indices) followed by one midpoint per unique edge.
    faces : (4F, 3) int
        Each triangle (a, b, c) with midpoints (ab, bc, ca) becomes (a, ab, ca), (ab, b, bc),
        (ca, bc, c), (ab, bc, ca): orientation is kept.
    edges : (E, 2) int
        The unique edges, sorted, in the order of their midpoints.
    """
    faces = np.asarray(faces, dtype=np.int64)
    edges, inverse = unique_edges(faces, return_inverse=True)
    n_v = len(vertices)
    mid = n_v + inverse.T
    ab, bc, ca = mid
    a, b, c = faces.T
    new_faces = np.concatenate(
        [np.column_stack(t) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    )
    new_vertices = np.concatenate([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])])
    return new_vertices, new_faces, edges


def _refine_loop(loop: np.ndarray, edge_index: dict[tuple[int, int], int]) -> np.ndarray:
    """Insert the midpoint vertex between consecutive vertices of a closed loop."""
    out = []
    for i, j in zip(loop, np.roll(loop, -1), strict=True):
        out += [int(i), edge_index[(min(i, j), max(i, j))]]
    return np.asarray(out, dtype=np.int64)


def subdivide_template(template, levels: int = 1):
    """Subdivide a template ``levels`` times (0 returns it unchanged).

    Base vertex indices (fiducials, named points) are kept; the outer and mouth boundary loops
    get their midpoints inserted, in order. The canonical 2D coordinates are subdivided, so the
    warp is applied afterwards to every vertex (midpoints follow the spline, not the chords).

    Parameters
    ----------
    template : Template
        Base (or already subdivided) template.
    levels : int
        Number of 1-to-4 subdivisions (default 1, the paper's high resolution). Each level adds
        one vertex per edge (V + E vertices) and multiplies the faces by 4.

    Returns
    -------
    Template
        With ``level`` increased by ``levels``; ``fiducials``, ``named`` and ``ibug_vertex`` are
        unchanged (base indices are kept, new vertices are appended).

    Raises
    ------
    InputError
        ``levels`` is not an integer >= 0.
    """
    if isinstance(levels, bool) or int(levels) != levels or levels < 0:
        raise InputError(
            "config", f"template.subdivision_levels: expected an integer >= 0, got {levels!r}"
        )
    for _ in range(int(levels)):
        vertices, faces, edges = subdivide(template.vertices, template.faces)
        index = {(int(a), int(b)): len(template.vertices) + k for k, (a, b) in enumerate(edges)}
        template = dataclasses.replace(
            template,
            vertices=vertices,
            faces=faces,
            boundary=_refine_loop(template.boundary, index),
            mouth_boundary=_refine_loop(template.mouth_boundary, index),
            level=template.level + 1,
        )
    return template
