"""Windowed matching on locally normalised images: texture measure, sub-pixel refinement.

Gaussian-window statistics of the rectified images and the Gauss-Newton refinement of SGBM's
disparity over a Gaussian window (removes SGBM's pixel-locking bias).
"""

from __future__ import annotations

import cv2
import numpy as np


def _local_std(image: np.ndarray, sigma: float, mask: np.ndarray | None = None) -> np.ndarray:
    """Standard deviation of the grey levels in a Gaussian window of ``sigma`` px, (h, w).

    With ``mask``, only the masked pixels count (so the black surround of a rectified image
    does not pass for texture).
    """
    img = image.astype(np.float32)
    if mask is None:
        mean = cv2.GaussianBlur(img, (0, 0), sigma)
        mean_sq = cv2.GaussianBlur(img * img, (0, 0), sigma)
    else:
        m = mask.astype(np.float32)
        norm = np.maximum(cv2.GaussianBlur(m, (0, 0), sigma), 1e-6)
        mean = cv2.GaussianBlur(img * m, (0, 0), sigma) / norm
        mean_sq = cv2.GaussianBlur(img * img * m, (0, 0), sigma) / norm
    return np.sqrt(np.maximum(mean_sq - mean * mean, 0.0))


def _normalised(image: np.ndarray, sigma: float) -> np.ndarray:
    """Image minus its local mean over its local standard deviation (Gaussian window).

    One grey level of variance is added so that flat areas stay near zero instead of
    amplifying noise.
    """
    img = image.astype(np.float32)
    mean = cv2.GaussianBlur(img, (0, 0), sigma)
    var = cv2.GaussianBlur(img * img, (0, 0), sigma) - mean * mean
    return (img - mean) / np.sqrt(np.maximum(var, 0.0) + 1.0)


def _refine_subpixel(
    left_r: np.ndarray,
    right_r: np.ndarray,
    disparity: np.ndarray,
    iterations: int,
    sigma: float,
    min_zncc: float,
) -> np.ndarray:
    """Sub-pixel refinement of a rectified disparity map by windowed Gauss-Newton.

    Minimises ``sum_q w(q - p) (L(q) - R(q - d(q)))^2`` over a correction of ``d(p)``, with
    ``w`` a Gaussian window and ``L``, ``R`` the locally normalised images (robust to gain and
    offset between the cameras); the gradient is the mean of both images' (ESM). This removes
    the pixel-locking bias of SGBM's parabola fit. Pixels that move by more than a pixel, or whose
    windowed ZNCC ends below ``min_zncc``, are dropped.

    Parameters
    ----------
    left_r, right_r : (h, w) uint8
        Rectified grey images.
    disparity : (h, w) float32
        Initial disparity, px; NaN where invalid.

    Returns
    -------
    (h, w) float32
        Refined disparity, px; NaN where invalid.
    """
    h, w = disparity.shape
    valid = np.isfinite(disparity)
    weight = valid.astype(np.float32)
    d0 = np.where(valid, disparity, 0.0).astype(np.float32)
    d = d0.copy()
    ln = _normalised(left_r, 2.0 * sigma)
    rn = _normalised(right_r, 2.0 * sigma)
    gl = cv2.Sobel(ln, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gr = cv2.Sobel(rn, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    xs = np.broadcast_to(np.arange(w, dtype=np.float32), (h, w))
    ys = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    for _ in range(iterations):
        mx = np.ascontiguousarray(xs - d)
        rw = cv2.remap(rn, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        g = 0.5 * (gl + cv2.remap(gr, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE))
        e = ln - rw
        num = cv2.GaussianBlur(weight * g * e, (0, 0), sigma)
        den = cv2.GaussianBlur(weight * g * g, (0, 0), sigma)
        step = -num / np.maximum(den, 1e-6)
        d += weight * np.clip(step, -0.5, 0.5)
    keep = valid & (np.abs(d - d0) <= 1.0)
    if min_zncc > 0:
        mx = np.ascontiguousarray(xs - d)
        rw = cv2.remap(rn, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        sll = cv2.GaussianBlur(ln * ln, (0, 0), sigma)
        srr = cv2.GaussianBlur(rw * rw, (0, 0), sigma)
        slr = cv2.GaussianBlur(ln * rw, (0, 0), sigma)
        keep &= slr >= min_zncc * np.sqrt(sll * srr)
    return np.where(keep, d, np.nan).astype(np.float32)
