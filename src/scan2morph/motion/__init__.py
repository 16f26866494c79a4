"""Viseme motion: per-vertex motion vectors, the upper-face stencil mask, Laplacian smoothing,
and the motion's click-noise error bar with the click precision measured on stable landmarks."""

from scan2morph.motion.clicks import ClickedTake, clicked_take
from scan2morph.motion.mask import dijkstra_path, stencil_mask
from scan2morph.motion.precision import click_precision, resolve_click_noise
from scan2morph.motion.smooth import Relief, fill_missing, laplacian_smooth
from scan2morph.motion.uncertainty import click_noise_motion, subject_motion_noise
from scan2morph.motion.vectors import motion_vectors

__all__ = [
    "ClickedTake",
    "Relief",
    "click_noise_motion",
    "click_precision",
    "clicked_take",
    "dijkstra_path",
    "fill_missing",
    "laplacian_smooth",
    "motion_vectors",
    "resolve_click_noise",
    "stencil_mask",
    "subject_motion_noise",
]
