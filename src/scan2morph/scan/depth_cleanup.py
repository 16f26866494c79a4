"""Depth-camera (RGB-D) cleanup of a range image: the far side of depth edges dropped (flying
pixels, :func:`trim_depth_edges`) and the depth noise smoothed along each pixel's ray
(:func:`smooth_depth`)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from scan2morph.scan.view import scanner_view


def _ranges(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (H, W) of every point from the scanner's centre (estimated from the pixel grid,
    see :func:`~scan2morph.scan.view.scanner_view`), and that centre (3,)."""
    view = scanner_view(xyz)
    centre = np.asarray(view.centre, dtype=np.float64) if view.estimated else np.zeros(3)
    return np.linalg.norm(xyz - centre, axis=-1), centre


def trim_depth_edges(
    xyz: np.ndarray, jump_mm: float, trim_px: int
) -> tuple[np.ndarray, np.ndarray]:
    """Drop the far side of depth edges: flying pixels and surfaces seen past a silhouette.

    A depth camera returns, at a depth edge, points between the near and the far surface
    (flying pixels), and an RGB-D image resampled onto the colour camera shows the far surface
    through the gap that the baseline opens beside a silhouette. Both lie farther from the
    scanner than a pixel ``k`` <= ``trim_px`` pixels away (chessboard distance) by more than
    ``k`` x ``jump_mm``: a range step steeper than ``jump_mm`` per pixel, which a face's own
    slopes reach only at grazing angles.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    jump_mm : float
        Least range step of a depth edge per pixel, mm.
    trim_px : int
        Half side of the square neighbourhood searched for a nearer surface, px (0: off).

    Returns
    -------
    xyz_trimmed : (H, W, 3) float64, mm (a copy)
    dropped : (H, W) bool
    """
    out = np.array(xyz, dtype=np.float64)
    if trim_px <= 0:
        return out, np.zeros(out.shape[:2], bool)
    rng, _ = _ranges(out)
    filled = np.where(np.isfinite(rng), rng, np.inf)
    dropped = np.zeros(rng.shape, bool)
    for k in range(1, trim_px + 1):  # k px away a nearer surface must be k x jump_mm nearer
        near = ndimage.minimum_filter(filled, size=2 * k + 1)
        with np.errstate(invalid="ignore"):
            dropped |= np.isfinite(rng) & (rng - near > k * jump_mm)
    out[dropped] = np.nan
    return out, dropped


def smooth_depth(xyz: np.ndarray, sigma_px: float, jump_mm: float) -> np.ndarray:
    """Edge-preserving smoothing of a depth camera's noise along each pixel's ray.

    Each point's distance from the scanner becomes the Gaussian-weighted mean (``sigma_px``,
    window of 3 sigma) of its neighbours' distances within ``jump_mm`` of its own; its direction
    is kept, so the point stays on its pixel's ray. Pixels without data stay without.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    sigma_px : float
        Gaussian standard deviation, px (0: off).
    jump_mm : float
        Neighbours farther than this in range are another surface and are left out, mm.

    Returns
    -------
    (H, W, 3) float64, mm
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if sigma_px <= 0:
        return xyz.copy()
    rng, centre = _ranges(xyz)
    r = int(np.ceil(3 * sigma_px))
    h, w = rng.shape
    pad = np.pad(rng, r, constant_values=np.nan)
    # a neighbour counts only where it is finite (``same``); 0 elsewhere, times its weight 0
    pad0 = np.where(np.isfinite(pad), pad, 0.0)
    num, den = np.zeros_like(rng), np.zeros_like(rng)
    step, same, wgt = np.empty_like(rng), np.empty(rng.shape, dtype=bool), np.empty_like(rng)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            nb = np.s_[r + dy : r + dy + h, r + dx : r + dx + w]
            with np.errstate(invalid="ignore"):  # in place: the same numbers, no new arrays
                np.abs(np.subtract(pad[nb], rng, out=step), out=step)
                np.less_equal(step, jump_mm, out=same)
            np.multiply(np.exp(-(dx * dx + dy * dy) / (2 * sigma_px**2)), same, out=wgt)
            num += np.multiply(pad0[nb], wgt, out=step)
            den += wgt
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(den > 0, num / den / rng, np.nan)
    return centre + (xyz - centre) * scale[..., None]


__all__ = ["smooth_depth", "trim_depth_edges"]
