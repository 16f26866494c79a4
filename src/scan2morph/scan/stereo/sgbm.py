"""Semi-global matching of the rectified pair: search range, padding, matcher, left-right check.

The disparity search range follows from the expected depth range; the canvas is padded so
that SGBM's unmatched border bands hold no image content; the left and right views' disparities
(1/16 px) must agree.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

from scan2morph.scan.stereo.params import _MODES


def _sgbm_matcher(p: Mapping[str, Any], min_disp: int, num_disp: int) -> cv2.StereoSGBM:
    """The left view's semi-global matcher (:func:`cv2.StereoSGBM_create`) for parameters ``p``.

    ``P1`` and ``P2`` default to ``8 * blockSize**2`` and ``32 * blockSize**2``; OpenCV's own
    left-right check is off (:func:`_lr_consistent` replaces it).

    Parameters
    ----------
    p : mapping
        Checked parameters (:func:`~scan2morph.scan.stereo.params.stereo_params`).
    min_disp, num_disp : int
        ``minDisparity`` and ``numDisparities``, px (:func:`_disparity_range`).

    Returns
    -------
    cv2.StereoSGBM
        The matcher (disparities in 1/16 px).
    """
    block = int(p["blockSize"])
    return cv2.StereoSGBM_create(
        minDisparity=min_disp,
        numDisparities=num_disp,
        blockSize=block,
        P1=int(p["P1"] if p["P1"] is not None else 8 * block * block),
        P2=int(p["P2"] if p["P2"] is not None else 32 * block * block),
        disp12MaxDiff=-1,  # our own left-right check: _lr_consistent
        preFilterCap=int(p["preFilterCap"]),
        uniquenessRatio=int(p["uniquenessRatio"]),
        speckleWindowSize=int(p["speckleWindowSize"]),
        speckleRange=int(p["speckleRange"]),
        mode=_MODES[p["mode"]],
    )


def _depth_to_disparity(rect: Mapping[str, Any], depth_mm: np.ndarray | float) -> np.ndarray:
    """Rectified disparity of depths: ``d(Z) = (cx1 - cx2) - f Tx / Z``, px.

    Parameters
    ----------
    rect : mapping
        The rectification (``P1``, ``P2``); ``Tx = P2[0, 3] / f``, mm.
    depth_mm : float or array
        Depth along the rectified optical axis, mm (> 0).

    Returns
    -------
    array of the shape of ``depth_mm``
        Disparity, px.
    """
    P1, P2 = rect["P1"], rect["P2"]
    tx = P2[0, 3] / P2[0, 0]
    return (P1[0, 2] - P2[0, 2]) - P1[0, 0] * tx / np.asarray(depth_mm, dtype=np.float64)


def _disparity_to_depth(rect: Mapping[str, Any], disparity: np.ndarray | float) -> np.ndarray:
    """Depth of rectified disparities, mm (the inverse of :func:`_depth_to_disparity`).

    Parameters
    ----------
    rect : mapping
        The rectification (``P1``, ``P2``).
    disparity : float or array
        Disparity, px.

    Returns
    -------
    array of the shape of ``disparity``
        Depth, mm; ``inf`` for disparities at or beyond the one of infinity (no depth).
    """
    P1, P2 = rect["P1"], rect["P2"]
    tx = P2[0, 3] / P2[0, 0]
    offset = np.asarray(disparity, dtype=np.float64) - (P1[0, 2] - P2[0, 2])
    with np.errstate(divide="ignore"):
        depth = -P1[0, 0] * tx / offset
    return np.where(depth > 0, depth, np.inf)


def _disparity_range(rect: Mapping[str, Any], p: Mapping[str, Any]) -> tuple[int, int]:
    """SGBM's ``minDisparity`` and ``numDisparities`` covering the depth range of ``p``.

    In the rectified pair ``d(Z) = (cx1 - cx2) - f Tx / Z`` with ``Tx = P2[0, 3] / f``
    (:func:`_depth_to_disparity`); explicit ``minDisparity`` / ``numDisparities`` win.
    """
    if p["minDisparity"] is not None and p["numDisparities"] is not None:
        return int(p["minDisparity"]), int(p["numDisparities"])
    d = _depth_to_disparity(rect, [p["min_depth_mm"], p["max_depth_mm"]])
    lo, hi = int(np.floor(d.min())) - 1, int(np.ceil(d.max())) + 1
    min_disp = int(p["minDisparity"]) if p["minDisparity"] is not None else lo
    if p["numDisparities"] is not None:
        num_disp = int(p["numDisparities"])
    else:
        num_disp = int(16 * np.ceil(max(hi - min_disp, 16) / 16))
    return min_disp, num_disp


def _match_views(
    matcher: cv2.StereoSGBM, left: np.ndarray, right: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Semi-global matching of the left view and of the right view.

    Parameters
    ----------
    matcher : cv2.StereoSGBM
        The left view's matcher.
    left, right : (h, w) uint8
        Rectified (padded) views.

    Returns
    -------
    disp_l16, disp_r16 : (h, w) int16
        Disparities of the left and right view, 1/16 px (below the matcher's
        ``minDisparity``: no match).
    min_disp_r : int
        ``minDisparity`` of the right view's matcher, px.
    """
    disp_l16 = matcher.compute(left, right)
    right_matcher = cv2.ximgproc.createRightMatcher(matcher)
    disp_r16 = right_matcher.compute(right, left)
    return disp_l16, disp_r16, right_matcher.getMinDisparity()


