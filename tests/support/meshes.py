"""Small analytic meshes shared by tests."""

from __future__ import annotations

import numpy as np


def grid_mesh(nx: int = 12, ny: int = 10, spacing: float = 5.0, z=None):
    """A rectangular grid of triangles in the xy plane (optionally lifted by z(x, y)), mm.

    Returns vertices (nx*ny, 3) and faces (2*(nx-1)*(ny-1), 3), counter-clockwise seen from +z.
    """
    x, y = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing)
    zz = np.zeros_like(x) if z is None else z(x, y)
    vertices = np.column_stack([x.ravel(), y.ravel(), zz.ravel()]).astype(float)
    i = np.arange(nx - 1)[None, :] + nx * np.arange(ny - 1)[:, None]
    i = i.ravel()
    faces = np.concatenate(
        [np.column_stack([i, i + 1, i + nx + 1]), np.column_stack([i, i + nx + 1, i + nx])]
    )
    return vertices, faces.astype(np.int64)


def plate_mesh(n: int, a: float = 100.0):
    """Flat square plate a x a (mm) in the z = 0 plane, n x n quads split with alternating
    diagonals."""
    xs = np.linspace(0.0, a, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    vertices = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    p = (j * (n + 1) + i).ravel()
    flip = ((i + j) % 2 == 1).ravel()[:, None]
    t1 = np.where(flip, np.c_[p, p + 1, p + n + 1], np.c_[p, p + 1, p + n + 2])
    t2 = np.where(flip, np.c_[p + 1, p + n + 2, p + n + 1], np.c_[p, p + n + 2, p + n + 1])
    return vertices, np.r_[t1, t2]
