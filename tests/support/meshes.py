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
