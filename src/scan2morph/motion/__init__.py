"""Viseme motion: per-vertex motion vectors, the upper-face stencil mask and Laplacian smoothing."""

from scan2morph.motion.mask import dijkstra_path, stencil_mask
from scan2morph.motion.smooth import fill_missing, laplacian_smooth
from scan2morph.motion.vectors import motion_vectors

__all__ = ["dijkstra_path", "fill_missing", "laplacian_smooth", "motion_vectors", "stencil_mask"]
