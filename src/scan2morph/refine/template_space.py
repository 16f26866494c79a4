"""Template space: a regular grid over the template's 2D domain (and a margin around it), onto
which each take's image is pulled back through the map its template fit defines (the fit's
thin-plate spline from template coordinates to the take's pixels). Pulling each take's colour image back
through its map gives images of the *same* template domain: where the fit put a take's vertex
on the right skin point, the neutral's and the take's pull-backs agree there; where it slid, the
two differ by a displacement that image correlation can measure.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt

from scan2morph.geometry import finite_points

#: Sub-pixel bits of the triangle rasteriser (OpenCV's fixed-point vertices).
_SHIFT = 4


@dataclass(frozen=True)
class TemplateGrid:
    """A grid over the template domain with each grid point's triangle and barycentrics.

    Attributes
    ----------
    origin : (2,) float
        Template coordinates of grid point (0, 0).
    step : float
        Grid spacing, template units.
    shape : (int, int)
        Grid (rows, columns).
    face : (rows, columns) int64
        Template triangle of each grid point, -1 outside the template.
    bary : (rows, columns, 3) float64
        Barycentric coordinates in that triangle (0 outside).
    faces : (F, 3) int64
        The template's triangles.
    """

    origin: np.ndarray
    step: float
    shape: tuple[int, int]
    face: np.ndarray
    bary: np.ndarray
    faces: np.ndarray
    margin: int = 0

    @property
    def inside(self) -> np.ndarray:
        """(rows, columns) bool: grid points inside the template."""
        return self.face >= 0

    @property
    def domain(self) -> np.ndarray:
        """(rows, columns) bool: grid points within ``margin`` grid steps of the template (the
        skin just outside the template's outline can be where an outline vertex went)."""
        if self.margin <= 0:
            return self.inside
        return distance_transform_edt(~self.inside) <= self.margin

    def points(self) -> np.ndarray:
        """(rows, columns, 2) template coordinates of every grid point."""
        gx, gy = np.meshgrid(np.arange(self.shape[1]), np.arange(self.shape[0]))
        return self.to_template(np.stack([gx, gy], axis=-1))

    def to_grid(self, points: np.ndarray) -> np.ndarray:
        """Template coordinates (n, 2) -> grid coordinates (column, row) (n, 2)."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.step

    def to_template(self, grid_points: np.ndarray) -> np.ndarray:
        """Grid coordinates (column, row) (n, 2) -> template coordinates (n, 2)."""
        return np.asarray(grid_points, dtype=np.float64) * self.step + self.origin

    def interpolate(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values (V, k) -> piecewise-linear field (rows, columns, k); NaN outside
        the template and in triangles with a non-finite vertex value."""
        values = np.asarray(values, dtype=np.float64)
        f = np.where(self.inside, self.face, 0)
        corners = values[self.faces[f]]  # (rows, cols, 3, k)
        out = np.einsum("rck,rckd->rcd", self.bary, corners)
        out[~self.inside] = np.nan
        return out


def template_grid(
    vertices2d: np.ndarray, faces: np.ndarray, step: float, margin: int = 0
) -> TemplateGrid:
    """Rasterise the template's triangles onto a grid of spacing ``step``.

    Parameters
    ----------
    vertices2d : (V, 2) float
        Template vertices, template units.
    faces : (F, 3) int
        Non-overlapping triangles.
    step : float
        Grid spacing, template units (> 0).
    margin : int
        Grid steps added around the template's bounding box (its :attr:`TemplateGrid.domain`).

    Returns
    -------
    TemplateGrid
    """
    v = np.asarray(vertices2d, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lo, hi = v.min(axis=0) - margin * step, v.max(axis=0) + margin * step
    cols, rows = (np.ceil((hi - lo) / step).astype(int) + 1).tolist()
    g = (v - lo) / step
    tri = g[faces]  # (F, 3, 2) grid coordinates
    edges = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=-1)  # (F, 2, 2)
    det = np.linalg.det(edges)
    good = np.abs(det) > 1e-12
    # each triangle's pixels, filled in C (OpenCV) with its index; shared edges go to one side
    face = np.full((rows, cols), -1, dtype=np.int32)
    fixed = np.rint(tri * (1 << _SHIFT)).astype(np.int32)
    for k in np.flatnonzero(good):
        cv2.fillPoly(face, [fixed[k]], int(k), lineType=cv2.LINE_8, shift=_SHIFT)
    face = face.astype(np.int64)
    bary = np.zeros((rows, cols, 3))
    r, c = np.nonzero(face >= 0)
    f = face[r, c]
    inv = np.zeros_like(edges)
    inv[good] = np.linalg.inv(edges[good])
    l12 = np.einsum("nij,nj->ni", inv[f], np.column_stack([c, r]) - tri[f, 0])
    bary[r, c] = np.column_stack([1.0 - l12.sum(axis=1), l12])
    return TemplateGrid(lo, float(step), (rows, cols), face, bary, faces, int(margin))


def pull_back(image: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Bilinear samples of an image at pixel positions given on a grid.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array
        Pixel (0, 0)'s centre at coordinates (0, 0).
    pixels : (rows, columns, 2) float
        (x, y) pixel positions, NaN where there is nothing to sample.

    Returns
    -------
    (rows, columns) or (rows, columns, C) float32
        NaN where ``pixels`` is NaN or outside the image.
    """
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape[:2]
    px = np.asarray(pixels, dtype=np.float32)
    bad = ~finite_points(px)
    bad |= (px[..., 0] < 0) | (px[..., 1] < 0) | (px[..., 0] > w - 1) | (px[..., 1] > h - 1)
    px = np.where(bad[..., None], -1.0, px)
    out = cv2.remap(img, px[..., 0], px[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out[bad] = np.nan
    return out
