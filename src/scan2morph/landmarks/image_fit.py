"""What the image fits of a doubtful detection's features share (:mod:`scan2morph.landmarks.lips`,
:mod:`scan2morph.landmarks.brows`): the region read about the feature, a CIELAB channel of it
(smoothed), and the coordinate search."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import cv2
import numpy as np


def as_rgb8(roi: np.ndarray) -> np.ndarray:
    """An RGB(A) region (..., 3 or 4) as 8-bit RGB: floats in [0, 1] and wider integers scaled to
    0-255, NaN as 0."""
    rgb = roi[..., :3]
    if rgb.dtype == np.uint8:
        return np.ascontiguousarray(rgb)
    values = rgb.astype(np.float64)
    if np.issubdtype(rgb.dtype, np.integer):
        values *= 255.0 / np.iinfo(rgb.dtype).max
    elif np.nanmax(values, initial=0.0) <= 1.0:  # floats in [0, 1]; bool too
        values *= 255.0
    return np.clip(np.rint(np.nan_to_num(values)), 0, 255).astype(np.uint8)


def region(
    points: np.ndarray, margin: float, shape: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray] | None:
    """The box about ``points`` (n, 2) px, ``margin`` px wider on every side, within an image of
    ``shape`` (H, W, ...): its (x, y) bounds ``lo``, ``hi`` (int, inclusive); None when it is
    less than 8 px wide or high."""
    size = np.array([shape[1] - 1, shape[0] - 1])
    lo = np.clip(np.floor(points.min(axis=0) - margin), 0, size).astype(int)
    hi = np.clip(np.ceil(points.max(axis=0) + margin), 0, size).astype(int)
    return None if (hi - lo < 8).any() else (lo, hi)


def lab_channel(color: np.ndarray, lo: np.ndarray, hi: np.ndarray, channel: int):
    """CIELAB channel ``channel`` (0: ``L*``, 1: ``a*``) of ``color[lo:hi]`` (x, y px bounds,
    inclusive; 8-bit levels, float32); None for a grey region (every channel equal)."""
    roi = as_rgb8(color[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1])
    if np.ptp(roi.astype(np.int16), axis=2).max(initial=0) == 0:
        return None
    return cv2.cvtColor(roi, cv2.COLOR_RGB2LAB)[..., channel].astype(np.float32)


def smoothed_channel(
    color: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    channel: int,
    sigma: float,
    min_spread: float,
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """CIELAB channel ``channel`` of the region ``box`` (:func:`region`'s ``lo``, ``hi``) as read
    (:func:`lab_channel`) and Gaussian-smoothed by ``sigma`` px (at least 0.5), with the smoothed
    channel's standard deviation (8-bit levels); None for a grey region, or one whose smoothed
    channel varies by less than ``min_spread`` (a flat image: a camera's noise alone).

    Returns
    -------
    smooth, raw : (h, w) float32
    spread : float
    """
    raw = lab_channel(color, *box, channel)
    if raw is None:
        return None
    smooth = cv2.GaussianBlur(raw, (0, 0), max(0.5, sigma))
    spread = float(smooth.std())
    return None if spread < min_spread else (smooth, raw, spread)


def ascend(
    value: Callable[[np.ndarray], float],
    start: np.ndarray,
    score: float,
    unit: np.ndarray,
    steps: Sequence[float],
) -> tuple[np.ndarray, float]:
    """A coordinate ascent of ``value`` from ``start`` (whose value is ``score``).

    At each of ``steps`` (times ``unit``, per parameter), coarse to fine, each parameter is
    stepped up and down, a step taken whenever it raises the value, until none does.

    Returns
    -------
    best : (P,) float64
        The parameters found.
    score : float
        Their value.
    """
    best = np.asarray(start, dtype=np.float64)
    for step in steps:
        improved = True
        while improved:
            improved = False
            for k in range(len(best)):
                for sign in (1.0, -1.0):
                    t = best.copy()
                    t[k] += sign * step * unit[k]
                    v = value(t)
                    if v > score + 1e-9:
                        best, score, improved = t, v, True
    return best, score
