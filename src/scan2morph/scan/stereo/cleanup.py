"""Clean-up of a rectified disparity map: edge trim, small segments, small holes, erosion.

Depth discontinuities lose their background side, small disconnected segments are dropped
and small holes enclosed by one plane are filled.
"""

from __future__ import annotations

import cv2
import numpy as np


def _remove_small_segments(disparity: np.ndarray, min_px: int, step_px: float) -> np.ndarray:
    """Drop connected segments of fewer than ``min_px`` pixels (:func:`cv2.filterSpeckles`).

    Neighbours belong to one segment when their disparities differ by at most ``step_px``:
    islands of wrong matches (e.g. in an occluded band) differ from the surface around them.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    min_px : int
        Smallest segment kept, px.
    step_px : float
        Largest disparity step inside a segment, px.

    Returns
    -------
    (h, w) float32
    """
    valid = np.isfinite(disparity)
    invalid = -32768
    fixed = np.clip(np.rint(np.where(valid, disparity, 0.0) * 16.0), -32767, 32767)
    d16 = np.where(valid, fixed, invalid).astype(np.int16)
    cv2.filterSpeckles(d16, invalid, int(min_px), int(round(16.0 * step_px)))
    return np.where(d16 != invalid, disparity, np.nan).astype(np.float32)


def _fill_small_holes(
    disparity: np.ndarray, max_px: int, max_residual_px: float, allowed: np.ndarray
) -> np.ndarray:
    """Fill small holes enclosed by one consistent surface with its plane.

    A hole (4-connected unmatched pixels) of at most ``max_px`` pixels, inside ``allowed`` and
    not touching the canvas border, is filled when the disparities of its border ring (its
    8-neighbours) fit a plane in ``(x, y)`` within ``max_residual_px``; the hole gets that
    plane. Holes at depth discontinuities (a ring on two surfaces) and large holes stay.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    max_px : int
        Largest hole filled, px (area).
    max_residual_px : float
        Largest deviation of a ring pixel from the fitted plane, px.
    allowed : (h, w) bool
        Pixels that may be filled (inside the left image).

    Returns
    -------
    (h, w) float32
    """
    holes = (~np.isfinite(disparity)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(holes, connectivity=4)
    h, w = disparity.shape
    out = disparity.copy()
    ring_kernel = np.ones((3, 3), np.uint8)
    for i in np.flatnonzero(stats[:, cv2.CC_STAT_AREA] <= max_px):
        x0, y0, bw, bh = stats[i, :4]
        if i == 0 or x0 == 0 or y0 == 0 or x0 + bw >= w or y0 + bh >= h:
            continue
        box = (slice(y0 - 1, y0 + bh + 1), slice(x0 - 1, x0 + bw + 1))
        hole = labels[box] == i
        ring = cv2.dilate(hole.astype(np.uint8), ring_kernel).astype(bool) & ~hole
        ry, rx = np.nonzero(ring)
        d = disparity[box][ry, rx].astype(np.float64)
        hy, hx = np.nonzero(hole)
        if not (np.all(np.isfinite(d)) and allowed[box][hy, hx].all()):
            continue
        design = np.stack([np.ones(rx.size), rx, ry], axis=1).astype(np.float64)
        coef = np.linalg.lstsq(design, d, rcond=None)[0]
        if np.abs(d - design @ coef).max() > max_residual_px:
            continue
        out[box][hy, hx] = coef[0] + coef[1] * hx + coef[2] * hy
    return out


def _trim_discontinuities(
    disparity: np.ndarray, width: int, jump_px: float, gap_px: int
) -> np.ndarray:
    """Drop the background side of depth discontinuities, where window matching errs.

    A window that straddles a step matches the texture of the side that fills most of it, so
    the errors of the matched disparities sit on the low-disparity (background) side: the
    foreground's disparity, or garbage matched in the band the foreground hides from the right
    camera (the occluded side of an occlusion). The foreground side is kept. Two rules:

    * a pixel is dropped when a valid pixel within ``width`` px (Chebyshev) has a disparity
      more than ``jump_px`` above its own (steps in any direction, e.g. below the nose);
    * along each row (the epipolar line), where two valid pixels are separated by 1 to
      ``gap_px`` unmatched ones (an occlusion gap, or the silhouette against an untextured
      background) and their disparities differ by more than ``jump_px``, the ``width`` pixels
      of the lower side next to the gap are dropped.

    A continuous surface changes its disparity by well under ``jump_px`` per px except where
    it is seen at a grazing angle.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    width : int
        Width of the trimmed band, px (>= 1).
    jump_px : float
        Disparity step that makes a discontinuity, px.
    gap_px : int
        Longest run of unmatched pixels across which a row step still counts, px.

    Returns
    -------
    (h, w) float32
    """
    valid = np.isfinite(disparity)
    kernel = np.ones((2 * width + 1, 2 * width + 1), np.uint8)
    filled = np.where(valid, disparity, np.float32(-1e9)).astype(np.float32)
    drop = cv2.dilate(filled, kernel) - filled > jump_px
    if gap_px > 0:
        h, w = disparity.shape
        cols = np.broadcast_to(np.arange(w), (h, w))
        beyond = w + gap_px + 1
        # the next valid pixel strictly to the right of every pixel (beyond: none)
        nearest = np.minimum.accumulate(np.where(valid, cols, beyond)[:, ::-1], axis=1)[:, ::-1]
        nxt = np.concatenate([nearest[:, 1:], np.full((h, 1), beyond)], axis=1)
        gap = nxt - cols - 1
        pair = valid & (nxt < w) & (gap >= 1) & (gap <= gap_px)
        rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
        step = np.where(pair, disparity[rows, np.minimum(nxt, w - 1)] - disparity, 0.0)
        low_left = (step > jump_px).astype(np.uint8)  # this pixel is the low side
        low_right = np.zeros((h, w), np.uint8)  # the next valid pixel is the low side
        ry, rx = np.nonzero(step < -jump_px)
        low_right[ry, nxt[ry, rx]] = 1
        band = np.ones((1, width), np.uint8)
        # extend the seeds away from the gap: to the left, respectively to the right
        drop |= cv2.dilate(low_left, band, anchor=(0, 0)).astype(bool)
        drop |= cv2.dilate(low_right, band, anchor=(width - 1, 0)).astype(bool)
    return np.where(valid & ~drop, disparity, np.nan).astype(np.float32)


def _erode_valid(disparity: np.ndarray, radius: int) -> np.ndarray:
    """Drop valid pixels within ``radius`` px of an invalid one."""
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    keep = cv2.erode(np.isfinite(disparity).astype(np.uint8), kernel).astype(bool)
    return np.where(keep, disparity, np.nan).astype(np.float32)