def _padding(
    valid_l: np.ndarray, valid_r: np.ndarray, min_disp: int, num_disp: int
) -> tuple[int, int]:
    """Columns to add left and right so that SGBM's unmatched bands hold no image content.

    The left matcher leaves columns ``x < minDisparity + numDisparities`` (and, for a negative
    ``minDisparity``, the last ``-minDisparity``) empty; the right matcher mirrors that.
    """
    w = valid_l.shape[1]
    cols_l = np.flatnonzero(valid_l.any(axis=0))
    cols_r = np.flatnonzero(valid_r.any(axis=0))
    if cols_l.size == 0 or cols_r.size == 0:
        return 0, 0
    reach = min_disp + num_disp
    pad_l = max(0, reach - int(cols_l[0]), 1 - min_disp - int(cols_r[0]))
    pad_r = max(0, int(cols_r[-1]) + reach - w, int(cols_l[-1]) - min_disp + 1 - w)
    return pad_l, pad_r


def _pad_views(
    left: np.ndarray,
    right: np.ndarray,
    valid_l: np.ndarray,
    valid_r: np.ndarray,
    min_disp: int,
    num_disp: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Both views and their content masks on a canvas padded by :func:`_padding`.

    Parameters
    ----------
    left, right : (h, w) uint8
        Rectified views.
    valid_l, valid_r : (h, w) bool
        Their content masks.
    min_disp, num_disp : int
        SGBM's ``minDisparity`` and ``numDisparities``, px.

    Returns
    -------
    left, right : (h, w + pad_l + pad_r) uint8
        Padded views (0 in the padding).
    valid_l, valid_r : (h, w + pad_l + pad_r) bool
        Padded content masks.
    pad_l, pad_r : int
        Columns added on the left and on the right, px.
    """
    pad_l, pad_r = _padding(valid_l, valid_r, min_disp, num_disp)
    left, right, valid_l, valid_r = (
        cv2.copyMakeBorder(a, 0, 0, pad_l, pad_r, cv2.BORDER_CONSTANT, value=0)
        for a in (left, right, valid_l.view(np.uint8), valid_r.view(np.uint8))
    )
    return left, right, valid_l.astype(bool), valid_r.astype(bool), pad_l, pad_r


def _lr_consistent(
    disp_l16: np.ndarray,
    disp_r16: np.ndarray,
    matched_l: np.ndarray,
    matched_r: np.ndarray,
    max_diff_px: float,
) -> np.ndarray:
    """Left pixels whose disparity the right view confirms.

    The right matcher reports the disparity of right pixel ``xr`` as ``-d`` for the match
    ``xl = xr + d``, so a consistent pair has ``d_left + d_right ~ 0``.

    Parameters
    ----------
    disp_l16, disp_r16 : (h, w) int16
        Left and right disparity maps, 1/16 px.
    matched_l, matched_r : (h, w) bool
        Pixels with a disparity, inside their source image.
    max_diff_px : float
        Largest accepted ``|d_left + d_right|``, px.
    """
    h, w = disp_l16.shape
    d_l = disp_l16.astype(np.float32) / 16.0
    xr = np.rint(np.arange(w, dtype=np.float32)[None, :] - d_l).astype(np.int64)
    inside = matched_l & (xr >= 0) & (xr < w)
    xr = np.clip(xr, 0, w - 1)
    rows = np.arange(h)[:, None]
    agree = np.abs(d_l + disp_r16[rows, xr].astype(np.float32) / 16.0) <= max_diff_px
    return inside & matched_r[rows, xr] & agree
