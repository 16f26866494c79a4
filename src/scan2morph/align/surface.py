"""A surface given by samples with normals (:class:`SampledSurface`): point-to-plane residuals
against the nearest sample, which points its data covers, and its noise."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from scan2morph.align.noise import mesh_noise
from scan2morph.errors import InputError


class SampledSurface:
    """A surface given by samples with normals (a range image's pixels): point-to-plane
    residuals against the nearest sample, and which points its data covers.

    Parameters
    ----------
    points, normals : (m, 3) float
        Samples, mm, and their unit normals (samples without a finite normal are left out).
    source : str
        Label for error messages.
    edge : (m,) bool, optional
        Samples on the edge of the data (a pixel next to one without data): a point nearest to
        one of them may lie beyond the data, and is not counted as covered.
    """

    def __init__(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        source: str = "surface",
        edge: np.ndarray | None = None,
    ):
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
            raise InputError(
                source,
                f"surface: expected (m, 3) points and normals, got {points.shape}, {normals.shape}",
            )
        edge = np.zeros(len(points), dtype=bool) if edge is None else np.asarray(edge, bool)
        if edge.shape != (len(points),):
            raise InputError(source, f"edge: expected ({len(points)},) bool, got {edge.shape}")
        ok = np.isfinite(points).all(axis=1) & np.isfinite(normals).all(axis=1)
        if not ok.any():
            raise InputError(source, "surface: no sample with a finite point and normal")
        self.points, self.normals, self.edge = points[ok], normals[ok], edge[ok]
        self.tree = cKDTree(self.points)

    def noise(self, x: np.ndarray, source: str = "surface") -> float:
        """The samples' noise where points ``x`` (n, 3) are (:func:`mesh_noise` of the nearest
        samples), mm."""
        near = np.unique(self.tree.query(x)[1])
        every = np.ones(len(self.points), dtype=bool)
        return mesh_noise(self.points, every, at=near, source=source).region(near)

    def reach(self, x: np.ndarray, noise: float) -> float:
        """How far from a sample a point on the surface near ``x`` (n, 3) can be, mm: twice the
        samples' median spacing there plus three times the ``noise`` (mm). A point whose nearest
        sample is farther is off the data (skin the scan did not see)."""
        near = np.unique(self.tree.query(x)[1])
        spacing = float(np.median(self.tree.query(self.points[near], k=2)[0][:, 1]))
        return 2.0 * spacing + 3.0 * float(noise)

    def plane(self, x: np.ndarray) -> np.ndarray:
        """(n,) signed distance of points ``x`` (n, 3) to their nearest sample's tangent plane,
        mm."""
        return self.residuals(x, np.inf)[0]

    def residuals(self, x: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(plane, seen, distance)`` of points ``x`` (n, 3): the signed distance to the nearest
        sample's tangent plane, whether the surface covers the point (that sample is within
        ``reach``, mm, and not on the data's edge, beyond which the point may lie), and the
        distance to that sample."""
        x = np.asarray(x, dtype=np.float64)
        d, j = self.tree.query(x)
        plane = np.einsum("ij,ij->i", x - self.points[j], self.normals[j])
        return plane, (d <= reach) & ~self.edge[j], d


__all__ = ["SampledSurface"]
